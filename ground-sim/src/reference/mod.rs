//! The reference folder the ground segment hands to the flyer and to the evaluation tools:
//! `tile.bin` (the tile blob of `nav_core::tile`), `slope.tif` (the reference slope map in
//! degrees), `reference-dem.tif` (the DEM it came from) and `tile.json` (a summary).
//!
//! `ground-sim tile` writes it from any DEM; `ground-sim insar` writes the same layout from the
//! InSAR-derived DEM.

use std::path::Path;

use anyhow::{Context, Result, bail};
use nav_core::{SlopeImage, SurfConfig, Tile};
use serde::Serialize;

use crate::dem::{
    Dem, GeoRef, GeoTransform, Interpolation, read_geotiff, resample_to_pixel, write_geotiff,
};
use crate::reference::tile::{GeoGrid, build_tile};

pub mod atlas;
pub mod holes;
pub mod noise_floor;
pub mod tile;

/// Tile blob file name.
pub const TILE_FILE: &str = "tile.bin";
/// Reference slope GeoTIFF file name.
pub const SLOPE_FILE: &str = "slope.tif";
/// Reference DEM GeoTIFF file name.
pub const DEM_FILE: &str = "reference-dem.tif";
/// Summary JSON file name.
pub const META_FILE: &str = "tile.json";

/// Summary written to `tile.json`.
#[derive(Debug, Clone, Serialize)]
pub struct TileSummary {
    /// Tile size, pixels.
    pub width_px: usize,
    /// Tile size, pixels.
    pub height_px: usize,
    /// Reference pixel size, metres.
    pub pixel_m: f64,
    /// Features in the tile.
    pub features: usize,
    /// Tile blob size, bytes.
    pub tile_bytes: usize,
    /// Detector threshold used, deg².
    pub threshold: f32,
    /// Detector octaves used.
    pub octaves: u8,
    /// Terrain smoothing σ recorded in the tile (frames are smoothed to it), metres.
    pub smoothing_m: f64,
    /// The map's own horizontal error the tile claims, 1σ per axis (x, y), metres.
    pub reference_sigma_m: [f32; 2],
    /// The map's own height noise the tile claims, 1σ per pixel, metres (0 = none).
    pub height_noise_m: f64,
    /// Of it, the frame-wide error measured by flying frames over the map (`tile
    /// --calibrate-frames`), 1σ per axis, metres; 0 when not calibrated.
    pub frame_wide_sigma_m: f64,
    /// Of `reference_sigma_m`, the error from the map's own height noise against its slope
    /// signal ([`map_noise_sigma_m`]), 1σ per axis, metres; 0 for a map without height noise.
    pub map_noise_sigma_m: f64,
    /// Of the terrain smoothing, the σ applied by the tile builder, metres (the rest the DEM
    /// already had).
    pub smoothing_applied_m: f64,
    /// Missing cells of the reference DEM, and how many of them the builder filled to detect
    /// the features (holes within one smoothing σ of valid heights, only with
    /// [`Smoothing::fill_holes`]; [`holes`]). The folder's `reference-dem.tif` and the tile's
    /// slope raster keep them missing.
    pub holes: holes::HoleFill,
}

/// A loaded reference folder.
pub struct Reference {
    /// The tile blob (parse with `nav_core::Tile::parse`).
    pub tile_bytes: Vec<u8>,
    /// The reference slope map, degrees (if the folder has one).
    pub slope: Option<Dem>,
}

/// Read a reference folder.
pub fn load(dir: &Path) -> Result<Reference> {
    let tp = dir.join(TILE_FILE);
    let tile_bytes = std::fs::read(&tp).with_context(|| format!("reading {}", tp.display()))?;
    Tile::parse(&tile_bytes).map_err(|e| anyhow::anyhow!("{}: {e}", tp.display()))?;
    let sp = dir.join(SLOPE_FILE);
    let slope = if sp.exists() {
        Some(read_geotiff(&sp).with_context(|| format!("reading {}", sp.display()))?)
    } else {
        None
    };
    Ok(Reference { tile_bytes, slope })
}

