//! Absolute phase cycles from a coarse prior DEM, patch by patch.
//!
//! Unwrapping gives the flat-removed phase up to whole cycles. [`super::unwrap`] picks one
//! global cycle that puts the mean of the valid pixels nearest the datum. Where the relief spans
//! cycles and much of the scene is masked, that mean sits near a half cycle and the whole pass
//! lands one height of ambiguity off (183 m for the 32 m boom); and a slip where the growth
//! crossed a masked band moves everything beyond it. Such a cycle also moves the pixel on the
//! ground (by the height over tan θ), so the two looks no longer describe the same cells and no
//! fusion can mend it: on the Shackleton rim (suite, seed 1) the east-looking pass sat one cycle
//! low, 38–47 % of its pixels were thrown outside the map, and the fused map was ≈ 52 % valid
//! with a 185 m height RMSE.
//!
//! A real processor has a coarse DEM of the whole Moon before its own radar flies (LOLA's
//! gridded topography). The cycles need only that: a prior good to a fraction of the height of
//! ambiguity. Here the valid pixels are cut into *patches* (4-connected valid pixels whose
//! unwrapped phases differ by less than π: a slip line or a masked band separates them). For
//! each patch of at least [`PATCH_MIN_PIXELS`], every whole-cycle shift within
//! ±[`max_cycles`] (at least [`MAX_CYCLES`]) is tried: each pixel's height (eq 17) and ground position give a residual
//! against the prior there, and the shift with the smallest median |residual| wins. Smaller
//! patches follow the shift most voting pixels took (0 when nothing voted).
//!
//! In the simulation the prior is the truth DEM averaged over [`InsarConfig::prior_dem_cell_m`]
//! cells ([`coarse_prior`]): it decides cycles only, it never enters a height.
//!
//! [`InsarConfig::prior_dem_cell_m`]: super::pipeline::InsarConfig::prior_dem_cell_m

use serde::{Deserialize, Serialize};

use super::geocode::OutputGrid;
use crate::dem::Dem;

/// Least valid radar pixels of a patch for the prior to choose its cycles.
pub const PATCH_MIN_PIXELS: usize = 25;

/// Whole cycles tried either side of the unwrapper's choice, at least.
pub const MAX_CYCLES: i64 = 3;

/// Height, m, the cycle search spans either side of the unwrapper's choice: three cycles of
/// the 32 m boom (183 m each). A pair with a smaller height of ambiguity (a long baseline,
/// 46 m at 128 m) tries proportionally more cycles ([`max_cycles`]), as the datum rule can
/// leave it as many metres off.
pub const CYCLE_SEARCH_SPAN_M: f64 = 550.0;

/// Whole cycles to try either side for a pair whose height of ambiguity is `ambiguity_m`:
/// [`CYCLE_SEARCH_SPAN_M`] of height, rounded, and never fewer than [`MAX_CYCLES`] (nor more
/// than 64, for a bounded search).
pub fn max_cycles(ambiguity_m: f64) -> i64 {
    let k = (CYCLE_SEARCH_SPAN_M / ambiguity_m).round();
    if k.is_finite() {
        (k as i64).clamp(MAX_CYCLES, 64)
    } else {
        MAX_CYCLES
    }
}

/// Most pixels of a patch that vote (a fixed stride through larger patches), for a bounded
/// cost.
pub const MAX_VOTERS: usize = 4096;

/// A coarse DEM on the output grid, heights in metres above the datum, row-major.
#[derive(Debug, Clone, Copy)]
pub struct CyclePrior<'a> {
    /// Heights on `grid`, m.
    pub heights_m: &'a [f32],
    /// The grid they are on (SAR frame).
    pub grid: &'a OutputGrid,
}

