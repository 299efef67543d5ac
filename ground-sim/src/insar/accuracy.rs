//! Accuracy of the generated DEM against the truth on the same grid.
//!
//! The truth is the input DEM resampled to the output grid (block mean for an integer pixel
//! ratio — the same multilooking of the terrain the radar's window performs — bilinear
//! otherwise). Heights and slopes (nav-core's Horn slope of each DEM) are compared where both
//! are valid. The Cramér–Rao height bound is the RMS over valid pixels of
//! `σ_h = σ_φ(γ, N)·h_amb/2π`, with each pixel's measured coherence γ and the window's
//! equivalent looks N.

use serde::Serialize;

use super::demfilter::filter_dem;
use super::geocode::{eq20_fractions, label, ray_trace_mask};
use super::pipeline::InsarProduct;
use crate::dem::stats::slope_deg;
use crate::dem::{Dem, DemError};

/// How far (output pixels, Chebyshev) a masked pixel may lie from a truth pixel in geometric
/// shadow or layover and still count as explained by the geometry: one pixel, because each
/// pixel's height comes from a multilook window two output pixels wide, so a window centred
/// next to a folded or hidden pixel already mixes its echo in.
pub const GEOMETRY_MATCH_PX: usize = 1;

/// Accuracy figures (the core of `report.json`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Accuracy {
    /// RMS of (InSAR − truth) over pixels valid in both, m.
    pub height_rmse_m: f64,
    /// Mean of (InSAR − truth), m.
    pub height_bias_m: f64,
    /// Standard deviation of (InSAR − truth), m.
    pub height_std_m: f64,
    /// 95th percentile of |InSAR − truth|, m.
    pub height_abs_p95_m: f64,
    /// RMS slope difference over pixels with a valid slope in both, degrees.
    pub slope_rmse_deg: f64,
    /// Mean slope difference, degrees.
    pub slope_bias_deg: f64,
    /// Valid InSAR heights over valid truth pixels of the grid.
    pub valid_fraction: f64,
    /// 1 − valid fraction.
    pub masked_fraction: f64,
    /// Mean coherence over the valid pixels.
    pub coherence_mean: f64,
    /// RMS Cramér–Rao height bound over the valid pixels, m.
    pub crlb_height_m: f64,
    /// `height_rmse_m / crlb_height_m`.
    pub rmse_over_crlb: f64,
    /// Truth pixels violating eq 20 on the layover side (`γ ≥ θ` towards the radar).
    pub eq20_layover_fraction: f64,
    /// Truth pixels violating eq 20 on the shadow side (`γ ≥ 90° − θ` away from the radar).
    pub eq20_shadow_fraction: f64,
    /// Of the truth pixels violating eq 20, the fraction masked in the product (within one
    /// pixel); 1 when there are none.
    pub eq20_masked_fraction: f64,
    /// Truth pixels in geometric layover, ray-traced on the truth ([`ray_trace_mask`], no
    /// tolerance): folded onto another pixel's slant range.
    pub geometric_layover_fraction: f64,
    /// Truth pixels in geometric shadow, ray-traced on the truth: hidden from the radar.
    pub geometric_shadow_fraction: f64,
    /// Pixels masked in the product (any code but valid or outside) farther than
    /// [`GEOMETRY_MATCH_PX`] from every truth pixel in geometric shadow or layover, over the
    /// truth's valid pixels: what the mask takes beyond the geometry (0 for a noise-free run).
    pub masked_outside_geometry_fraction: f64,
    /// Pixels compared (heights).
    pub compared_pixels: usize,
    /// Height RMSE against the truth seen through the multilook window instead (a box of the
    /// window's ground size centred on each pixel, see [`window_truth`]): the error left once
    /// the product's coarser resolution is accounted for, m.
    pub height_rmse_window_matched_m: f64,
    /// Slope RMSE against the window-matched truth, degrees.
    pub slope_rmse_window_matched_deg: f64,
    /// Height RMSE against the truth through the chain's whole resolution: the window-matched
    /// truth passed through the product's DEM filter (its `config`'s), m. What is left is
    /// the error the bound speaks of (noise); the rest of [`Self::height_rmse_m`] is relief
    /// the chain flattens (a crater floor raised by `σ²/2·∇²h`), not noise. With a long pair
    /// at its own filter width (`InsarConfig::long_filter_sigma_px`) its cells were filtered
    /// otherwise, and the figure is approximate there.
    pub height_rmse_resolution_matched_m: f64,
    /// [`Self::height_rmse_resolution_matched_m`] over [`Self::crlb_height_m`].
    pub rmse_over_crlb_resolution_matched: f64,
}

