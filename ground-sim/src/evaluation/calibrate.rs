//! A tile's frame-wide error, measured by flying frames over the map it was made from.
//!
//! Why: a fix's covariance comes from its own residuals, and an error that shifts the whole
//! frame alike never shows in them. On smooth plains, frames binned to pixels finer than the
//! tile's fit it with such an error (mean NEES 3.1 where the σ covers the error on denser
//! floors; docs/registration.md, "What is left on the plains"). The ground segment has the map
//! before flight: it can fly simulated frames over it with the flight code, find the extra
//! isotropic σ that brings the fixes' mean NEES to 2, and write it into the tile
//! (`TileHeader::reference_sigma_m`), where nav-core adds it to every fix. The same procedure
//! runs on every map; nothing is set by hand.
//!
//! The frames come from the map's own DEM, so the map's height noise is their "truth": a tile
//! that claims height noise already carries its map-noise term
//! (`reference::map_noise_sigma_m`, session 47), which only pads these fixes. The calibration
//! then finds less frame-wide σ than it did before that term, often none; what it measures is
//! how the flyer's frames fit the map, not the map's error against the ground.

use anyhow::{Result, bail};
use indicatif::ProgressBar;
use nav_core::{NavConfig, Tile};
use serde::Serialize;

use crate::dem::Dem;
use crate::evaluation::campaign::{CampaignSpec, run_campaign};

/// Fewest scored fixes for a calibration: below that the mean NEES is too noisy to read an
/// extra σ from (its standard error is 2/√n).
pub const MIN_CALIBRATION_FIXES: usize = 50;

/// What a calibration measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Calibration {
    /// Frames flown.
    pub frames: usize,
    /// Correct fixes scored (false fixes are left out: their error is not the map's).
    pub fixes: usize,
    /// Mean NEES of those fixes under their reported covariance (2 if it is right).
    pub nees_before: f64,
    /// The extra isotropic 1σ per axis, metres, that brings the mean NEES to 2 (0 when it is
    /// 2 or less already).
    pub frame_wide_sigma_m: f64,
    /// Mean NEES with that σ added (isotropic approximation of each fix's covariance).
    pub nees_after: f64,
}

/// Mean NEES of fixes `(nees, σ)` (σ the larger principal 1σ of the fix's covariance, metres)
/// once an isotropic `extra_m` is added to each covariance: each NEES scales by σ²/(σ² + extra²)
/// (exact for an isotropic covariance, conservative otherwise).
pub fn mean_nees_with(fixes: &[(f64, f64)], extra_m: f64) -> f64 {
    if fixes.is_empty() {
        return f64::NAN;
    }
    let e2 = extra_m * extra_m;
    fixes
        .iter()
        .map(|&(n, s)| n * s * s / (s * s + e2))
        .sum::<f64>()
        / fixes.len() as f64
}

/// The smallest extra isotropic σ (metres) that brings the mean NEES of `fixes` to 2, by
/// bisection (the mean falls monotonically with it); 0 when the mean is 2 or less already.
pub fn frame_wide_sigma_m(fixes: &[(f64, f64)]) -> f64 {
    if !(mean_nees_with(fixes, 0.0) > 2.0) {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    // Bounded: 1 m doubles to at most 1 km (fixes are never that far off a kept map).
    for _ in 0..10 {
        if mean_nees_with(fixes, hi) <= 2.0 {
            break;
        }
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if mean_nees_with(fixes, mid) > 2.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Fly `spec` over `dem` against `tile` with the flight navigator and measure the tile's
/// frame-wide error.
pub fn calibrate(
    tile: Tile<'_>,
    dem: &Dem,
    spec: &CampaignSpec,
    progress: &ProgressBar,
) -> Result<Calibration> {
    let rows = run_campaign(tile, NavConfig::default(), dem, spec, progress)?;
    let fixes: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.fix && !r.false_fix)
        .filter_map(|r| Some((r.nees?, r.center_sigma_m?)))
        .filter(|(n, s)| n.is_finite() && s.is_finite() && *s > 0.0)
        .collect();
    if fixes.len() < MIN_CALIBRATION_FIXES {
        bail!(
            "calibration: {} fixes in {} frames, at least {MIN_CALIBRATION_FIXES} needed \
             (more frames, or a pixel range the map can fix)",
            fixes.len(),
            rows.len()
        );
    }
    let sigma = frame_wide_sigma_m(&fixes);
    Ok(Calibration {
        frames: rows.len(),
        fixes: fixes.len(),
        nees_before: mean_nees_with(&fixes, 0.0),
        frame_wide_sigma_m: sigma,
        nees_after: mean_nees_with(&fixes, sigma),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Fixes whose reported σ is 0.2 m but whose errors have 0.25 m per axis: the calibration
    /// finds the missing 0.15 m; fixes whose σ is right get nothing.
    #[test]
    fn finds_the_missing_sigma() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let mut normal = || crate::terrain::sfd::std_normal(&mut rng);
        let draw = |truth: f64, normal: &mut dyn FnMut() -> f64| -> Vec<(f64, f64)> {
            (0..4000)
                .map(|_| {
                    let (ex, ey) = (truth * normal(), truth * normal());
                    ((ex * ex + ey * ey) / 0.04, 0.2)
                })
                .collect()
        };
        let off = draw(0.25, &mut normal);
        let s = frame_wide_sigma_m(&off);
        assert!((s - 0.15).abs() < 0.02, "{s}");
        assert!((mean_nees_with(&off, s) - 2.0).abs() < 1e-9);
        let right = draw(0.19, &mut normal);
        assert_eq!(frame_wide_sigma_m(&right), 0.0);
        assert_eq!(frame_wide_sigma_m(&[]), 0.0);
    }
}
