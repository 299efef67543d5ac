//! Geometric correction of radar parallax: from radar geometry (azimuth line × slant range) to a
//! regular ground grid aligned with the truth DEM's georeference.
//!
//! A multilooked pixel at A1 slant range `R1` with generated height `z` lies at ground range
//! `y = y_1 + sqrt(R1² − (z_1 − z)²)` (its true position; a flat-Moon mapping would put it
//! `≈ (z − z_ref)·cot θ` nearer, the radar parallax the paper corrects). Each azimuth line is
//! then resampled along `y` by linear interpolation between consecutive valid radar pixels onto
//! the grid's column centres, and the lines are interpolated linearly along `x` onto the grid's
//! row centres. Pixels with no valid bracketing samples stay nodata and carry a [`label`].
//!
//! Grid frame: the SAR frame of the DEM the radar saw — DEM node `(row r, col c)` at
//! `x = r·p`, `y = c·p` (p = DEM pixel), so grid column `C` of a north-up output grid whose
//! pixel-corner geotransform is `t` sits at `y = t0 + (C + ½)·t1 − (X0 + ½p)` with `X0` the DEM's
//! own corner, and likewise for rows.

use crate::dem::{Dem, DemError, GeoRef};
use rayon::prelude::*;

/// Per-pixel mask codes (the `mask.tif` values).
pub mod label {
    /// Valid height.
    pub const VALID: u8 = 0;
    /// Layover: terrain facing the radar more steeply than the incidence (eq 20, `γ ≥ θ`), a fold
    /// of the generated ground positions, or a radar pixel stretched over more ground than
    /// [`super::GeocodeParams::max_gap_px`] allows.
    pub const LAYOVER: u8 = 1;
    /// Shadow: no echo above the noise (radar power far below the scene median) or terrain facing
    /// away more steeply than `90° − θ` (eq 20).
    pub const SHADOW: u8 = 2;
    /// Coherence below the threshold (height too noisy to keep).
    pub const LOW_COHERENCE: u8 = 3;
    /// Outside the radar swath or the multilooked image.
    pub const OUTSIDE: u8 = 4;

    /// The label to keep when two inputs disagree: layover, then shadow, then low coherence,
    /// then outside.
    pub fn worst(a: u8, b: u8) -> u8 {
        let rank = |l: u8| match l {
            LAYOVER => 4,
            SHADOW => 3,
            LOW_COHERENCE => 2,
            OUTSIDE => 1,
            _ => 0,
        };
        if rank(a) >= rank(b) { a } else { b }
    }

    /// Human-readable name.
    pub fn name(l: u8) -> &'static str {
        match l {
            VALID => "valid",
            LAYOVER => "layover",
            SHADOW => "shadow",
            LOW_COHERENCE => "low coherence",
            OUTSIDE => "outside",
            _ => "?",
        }
    }
}

/// A regular north-up ground grid in the SAR frame of the scene, with its georeference.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputGrid {
    /// Columns (ground range, east).
    pub width: usize,
    /// Rows (azimuth, south).
    pub height: usize,
    /// Pixel size, m.
    pub pixel_m: f64,
    /// SAR-frame `x` (along track) of row 0's centre, m.
    pub x0_m: f64,
    /// SAR-frame `y` (ground range) of column 0's centre, m.
    pub y0_m: f64,
    /// Georeference of the grid (the truth DEM's CRS).
    pub geo: GeoRef,
}

impl OutputGrid {
    /// The grid of `like` (e.g. the truth resampled to 20 m) placed in the SAR frame of
    /// `scene`, the DEM the radar saw (north-up, square pixels, node `(r, c)` at `(r·p, c·p)`).
    pub fn aligned(scene: &Dem, like: &Dem) -> Result<Self, DemError> {
        scene.pixel_m()?;
        let pixel_m = like.pixel_m()?;
        let (sx, sy) = scene.pixel_centre_m(0.0, 0.0);
        let (lx, ly) = like.pixel_centre_m(0.0, 0.0);
        Ok(Self {
            width: like.width(),
            height: like.height(),
            pixel_m,
            // Rows grow southwards (map −y) and along track (+x).
            x0_m: sy - ly,
            y0_m: lx - sx,
            geo: like.geo.clone(),
        })
    }
    /// SAR-frame `x` of row `r`'s centre, m.
    pub fn x_m(&self, r: usize) -> f64 {
        self.x0_m + r as f64 * self.pixel_m
    }
    /// SAR-frame `y` of column `c`'s centre, m.
    pub fn y_m(&self, c: usize) -> f64 {
        self.y0_m + c as f64 * self.pixel_m
    }
    /// A DEM-shaped raster on this grid.
    pub fn raster(&self, values: Vec<f32>) -> Result<Dem, DemError> {
        Dem::new(self.width, self.height, values, self.geo.clone())
    }
}

