//! The detector's noise floor: how strong a Hessian response the flyer's own measurement noise
//! produces on perfectly flat ground, after the frame goes through the same binning, smoothing
//! and slope as in flight. A reference tile's detector threshold is set a margin above it
//! ([`auto_threshold`]), so frames and tile keep every blob the sensor can tell from noise, on
//! gentle terrain as on rough: a fixed absolute threshold (0.1 deg² before) finds nothing on
//! smooth plains, where slopes are a fifth of a cratered floor's and responses a 25th.
//!
//! Why a simulation and not a formula: the response is a product of box-filtered second
//! derivatives of a binned, Gaussian-smoothed, dropout-filled slope magnitude; its noise
//! statistics have no closed form worth trusting, but nav-core's own code run on noise frames
//! gives them exactly. The draw is seeded, so a tile's threshold is reproducible.

use anyhow::{Result, bail};
use nav_core::slope::slope_into_binned_smoothed;
use nav_core::surf::{Scratch, scratch_len};
use nav_core::{DemPatch, Features, SlopePx, SurfConfig, extract};
use rand::SeedableRng;

use crate::terrain::sfd::std_normal;

/// Noise frames simulated per floor estimate. The floor is the largest response over all of
/// them: 16 frames of 200² pixels are 640 000 pixels of pure noise, more than a 4 km tile at
/// 5 m, so a blob above the floor is rarer than one per map.
pub const FLOOR_FRAMES: usize = 16;
/// Threshold over floor: a response must be this many times the strongest pure-noise response.
/// Responses scale with slope², so 2 means slopes √2 above the noise's strongest blob.
pub const FLOOR_MARGIN: f32 = 2.0;
/// Seed of the noise frames (fixed: the floor is a property of the sensor, not of a campaign).
pub const FLOOR_SEED: u64 = 0x5EED_F1A7;

/// The flyer's ranging sensor as the detector sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameNoise {
    /// Frame side, pixels (square frames).
    pub side_px: usize,
    /// Frame ground sample distance, metres.
    pub pixel_m: f64,
    /// 1σ white height (range) noise per pixel, metres.
    pub height_sigma_m: f64,
}

impl FrameNoise {
    /// The ground segment's default sensor (`crate::flyer::frames::SensorModel::default()`:
    /// 200 px frames, 0.5 m range noise) at the campaigns' nominal 10 m pixels.
    pub fn default_sensor() -> Self {
        let s = crate::flyer::frames::SensorModel::default();
        Self {
            side_px: s.width_px.min(s.height_px),
            pixel_m: NOMINAL_FRAME_PIXEL_M,
            height_sigma_m: s.range_noise_m,
        }
    }
}

/// Nominal frame pixel of the campaigns (9–11 m: frames at half the 20 m tile's pixel), metres.
pub const NOMINAL_FRAME_PIXEL_M: f64 = 10.0;

/// The noise floor, deg² of slope (the detector's response unit), of frames with `noise`
/// against a tile of `tile_pixel_m` metres carrying terrain smoothing `smoothing_m` (metres),
/// with the detector settings `surf` (its threshold ignored): the largest response SURF finds
/// on [`FLOOR_FRAMES`] flat frames of white height noise, binned and smoothed as the navigator
/// does (`nav_core::navigator::bin_factor_for`, `matched_smoothing_px`: the same functions).
pub fn noise_floor(
    noise: &FrameNoise,
    tile_pixel_m: f64,
    smoothing_m: f64,
    surf: &SurfConfig,
) -> Result<f32> {
    let valid = noise.pixel_m > 0.0
        && tile_pixel_m > 0.0
        && noise.height_sigma_m >= 0.0
        && smoothing_m >= 0.0
        && noise.side_px >= 16;
    if !valid {
        bail!(
            "noise floor: frame pixel, tile pixel and side must be positive, noise and smoothing >= 0"
        );
    }
    if noise.height_sigma_m == 0.0 {
        return Ok(0.0);
    }
    let k = nav_core::navigator::bin_factor_for(tile_pixel_m as f32, noise.pixel_m as f32);
    let binned_m = noise.pixel_m * k as f64;
    let sigma_px = nav_core::navigator::matched_smoothing_px(
        smoothing_m as f32,
        tile_pixel_m as f32,
        binned_m as f32,
    );
    let side = noise.side_px;
    let (bw, bh) = (side / k, side / k);
    let mut cfg = *surf;
    cfg.detector.threshold = 0.0;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(FLOOR_SEED);
    let mut heights = vec![0f32; side * side];
    let mut slope = vec![SlopePx::default(); bw * bh];
    let (n_int, n_ring) = scratch_len(bw, bh);
    let mut integral = vec![0u32; n_int];
    let mut ring = vec![0.0f32; n_ring];
    let mut floor = 0f32;
    crate::flyer::onboard::with_big_stack(|| {
        let mut feats = Box::new(Features::<1024>::new());
        for _ in 0..FLOOR_FRAMES {
            for h in heights.iter_mut() {
                *h = (noise.height_sigma_m * std_normal(&mut rng)) as f32;
            }
            let dem = DemPatch::new_checked(&heights, side, side, noise.pixel_m as f32)
                .map_err(|e| anyhow::anyhow!("noise frame: {e}"))?;
            let img = slope_into_binned_smoothed::<{ nav_core::slope::BIN_ROW_CAP }>(
                &dem, k, sigma_px, &mut slope, true,
            )
            .map_err(|e| anyhow::anyhow!("noise frame slope: {e}"))?;
            extract(
                &img,
                &cfg,
                Scratch {
                    integral: &mut integral,
                    ring: &mut ring,
                },
                &mut feats,
            )
            .map_err(|e| anyhow::anyhow!("noise frame SURF: {e}"))?;
            // Strongest first.
            if let Some(f) = feats.as_slice().first() {
                floor = floor.max(f.keypoint.response);
            }
        }
        Ok(())
    })?;
    Ok(floor)
}

