//! `ground-sim tile`: a reference folder (tile.bin, slope.tif, reference-dem.tif, tile.json)
//! straight from a DEM, without the radar: the "perfect InSAR" reference, for closed-loop runs
//! before (or beside) the InSAR chain.

use std::path::PathBuf;

use anyhow::Context;
use ground_sim::dem::read_geotiff;
use ground_sim::reference::tile::MAX_TILE_FEATURES;
use ground_sim::reference::{DEFAULT_SMOOTHING_M, Smoothing, reference_dem, write_reference};
use nav_core::{DetectorConfig, SurfConfig};

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
    /// Detector threshold, (degrees of slope)².
    #[arg(long, default_value_t = ground_sim::reference::DEFAULT_THRESHOLD)]
    pub threshold: f32,
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
    let cfg = SurfConfig {
        detector: DetectorConfig {
            threshold: a.threshold,
            ..Default::default()
        },
        upright: false,
    };
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
        "reference  {}x{} px at {} m, smoothing σ {} m: {} features, {} bytes -> {}",
        s.width_px,
        s.height_px,
        s.pixel_m,
        s.smoothing_m,
        s.features,
        s.tile_bytes,
        a.out.display()
    );
    if let Some(j) = &a.json {
        super::write_json(j, &s)?;
    }
    Ok(())
}