/// Geocoding limits.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GeocodeParams {
    /// Largest ground distance between two consecutive valid radar pixels of a line that is
    /// still interpolated, in output pixels (a wider gap is a radar pixel smeared over a slope
    /// facing the radar close to layover).
    pub max_gap_px: f64,
    /// How far beyond the first/last radar sample (range or azimuth) the edge value is
    /// extended, in output pixels.
    pub edge_px: f64,
}

impl Default for GeocodeParams {
    fn default() -> Self {
        Self {
            max_gap_px: 4.0,
            edge_px: 0.5,
        }
    }
}

/// Radar-geometry inputs of the geocoding: `lines × cols` multilooked pixels.
#[derive(Debug, Clone, Copy)]
pub struct RadarPixels<'a> {
    /// Multilooked lines.
    pub lines: usize,
    /// Multilooked range columns.
    pub cols: usize,
    /// SAR-frame `x` of line 0, m.
    pub x0_m: f64,
    /// Line spacing, m.
    pub dx_m: f64,
    /// Ground range `y` of every pixel, m (row-major).
    pub ground_y_m: &'a [f64],
    /// Label of every pixel ([`label`]).
    pub labels: &'a [u8],
}

/// Geocoded channels and labels on the output grid.
#[derive(Debug, Clone)]
pub struct Geocoded {
    /// One vector per input channel, `width × height`, `NaN` where not valid.
    pub channels: Vec<Vec<f64>>,
    /// Label per output pixel.
    pub labels: Vec<u8>,
}

