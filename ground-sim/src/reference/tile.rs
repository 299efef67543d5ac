//! Reference tile builder: SURF features of a slope image computed by nav-core itself on the
//! host, written in the tile format of `nav_core::tile`.

use anyhow::{Context, Result, bail};
use nav_core::surf::{Scratch, scratch_len};
use nav_core::tile::{MAX_HEADER_LEN, TileHeader, tile_len_with_raster, write_tile_with_raster};
use nav_core::{Features, SlopeImage, SurfConfig, extract};

/// Most features a ground-built tile holds: 8192 × 280 B = 2.2 MiB of flash. The flight matcher
/// only compares the features inside the prior's footprint, so a large map stays affordable.
pub const MAX_TILE_FEATURES: usize = 8192;

/// Geo-reference of a tile's pixel grid: the centre of pixel (0, 0) and the step per
/// column/row, metres in the named projection.
#[derive(Debug, Clone, PartialEq)]
pub struct GeoGrid {
    /// Geo x of the centre of pixel (0, 0), metres.
    pub origin_x_m: f64,
    /// Geo y of the centre of pixel (0, 0), metres.
    pub origin_y_m: f64,
    /// Geo x step per column, metres.
    pub pixel_x_m: f64,
    /// Geo y step per row, metres (negative for north-up).
    pub pixel_y_m: f64,
    /// Projection note stored in the tile.
    pub projection: String,
}

/// Extract up to `MAX_TILE_FEATURES` SURF features from `slope` with `cfg`; return the features
/// and the number dropped by the budget.
pub fn tile_features(
    slope: &SlopeImage<'_>,
    cfg: &SurfConfig,
) -> Result<Box<Features<MAX_TILE_FEATURES>>> {
    let (n_int, n_ring) = scratch_len(slope.width(), slope.height());
    let mut integral = vec![0u32; n_int];
    let mut ring = vec![0.0f32; n_ring];
    // The feature set is a few MiB of fixed arrays: build it where the stack has room.
    crate::flyer::onboard::with_big_stack(|| {
        let mut feats = Box::new(Features::<MAX_TILE_FEATURES>::new());
        extract(
            slope,
            cfg,
            Scratch {
                integral: &mut integral,
                ring: &mut ring,
            },
            &mut feats,
        )
        .map_err(|e| anyhow::anyhow!("SURF on the reference slope: {e}"))?;
        Ok(feats)
    })
}

/// Build a tile blob from a slope image: features by nav-core (the strongest `max_features`, at
/// most [`MAX_TILE_FEATURES`]), header from `grid`, `cfg` and the terrain smoothing σ the slope
/// carries (`smoothing_m`, metres; see `nav_core::TileHeader::smoothing_m`; 0 for slope images
/// that frames will be compared with as they are), and the slope image itself as the tile's
/// reference raster (2 bytes per pixel), which the flyer's dense refinement aligns frames to.
/// `reference_sigma_m` is the map's own horizontal error the tile claims (x, y; metres; see
/// `nav_core::TileHeader::reference_sigma_m` and [`super::reference_sigma_m`]);
/// `height_noise_m` the map's own height noise, 1σ per pixel, metres (0 = none claimed; see
/// `nav_core::TileHeader::height_noise_m`). `raster` (same size as `slope`), when given, is the
/// tile's slope raster in place of `slope`'s own pixels (features from a hole-filled slope, the
/// raster with its holes: `super::write_reference_with`).
#[allow(clippy::too_many_arguments)]
pub fn build_tile(
    slope: &SlopeImage<'_>,
    grid: &GeoGrid,
    cfg: &SurfConfig,
    max_features: usize,
    smoothing_m: f64,
    reference_sigma_m: [f32; 2],
    height_noise_m: f32,
    raster: Option<&[nav_core::SlopePx]>,
) -> Result<Vec<u8>> {
    let raster = raster.unwrap_or(slope.pixels());
    if raster.len() != slope.pixels().len() {
        bail!(
            "tile raster has {} pixels, the slope image {}",
            raster.len(),
            slope.pixels().len()
        );
    }
    let all = tile_features(slope, cfg)?;
    let feats = &all.as_slice()[..all.len().min(max_features)];
    if grid.projection.len() > nav_core::tile::MAX_PROJECTION_LEN {
        bail!(
            "projection note longer than {} bytes",
            nav_core::tile::MAX_PROJECTION_LEN
        );
    }
    let header = TileHeader {
        width_px: u32::try_from(slope.width()).context("tile width")?,
        height_px: u32::try_from(slope.height()).context("tile height")?,
        origin_x_m: grid.origin_x_m,
        origin_y_m: grid.origin_y_m,
        pixel_x_m: grid.pixel_x_m,
        pixel_y_m: grid.pixel_y_m,
        projection: &grid.projection,
        feature_count: feats.len() as u32,
        octaves: cfg.detector.octaves,
        layers: cfg.detector.layers,
        threshold: cfg.detector.threshold,
        min_scale_px: cfg.detector.min_scale_px,
        upright: cfg.upright,
        smoothing_m: smoothing_m as f32,
        reference_sigma_m,
        height_noise_m,
    };
    let mut buf = vec![0u8; tile_len_with_raster(MAX_HEADER_LEN, feats.len(), raster.len())];
    let len = write_tile_with_raster(&header, feats, Some(raster), &mut buf)
        .map_err(|e| anyhow::anyhow!("writing the tile: {e}"))?;
    buf.truncate(len);
    Ok(buf)
}