/// The truth averaged over a `side_m × side_m` ground box centred on every pixel of the grid of
/// `like` (same georeference): what a noise-free multilook of that footprint would measure.
/// Truth pixels whose centres lie on the box edge count half (a quarter at a corner).
pub fn window_truth(truth: &Dem, like: &Dem, side_m: f64) -> Result<Dem, DemError> {
    let p = truth.pixel_m()?;
    let (sx, sy) = truth.pixel_centre_m(0.0, 0.0);
    let hw = 0.5 * side_m / p;
    let (tw, th) = (truth.width() as i64, truth.height() as i64);
    let (w, h) = (like.width(), like.height());
    let mut out = vec![f32::NAN; w * h];
    let weight = |d: f64| -> f64 {
        let e = (d.abs() - hw).abs();
        if e < 1e-6 {
            0.5
        } else if d.abs() < hw {
            1.0
        } else {
            0.0
        }
    };
    for r in 0..h {
        for c in 0..w {
            let (x, y) = like.pixel_centre_m(c as f64, r as f64);
            // Centre in truth pixel coordinates.
            let (u, v) = ((x - sx) / p, (sy - y) / p);
            let (mut acc, mut wsum) = (0.0f64, 0.0f64);
            let mut bad = false;
            for j in (v - hw).floor() as i64..=(v + hw).ceil() as i64 {
                let wy = weight(j as f64 - v);
                if wy == 0.0 {
                    continue;
                }
                for i in (u - hw).floor() as i64..=(u + hw).ceil() as i64 {
                    let wx = weight(i as f64 - u);
                    if wx == 0.0 {
                        continue;
                    }
                    if i < 0 || j < 0 || i >= tw || j >= th {
                        bad = true;
                        continue;
                    }
                    match truth.get(i as usize, j as usize) {
                        Some(z) => {
                            acc += wx * wy * f64::from(z);
                            wsum += wx * wy;
                        }
                        None => bad = true,
                    }
                }
            }
            if !bad && wsum > 0.0 {
                out[r * w + c] = (acc / wsum) as f32;
            }
        }
    }
    Dem::new(w, h, out, like.geo.clone())
}

fn height_and_slope_rmse(product: &Dem, truth: &Dem) -> Result<(f64, f64), DemError> {
    let d: Vec<f64> = product
        .heights_m()
        .iter()
        .zip(truth.heights_m())
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| f64::from(*a) - f64::from(*b))
        .collect();
    let (ps, ts) = (slope_deg(product)?, slope_deg(truth)?);
    let s: Vec<f64> = ps
        .iter()
        .zip(&ts)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| f64::from(*a) - f64::from(*b))
        .collect();
    Ok((rms_bias(&d).0, rms_bias(&s).0))
}