/// Resample `channels` (each `lines × cols`, row-major) from radar geometry onto `grid`.
pub fn geocode(
    radar: &RadarPixels<'_>,
    channels: &[&[f64]],
    grid: &OutputGrid,
    p: &GeocodeParams,
) -> Geocoded {
    let (w, nch) = (grid.width, channels.len());
    let px = grid.pixel_m;
    let max_gap = p.max_gap_px * px;
    let ext = p.edge_px * px;
    // Step 1: each radar line onto the grid's columns.
    let mut line_vals = vec![f64::NAN; radar.lines * w * nch];
    let mut line_lab = vec![label::OUTSIDE; radar.lines * w];
    for k in 0..radar.lines {
        let row = k * radar.cols;
        let ys = &radar.ground_y_m[row..row + radar.cols];
        let labs = &radar.labels[row..row + radar.cols];
        let mut hits = vec![0u8; w];
        let col_range = |a: f64, b: f64| -> (usize, usize) {
            // Columns with a ≤ y_C < b.
            let lo = ((a - grid.y0_m) / px).ceil().max(0.0);
            let hi = ((b - grid.y0_m) / px).ceil().min(w as f64);
            if hi <= lo {
                (0, 0)
            } else {
                (lo as usize, hi as usize)
            }
        };
        let mut set = |c: usize, src: (usize, usize, f64), lab: u8, hits: &mut [u8]| {
            let o = k * w + c;
            if lab == label::VALID {
                hits[c] = hits[c].saturating_add(1);
                for (ch, data) in channels.iter().enumerate() {
                    let (a, b) = (data[row + src.0], data[row + src.1]);
                    line_vals[o * nch + ch] = a + src.2 * (b - a);
                }
                line_lab[o] = label::VALID;
            } else if hits[c] == 0 {
                line_lab[o] = if line_lab[o] == label::OUTSIDE {
                    lab
                } else {
                    label::worst(line_lab[o], lab)
                };
            }
        };
        for m in 0..radar.cols.saturating_sub(1) {
            let (ya, yb) = (ys[m], ys[m + 1]);
            if !(yb > ya) {
                continue;
            }
            let mut lab = label::worst(labs[m], labs[m + 1]);
            if lab == label::VALID && yb - ya > max_gap {
                lab = label::LAYOVER;
            }
            let (c0, c1) = col_range(ya, yb);
            for c in c0..c1 {
                let t = (grid.y_m(c) - ya) / (yb - ya);
                set(c, (m, m + 1, t), lab, &mut hits);
            }
        }
        // Edge extension by up to `ext` beyond the first and last sample of the line.
        if radar.cols > 0 {
            let (first, last) = (0, radar.cols - 1);
            let (c0, c1) = col_range(ys[first] - ext, ys[first]);
            for c in c0..c1 {
                if hits[c] == 0 {
                    set(c, (first, first, 0.0), labs[first], &mut hits);
                }
            }
            let (c0, c1) = col_range(ys[last], ys[last] + ext);
            for c in c0..c1 {
                if hits[c] == 0 {
                    set(c, (last, last, 0.0), labs[last], &mut hits);
                }
            }
        }
        // A column reached by two separate valid stretches is folded over: layover.
        for (c, &h) in hits.iter().enumerate() {
            if h > 1 {
                let o = k * w + c;
                line_lab[o] = label::LAYOVER;
                for ch in 0..nch {
                    line_vals[o * nch + ch] = f64::NAN;
                }
            }
        }
    }
    // Step 2: lines onto the grid's rows.
    let n = w * grid.height;
    let mut out = Geocoded {
        channels: vec![vec![f64::NAN; n]; nch],
        labels: vec![label::OUTSIDE; n],
    };
    if radar.lines == 0 {
        return out;
    }
    let last = radar.lines - 1;
    let edge_lines = ext / radar.dx_m;
    for r in 0..grid.height {
        let u = (grid.x_m(r) - radar.x0_m) / radar.dx_m;
        let (ka, kb, t) = if u < 0.0 {
            if u < -edge_lines {
                continue;
            }
            (0, 0, 0.0)
        } else if u > last as f64 {
            if u > last as f64 + edge_lines {
                continue;
            }
            (last, last, 0.0)
        } else {
            let k = (u.floor() as usize).min(last.saturating_sub(1));
            (k, (k + 1).min(last), u - k as f64)
        };
        for c in 0..w {
            let (oa, ob) = (ka * w + c, kb * w + c);
            let (la, lb) = (line_lab[oa], line_lab[ob]);
            let o = r * w + c;
            let pick = match (la == label::VALID, lb == label::VALID) {
                (true, true) => Some((oa, ob, t)),
                (true, false) if t <= 0.5 => Some((oa, oa, 0.0)),
                (false, true) if t >= 0.5 => Some((ob, ob, 0.0)),
                _ => None,
            };
            match pick {
                Some((a, b, t)) => {
                    for ch in 0..nch {
                        let (va, vb) = (line_vals[a * nch + ch], line_vals[b * nch + ch]);
                        out.channels[ch][o] = va + t * (vb - va);
                    }
                    out.labels[o] = label::VALID;
                }
                None => {
                    out.labels[o] = if t < 0.5 { la } else { lb };
                    if out.labels[o] == label::VALID {
                        out.labels[o] = if t < 0.5 { lb } else { la };
                    }
                }
            }
        }
    }
    out
}

/// Eq 20 on a generated DEM: mark pixels whose slope along the look direction makes them
/// layover (`∂z/∂y ≥ tan θ`) or shadow (`∂z/∂y ≤ −cot θ`), θ the look angle from the platform
/// at `(track_y, track_z)`. Central differences along `y` on the grid; returns the new labels
/// (existing non-valid labels are kept) and how many pixels it removed.
pub fn eq20_mask(
    heights: &[f64],
    labels: &mut [u8],
    grid: &OutputGrid,
    track_yz_m: [f64; 2],
) -> usize {
    let (w, h) = (grid.width, grid.height);
    let mut removed = 0;
    let mut new = labels.to_vec();
    for r in 0..h {
        for c in 1..w.saturating_sub(1) {
            let o = r * w + c;
            let (a, b, z) = (heights[o - 1], heights[o + 1], heights[o]);
            if !(a.is_finite() && b.is_finite() && z.is_finite()) {
                continue;
            }
            let dzdy = (b - a) / (2.0 * grid.pixel_m);
            let tan_theta = (grid.y_m(c) - track_yz_m[0]) / (track_yz_m[1] - z);
            let l = if dzdy >= tan_theta {
                label::LAYOVER
            } else if dzdy <= -1.0 / tan_theta {
                label::SHADOW
            } else {
                continue;
            };
            if new[o] == label::VALID {
                removed += 1;
            }
            new[o] = label::worst(new[o], l);
        }
    }
    labels.copy_from_slice(&new);
    removed
}

