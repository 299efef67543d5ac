//! Navigability map: from a reference tile alone (what the ground has before flight), predict
//! for every map cell whether a frame centred there will get a fix.
//!
//! Per tile pixel, over the disk a frame covers whatever its heading (radius = half the frame's
//! side on the ground), the predictor reads three things the flyer's fix depends on: how many
//! tile features lie under the frame (the matcher can only use those), how much of the reference
//! slope raster is valid there (the InSAR mask: layover, shadow, low coherence), and the slope
//! texture (standard deviation of the reference slope, degrees; the dense refinement that
//! confirms thin fixes needs it). A cell is "go" when all three clear their thresholds
//! ([`NavmapThresholds`]). The thresholds are checked, not assumed: `ground-sim suite` scores
//! the prediction at every frame's true centre against that frame's outcome.

use nav_core::Tile;
use nav_core::frame::slope_to_deg;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// When a cell is predicted "go".
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NavmapThresholds {
    /// Fewest tile features under the frame's footprint disk.
    pub min_features: f64,
    /// Smallest valid fraction of the reference slope raster under the disk.
    pub min_valid_frac: f64,
    /// Smallest standard deviation of the reference slope under the disk, degrees.
    pub min_texture_deg: f64,
}

impl Default for NavmapThresholds {
    /// [`NAVMAP_MIN_FEATURES`], [`NAVMAP_MIN_VALID_FRAC`], [`NAVMAP_MIN_TEXTURE_DEG`].
    fn default() -> Self {
        Self {
            min_features: NAVMAP_MIN_FEATURES,
            min_valid_frac: NAVMAP_MIN_VALID_FRAC,
            min_texture_deg: NAVMAP_MIN_TEXTURE_DEG,
        }
    }
}

/// Default fewest tile features under a frame's footprint for "go". Chosen on `ground-sim
/// suite` seed 1 (300 frames per campaign, flight budget) as the count above which "go" frames
/// on truth-built tiles failed least; measured, not a guarantee: "go" frames succeed 99.0 % on
/// truth-built tiles at seed 1 (plains 84–95 %) and 97.7 % at seed 2, and only 58 % / 91 % on
/// InSAR tiles, whose own map error the tile does not carry (docs/results.md has both seeds).
pub const NAVMAP_MIN_FEATURES: f64 = 30.0;
/// Default smallest valid fraction of the reference under the footprint for "go".
pub const NAVMAP_MIN_VALID_FRAC: f64 = 0.9;
/// Default smallest slope standard deviation under the footprint for "go", degrees (a floor
/// against featureless ground; higher values removed good frames without removing failures on
/// the suite).
pub const NAVMAP_MIN_TEXTURE_DEG: f64 = 1.0;

/// The map: one value per tile pixel, row-major on the tile's grid.
#[derive(Debug, Clone)]
pub struct NavMap {
    /// Width, tile pixels.
    pub width: usize,
    /// Height, tile pixels.
    pub height: usize,
    /// Radius of the footprint disk, tile pixels.
    pub radius_px: f64,
    /// Tile features under the disk centred on each pixel.
    pub features: Vec<f32>,
    /// Valid fraction of the reference slope under the disk.
    pub valid_frac: Vec<f32>,
    /// Standard deviation of the valid reference slope under the disk, degrees (NaN: none
    /// valid).
    pub texture_deg: Vec<f32>,
    /// Whether the whole disk lies inside the tile (a frame centred here fits the map).
    pub inside: Vec<bool>,
    /// Thresholds of the prediction.
    pub thresholds: NavmapThresholds,
}

/// Running row sums of one layer: `sum(row, c0..=c1)` in O(1).
struct RowSums {
    w: usize,
    acc: Vec<f64>,
}

impl RowSums {
    fn new(v: &[f64], w: usize) -> Self {
        let h = v.len() / w.max(1);
        let mut acc = vec![0.0; (w + 1) * h];
        for r in 0..h {
            for c in 0..w {
                acc[r * (w + 1) + c + 1] = acc[r * (w + 1) + c] + v[r * w + c];
            }
        }
        Self { w, acc }
    }
    fn sum(&self, r: usize, c0: usize, c1: usize) -> f64 {
        let b = r * (self.w + 1);
        self.acc[b + c1 + 1] - self.acc[b + c0]
    }
}

