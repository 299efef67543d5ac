//! `ground-sim navmap`: the navigability map of a reference folder — where a frame centred on a
//! map cell is predicted to get a fix — as GeoTIFFs and a PNG, from the tile alone.

use std::path::PathBuf;

use anyhow::anyhow;
use ground_sim::evaluation::navmap::{
    NAVMAP_MIN_FEATURES, NAVMAP_MIN_TEXTURE_DEG, NAVMAP_MIN_VALID_FRAC, NavMap, NavmapThresholds,
};
use ground_sim::evaluation::suite::write_navmap;
use ground_sim::reference::load;
use nav_core::Tile;

/// Arguments of `ground-sim navmap`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder (tile.bin with its slope raster, slope.tif for the georeference).
    #[arg(long)]
    pub tile: PathBuf,
    /// Output folder: navmap.tif (1 go, 0 no-go, NaN where a frame would leave the map),
    /// navmap-features.tif, navmap-texture.tif, navmap.png, navmap.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Side of the flyer's frame on the ground, metres (200 px at 9 m: 1 800).
    #[arg(long, default_value_t = 1800.0)]
    pub frame_side_m: f64,
    /// Fewest tile features under a frame for "go".
    #[arg(long, default_value_t = NAVMAP_MIN_FEATURES)]
    pub min_features: f64,
    /// Smallest valid fraction of the reference under a frame for "go".
    #[arg(long, default_value_t = NAVMAP_MIN_VALID_FRAC)]
    pub min_valid_frac: f64,
    /// Smallest slope standard deviation under a frame for "go", degrees.
    #[arg(long, default_value_t = NAVMAP_MIN_TEXTURE_DEG)]
    pub min_texture_deg: f64,
}

/// What `navmap` reports (`navmap.json`).
#[derive(Debug, serde::Serialize)]
struct Summary {
    tile: PathBuf,
    width_px: usize,
    height_px: usize,
    footprint_radius_px: f64,
    thresholds: NavmapThresholds,
    go_fraction: f64,
    files: Vec<PathBuf>,
}

/// Run `ground-sim navmap`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let reference = load(&a.tile)?;
    let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
    let thresholds = NavmapThresholds {
        min_features: a.min_features,
        min_valid_frac: a.min_valid_frac,
        min_texture_deg: a.min_texture_deg,
    };
    let m = NavMap::build(&tile, 0.5 * a.frame_side_m, thresholds)?;
    std::fs::create_dir_all(&a.out)?;
    let stem = a.out.join("navmap");
    write_navmap(&m, reference.slope.as_ref(), &stem)?;
    let files: Vec<PathBuf> = [
        "navmap.tif",
        "navmap-features.tif",
        "navmap-texture.tif",
        "navmap.png",
    ]
    .iter()
    .map(|f| a.out.join(f))
    .collect();
    let s = Summary {
        tile: a.tile.clone(),
        width_px: m.width,
        height_px: m.height,
        footprint_radius_px: m.radius_px,
        thresholds,
        go_fraction: m.go_fraction(),
        files,
    };
    println!(
        "navmap     {}x{} cells, footprint radius {:.1} px: go on {:.1} % of the cells a frame fits",
        s.width_px,
        s.height_px,
        s.footprint_radius_px,
        100.0 * s.go_fraction
    );
    for f in &s.files {
        println!("  {}", f.display());
    }
    super::write_json(&a.out.join("navmap.json"), &s)?;
    Ok(())
}