/// The detector threshold a tile carries for frames with `noise`: [`FLOOR_MARGIN`] ×
/// [`noise_floor`], deg².
pub fn auto_threshold(
    noise: &FrameNoise,
    tile_pixel_m: f64,
    smoothing_m: f64,
    surf: &SurfConfig,
) -> Result<f32> {
    Ok(FLOOR_MARGIN * noise_floor(noise, tile_pixel_m, smoothing_m, surf)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flight_noise(sigma: f64) -> FrameNoise {
        FrameNoise {
            side_px: 200,
            pixel_m: 10.0,
            height_sigma_m: sigma,
        }
    }

    #[test]
    fn floor_grows_with_noise_squared_and_falls_with_smoothing() {
        let surf = SurfConfig::default();
        let f1 = noise_floor(&flight_noise(0.5), 20.0, 40.0, &surf).unwrap();
        let f2 = noise_floor(&flight_noise(1.0), 20.0, 40.0, &surf).unwrap();
        eprintln!("floor 0.5 m: {f1}, 1.0 m: {f2}");
        assert!(f1 > 0.0);
        // Same noise pattern scaled by 2: slopes ×2, responses ×4 (up to f32 rounding).
        assert!((f2 / f1 - 4.0).abs() < 0.2, "{f2} / {f1}");
        let rough = noise_floor(&flight_noise(0.5), 20.0, 0.0, &surf).unwrap();
        assert!(rough > 5.0 * f1, "unsmoothed {rough} vs smoothed {f1}");
        assert_eq!(
            noise_floor(&flight_noise(0.0), 20.0, 40.0, &surf).unwrap(),
            0.0
        );
    }

    /// The reason for the rule: on smooth plains a fixed 0.1 deg² keeps few blobs, the floor
    /// rule keeps every one above the sensor's noise (seed 1, 2 km of the `plains` preset).
    #[test]
    fn plains_keep_their_blobs() {
        use crate::reference::{DEFAULT_SMOOTHING_M, Smoothing, reference_dem, write_reference};
        use crate::terrain::{Preset, TerrainParams, generate};
        let mut p = TerrainParams::new(Preset::Plains);
        p.size_m = 2000.0;
        let (dem, _) = generate(&p, &indicatif::ProgressBar::hidden()).unwrap();
        let r = reference_dem(&dem, 20.0).unwrap();
        let auto = crate::reference::surf_config_for(
            &FrameNoise::default_sensor(),
            20.0,
            DEFAULT_SMOOTHING_M,
        )
        .unwrap();
        let mut fixed = auto;
        fixed.detector.threshold = 0.1;
        let dir = tempfile::tempdir().unwrap();
        let count = |cfg: &SurfConfig| {
            write_reference(&r, dir.path(), cfg, 8192, Smoothing::default_for_truth())
                .unwrap()
                .features
        };
        let (n_auto, n_fixed) = (count(&auto), count(&fixed));
        eprintln!(
            "plains 2 km: {n_auto} features at {:.2e} deg², {n_fixed} at 0.1",
            auto.detector.threshold
        );
        assert!(auto.detector.threshold < 0.01);
        assert!(
            n_auto >= 3 * n_fixed && n_auto >= 30,
            "{n_auto} vs {n_fixed}"
        );
    }

    #[test]
    fn bad_input_is_refused() {
        let surf = SurfConfig::default();
        assert!(noise_floor(&flight_noise(-1.0), 20.0, 40.0, &surf).is_err());
        assert!(noise_floor(&flight_noise(0.5), 0.0, 40.0, &surf).is_err());
        assert!(noise_floor(&flight_noise(0.5), 20.0, f64::NAN, &surf).is_err());
    }
}
