//! `ground-sim tile`: a reference folder (tile.bin, slope.tif, reference-dem.tif, tile.json)
//! straight from a DEM, without the radar: the "perfect InSAR" reference, for closed-loop runs
//! before (or beside) the InSAR chain.

use std::path::PathBuf;

use anyhow::Context;
use ground_sim::dem::read_geotiff;
use ground_sim::reference::noise_floor::FrameNoise;
use ground_sim::reference::tile::MAX_TILE_FEATURES;
use ground_sim::reference::{
    DEFAULT_SMOOTHING_M, Smoothing, reference_dem, surf_config_for, write_reference,
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
    /// Most features kept (strongest first).
    #[arg(long, default_value_t = MAX_TILE_FEATURES)]
    pub max_features: usize,
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
    let s = write_reference(
        &r,
        &a.out,
        &cfg,
        a.max_features.min(MAX_TILE_FEATURES),
        Smoothing {
            target_m: a.smoothing_m,
            inherent_m: a.inherent_smoothing_m,
        },
    )?;
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
    if let Some(j) = &a.json {
        super::write_json(j, &s)?;
    }
    Ok(())
}
