//! `ground-sim atlas`: cut a reference tile's map into a flight atlas (overlapping tiles of
//! bounded size plus an index; `nav_core::atlas`), with its JSON index and a picture.

use std::path::PathBuf;

use anyhow::{Context, anyhow};
use ground_sim::reference::atlas::{AtlasLayout, atlas_picture, build_atlas, build_atlas_within};
use ground_sim::reference::load;
use ground_sim::reference::tile::MAX_TILE_FEATURES;

/// Arguments of `ground-sim atlas`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder whose tile (with its slope raster) is cut (`tile`, `insar`).
    #[arg(long)]
    pub tile: PathBuf,
    /// Largest core side, map pixels (the cores split the map evenly).
    #[arg(long, default_value_t = 200)]
    pub core_px: usize,
    /// Overlap beyond each core edge, map pixels: at least a frame's half-diagonal plus 3σ of
    /// the prior for one tile to hold every frame (90 px = 1.8 km at 20 m: a 200 px frame at
    /// 10 m reaches 1.42 km from its centre).
    #[arg(long, default_value_t = 90)]
    pub margin_px: usize,
    /// Most features per tile (strongest first).
    #[arg(long, default_value_t = MAX_TILE_FEATURES)]
    pub max_features: usize,
    /// Largest tile allowed, bytes (e.g. the flyer's RAM buffer for tiles read from external
    /// flash): the cores shrink from `--core-px` until every tile fits.
    #[arg(long)]
    pub max_tile_bytes: Option<usize>,
    /// Output folder: atlas.bin, atlas.json, atlas.png.
    #[arg(long)]
    pub out: PathBuf,
}

/// Run `ground-sim atlas`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let reference = load(&a.tile)?;
    let layout = AtlasLayout {
        core_px: a.core_px,
        margin_px: a.margin_px,
    };
    let max_features = a.max_features.min(MAX_TILE_FEATURES);
    let (bytes, summary) = match a.max_tile_bytes {
        Some(m) => build_atlas_within(&reference.tile_bytes, layout, max_features, m)?,
        None => build_atlas(&reference.tile_bytes, layout, max_features)?,
    };
    // What flies reads it back: every tile validated as the flyer will.
    nav_core::atlas::MappedAtlas::<{ ground_sim::flyer::onboard::GROUND_ATLAS_TILES }>::new(&bytes)
        .map_err(|e| anyhow!("the atlas just written does not read back: {e}"))?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let bin = a.out.join("atlas.bin");
    std::fs::write(&bin, &bytes).with_context(|| format!("writing {}", bin.display()))?;
    let json = a.out.join("atlas.json");
    super::write_json(&json, &summary)?;
    let png = a.out.join("atlas.png");
    atlas_picture(&reference.tile_bytes, &summary)?
        .save(&png)
        .with_context(|| format!("writing {}", png.display()))?;
    let feats: usize = summary.tiles.iter().map(|t| t.features).sum();
    println!(
        "atlas        {} × {} tiles over {} × {} px at {} m (core ≤ {} px, margin {} px)",
        summary.tiles_xy[0],
        summary.tiles_xy[1],
        summary.grid_px[0],
        summary.grid_px[1],
        summary.pixel_m,
        summary.layout.core_px,
        a.margin_px
    );
    println!(
        "size         {} B in all (index {} B), largest tile {} B; the single tile: {} B, {} features; the tiles: {} features",
        summary.atlas_bytes,
        summary.index_bytes,
        summary.largest_tile_bytes,
        summary.source_tile_bytes,
        summary.source_features,
        feats
    );
    println!(
        "written      {} {} {}",
        bin.display(),
        json.display(),
        png.display()
    );
    Ok(())
}