/// Block-average a DEM by an integer `factor` (multilooking, as the InSAR product averages);
/// a block with any no data is no data.
pub fn block_mean(dem: &Dem, factor: usize) -> Result<Dem> {
    if factor == 0 {
        bail!("block factor must be ≥ 1");
    }
    let (w, h) = (dem.width() / factor, dem.height() / factor);
    if w == 0 || h == 0 {
        bail!(
            "DEM {}x{} is smaller than one {factor}x{factor} block",
            dem.width(),
            dem.height()
        );
    }
    let mut z = vec![0.0f32; w * h];
    for r in 0..h {
        for c in 0..w {
            let mut acc = 0.0f64;
            for j in 0..factor {
                for i in 0..factor {
                    acc += dem
                        .get(c * factor + i, r * factor + j)
                        .map_or(f64::NAN, f64::from);
                }
            }
            z[r * w + c] = (acc / (factor * factor) as f64) as f32;
        }
    }
    let t = dem.geo.transform.0;
    let geo = GeoRef {
        transform: GeoTransform([
            t[0],
            t[1] * factor as f64,
            t[2],
            t[3],
            t[4],
            t[5] * factor as f64,
        ]),
        ..dem.geo.clone()
    };
    Ok(Dem::new(w, h, z, geo)?)
}

/// The DEM at the reference pixel size: block mean for an integer ratio, bilinear otherwise.
pub fn reference_dem(dem: &Dem, pixel_m: f64) -> Result<Dem> {
    let ratio = pixel_m / dem.pixel_m()?;
    let k = ratio.round();
    if (ratio - k).abs() < 1e-9 && k >= 1.0 {
        block_mean(dem, k as usize)
    } else {
        Ok(resample_to_pixel(dem, pixel_m, Interpolation::Bilinear)?)
    }
}

/// Default terrain resolution of reference tiles: a Gaussian of σ = 40 m (2 reference pixels)
/// on top of the 20 m pixel averaging. Both sides smoothing to this σ makes frame and tile
/// keypoints land alike: heading error p95 0.535° → 0.215° against truth tiles (docs/results.md).
/// InSAR DEMs carry pixel-scale height noise and get more: [`INSAR_SMOOTHING_M`].
pub const DEFAULT_SMOOTHING_M: f64 = 40.0;

/// Terrain smoothing of tiles built from InSAR DEMs (`ground-sim insar`): their pixel-scale
/// height noise moves keypoints, and σ 50 m gives the most correct fixes. Before the dense
/// confirmation, low detector thresholds on such tiles let false fixes through (6–7 inliers,
/// wrong scale); the navigator now refuses fixes the slope correlation contradicts. Measured
/// (500 frames, seed 1): shoemaker 92.0 % → 99.2 % success, shackleton 99.8 % → 100 %, no false
/// fix; sweep in docs/insar.md.
pub const INSAR_SMOOTHING_M: f64 = 50.0;

/// How far, per metre of blur the frames do not share, the map's blobs sit from where a frame
/// finds them (the κ of [`reference_sigma_m`]). Calibrated on the terrain suite's InSAR tiles
/// (terrain and campaign seed 1: lola, shoemaker, shackleton-floor, plains; the fixes' mean
/// NEES under the refinement's covariance plus this term), checked on seed 2 and on the noisy
/// mission-radar tiles (docs/registration.md, Covariance).
pub const REFERENCE_SHIFT_PER_BLUR: f64 = 0.08;