impl NavMap {
    /// Build the map of `tile` for frames whose footprint disk has `radius_m` on the ground
    /// (half the frame side: 1 000 m for 200 px at 10 m). Needs the tile's slope raster.
    pub fn build(
        tile: &Tile<'_>,
        radius_m: f64,
        thresholds: NavmapThresholds,
    ) -> anyhow::Result<Self> {
        let h = tile.header();
        let (w, hh) = (h.width_px as usize, h.height_px as usize);
        let raster = tile.slope_raster().ok_or_else(|| {
            anyhow::anyhow!(
                "the tile carries no slope raster (tile format ≥ v3 built by ground-sim)"
            )
        })?;
        if !(radius_m.is_finite() && radius_m > 0.0) {
            anyhow::bail!("footprint radius must be > 0 m, got {radius_m}");
        }
        let radius_px = radius_m / h.pixel_m();
        let mut count = vec![0.0f64; w * hh];
        for i in 0..tile.len() {
            let k = tile.keypoint(i);
            let (c, r) = (k.x_px.round(), k.y_px.round());
            if c >= 0.0 && r >= 0.0 && (c as usize) < w && (r as usize) < hh {
                count[r as usize * w + c as usize] += 1.0;
            }
        }
        let mut valid = vec![0.0f64; w * hh];
        let mut s1 = vec![0.0f64; w * hh];
        let mut s2 = vec![0.0f64; w * hh];
        for r in 0..hh {
            for c in 0..w {
                if let Some(v) = slope_to_deg(raster.get(c, r)).map(f64::from) {
                    let i = r * w + c;
                    valid[i] = 1.0;
                    s1[i] = v;
                    s2[i] = v * v;
                }
            }
        }
        let (cs, vs, a1, a2) = (
            RowSums::new(&count, w),
            RowSums::new(&valid, w),
            RowSums::new(&s1, w),
            RowSums::new(&s2, w),
        );
        let rad = radius_px.floor() as i64;
        let cells: Vec<(f32, f32, f32, bool)> = (0..w * hh)
            .into_par_iter()
            .map(|i| {
                let (r0, c0) = ((i / w) as i64, (i % w) as i64);
                let (mut n, mut nv, mut area, mut m1, mut m2) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for dy in -rad..=rad {
                    let half = ((radius_px * radius_px - (dy * dy) as f64).max(0.0)).sqrt() as i64;
                    let r = r0 + dy;
                    let (lo, hi) = (c0 - half, c0 + half);
                    area += (hi - lo + 1) as f64;
                    if r < 0 || r >= hh as i64 {
                        continue;
                    }
                    let (lo, hi) = (lo.max(0), hi.min(w as i64 - 1));
                    if hi < lo {
                        continue;
                    }
                    let (r, lo, hi) = (r as usize, lo as usize, hi as usize);
                    n += cs.sum(r, lo, hi);
                    nv += vs.sum(r, lo, hi);
                    m1 += a1.sum(r, lo, hi);
                    m2 += a2.sum(r, lo, hi);
                }
                let inside = r0 >= rad && c0 >= rad && r0 + rad < hh as i64 && c0 + rad < w as i64;
                let tex = if nv > 1.0 {
                    let mean = m1 / nv;
                    ((m2 / nv - mean * mean).max(0.0)).sqrt() as f32
                } else {
                    f32::NAN
                };
                (n as f32, (nv / area) as f32, tex, inside)
            })
            .collect();
        Ok(Self {
            width: w,
            height: hh,
            radius_px,
            features: cells.iter().map(|c| c.0).collect(),
            valid_frac: cells.iter().map(|c| c.1).collect(),
            texture_deg: cells.iter().map(|c| c.2).collect(),
            inside: cells.iter().map(|c| c.3).collect(),
            thresholds,
        })
    }

    /// Whether cell `i` is predicted "go" (its disk inside the tile and every threshold met).
    pub fn go(&self, i: usize) -> bool {
        let t = &self.thresholds;
        self.inside.get(i).copied().unwrap_or(false)
            && f64::from(self.features[i]) >= t.min_features
            && f64::from(self.valid_frac[i]) >= t.min_valid_frac
            && f64::from(self.texture_deg[i]) >= t.min_texture_deg
    }

    /// The cell nearest to tile pixel `(x, y)`; `None` off the map.
    pub fn cell_at(&self, x_px: f64, y_px: f64) -> Option<usize> {
        let (c, r) = (x_px.round(), y_px.round());
        (c >= 0.0 && r >= 0.0 && (c as usize) < self.width && (r as usize) < self.height)
            .then(|| r as usize * self.width + c as usize)
    }

    /// The prediction for a frame centred at tile pixel `(x, y)` (nearest cell); `false` off the
    /// map.
    pub fn go_at(&self, x_px: f64, y_px: f64) -> bool {
        self.cell_at(x_px, y_px).is_some_and(|i| self.go(i))
    }