/// Ray-traced radar visibility of a DEM on `grid`, row by row in the cross-track plane of a
/// platform at `(track_y, track_z)` (m, SAR frame) looking towards `+y` (the SAR frame's look
/// direction). Returns one label per cell: [`label::SHADOW`] where a nearer cell rises above the
/// ray from the platform, [`label::LAYOVER`] where the cell's slant range is shared with another
/// cell of its row (slant range not increasing with ground range: a foreslope steeper than the
/// look angle and the cells it folds onto), [`label::VALID`] elsewhere and for non-finite heights
/// (which neither block nor are labelled).
///
/// `tol_m` is a per-cell height uncertainty, m (0 for the truth): a cell blocks a ray only if it
/// is above it by more than the two cells' tolerances, and two slant ranges count as shared only
/// if they cross by more than that — so height noise of that size makes no shadow or layover.
/// Unlike eq 20, which tests each cell's own slope, this also flags the cells a steep wall hides
/// (shadow) or folds its echo onto (layover). Only cells within `reach_m` of ground range of
/// each other are compared (the reach of the scene's highest wall, see
/// `pipeline::fold_reach_m`; infinite for the truth), so one wrong height cannot mark a whole
/// row. Cost: `O(width·height)` (sliding-window extremes), rows in parallel.
pub fn ray_trace_mask(
    heights: &[f64],
    tol_m: &[f64],
    grid: &OutputGrid,
    track_yz_m: [f64; 2],
    reach_m: f64,
) -> Vec<u8> {
    let w = grid.width;
    let reach = if reach_m.is_finite() {
        ((reach_m / grid.pixel_m).ceil().max(1.0) as usize).min(w)
    } else {
        w
    };
    let mut out = vec![label::VALID; w * grid.height];
    if w == 0 {
        return out;
    }
    out.par_chunks_mut(w)
        .enumerate()
        .for_each(|(r, labels)| trace_row(heights, tol_m, grid, track_yz_m, reach, r, labels));
    out
}

/// One row of [`ray_trace_mask`]. Each test "does any usable cell within `reach` before (or
/// after) this one exceed (or undercut) it" is a running maximum (minimum) over a sliding
/// window, kept in a monotone deque: `O(width)` per row instead of `O(width·reach)`, with the
/// same per-cell values, so the same labels.
fn trace_row(
    heights: &[f64],
    tol_m: &[f64],
    grid: &OutputGrid,
    [ty, tz]: [f64; 2],
    reach: usize,
    r: usize,
    labels: &mut [u8],
) {
    let w = labels.len();
    let row = r * w;
    let ok: Vec<bool> = (0..w).map(|c| heights[row + c].is_finite()).collect();
    let tol: Vec<f64> = (0..w)
        .map(|c| tol_m.get(row + c).copied().unwrap_or(0.0).max(0.0))
        .collect();
    let range: Vec<f64> = (0..w)
        .map(|c| (grid.y_m(c) - ty).hypot(tz - heights[row + c]))
        .collect();
    // Look-angle tangent to the lowest and the highest point a cell certainly reaches.
    let tan_lo: Vec<f64> = (0..w)
        .map(|c| (grid.y_m(c) - ty) / (tz - heights[row + c] + tol[c]))
        .collect();
    let tan_hi = |c: usize| (grid.y_m(c) - ty) / (tz - heights[row + c] - tol[c]);
    let near_far: Vec<f64> = (0..w).map(|c| range[c] - tol[c]).collect();
    let far_near: Vec<f64> = (0..w).map(|c| range[c] + tol[c]).collect();
    // Largest `tan_lo` and `range − tol` over the usable cells of [c − reach, c).
    let mut shadow_max = WindowExtreme::new(reach, true);
    let mut fold_max = WindowExtreme::new(reach, true);
    for c in 0..w {
        if ok[c] {
            let (rc, e) = (range[c], tol[c]);
            // Shadow: an earlier cell subtends a larger look angle than this one's top.
            if shadow_max.get(&tan_lo, c).is_some_and(|v| v > tan_hi(c)) {
                labels[c] = label::SHADOW;
            }
            // Layover: an earlier cell is certainly farther (a later one: below).
            if fold_max.get(&near_far, c).is_some_and(|v| v > rc + e) {
                labels[c] = label::LAYOVER;
            }
            shadow_max.push(&tan_lo, c);
            fold_max.push(&near_far, c);
        }
    }
    // Smallest `range + tol` over the usable cells of (c, c + reach]: walked from the far end.
    let mut fold_min = WindowExtreme::new(reach, false);
    for c in (0..w).rev() {
        if ok[c] {
            let (rc, e) = (range[c], tol[c]);
            if fold_min.get(&far_near, c).is_some_and(|v| v < rc - e) {
                labels[c] = label::LAYOVER;
            }
            fold_min.push(&far_near, c);
        }
    }
}