/// The map's own horizontal error a tile claims, 1σ per axis, metres
/// (`nav_core::TileHeader::reference_sigma_m`): [`REFERENCE_SHIFT_PER_BLUR`] × the blur the
/// frames cannot reproduce, the DEM's inherent smoothing `inherent_m` (e.g. an InSAR DEM's
/// multilook and filter blur, Gaussian-equivalent σ; its shape is not the Gaussian the frames
/// are smoothed with, so blobs land differently), × `one_look_share`, the share of valid
/// cells made by one look direction alone under the frame that has most of them (1 for a
/// one-look map or when unknown; `insar` passes `LookFusion::one_look_share_for_frames`).
///
/// Why the share: the blobs' displacement comes from a multilook window that spans more ground
/// on slopes facing the radar than on slopes facing away, so it points along the look's range
/// axis and flips sign with the look direction. A cell fused from an east- and a west-looking
/// pass averages the two and cancels it to first order; a frame's fix moves by the share of its
/// cells that keep one look's shift. κ was calibrated on one-look maps; on the fused maps of
/// the default radar (session 21, docs/insar.md, "The default radar") κ × blur made the
/// fixes padded (mean NEES 0.30–0.97 on the seed-1 suite), with the share 0.62–2.09 at both
/// seeds. The whole map's share left frames over the parts one look maps alone (walls)
/// claiming too little (the fresh rim's fixes: NEES 6.6–6.8); since session 24 the share is
/// the worst frame-sized window's, a bound for every frame over the map.
///
/// Errors that shift a whole frame alike never show in a fix's residuals, so the tile must say
/// them. A DEM with no blur of its own (a truth-built tile) claims 0: the frames' binning and
/// smoothing reproduce its resolution, and the suite's truth-tile fixes have mean offsets ≤ 0.3 m
/// (docs/registration.md, where a grid-phase term, pixel/√12, was tried and left the truth
/// tiles' σ four times too large).
pub fn reference_sigma_m(inherent_m: f64, one_look_share: f64) -> [f32; 2] {
    let share = if one_look_share.is_finite() {
        one_look_share.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let s = REFERENCE_SHIFT_PER_BLUR * inherent_m.max(0.0) * share;
    [s as f32; 2]
}

/// κ of [`map_noise_sigma_m`], dimensionless: the frame-wide fix error that the map's own height
/// noise causes beyond what the fix's residuals show, per metre of the tile's terrain
/// smoothing σ and per unit of (slope noise / slope signal)².
///
/// Fitted (session 47) on pooled campaigns over 30 4 km scenes never used before: plains, lola
/// and shoemaker at terrain and radar seeds 11–20, each mapped by the default radar and by the
/// 128 m second baseline (`eval --trials 300 --seed s`, prior 50 m, 2°, 2 %), as the κ that
/// brings each scene × radar pool's mean NEES nearest 2 (least squares in log NEES). The
/// exponent 2 was chosen among 1, 2 and 2.5 because its κ came out the same (1.77) fitted on
/// seeds 11–15, on 16–20 and on all ten; with exponent 1 or 2.5 κ moved by 1.8× and 1.3×.
/// Checked on the held-out halves and on Shackleton-floor and fresh-crater scenes it was not
/// fitted on (docs/registration.md, "The map's slope noise against its slope signal").
pub const MAP_NOISE_SHIFT_PER_SMOOTHING: f64 = 1.77;

/// RMS magnitude of the slope noise that white height noise of `height_noise_m` (1σ per pixel
/// of `pixel_m`, metres) leaves after a Gaussian smoothing of σ `smoothing_m` (metres), degrees
/// (small-angle). Each gradient component of white noise of power `P` per unit area (m⁴),
/// smoothed by a Gaussian of σ, has variance `P / (8π σ⁴)`; the magnitude sums two of them.
/// 0 for no noise, and for no smoothing, where white noise has no finite slope to predict.
pub fn map_slope_noise_deg(height_noise_m: f64, pixel_m: f64, smoothing_m: f64) -> f64 {
    let usable = |v: f64| v.is_finite() && v > 0.0;
    if !(usable(height_noise_m) && usable(pixel_m) && usable(smoothing_m)) {
        return 0.0;
    }
    let power_m4 = (height_noise_m * pixel_m).powi(2);
    (2.0 * power_m4 / (8.0 * std::f64::consts::PI * smoothing_m.powi(4)))
        .sqrt()
        .to_degrees()
}

/// The map's horizontal error from its own height noise that a fix's residuals do not show,
/// 1σ per axis, metres: [`MAP_NOISE_SHIFT_PER_SMOOTHING`] × `smoothing_m` × (g / s)², with g the
/// slope noise of [`map_slope_noise_deg`] and s = `slope_rms_deg`, the RMS of the tile's own
/// slope raster (degrees; the signal the frames register on). The ratio is held at 1 at most,
/// so a tile whose slope is all noise, or has no valid slope (NaN), claims κ × `smoothing_m`
/// (88.5 m at 50 m).
///
/// Why the square: the map's slope is the magnitude of a noisy gradient, so its noise does not
/// only scatter the residuals (which the refinement's covariance already counts) but lifts low
/// slopes by about g²/4s (each gradient component carries g²/2), a distortion that looks like
/// terrain and moves blobs alike over a frame. It matters where the signal is weak: on 4 km
/// plains InSAR maps (s = 0.9–2.2°, g = 0.13–0.23°) it gives 0.33–4.1 m; on cratered scenes
/// (s = 2.4–13°) 0.06–0.76 m. A truth-built tile (no height noise claimed) gets 0.
pub fn map_noise_sigma_m(
    height_noise_m: f64,
    pixel_m: f64,
    smoothing_m: f64,
    slope_rms_deg: f64,
) -> f64 {
    let g = map_slope_noise_deg(height_noise_m, pixel_m, smoothing_m);
    if g == 0.0 {
        return 0.0;
    }
    let ratio = if slope_rms_deg.is_finite() && slope_rms_deg > g {
        g / slope_rms_deg
    } else {
        1.0
    };
    MAP_NOISE_SHIFT_PER_SMOOTHING * smoothing_m * ratio * ratio
}

/// RMS of a slope raster's valid cells, degrees (NaN cells, the tile's holes, left out);
/// NaN when none is valid.
pub fn slope_rms_deg(slope_deg: &[f32]) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for &v in slope_deg.iter().filter(|v| v.is_finite()) {
        sum += f64::from(v) * f64::from(v);
        n += 1;
    }
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// SURF settings of a reference tile for frames with `noise`, on a tile of `pixel_m` metres
/// whose terrain carries `smoothing_m` (metres) of Gaussian smoothing: nav-core's defaults with
/// the detector threshold a margin above the frames' noise floor
/// ([`noise_floor::auto_threshold`]). The tile header carries the threshold, so the flyer
/// detects its frames alike; both sides then keep every blob the sensor can tell from noise,
/// and the frame keeps its strongest within its keypoint budget: detection follows the
/// terrain's contrast instead of a fixed absolute threshold.
///
/// Measured before this rule (truth-built tiles, fixed 0.1 deg², seed 1, 300 frames, flight
/// budget, no prior): plains 81.7 % success, fresh crater rim 84.0 %; with it 96.3 % and 93.7 %
/// (docs/registration.md). InSAR tiles were already at 0.003 deg²; the rule changes nothing
/// measurable there.
pub fn surf_config_for(
    noise: &noise_floor::FrameNoise,
    pixel_m: f64,
    smoothing_m: f64,
) -> Result<SurfConfig> {
    let mut cfg = SurfConfig::default();
    cfg.detector.threshold = noise_floor::auto_threshold(noise, pixel_m, smoothing_m, &cfg)?;
    Ok(cfg)
}

/// Widest reference slope map, pixels (the stack rings of nav-core's streaming slope).
pub const MAX_REFERENCE_WIDTH: usize = 2048;

/// How much the reference terrain is smoothed before slope and SURF.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Smoothing {
    /// Gaussian σ the tile's terrain should carry beyond pixel averaging, metres (recorded in
    /// the tile header; the flyer smooths its frames by the same σ). 0 = none.
    pub target_m: f64,
    /// Gaussian-equivalent σ the DEM already carries, metres (e.g. InSAR multilooking and its
    /// DEM filter); the builder applies `sqrt(target² − inherent²)`.
    pub inherent_m: f64,
    /// Share of valid cells made by a single look direction under the frame-sized window
    /// that has most of them, 0–1 (1: a one-look InSAR map, or unknown; 0: every cell fused
    /// from two opposite looks). Scales the blur term of the tile's reference error
    /// ([`reference_sigma_m`]).
    pub one_look_share: f64,
    /// The DEM's own height noise, 1σ per pixel of white noise of the same power per unit area,
    /// metres (an InSAR DEM: `insar::products::white_noise_m`), recorded in the tile
    /// (`nav_core::TileHeader::height_noise_m`). 0 = none claimed (a truth DEM).
    pub height_noise_m: f64,
    /// Detect the tile's features on the DEM with its small holes filled (every cell within
    /// `target_m` of valid heights, [`holes::fill_small_holes`]); the tile's slope raster keeps
    /// them missing. Off in [`Smoothing::default_for_truth`]; InSAR products take it from
    /// `InsarConfig::fill_tile_holes` (on). docs/insar.md, "The parallax of the height error,
    /// and holes in the tile".
    pub fill_holes: bool,
}