impl CyclePrior<'_> {
    /// Bilinear height at SAR-frame `(x, y)`, m; `None` outside the grid or on nodata.
    pub fn height_at(&self, x_m: f64, y_m: f64) -> Option<f64> {
        let g = self.grid;
        if g.width == 0 || g.height == 0 || self.heights_m.len() != g.width * g.height {
            return None;
        }
        let r = (x_m - g.x0_m) / g.pixel_m;
        let c = (y_m - g.y0_m) / g.pixel_m;
        let (w, h) = (g.width, g.height);
        if !(r >= 0.0 && c >= 0.0 && r <= (h.max(1) - 1) as f64 && c <= (w.max(1) - 1) as f64) {
            return None;
        }
        let (r0, c0) = (r.floor() as usize, c.floor() as usize);
        let (r1, c1) = ((r0 + 1).min(h - 1), (c0 + 1).min(w - 1));
        let (fr, fc) = (r - r0 as f64, c - c0 as f64);
        let at = |r: usize, c: usize| f64::from(self.heights_m[r * w + c]);
        let v = (1.0 - fr) * ((1.0 - fc) * at(r0, c0) + fc * at(r0, c1))
            + fr * ((1.0 - fc) * at(r1, c0) + fc * at(r1, c1));
        v.is_finite().then_some(v)
    }
}

/// `dem` averaged over square cells of `cell_m` (a box of whole pixels, at least one) and
/// interpolated back bilinearly onto its own pixels: what a global DEM of that resolution knows.
/// Nodata pixels stay out of the averages; a cell with no data stays nodata (NaN).
pub fn coarse_prior(dem: &Dem, cell_m: f64) -> Vec<f32> {
    let (w, h) = (dem.width(), dem.height());
    let p = dem.pixel_m().unwrap_or(1.0);
    let k = ((cell_m / p).round() as usize).max(1);
    let (cw, ch) = (w.div_ceil(k), h.div_ceil(k));
    let src = dem.heights_m();
    let mut cells = vec![f64::NAN; cw * ch];
    for cr in 0..ch {
        for cc in 0..cw {
            let (mut s, mut n) = (0.0, 0usize);
            for r in cr * k..((cr + 1) * k).min(h) {
                for c in cc * k..((cc + 1) * k).min(w) {
                    let v = src[r * w + c];
                    if v.is_finite() {
                        s += f64::from(v);
                        n += 1;
                    }
                }
            }
            if n > 0 {
                cells[cr * cw + cc] = s / n as f64;
            }
        }
    }
    // Cell centres sit at (i + 0.5)·k − 0.5 pixels; clamp at the borders.
    let coord = |px: usize, cells: usize| {
        let t = ((px as f64 + 0.5) / k as f64 - 0.5).clamp(0.0, (cells - 1) as f64);
        let i0 = t.floor() as usize;
        (i0, (i0 + 1).min(cells - 1), t - i0 as f64)
    };
    let mut out = vec![f32::NAN; w * h];
    for r in 0..h {
        let (r0, r1, fr) = coord(r, ch);
        for c in 0..w {
            let (c0, c1, fc) = coord(c, cw);
            let at = |r: usize, c: usize| cells[r * cw + c];
            let v = (1.0 - fr) * ((1.0 - fc) * at(r0, c0) + fc * at(r0, c1))
                + fr * ((1.0 - fc) * at(r1, c0) + fc * at(r1, c1));
            out[r * w + c] = v as f32;
        }
    }
    out
}

/// What the prior did to the unwrapped phase (in `report.json` under `unwrap`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CycleChoice {
    /// Whether a prior chose cycles.
    pub ran: bool,
    /// Patches of at least [`PATCH_MIN_PIXELS`] valid pixels that voted.
    pub patches: usize,
    /// Of those, patches moved by a non-zero number of cycles.
    pub patches_shifted: usize,
    /// Valid pixels moved (voting patches and the small ones that follow the majority), as a
    /// fraction of all valid pixels, 0–1.
    pub pixels_shifted: f64,
    /// Median |height − prior| over the voting pixels after the choice, m (how well the prior
    /// and the map agree; a fraction of the height of ambiguity when the choice is safe);
    /// `None` when no patch voted.
    pub median_residual_m: Option<f64>,
}