    /// The prediction as a raster: 1 go, 0 no-go, NaN where a frame would leave the map.
    pub fn go_layer(&self) -> Vec<f32> {
        (0..self.width * self.height)
            .map(|i| {
                if !self.inside[i] {
                    f32::NAN
                } else if self.go(i) {
                    1.0
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Fraction of in-map cells predicted "go".
    pub fn go_fraction(&self) -> f64 {
        let inside = self.inside.iter().filter(|&&b| b).count();
        let go = (0..self.inside.len()).filter(|&i| self.go(i)).count();
        go as f64 / inside.max(1) as f64
    }
}

/// Go success the navigability maps are held to (issue 14): of the frames a map calls "go",
/// at least this fraction must get a correct fix.
pub const GO_SUCCESS_BAR: f64 = 0.99;

/// The best agreement any go/no-go map could reach over frames whose chances of a fix are
/// `chances` (0–1, one per frame; non-finite ones are left out), if those chances are right,
/// while the frames it calls "go" are expected to fix at `min_go_success` or better.
///
/// Why: where frames over the same ground fix at random (a chance well inside 0–1), a map of
/// cells cannot be right about each frame; it can only choose which cells to call "go". The
/// expected agreement of a choice is Σ_go p + Σ_no-go (1 − p), and among choices with the
/// same number of "go" frames the highest chances give both the most agreement and the best
/// go success, so the optimum is the longest run of the highest chances (adding a frame helps
/// while its p > 0.5) whose mean stays at `min_go_success`. A campaign whose measured
/// agreement sits near this figure is limited by its outcomes' randomness, not by the map.
/// Returns NaN when no chance is finite.
pub fn agreement_ceiling(chances: &[f64], min_go_success: f64) -> f64 {
    let mut p: Vec<f64> = chances
        .iter()
        .copied()
        .filter(|c| c.is_finite())
        .map(|c| c.clamp(0.0, 1.0))
        .collect();
    if p.is_empty() {
        return f64::NAN;
    }
    p.sort_by(|a, b| b.total_cmp(a));
    // All "no-go" first; then each prefix of the highest chances as the "go" set.
    let mut agree: f64 = p.iter().map(|c| 1.0 - c).sum();
    let mut best = agree;
    let mut go_sum = 0.0;
    for (k, c) in p.iter().enumerate() {
        go_sum += c;
        agree += 2.0 * c - 1.0;
        // A small tolerance so that chances of exactly the bar count as meeting it.
        if go_sum / (k + 1) as f64 >= min_go_success - 1e-12 {
            best = best.max(agree);
        }
    }
    best / p.len() as f64
}

/// How the prediction fared on a campaign: each frame's prediction at its true centre against
/// its outcome (a correct fix or not).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct NavmapScore {
    /// Frames predicted "go".
    pub go_frames: usize,
    /// Of those, frames with a correct fix.
    pub go_success: usize,
    /// Frames predicted "no-go".
    pub nogo_frames: usize,
    /// Of those, frames with a correct fix anyway.
    pub nogo_success: usize,
}

impl NavmapScore {
    /// Add one frame.
    pub fn add(&mut self, predicted_go: bool, success: bool) {
        if predicted_go {
            self.go_frames += 1;
            self.go_success += usize::from(success);
        } else {
            self.nogo_frames += 1;
            self.nogo_success += usize::from(success);
        }
    }
    /// Success rate of frames predicted "go" (NaN when none was).
    pub fn go_success_rate(&self) -> f64 {
        if self.go_frames == 0 {
            f64::NAN
        } else {
            self.go_success as f64 / self.go_frames as f64
        }
    }
    /// Fraction of frames whose outcome the prediction got right.
    pub fn agreement(&self) -> f64 {
        let n = self.go_frames + self.nogo_frames;
        let right = self.go_success + (self.nogo_frames - self.nogo_success);
        right as f64 / n.max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::{GO_SUCCESS_BAR, agreement_ceiling};

    #[test]
    fn the_ceiling_is_what_a_map_of_right_chances_can_agree() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        // Certain outcomes: a map can be right on every frame.
        assert!(close(
            agreement_ceiling(&[1.0, 1.0, 0.0], GO_SUCCESS_BAR),
            1.0
        ));
        // Every frame a coin weighted 1 in 4: "no-go" everywhere is right 3 times in 4, and
        // no "go" set can reach 99 %.
        assert!(close(agreement_ceiling(&[0.25; 8], GO_SUCCESS_BAR), 0.75));
        // Frames that fix 95 % of the time: without the go bar, "go" everywhere agrees 95 %;
        // with it, nothing may be called "go", and the map agrees on the 5 % that fail.
        assert!(close(agreement_ceiling(&[0.95; 10], 0.5), 0.95));
        assert!(close(agreement_ceiling(&[0.95; 10], GO_SUCCESS_BAR), 0.05));
        // A mix: the certain frames go, the 0.98 ones only as far as the mean stays at 0.99
        // (one of them beside the one certain frame: (1 + 0.98) / 2 = 0.99), the rest no-go.
        let p = [1.0, 0.98, 0.98, 0.1];
        let want = (1.0 + 0.98 + (1.0 - 0.98) + 0.9) / 4.0;
        assert!(close(agreement_ceiling(&p, GO_SUCCESS_BAR), want));
        // Frames off the map's sites are left out; none at all gives NaN.
        assert!(close(
            agreement_ceiling(&[f64::NAN, 0.25], GO_SUCCESS_BAR),
            0.75
        ));
        assert!(agreement_ceiling(&[f64::NAN], GO_SUCCESS_BAR).is_nan());
    }
}