/// Running maximum (or minimum) of `values` over the cells pushed within `reach` of the
/// current one, walking in either direction: a deque of indices whose values are monotone,
/// so each cell enters and leaves once. NaN values are never pushed (they exceed nothing).
struct WindowExtreme {
    reach: usize,
    max: bool,
    idx: std::collections::VecDeque<usize>,
}

impl WindowExtreme {
    fn new(reach: usize, max: bool) -> Self {
        Self {
            reach,
            max,
            idx: std::collections::VecDeque::new(),
        }
    }

    /// `a` is at least as extreme as `b`.
    fn dominates(&self, a: f64, b: f64) -> bool {
        if self.max { a >= b } else { a <= b }
    }

    /// The extreme over pushed cells within `reach` of `c` (excluding `c`).
    fn get(&mut self, values: &[f64], c: usize) -> Option<f64> {
        while let Some(&q) = self.idx.front() {
            if q.abs_diff(c) > self.reach {
                self.idx.pop_front();
            } else {
                break;
            }
        }
        self.idx.front().map(|&q| values[q])
    }

    fn push(&mut self, values: &[f64], c: usize) {
        let v = values[c];
        if v.is_nan() {
            return;
        }
        while let Some(&q) = self.idx.back() {
            if self.dominates(v, values[q]) {
                self.idx.pop_back();
            } else {
                break;
            }
        }
        self.idx.push_back(c);
    }
}