impl Smoothing {
    /// The default target on a DEM that carries no smoothing of its own.
    pub fn default_for_truth() -> Self {
        Self {
            target_m: DEFAULT_SMOOTHING_M,
            inherent_m: 0.0,
            one_look_share: 1.0,
            height_noise_m: 0.0,
            fill_holes: false,
        }
    }
    /// σ to apply, metres.
    pub fn applied_m(&self) -> f64 {
        (self.target_m.powi(2) - self.inherent_m.powi(2))
            .max(0.0)
            .sqrt()
    }
}

/// Slope of a reference DEM smoothed by `sigma_m` (Gaussian, metres), through nav-core's
/// streaming slope (the frames' code path), as nav-core pixels.
pub fn reference_slope_px(dem: &Dem, sigma_m: f64) -> Result<Vec<nav_core::SlopePx>> {
    use nav_core::DemPatch;
    if dem.width() > MAX_REFERENCE_WIDTH {
        bail!(
            "reference DEM is {} px wide; at most {MAX_REFERENCE_WIDTH} px are supported",
            dem.width()
        );
    }
    let pixel_m = dem.pixel_m()?;
    if !(sigma_m.is_finite() && sigma_m >= 0.0) {
        bail!("smoothing σ must be finite and ≥ 0, got {sigma_m}");
    }
    let sigma_px = (sigma_m / pixel_m) as f32;
    // nav-core cuts kernels at MAX_SMOOTH_RADIUS; the reference gets a full ±3σ kernel.
    let max_px = nav_core::slope::MAX_SMOOTH_RADIUS as f32 / 3.0;
    if sigma_px > max_px + 1e-4 {
        bail!(
            "smoothing σ {sigma_m} m is {sigma_px:.2} reference px; at most {max_px} px are supported"
        );
    }
    let heights = dem.heights_m().to_vec();
    let (w, h) = (dem.width(), dem.height());
    crate::flyer::onboard::with_big_stack(move || {
        let patch = DemPatch::new_checked(&heights, w, h, pixel_m as f32)
            .map_err(|e| anyhow::anyhow!("reference DEM: {e}"))?;
        let mut px = vec![nav_core::SLOPE_NODATA; w * h];
        nav_core::slope::slope_into_binned_smoothed::<MAX_REFERENCE_WIDTH>(
            &patch, 1, sigma_px, &mut px, false,
        )
        .map_err(|e| anyhow::anyhow!("reference slope: {e}"))?;
        Ok(px)
    })
}

