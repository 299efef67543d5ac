//! The reference folder the ground segment hands to the flyer and to the evaluation tools:
//! `tile.bin` (the tile blob of `nav_core::tile`), `slope.tif` (the reference slope map in
//! degrees), `reference-dem.tif` (the DEM it came from) and `tile.json` (a summary).
//!
//! `ground-sim tile` writes it from any DEM; `ground-sim insar` writes the same layout from the
//! InSAR-derived DEM.

use std::path::Path;

use anyhow::{Context, Result, bail};
use nav_core::frame::slope_from_deg;
use nav_core::{SlopeImage, SurfConfig, Tile};
use serde::Serialize;

use crate::analysis::slope_deg;
use crate::dem::{
    Dem, GeoRef, GeoTransform, Interpolation, read_geotiff, resample_to_pixel, write_geotiff,
};
use crate::tile::{GeoGrid, build_tile};

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

/// Slope map (degrees) of a DEM as a DEM-shaped raster with the same geo-reference.
pub fn slope_map(dem: &Dem) -> Result<Dem> {
    Ok(Dem::new(
        dem.width(),
        dem.height(),
        slope_deg(dem)?,
        dem.geo.clone(),
    )?)
}

/// Build the tile from a reference DEM and write the folder. Returns the summary.
pub fn write_reference(
    ref_dem: &Dem,
    dir: &Path,
    cfg: &SurfConfig,
    max_features: usize,
) -> Result<TileSummary> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let slope = slope_map(ref_dem)?;
    let px: Vec<_> = slope
        .heights_m()
        .iter()
        .map(|&d| slope_from_deg(d))
        .collect();
    let pixel_m = ref_dem.pixel_m()?;
    let img = SlopeImage::new_checked(&px, slope.width(), slope.height(), pixel_m as f32)
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
    let bytes = build_tile(&img, &grid, cfg, max_features)?;
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
    };
    std::fs::write(
        dir.join(META_FILE),
        serde_json::to_string_pretty(&summary)? + "\n",
    )?;
    Ok(summary)
}