/// Truth-side eq 20: fraction of valid pixels of a DEM on `grid` that violate `γ < θ < 90° − γ`
/// along the look direction, split into `(layover, shadow)`; plus the per-pixel flags.
pub fn eq20_fractions(
    heights: &[f32],
    grid: &OutputGrid,
    track_yz_m: [f64; 2],
) -> (f64, f64, Vec<u8>) {
    let z: Vec<f64> = heights.iter().map(|&v| f64::from(v)).collect();
    let mut labs: Vec<u8> = z
        .iter()
        .map(|v| {
            if v.is_finite() {
                label::VALID
            } else {
                label::OUTSIDE
            }
        })
        .collect();
    eq20_mask(&z, &mut labs, grid, track_yz_m);
    let valid = z.iter().filter(|v| v.is_finite()).count().max(1) as f64;
    let lay = labs.iter().filter(|&&l| l == label::LAYOVER).count() as f64;
    let sha = labs.iter().filter(|&&l| l == label::SHADOW).count() as f64;
    (lay / valid, sha / valid, labs)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The direct `O(width·height·reach)` form of [`ray_trace_mask`], the oracle of the
    /// sliding-window one.
    fn ray_trace_reference(
        heights: &[f64],
        tol_m: &[f64],
        grid: &OutputGrid,
        track_yz_m: [f64; 2],
        reach_m: f64,
    ) -> Vec<u8> {
        let (w, h) = (grid.width, grid.height);
        let [ty, tz] = track_yz_m;
        let reach = if reach_m.is_finite() {
            ((reach_m / grid.pixel_m).ceil().max(1.0) as usize).min(w)
        } else {
            w
        };
        let mut out = vec![label::VALID; w * h];
        for r in 0..h {
            let row = r * w;
            let ok = |c: usize| heights[row + c].is_finite();
            let tol = |c: usize| tol_m.get(row + c).copied().unwrap_or(0.0).max(0.0);
            let range = |c: usize| (grid.y_m(c) - ty).hypot(tz - heights[row + c]);
            // Look-angle tangent to the lowest and the highest point a cell certainly reaches.
            let tan_lo = |c: usize| (grid.y_m(c) - ty) / (tz - heights[row + c] + tol(c));
            let tan_hi = |c: usize| (grid.y_m(c) - ty) / (tz - heights[row + c] - tol(c));
            for c in (0..w).filter(|&c| ok(c)) {
                let (rc, e) = (range(c), tol(c));
                let near = (c.saturating_sub(reach)..c).filter(|&q| ok(q));
                // Shadow: an earlier cell subtends a larger look angle than this one's top.
                if near.clone().any(|q| tan_lo(q) > tan_hi(c)) {
                    out[row + c] = label::SHADOW;
                }
                // Layover: an earlier cell is certainly farther, or a later one certainly nearer.
                let far = (c + 1..(c + 1 + reach).min(w)).filter(|&q| ok(q));
                if near.clone().any(|q| range(q) - tol(q) > rc + e)
                    || far.clone().any(|q| range(q) + tol(q) < rc - e)
                {
                    out[row + c] = label::LAYOVER;
                }
            }
        }
        out
    }

    #[test]
    fn sliding_window_ray_tracing_is_the_direct_one() {
        // Rough rows with walls both ways, NaN holes and random tolerances; reach from one
        // cell to the whole row.
        let (w, h) = (97, 23);
        let g = grid(w, h, 20.0);
        let track = [-48_773.0, 100_000.0];
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut z = Vec::with_capacity(w * h);
        for _ in 0..h {
            let mut v = 0.0;
            for _ in 0..w {
                v += (next() - 0.5) * 120.0;
                z.push(if next() < 0.05 { f64::NAN } else { v });
            }
        }
        let tol: Vec<f64> = (0..w * h).map(|_| next() * 15.0).collect();
        let mut labelled = 0;
        for reach_m in [10.0, 60.0, 340.0, 1000.0, f64::INFINITY] {
            for t in [&tol[..], &[][..]] {
                let fast = ray_trace_mask(&z, t, &g, track, reach_m);
                assert_eq!(
                    fast,
                    ray_trace_reference(&z, t, &g, track, reach_m),
                    "{reach_m}"
                );
                labelled += fast.iter().filter(|&&l| l != label::VALID).count();
            }
        }
        assert!(labelled > 500, "{labelled}");
    }

    fn grid(w: usize, h: usize, px: f64) -> OutputGrid {
        OutputGrid {
            width: w,
            height: h,
            pixel_m: px,
            x0_m: 0.0,
            y0_m: 0.0,
            geo: GeoRef::local(0.0, 0.0, px, "test"),
        }
    }

    #[test]
    fn geocoding_a_stretched_line_interpolates_linearly() {
        // Two lines, 6 radar columns at irregular ground positions, channel = 2·y + x.
        let ys = [0.0, 13.0, 31.0, 44.0, 58.0, 83.0];
        let (lines, cols) = (2, ys.len());
        let mut gy = Vec::new();
        let mut v = Vec::new();
        for k in 0..lines {
            for &y in &ys {
                gy.push(y);
                v.push(2.0 * y + 20.0 * k as f64);
            }
        }
        let labs = vec![label::VALID; lines * cols];
        let radar = RadarPixels {
            lines,
            cols,
            x0_m: 0.0,
            dx_m: 20.0,
            ground_y_m: &gy,
            labels: &labs,
        };
        let g = grid(5, 2, 20.0);
        let out = geocode(&radar, &[&v], &g, &GeocodeParams::default());
        for r in 0..2 {
            for c in 0..5 {
                let want = 2.0 * (20.0 * c as f64) + 20.0 * r as f64;
                let got = out.channels[0][r * 5 + c];
                assert!((got - want).abs() < 1e-9, "({r},{c}) {got} vs {want}");
            }
        }
    }

    #[test]
    fn folds_and_invalid_pixels_become_labelled_holes() {
        // y goes 0, 20, 40, 30 (fold), 60, 80: columns 30..40 are hit twice → layover.
        let ys = [0.0, 20.0, 40.0, 30.0, 60.0, 80.0];
        let mut labs = vec![label::VALID; 6];
        let gy = ys.to_vec();
        let v: Vec<f64> = ys.iter().map(|y| y * 0.5).collect();
        let radar = RadarPixels {
            lines: 1,
            cols: 6,
            x0_m: 0.0,
            dx_m: 20.0,
            ground_y_m: &gy,
            labels: &labs,
        };
        let g = grid(9, 1, 10.0);
        let out = geocode(&radar, &[&v], &g, &GeocodeParams::default());
        assert_eq!(out.labels[3], label::LAYOVER, "{:?}", out.labels);
        assert_eq!(out.labels[1], label::VALID);
        // A low-coherence pixel leaves a hole with its label.
        labs[1] = label::LOW_COHERENCE;
        let radar = RadarPixels {
            lines: 1,
            cols: 6,
            x0_m: 0.0,
            dx_m: 20.0,
            ground_y_m: &gy,
            labels: &labs,
        };
        let out = geocode(&radar, &[&v], &g, &GeocodeParams::default());
        assert_eq!(out.labels[1], label::LOW_COHERENCE);
        assert!(out.channels[0][1].is_nan());
    }

    #[test]
    fn eq20_flags_steep_facing_and_away_slopes() {
        // Platform far to the −y side, 100 km up: θ ≈ 26° at y = 48.8 km away.
        let g = grid(10, 1, 20.0);
        let track = [-48_773.0, 100_000.0];
        // Facing slope of 30° (> θ) on the left half, 70° away on the right.
        let mut z = Vec::new();
        let mut acc = 0.0f64;
        for c in 0..10 {
            z.push(acc as f32);
            acc += if c < 5 {
                20.0 * 30f64.to_radians().tan()
            } else {
                -20.0 * 70f64.to_radians().tan()
            };
        }
        let (lay, sha, labs) = eq20_fractions(&z, &g, track);
        assert_eq!(labs[2], label::LAYOVER);
        assert_eq!(labs[7], label::SHADOW);
        assert!(lay > 0.2 && sha > 0.2);
    }

    #[test]
    fn ray_tracing_finds_hidden_and_folded_cells_beyond_eq20() {
        // θ ≈ 26° at 48.8 km ground range, 100 km up; 40 cells of 20 m.
        let g = grid(40, 1, 20.0);
        let track = [-48_773.0, 100_000.0];
        let flat = vec![0.0f64; 40];
        let none = vec![0.0f64; 40];
        assert!(
            ray_trace_mask(&flat, &none, &g, track, f64::INFINITY)
                .iter()
                .all(|&l| l == label::VALID)
        );
        // A 60 m cliff facing away at cell 10 (10 → 11): eq 20 flags only the cliff; the ray
        // over its top (descending 2.05 m per metre) hides the next 29 m, i.e. cell 11 only.
        let mut z = flat.clone();
        for v in z.iter_mut().take(11) {
            *v = 60.0;
        }
        let labs = ray_trace_mask(&z, &none, &g, track, f64::INFINITY);
        assert_eq!(labs[11], label::SHADOW, "{labs:?}");
        assert_eq!(labs[12], label::VALID, "{labs:?}");
        assert_eq!(labs[5], label::VALID);
        // With a ±40 m height tolerance nothing is certain any more.
        let loose = vec![40.0f64; 40];
        assert_eq!(
            ray_trace_mask(&z, &loose, &g, track, f64::INFINITY)[11],
            label::VALID
        );
        // A 100 m wall facing the radar between cells 20 and 21: cell 21's slant range is
        // ≈ 90 m shorter than cell 20's, so it folds onto the ~10 cells before it.
        let mut z = flat.clone();
        for v in z.iter_mut().skip(21) {
            *v = 100.0;
        }
        let labs = ray_trace_mask(&z, &none, &g, track, f64::INFINITY);
        for c in [12, 15, 20, 21, 28, 30] {
            assert_eq!(labs[c], label::LAYOVER, "cell {c}: {labs:?}");
        }
        assert_eq!(labs[5], label::VALID, "{labs:?}");
        assert_eq!(labs[35], label::VALID, "{labs:?}");
        // One wrong height (500 m too low at cell 5, ≈ 450 m too far in slant range) folds every
        // later cell within 450 m of range onto itself; a 100 m reach confines it to 5 cells.
        let mut z = flat.clone();
        z[5] = -500.0;
        assert_eq!(
            ray_trace_mask(&z, &none, &g, track, f64::INFINITY)[30],
            label::LAYOVER
        );
        let labs = ray_trace_mask(&z, &none, &g, track, 100.0);
        assert_eq!(labs[8], label::LAYOVER, "{labs:?}");
        assert_eq!(labs[30], label::VALID, "{labs:?}");
        // NaN cells neither block nor get a label.
        let mut z = flat.clone();
        z[3] = f64::NAN;
        assert!(
            ray_trace_mask(&z, &none, &g, track, f64::INFINITY)
                .iter()
                .all(|&l| l == label::VALID)
        );
    }
}