/// Label the valid pixels of the `width`-wide `unw` (rad) by patch; returns (label per pixel,
/// `u32::MAX` for none; pixels per patch).
pub fn patches(unw: &[f64], valid: &[bool], width: usize) -> (Vec<u32>, Vec<usize>) {
    let n = valid.len().min(unw.len());
    let mut lab = vec![u32::MAX; n];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    let ok = |i: usize| valid[i] && unw[i].is_finite();
    for seed in 0..n {
        if lab[seed] != u32::MAX || !ok(seed) {
            continue;
        }
        let id = sizes.len() as u32;
        lab[seed] = id;
        stack.push(seed);
        let mut count = 0usize;
        while let Some(i) = stack.pop() {
            count += 1;
            let c = i % width;
            let nb = [
                (c > 0).then(|| i - 1),
                (c + 1 < width).then(|| i + 1),
                i.checked_sub(width),
                (i + width < n).then(|| i + width),
            ];
            for j in nb.into_iter().flatten() {
                if lab[j] == u32::MAX && ok(j) && (unw[j] - unw[i]).abs() < std::f64::consts::PI {
                    lab[j] = id;
                    stack.push(j);
                }
            }
        }
        sizes.push(count);
    }
    (lab, sizes)
}

/// Move each patch of `unw` (radar geometry, `width` wide, rad) by the whole cycles that best
/// agree with `prior` (module docs), trying up to `max_cycles` either side ([`max_cycles`]).
/// `place(i, phase)` gives pixel `i`'s SAR-frame ground position and height `(x, y, z)`, m,
/// for an unwrapped phase.
pub fn choose_cycles(
    unw: &mut [f64],
    valid: &[bool],
    width: usize,
    prior: &CyclePrior<'_>,
    max_cycles: i64,
    place: impl Fn(usize, f64) -> (f64, f64, f64),
) -> CycleChoice {
    let tau = std::f64::consts::TAU;
    let (lab, sizes) = patches(unw, valid, width.max(1));
    let mut members: Vec<Vec<usize>> = sizes.iter().map(|&s| Vec::with_capacity(s)).collect();
    for (i, &l) in lab.iter().enumerate() {
        if l != u32::MAX {
            members[l as usize].push(i);
        }
    }
    let mut vote: Vec<Option<i64>> = vec![None; sizes.len()];
    let mut residuals = Vec::new();
    for (p, px) in members.iter().enumerate() {
        if px.len() < PATCH_MIN_PIXELS {
            continue;
        }
        let stride = px.len().div_ceil(MAX_VOTERS).max(1);
        let voters: Vec<usize> = px.iter().step_by(stride).copied().collect();
        // (median |residual|, |k|, k): the smallest median wins, ties to the fewest cycles.
        let mut best: Option<(f64, i64, i64, Vec<f64>)> = None;
        for k in -max_cycles..=max_cycles {
            let mut res: Vec<f64> = voters
                .iter()
                .filter_map(|&i| {
                    let (x, y, z) = place(i, unw[i] + k as f64 * tau);
                    prior.height_at(x, y).map(|h| (z - h).abs())
                })
                .collect();
            if res.len() * 2 < voters.len() {
                // Most of the patch would fall off the map: not this cycle.
                continue;
            }
            res.sort_by(f64::total_cmp);
            let med = res[res.len() / 2];
            let better = match &best {
                None => true,
                Some((m, a, _, _)) => med < *m || (med == *m && k.abs() < *a),
            };
            if better {
                best = Some((med, k.abs(), k, res));
            }
        }
        if let Some((_, _, k, res)) = best {
            vote[p] = Some(k);
            residuals.extend(res);
        }
    }
    // Patches too small to vote (and any whose every cycle fell off the map) follow the shift
    // that most voting pixels chose: when the datum rule put a whole pass a cycle off, its
    // fragments are off alike; when one slip moved one region, the majority is 0.
    let mut by_shift: std::collections::BTreeMap<i64, usize> = Default::default();
    for (p, v) in vote.iter().enumerate() {
        if let Some(k) = v {
            *by_shift.entry(*k).or_default() += members[p].len();
        }
    }
    let majority = by_shift
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.abs().cmp(&a.0.abs())))
        .map_or(0, |(&k, _)| k);
    let shift: Vec<i64> = vote.iter().map(|v| v.unwrap_or(majority)).collect();
    let mut moved = 0usize;
    for (i, &l) in lab.iter().enumerate() {
        if l != u32::MAX && shift[l as usize] != 0 {
            unw[i] += shift[l as usize] as f64 * tau;
            moved += 1;
        }
    }
    residuals.sort_by(f64::total_cmp);
    let valid_total = lab.iter().filter(|&&l| l != u32::MAX).count();
    CycleChoice {
        ran: true,
        patches: vote.iter().filter(|v| v.is_some()).count(),
        patches_shifted: vote.iter().filter(|v| v.is_some_and(|k| k != 0)).count(),
        pixels_shifted: moved as f64 / valid_total.max(1) as f64,
        median_residual_m: residuals.get(residuals.len() / 2).copied(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dem::GeoRef;

    fn grid(w: usize, h: usize) -> OutputGrid {
        OutputGrid {
            width: w,
            height: h,
            pixel_m: 10.0,
            x0_m: 0.0,
            y0_m: 0.0,
            geo: GeoRef::local(0.0, 0.0, 10.0, "cycles test"),
        }
    }

    /// A toy radar: pixel i of a 40 × 30 image sits at x = 10·row, y = 10·col, and its height
    /// is 100 m per radian of phase (one cycle = 628 m, moving the pixel 50 m per cycle in y).
    /// The truth is a ramp; the right half slipped one cycle, the left quarter is one cycle low
    /// as a whole, and a masked column separates them.
    #[test]
    fn each_patch_takes_the_cycle_the_prior_agrees_with() {
        let (w, h) = (40usize, 30usize);
        let g = grid(w, h);
        let truth_h = |y: f64| 2.0 * y;
        let prior: Vec<f32> = (0..w * h)
            .map(|i| (truth_h(10.0 * (i % w) as f64) + 30.0) as f32) // 30 m off everywhere
            .collect();
        let p = CyclePrior {
            heights_m: &prior,
            grid: &g,
        };
        let tau = std::f64::consts::TAU;
        let place = |i: usize, phase: f64| {
            let (r, c) = (i / w, i % w);
            let z = 100.0 * phase;
            let dz = z - truth_h(10.0 * c as f64);
            (10.0 * r as f64, 10.0 * c as f64 + dz / 628.0 * 50.0, z)
        };
        let true_phase = |i: usize| truth_h(10.0 * (i % w) as f64) / 100.0;
        let mut valid = vec![true; w * h];
        let mut unw: Vec<f64> = (0..w * h).map(true_phase).collect();
        for i in 0..w * h {
            let c = i % w;
            if c == 10 || c == 20 {
                valid[i] = false;
            }
            if c > 20 {
                unw[i] += tau;
            }
            if c < 10 {
                unw[i] -= tau;
            }
        }
        let choice = choose_cycles(&mut unw, &valid, w, &p, MAX_CYCLES, place);
        assert_eq!(choice.patches, 3, "{choice:?}");
        assert_eq!(choice.patches_shifted, 2, "{choice:?}");
        let med = choice.median_residual_m.unwrap();
        assert!((med - 30.0).abs() < 1.0, "{choice:?}");
        for i in (0..w * h).filter(|&i| valid[i]) {
            assert!((unw[i] - true_phase(i)).abs() < 1e-9, "pixel {i}");
        }
    }

    /// A whole pass one cycle low, with a 2 × 2 island cut off by masked pixels: the island is
    /// too small to vote and follows the big patch's shift.
    #[test]
    fn small_patches_follow_the_majority_shift() {
        let (w, h) = (20usize, 20usize);
        let g = grid(w, h);
        let prior = vec![0f32; w * h];
        let p = CyclePrior {
            heights_m: &prior,
            grid: &g,
        };
        let place =
            |i: usize, phase: f64| (10.0 * (i / w) as f64, 10.0 * (i % w) as f64, 100.0 * phase);
        let tau = std::f64::consts::TAU;
        let mut unw = vec![-tau; w * h];
        let mut valid = vec![true; w * h];
        // The ring around rows 10–11, columns 10–11.
        for r in 9..13 {
            for c in 9..13 {
                valid[r * w + c] = (10..12).contains(&r) && (10..12).contains(&c);
            }
        }
        let choice = choose_cycles(&mut unw, &valid, w, &p, MAX_CYCLES, place);
        assert_eq!(
            (choice.patches, choice.patches_shifted),
            (1, 1),
            "{choice:?}"
        );
        assert!((choice.pixels_shifted - 1.0).abs() < 1e-12, "{choice:?}");
        for i in (0..w * h).filter(|&i| valid[i]) {
            assert!(unw[i].abs() < 1e-9, "pixel {i}: {}", unw[i]);
        }
        // Nothing votes when every patch is small: nothing moves and no residual is claimed.
        let mut specks = vec![-tau; 4];
        let c = choose_cycles(&mut specks, &[true; 4], 2, &p, MAX_CYCLES, place);
        assert_eq!(c.patches, 0);
        assert_eq!(c.median_residual_m, None);
        assert!(specks.iter().all(|&v| v == -tau));
    }

    #[test]
    fn patches_split_at_masked_pixels_and_at_slips() {
        // One row: 0.1 rad steps, a slip of 2π between pixels 3 and 4, pixel 7 masked.
        let tau = std::f64::consts::TAU;
        let unw = [
            0.0,
            0.1,
            0.2,
            0.3,
            0.4 + tau,
            0.5 + tau,
            0.6 + tau,
            0.7,
            0.8,
            0.9,
        ];
        let mut valid = [true; 10];
        valid[7] = false;
        let (lab, sizes) = patches(&unw, &valid, 10);
        assert_eq!(sizes, vec![4, 3, 2]);
        assert_eq!(lab[7], u32::MAX);
        assert_eq!((lab[0], lab[4], lab[9]), (0, 1, 2));
    }

    #[test]
    fn the_coarse_prior_keeps_a_plane_and_averages_relief_away() {
        let (w, h) = (48usize, 36usize);
        let plane: Vec<f32> = (0..w * h)
            .map(|i| (3.0 * (i % w) as f64 - 2.0 * (i / w) as f64) as f32)
            .collect();
        let dem = Dem::new(
            w,
            h,
            plane.clone(),
            GeoRef::local(0.0, 0.0, 10.0, "cycles test"),
        )
        .unwrap();
        let out = coarse_prior(&dem, 12.0 * dem.pixel_m().unwrap());
        // Interior pixels (between the outermost cell centres) are exact for a plane.
        for r in 6..h - 6 {
            for c in 6..w - 6 {
                let i = r * w + c;
                assert!(
                    (out[i] - plane[i]).abs() < 1e-3,
                    "{r},{c}: {} {}",
                    out[i],
                    plane[i]
                );
            }
        }
        // A checkerboard of ±50 m averages to nothing.
        let chk: Vec<f32> = (0..w * h)
            .map(|i| {
                if (i % w + i / w) % 2 == 0 {
                    50.0
                } else {
                    -50.0
                }
            })
            .collect();
        let dem = Dem::new(w, h, chk, GeoRef::local(0.0, 0.0, 10.0, "cycles test")).unwrap();
        let out = coarse_prior(&dem, 12.0 * dem.pixel_m().unwrap());
        assert!(out.iter().all(|v| v.abs() < 1e-3));
    }
}
