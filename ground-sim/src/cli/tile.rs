//! `ground-sim tile`: a reference folder (tile.bin, slope.tif, reference-dem.tif, tile.json)
//! straight from a DEM, without the radar: the "perfect InSAR" reference, for closed-loop runs
//! before (or beside) the InSAR chain.

use std::path::PathBuf;

use anyhow::Context;
use ground_sim::dem::read_geotiff;
use ground_sim::evaluation::calibrate::calibrate;
use ground_sim::evaluation::campaign::{CampaignSpec, PriorSpec};
use ground_sim::flyer::frames::SensorModel;
use ground_sim::flyer::onboard::Budget;
use ground_sim::reference::noise_floor::FrameNoise;
use ground_sim::reference::tile::MAX_TILE_FEATURES;
use ground_sim::reference::{
    DEFAULT_SMOOTHING_M, Smoothing, TILE_FILE, reference_dem, surf_config_for, write_reference_with,
};

/// Arguments of `ground-sim tile`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Source DEM (GeoTIFF, north-up).
    #[arg(long)]
    pub dem: PathBuf,
    /// Reference pixel size, metres (the paper: 20).
    #[arg(long, default_value_t = 20.0)]
    pub pixel_m: f64,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Detector threshold, (degrees of slope)². Default: twice the noise floor of the flyer's
    /// frames (`--frame-noise-m`, `--frame-pixel-m`; `ground_sim::reference::noise_floor`), so
    /// the tile and the frames keep every blob the sensor can tell from noise.
    #[arg(long)]
    pub threshold: Option<f32>,
    /// 1σ range (height) noise of the flyer's frames, metres: sets the default threshold.
    #[arg(long, default_value_t = FrameNoise::default_sensor().height_sigma_m)]
    pub frame_noise_m: f64,
    /// Ground pixel of the flyer's frames, metres: sets the default threshold.
    #[arg(long, default_value_t = FrameNoise::default_sensor().pixel_m)]
    pub frame_pixel_m: f64,
    /// Terrain smoothing, metres: Gaussian σ applied to the reference DEM before slope and
    /// recorded in the tile, so the flyer smooths its frames alike (0 = none). At most 3
    /// reference pixels.
    #[arg(long, default_value_t = DEFAULT_SMOOTHING_M)]
    pub smoothing_m: f64,
    /// Gaussian-equivalent σ the DEM already carries, metres (e.g. an InSAR DEM: 22.4 with
    /// `insar`'s defaults); only the remainder is applied.
    #[arg(long, default_value_t = 0.0)]
    pub inherent_smoothing_m: f64,
    /// Share of valid cells made by one look direction alone under the frame that has most of
    /// them, 0–1 (an InSAR DEM fused from two opposite looks: its `report.json` →
    /// `looks.worst_window_one_look_share`; 1 = one look or unknown). Scales the blur term of
    /// the tile's reference error (`ground_sim::reference::reference_sigma_m`).
    #[arg(long, default_value_t = 1.0)]
    pub one_look_share: f64,
    /// The DEM's own height noise, 1σ per tile pixel (`--pixel-m`), metres, recorded in the
    /// tile (an InSAR DEM: its `report.json` → `crlb_height_m` / `crlb_filter_factor`, which
    /// `insar` records itself; 0 = none, e.g. a truth DEM). The navigation filter treats the fix error it causes as the ground's,
    /// shared by successive fixes (`nav_core::filter::map_noise_share`). It also adds to the
    /// tile's reference error the shift it causes against the tile's slope signal
    /// (`ground_sim::reference::map_noise_sigma_m`).
    #[arg(long, default_value_t = 0.0)]
    pub height_noise_m: f64,
    /// Most features kept (strongest first).
    #[arg(long, default_value_t = MAX_TILE_FEATURES)]
    pub max_features: usize,
    /// Detect the features on the DEM with its small holes filled: holes (not touching the
    /// edge) whose every cell lies within one `--smoothing-m` of valid heights, filled from
    /// their rims. The tile's slope raster keeps them missing. An explicit option: it gives
    /// more features on holed InSAR maps, and noisy stretches of map their noise's blobs
    /// (docs/insar.md, "The parallax of the height error, and holes in the tile").
    #[arg(long)]
    pub fill_holes: bool,
    /// Measure the tile's frame-wide error by flying this many simulated frames over the
    /// source DEM with the flight navigator (a prior of 1 m, 1°, 2 % as the descent filter
    /// gives), and write the extra σ that brings their fixes' mean NEES to 2 into the tile's
    /// `reference_sigma_m` (`ground_sim::evaluation::calibrate`; 0 = off). An explicit option:
    /// the frames come from the map's own DEM, so it measures how the flyer's frames fit this
    /// map, not the map's error against the ground.
    #[arg(long, default_value_t = 0)]
    pub calibrate_frames: usize,
    /// Smallest frame pixel of the calibration frames, metres (the descent's TRN frames: 5.3 m
    /// at 2 km above the terrain).
    #[arg(long, default_value_t = 5.0)]
    pub calibrate_pixel_min_m: f64,
    /// Largest frame pixel of the calibration frames, metres (10 m at the 3.8 km release).
    #[arg(long, default_value_t = 10.5)]
    pub calibrate_pixel_max_m: f64,
    /// Seed of the calibration frames.
    #[arg(long, default_value_t = 1)]
    pub calibrate_seed: u64,
    /// Also write the summary JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Run `ground-sim tile`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let r = reference_dem(&dem, a.pixel_m)?;
    let noise = FrameNoise {
        pixel_m: a.frame_pixel_m,
        height_sigma_m: a.frame_noise_m,
        ..FrameNoise::default_sensor()
    };
    let mut cfg = surf_config_for(&noise, a.pixel_m, a.smoothing_m)?;
    if let Some(t) = a.threshold {
        if !(t.is_finite() && t >= 0.0) {
            anyhow::bail!("--threshold must be finite and >= 0, got {t}");
        }
        cfg.detector.threshold = t;
    }
    if !(0.0..=1.0).contains(&a.one_look_share) {
        anyhow::bail!(
            "--one-look-share must be in [0, 1], got {}",
            a.one_look_share
        );
    }
    let smoothing = Smoothing {
        target_m: a.smoothing_m,
        inherent_m: a.inherent_smoothing_m,
        one_look_share: a.one_look_share,
        height_noise_m: a.height_noise_m,
        fill_holes: a.fill_holes,
    };
    let max_features = a.max_features.min(MAX_TILE_FEATURES);
    let mut s = write_reference_with(&r, &a.out, &cfg, max_features, smoothing, 0.0)?;
    let mut calibration = None;
    if a.calibrate_frames > 0 {
        let spec = CampaignSpec {
            trials: a.calibrate_frames,
            seed: a.calibrate_seed,
            pixel_min_m: a.calibrate_pixel_min_m,
            pixel_max_m: a.calibrate_pixel_max_m,
            sensor: SensorModel::default(),
            prior: Some(PriorSpec {
                sigma_m: 1.0,
                heading_sigma_deg: 1.0,
                scale_sigma: 0.02,
            }),
            budget: Budget::Flight,
            host_time: false,
        };
        let bytes = std::fs::read(a.out.join(TILE_FILE))
            .with_context(|| format!("reading {}", a.out.join(TILE_FILE).display()))?;
        let tile = nav_core::Tile::parse(&bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
        let pb = super::progress(a.calibrate_frames as u64, "calibrate");
        let c = calibrate(tile, &dem, &spec, &pb)?;
        pb.finish_and_clear();
        println!(
            "calibration {} fixes of {} frames at {}–{} m: mean NEES {:.2}; frame-wide σ {:.3} m \
             (mean NEES with it {:.2})",
            c.fixes,
            c.frames,
            a.calibrate_pixel_min_m,
            a.calibrate_pixel_max_m,
            c.nees_before,
            c.frame_wide_sigma_m,
            c.nees_after
        );
        if c.frame_wide_sigma_m > 0.0 {
            s = write_reference_with(
                &r,
                &a.out,
                &cfg,
                max_features,
                smoothing,
                c.frame_wide_sigma_m,
            )?;
        }
        calibration = Some(c);
    }
    println!(
        "reference  {}x{} px at {} m, smoothing σ {} m, threshold {:.3e} deg²: {} features, {} bytes -> {}",
        s.width_px,
        s.height_px,
        s.pixel_m,
        s.smoothing_m,
        s.threshold,
        s.features,
        s.tile_bytes,
        a.out.display()
    );
    if s.holes.missing_cells > 0 {
        println!(
            "holes      {} of {} missing cells filled (within one smoothing σ of valid heights)",
            s.holes.filled_cells, s.holes.missing_cells
        );
    }
    if let Some(j) = &a.json {
        // The summary's fields, plus the calibration (null when not run).
        let mut v = serde_json::to_value(&s)?;
        if let Some(o) = v.as_object_mut() {
            o.insert("calibration".into(), serde_json::to_value(calibration)?);
        }
        super::write_json(j, &v)?;
    }
    Ok(())
}