/// Build the tile from a reference DEM (smoothed as `smoothing` says) and write the folder.
/// Returns the summary.
pub fn write_reference(
    ref_dem: &Dem,
    dir: &Path,
    cfg: &SurfConfig,
    max_features: usize,
    smoothing: Smoothing,
) -> Result<TileSummary> {
    write_reference_with(ref_dem, dir, cfg, max_features, smoothing, 0.0)
}

/// [`write_reference`] with a frame-wide error of `frame_wide_m` metres (1σ per axis) measured
/// by flying frames over the map (`evaluation::calibrate`), added in quadrature to the blur
/// term of [`reference_sigma_m`] and the map-noise term of [`map_noise_sigma_m`] in the tile's
/// `reference_sigma_m`.
pub fn write_reference_with(
    ref_dem: &Dem,
    dir: &Path,
    cfg: &SurfConfig,
    max_features: usize,
    smoothing: Smoothing,
    frame_wide_m: f64,
) -> Result<TileSummary> {
    if !(frame_wide_m.is_finite() && frame_wide_m >= 0.0) {
        anyhow::bail!("the frame-wide error must be finite and >= 0, got {frame_wide_m}");
    }
    let noise = smoothing.height_noise_m;
    if !(noise.is_finite()
        && (0.0..=f64::from(nav_core::tile::MAX_HEIGHT_NOISE_M)).contains(&noise))
    {
        anyhow::bail!(
            "the map's height noise must be in [0, {}] m, got {noise}",
            nav_core::tile::MAX_HEIGHT_NOISE_M
        );
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    // Features come from the DEM with its small holes filled; the raster that area search
    // and the slope confirmation compare cell by cell keeps them missing, as a filled height
    // is not a measurement.
    let fill_radius_m = if smoothing.fill_holes {
        smoothing.target_m
    } else {
        0.0
    };
    let (filled, hole_fill) = holes::fill_small_holes(ref_dem, fill_radius_m)?;
    let px = reference_slope_px(ref_dem, smoothing.applied_m())?;
    let px_filled = if hole_fill.filled_cells > 0 {
        Some(reference_slope_px(&filled, smoothing.applied_m())?)
    } else {
        None
    };
    let slope = Dem::new(
        ref_dem.width(),
        ref_dem.height(),
        px.iter()
            .map(|&p| nav_core::frame::slope_to_deg(p).unwrap_or(f32::NAN))
            .collect(),
        ref_dem.geo.clone(),
    )?;
    let pixel_m = ref_dem.pixel_m()?;
    let img = SlopeImage::new_checked(
        px_filled.as_deref().unwrap_or(&px),
        slope.width(),
        slope.height(),
        pixel_m as f32,
    )
    .map_err(|e| anyhow::anyhow!("reference slope: {e}"))?;
    let t = ref_dem.geo.transform.0;
    let grid = GeoGrid {
        origin_x_m: t[0] + 0.5 * t[1],
        origin_y_m: t[3] + 0.5 * t[5],
        pixel_x_m: t[1],
        pixel_y_m: t[5],
        projection: ref_dem
            .geo
            .keys
            .as_ref()
            .and_then(|k| k.ascii.clone())
            .unwrap_or_else(|| "local metric grid".into())
            .chars()
            .take(nav_core::tile::MAX_PROJECTION_LEN)
            .collect(),
    };
    // The map's own height noise against its slope signal: a frame-wide error the fixes'
    // residuals miss (session 47). In quadrature with the blur term and any calibration.
    let map_noise_m = map_noise_sigma_m(
        noise,
        pixel_m,
        smoothing.target_m,
        slope_rms_deg(slope.heights_m()),
    );
    let ref_sigma = reference_sigma_m(smoothing.inherent_m, smoothing.one_look_share)
        .map(|b| (b as f64).hypot(map_noise_m).hypot(frame_wide_m) as f32);
    let bytes = build_tile(
        &img,
        &grid,
        cfg,
        max_features,
        smoothing.target_m,
        ref_sigma,
        noise as f32,
        px_filled.is_some().then_some(px.as_slice()),
    )?;
    let features = Tile::parse(&bytes)
        .map(|t| t.len())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    std::fs::write(dir.join(TILE_FILE), &bytes)?;
    write_geotiff(&slope, &dir.join(SLOPE_FILE), None)?;
    write_geotiff(ref_dem, &dir.join(DEM_FILE), None)?;
    let summary = TileSummary {
        width_px: ref_dem.width(),
        height_px: ref_dem.height(),
        pixel_m,
        features,
        tile_bytes: bytes.len(),
        threshold: cfg.detector.threshold,
        octaves: cfg.detector.octaves,
        smoothing_m: smoothing.target_m,
        reference_sigma_m: ref_sigma,
        height_noise_m: f64::from(noise as f32),
        frame_wide_sigma_m: frame_wide_m,
        map_noise_sigma_m: map_noise_m,
        smoothing_applied_m: smoothing.applied_m(),
        holes: hole_fill,
    };
    std::fs::write(
        dir.join(META_FILE),
        serde_json::to_string_pretty(&summary)? + "\n",
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The predicted slope noise is what the tile's own slope path makes of white height
    /// noise: a pure-noise DEM through `reference_slope_px` has that RMS slope.
    #[test]
    fn the_slope_noise_of_white_height_noise_is_predicted() {
        let (n, px, sigma_h, smoothing) = (256usize, 20.0, 2.0, 50.0);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(47);
        let z: Vec<f32> = (0..n * n)
            .map(|_| (sigma_h * crate::terrain::sfd::std_normal(&mut rng)) as f32)
            .collect();
        let dem = Dem::new(n, n, z, GeoRef::local(0.0, 0.0, px, "noise test")).unwrap();
        let slope = reference_slope_px(&dem, smoothing).unwrap();
        let deg: Vec<f32> = slope
            .iter()
            .map(|&p| nav_core::frame::slope_to_deg(p).unwrap_or(f32::NAN))
            .collect();
        // The kernels' reach at the border is cut: measure the interior.
        let m = 12;
        let inner: Vec<f32> = (m..n - m)
            .flat_map(|r| deg[r * n + m..r * n + n - m].iter().copied())
            .collect();
        let measured = slope_rms_deg(&inner);
        let predicted = map_slope_noise_deg(sigma_h, px, smoothing);
        assert!(
            (measured / predicted - 1.0).abs() < 0.15,
            "measured {measured:.4}° predicted {predicted:.4}°"
        );
    }

    #[test]
    fn the_map_noise_term_grows_as_the_signal_fades_and_is_zero_without_noise() {
        assert_eq!(map_noise_sigma_m(0.0, 20.0, 50.0, 1.0), 0.0);
        assert_eq!(map_noise_sigma_m(1.7, 20.0, 0.0, 1.0), 0.0);
        assert_eq!(map_noise_sigma_m(f64::NAN, 20.0, 50.0, 1.0), 0.0);
        let g = map_slope_noise_deg(1.7, 20.0, 50.0);
        let rugged = map_noise_sigma_m(1.7, 20.0, 50.0, 5.0);
        let plains = map_noise_sigma_m(1.7, 20.0, 50.0, 1.5);
        assert!(rugged > 0.0 && plains > rugged);
        // The square of the noise-to-signal ratio.
        assert!((plains / rugged - (5.0f64 / 1.5).powi(2)).abs() < 1e-9);
        let expected = MAP_NOISE_SHIFT_PER_SMOOTHING * 50.0 * (g / 1.5).powi(2);
        assert!((plains - expected).abs() < 1e-12);
        // A slope that is all noise, or none to measure, claims κ × the smoothing σ.
        let cap = MAP_NOISE_SHIFT_PER_SMOOTHING * 50.0;
        assert_eq!(map_noise_sigma_m(1.7, 20.0, 50.0, 0.5 * g), cap);
        assert_eq!(map_noise_sigma_m(1.7, 20.0, 50.0, f64::NAN), cap);
        assert!(slope_rms_deg(&[f32::NAN]).is_nan());
        assert_eq!(slope_rms_deg(&[3.0, f32::NAN, 4.0]), (12.5f64).sqrt());
    }
}