fn rms_bias(d: &[f64]) -> (f64, f64, f64) {
    if d.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let n = d.len() as f64;
    let bias = d.iter().sum::<f64>() / n;
    let rms = (d.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    let std = (d.iter().map(|v| (v - bias).powi(2)).sum::<f64>() / n).sqrt();
    (rms, bias, std)
}

/// Compare `p` with the truth on its grid (`truth_grid`: same size and georeference), and with
/// the window-matched truth `window_truth` when given.
pub fn compare(
    p: &InsarProduct,
    truth_grid: &Dem,
    window_truth: Option<&Dem>,
) -> Result<Accuracy, DemError> {
    let (w, h) = (p.grid.width, p.grid.height);
    if truth_grid.width() != w || truth_grid.height() != h {
        return Err(DemError::Invalid(format!(
            "truth grid {}x{} vs product {w}x{h}",
            truth_grid.width(),
            truth_grid.height()
        )));
    }
    let tz = truth_grid.heights_m();
    let iz = p.dem.heights_m();
    let mut dh = Vec::new();
    let (mut truth_valid, mut valid) = (0usize, 0usize);
    let (mut coh, mut crlb2) = (0.0f64, 0.0f64);
    for i in 0..w * h {
        if !tz[i].is_finite() {
            continue;
        }
        truth_valid += 1;
        if iz[i].is_finite() {
            valid += 1;
            dh.push(f64::from(iz[i]) - f64::from(tz[i]));
            coh += f64::from(p.coherence.heights_m()[i]);
            crlb2 += f64::from(p.crlb_m.heights_m()[i]).powi(2);
        }
    }
    let (height_rmse_m, height_bias_m, height_std_m) = rms_bias(&dh);
    let mut abs: Vec<f64> = dh.iter().map(|v| v.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let height_abs_p95_m = abs
        .get(((abs.len() as f64 * 0.95) as usize).min(abs.len().saturating_sub(1)))
        .copied()
        .unwrap_or(f64::NAN);
    let ts = slope_deg(truth_grid)?;
    let is = slope_deg(&p.dem)?;
    let ds: Vec<f64> = ts
        .iter()
        .zip(&is)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| f64::from(*b) - f64::from(*a))
        .collect();
    let (slope_rmse_deg, slope_bias_deg, _) = rms_bias(&ds);
    let valid_fraction = valid as f64 / truth_valid.max(1) as f64;
    let crlb_height_m = (crlb2 / valid.max(1) as f64).sqrt();

    let (lay, sha, flags) = eq20_fractions(tz, &p.grid, p.geometry.a1_yz_m);
    let mut viol = 0usize;
    let mut viol_masked = 0usize;
    for r in 0..h {
        for c in 0..w {
            let i = r * w + c;
            if !matches!(flags[i], label::LAYOVER | label::SHADOW) {
                continue;
            }
            viol += 1;
            let near_mask = (r.saturating_sub(1)..(r + 2).min(h)).any(|rr| {
                (c.saturating_sub(1)..(c + 2).min(w))
                    .any(|cc| p.labels[rr * w + cc] != label::VALID)
            });
            if near_mask {
                viol_masked += 1;
            }
        }
    }
    let tz64: Vec<f64> = tz.iter().map(|&v| f64::from(v)).collect();
    let traced = ray_trace_mask(&tz64, &[], &p.grid, p.geometry.a1_yz_m, f64::INFINITY);
    let frac = |l: u8| {
        traced
            .iter()
            .zip(&tz64)
            .filter(|(t, z)| **t == l && z.is_finite())
            .count() as f64
            / truth_valid.max(1) as f64
    };
    let m = GEOMETRY_MATCH_PX;
    let mut outside_geometry = 0usize;
    for r in 0..h {
        for c in 0..w {
            let i = r * w + c;
            if matches!(p.labels[i], label::VALID | label::OUTSIDE) || !tz64[i].is_finite() {
                continue;
            }
            let near_geometry = (r.saturating_sub(m)..(r + m + 1).min(h)).any(|rr| {
                (c.saturating_sub(m)..(c + m + 1).min(w))
                    .any(|cc| traced[rr * w + cc] != label::VALID)
            });
            if !near_geometry {
                outside_geometry += 1;
            }
        }
    }
    let (height_rmse_window_matched_m, slope_rmse_window_matched_deg) = match window_truth {
        Some(t) => height_and_slope_rmse(&p.dem, t)?,
        None => (f64::NAN, f64::NAN),
    };
    let height_rmse_resolution_matched_m = match window_truth {
        Some(t) if t.width() == w && t.height() == h => {
            let z: Vec<f64> = t.heights_m().iter().map(|&v| f64::from(v)).collect();
            let filtered = filter_dem(&z, w, h, p.config.filter());
            let resolution = p
                .grid
                .raster(filtered.iter().map(|&v| v as f32).collect())?;
            height_and_slope_rmse(&p.dem, &resolution)?.0
        }
        _ => f64::NAN,
    };
    Ok(Accuracy {
        height_rmse_window_matched_m,
        slope_rmse_window_matched_deg,
        height_rmse_resolution_matched_m,
        rmse_over_crlb_resolution_matched: height_rmse_resolution_matched_m / crlb_height_m,
        height_rmse_m,
        height_bias_m,
        height_std_m,
        height_abs_p95_m,
        slope_rmse_deg,
        slope_bias_deg,
        valid_fraction,
        masked_fraction: 1.0 - valid_fraction,
        coherence_mean: coh / valid.max(1) as f64,
        crlb_height_m,
        rmse_over_crlb: height_rmse_m / crlb_height_m,
        eq20_layover_fraction: lay,
        eq20_shadow_fraction: sha,
        eq20_masked_fraction: if viol == 0 {
            1.0
        } else {
            viol_masked as f64 / viol as f64
        },
        geometric_layover_fraction: frac(label::LAYOVER),
        geometric_shadow_fraction: frac(label::SHADOW),
        masked_outside_geometry_fraction: outside_geometry as f64 / truth_valid.max(1) as f64,
        compared_pixels: dh.len(),
    })
}
