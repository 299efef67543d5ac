//! Flight atlas builder: a reference tile's map cut into overlapping tiles of bounded size on
//! the map's own pixel grid, each an ordinary nav-core tile, behind a checksummed index
//! (`nav_core::atlas`, docs/tile-format.md "Atlas").
//!
//! The tiles are cut from the whole map's slope raster (not re-derived per window), so every
//! tile's raster is the map's, pixel for pixel; each tile's features are detected on its
//! window alone (a window edge loses the blobs within a filter's reach of it, which the
//! overlap keeps away from the part of the grid the tile serves).

use anyhow::{Context, Result, bail};
use image::{Rgb, RgbImage};
use imageproc::drawing::draw_hollow_rect_mut;
use imageproc::rect::Rect;
use nav_core::atlas::{
    AtlasEntry, AtlasHeader, MAX_ATLAS_HEADER_LEN, MAX_ATLAS_TILE_SIDE, MAX_ATLAS_TILES,
    atlas_index_len, write_atlas_index,
};
use nav_core::{SlopeImage, SlopePx, Tile};
use rayon::prelude::*;
use serde::Serialize;

use super::tile::{GeoGrid, build_tile};

/// How a map is cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct AtlasLayout {
    /// Largest core side, map pixels: the cores split the grid evenly into the fewest cores of
    /// at most this side.
    pub core_px: usize,
    /// Overlap beyond each core edge, map pixels (clipped at the grid's edges).
    pub margin_px: usize,
}

/// One tile of a built atlas.
#[derive(Debug, Clone, Serialize)]
pub struct AtlasTileSummary {
    /// Tile index.
    pub index: usize,
    /// Map column and row of the tile's pixel (0, 0).
    pub col0: i32,
    /// Map row of the tile's pixel (0, 0).
    pub row0: i32,
    /// Size, px.
    pub width: u32,
    /// Size, px.
    pub height: u32,
    /// The core (the grid part this tile is deepest for): col0, row0, width, height, px.
    pub core: [usize; 4],
    /// Features.
    pub features: usize,
    /// Tile blob bytes.
    pub bytes: usize,
    /// The tile's CRC-32.
    pub crc32: String,
}

/// What `build_atlas` made.
#[derive(Debug, Clone, Serialize)]
pub struct AtlasSummary {
    /// The layout.
    pub layout: AtlasLayout,
    /// Map grid size, px.
    pub grid_px: [usize; 2],
    /// Map pixel, m.
    pub pixel_m: f64,
    /// Tiles across and down.
    pub tiles_xy: [usize; 2],
    /// Index bytes.
    pub index_bytes: usize,
    /// Whole atlas bytes.
    pub atlas_bytes: usize,
    /// Largest tile, bytes (what a RAM buffer of `nav_core::atlas::BufferedAtlas` needs).
    pub largest_tile_bytes: usize,
    /// The single tile the atlas was cut from, bytes and features (for comparison).
    pub source_tile_bytes: usize,
    /// Features of the source tile.
    pub source_features: usize,
    /// Per tile.
    pub tiles: Vec<AtlasTileSummary>,
}

/// Split `n` pixels into the fewest parts of at most `core` pixels, as evenly as possible:
/// part boundaries.
fn splits(n: usize, core: usize) -> Vec<usize> {
    let parts = n.div_ceil(core.max(1)).max(1);
    (0..=parts).map(|i| i * n / parts).collect()
}

/// Cut the map of `tile_bytes` (a tile with a slope raster) into an atlas with `layout`;
/// at most `max_features` per tile. Returns the atlas blob and its summary.
pub fn build_atlas(
    tile_bytes: &[u8],
    layout: AtlasLayout,
    max_features: usize,
) -> Result<(Vec<u8>, AtlasSummary)> {
    let tile = Tile::parse(tile_bytes).map_err(|e| anyhow::anyhow!("source tile: {e}"))?;
    let h = *tile.header();
    let raster = tile
        .slope_raster()
        .context("the source tile carries no slope raster (rebuild it with `ground-sim tile`)")?;
    let (w, ht) = (raster.width(), raster.height());
    if layout.core_px == 0 {
        bail!("--core-px must be ≥ 1");
    }
    let cols = splits(w, layout.core_px);
    let rows = splits(ht, layout.core_px);
    let (nx, ny) = (cols.len() - 1, rows.len() - 1);
    if nx * ny > MAX_ATLAS_TILES {
        bail!("{nx} × {ny} tiles: more than an atlas holds ({MAX_ATLAS_TILES}); raise --core-px");
    }
    let px: Vec<SlopePx> = (0..w * ht)
        .map(|i| SlopePx::from_bits(raster.raw_index(i)))
        .collect();
    let pixel_m = h.pixel_m();
    let m = layout.margin_px;
    // (core, extent) per tile, row-major.
    let mut cells = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let (c0, c1, r0, r1) = (cols[i], cols[i + 1], rows[j], rows[j + 1]);
            let (x0, x1) = (c0.saturating_sub(m), (c1 + m).min(w));
            let (y0, y1) = (r0.saturating_sub(m), (r1 + m).min(ht));
            if (x1 - x0) as u32 > MAX_ATLAS_TILE_SIDE || (y1 - y0) as u32 > MAX_ATLAS_TILE_SIDE {
                bail!(
                    "a tile of {}×{} px exceeds {MAX_ATLAS_TILE_SIDE} px",
                    x1 - x0,
                    y1 - y0
                );
            }
            cells.push(([c0, r0, c1 - c0, r1 - r0], [x0, y0, x1, y1]));
        }
    }
    let blobs: Vec<Vec<u8>> = cells
        .par_iter()
        .map(|&(_, [x0, y0, x1, y1])| {
            let (tw, th) = (x1 - x0, y1 - y0);
            let win: Vec<SlopePx> = (y0..y1)
                .flat_map(|y| px[y * w + x0..y * w + x1].iter().copied())
                .collect();
            let img = SlopeImage::new_checked(&win, tw, th, pixel_m as f32)
                .map_err(|e| anyhow::anyhow!("tile window: {e}"))?;
            let grid = GeoGrid {
                origin_x_m: h.origin_x_m + x0 as f64 * h.pixel_x_m,
                origin_y_m: h.origin_y_m + y0 as f64 * h.pixel_y_m,
                pixel_x_m: h.pixel_x_m,
                pixel_y_m: h.pixel_y_m,
                projection: h.projection.to_string(),
            };
            build_tile(
                &img,
                &grid,
                &h.surf_config(),
                max_features,
                h.smoothing_m as f64,
                h.reference_sigma_m,
                h.height_noise_m,
                None,
            )
        })
        .collect::<Result<_>>()?;
    let header = AtlasHeader {
        width_px: w as u32,
        height_px: ht as u32,
        origin_x_m: h.origin_x_m,
        origin_y_m: h.origin_y_m,
        pixel_x_m: h.pixel_x_m,
        pixel_y_m: h.pixel_y_m,
        projection: h.projection,
        margin_px: m as u32,
        smoothing_m: h.smoothing_m,
        octaves: h.octaves,
        layers: h.layers,
        threshold: h.threshold,
        min_scale_px: h.min_scale_px,
        upright: h.upright,
    };
    // Index length first (the header length is known after encoding once).
    let mut scratch = vec![0u8; atlas_index_len(MAX_ATLAS_HEADER_LEN, blobs.len())];
    let dummy: Vec<AtlasEntry> = cells
        .iter()
        .map(|&(_, [x0, y0, x1, y1])| AtlasEntry {
            col0: x0 as i32,
            row0: y0 as i32,
            width: (x1 - x0) as u32,
            height: (y1 - y0) as u32,
            offset: 0,
            length: 24,
            crc: 0,
        })
        .collect();
    // Offsets are checked only by the reader: placeholders size the index.
    let index_len = write_atlas_index(&header, &dummy, &mut scratch)
        .map_err(|e| anyhow::anyhow!("atlas index: {e}"))?;
    let mut entries = Vec::with_capacity(blobs.len());
    let mut at = index_len;
    for (d, b) in dummy.iter().zip(&blobs) {
        let crc = nav_core::tile::stored_crc(b).context("tile blob")?;
        entries.push(AtlasEntry {
            offset: u32::try_from(at).context("atlas larger than 4 GiB")?,
            // The reader refuses a blob that ends past 4 GiB: so does the writer.
            length: u32::try_from(b.len())
                .ok()
                .filter(|&l| u32::try_from(at + l as usize).is_ok())
                .context("atlas larger than 4 GiB")?,
            crc,
            ..*d
        });
        at = (at + b.len()).next_multiple_of(4);
    }
    let mut out = vec![0u8; at];
    let n = write_atlas_index(&header, &entries, &mut out)
        .map_err(|e| anyhow::anyhow!("atlas index: {e}"))?;
    debug_assert_eq!(n, index_len);
    for (e, b) in entries.iter().zip(&blobs) {
        out[e.offset as usize..e.offset as usize + b.len()].copy_from_slice(b);
    }
    let tiles = cells
        .iter()
        .zip(&entries)
        .zip(&blobs)
        .enumerate()
        .map(|(i, ((&(core, _), e), b))| {
            Ok(AtlasTileSummary {
                index: i,
                col0: e.col0,
                row0: e.row0,
                width: e.width,
                height: e.height,
                core,
                features: Tile::parse(b).map_err(|e| anyhow::anyhow!("{e}"))?.len(),
                bytes: b.len(),
                crc32: format!("{:08x}", e.crc),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let summary = AtlasSummary {
        layout,
        grid_px: [w, ht],
        pixel_m,
        tiles_xy: [nx, ny],
        index_bytes: index_len,
        atlas_bytes: out.len(),
        largest_tile_bytes: blobs.iter().map(Vec::len).max().unwrap_or(0),
        source_tile_bytes: tile_bytes.len(),
        source_features: tile.len(),
        tiles,
    };
    Ok((out, summary))
}

/// [`build_atlas`] with the largest core side ≤ `layout.core_px` whose every tile fits in
/// `max_tile_bytes` (e.g. the RAM buffer of a `nav_core::atlas::BufferedAtlas`): cores shrink
/// by 10 % (at least 1 px) until the largest tile fits. Errors when even 1 px cores do not fit
/// (the margins alone are too large for the budget).
pub fn build_atlas_within(
    tile_bytes: &[u8],
    layout: AtlasLayout,
    max_features: usize,
    max_tile_bytes: usize,
) -> Result<(Vec<u8>, AtlasSummary)> {
    let tile = Tile::parse(tile_bytes).map_err(|e| anyhow::anyhow!("source tile: {e}"))?;
    let (w, h) = (
        tile.header().width_px as usize,
        tile.header().height_px as usize,
    );
    let mut core = layout.core_px.max(1);
    loop {
        let l = AtlasLayout {
            core_px: core,
            ..layout
        };
        // Smaller cores only add tiles: past the atlas's tile limit the search is over.
        let tiles = w.div_ceil(core) * h.div_ceil(core);
        if tiles <= MAX_ATLAS_TILES {
            let (bytes, s) = build_atlas(tile_bytes, l, max_features)?;
            if s.largest_tile_bytes <= max_tile_bytes {
                return Ok((bytes, s));
            }
        }
        if core == 1 || tiles > MAX_ATLAS_TILES {
            bail!(
                "no core size gives tiles of at most {max_tile_bytes} bytes with {} px margins: lower --margin-px or --max-features, or raise --max-tile-bytes",
                layout.margin_px
            );
        }
        core = (core - (core / 10).max(1)).max(1);
    }
}

/// The map's slope (grey, 0–40°) under the atlas: each tile's core tinted in the tile's colour
/// and labelled with its index, each tile's extent outlined in the same colour (2 px), with a
/// title band above.
pub fn atlas_picture(tile_bytes: &[u8], summary: &AtlasSummary) -> Result<RgbImage> {
    use crate::pictures::render::{GLYPH, draw_text};
    let tile = Tile::parse(tile_bytes).map_err(|e| anyhow::anyhow!("source tile: {e}"))?;
    let r = tile.slope_raster().context("no slope raster")?;
    let (w, h) = (r.width(), r.height());
    let band = 2 * GLYPH + 12;
    let mut img = RgbImage::from_pixel(
        w.max(24 * GLYPH as usize) as u32,
        (h + band as usize) as u32,
        Rgb([0, 0, 0]),
    );
    let top = band as i32;
    for y in 0..h {
        for x in 0..w {
            let v = nav_core::frame::slope_to_deg(r.get(x, y))
                .map_or(60u8, |d| (d / 40.0 * 255.0).clamp(0.0, 255.0) as u8);
            img.put_pixel(x as u32, y as u32 + band, Rgb([v, v, v]));
        }
    }
    const COLOURS: [[u8; 3]; 6] = [
        [230, 60, 60],
        [60, 200, 80],
        [70, 120, 240],
        [240, 200, 40],
        [200, 80, 220],
        [40, 210, 210],
    ];
    let colour = |i: usize| COLOURS[(i + i / 4) % COLOURS.len()];
    for t in &summary.tiles {
        let [cx, cy, cw, ch] = t.core;
        let c = colour(t.index);
        for y in cy..(cy + ch).min(h) {
            for x in cx..(cx + cw).min(w) {
                let p = img.get_pixel_mut(x as u32, y as u32 + band);
                for (v, &t) in p.0.iter_mut().zip(&c) {
                    *v = ((3 * u16::from(*v) + u16::from(t)) / 4) as u8;
                }
            }
        }
    }
    for t in &summary.tiles {
        let c = colour(t.index);
        for inset in 0..2 {
            draw_hollow_rect_mut(
                &mut img,
                Rect::at(t.col0 + inset, t.row0 + inset + top).of_size(
                    (t.width as i32 - 2 * inset).max(1) as u32,
                    (t.height as i32 - 2 * inset).max(1) as u32,
                ),
                Rgb(c),
            );
        }
        let [cx, cy, cw, ch] = t.core;
        let label = t.index.to_string();
        let lx = (cx + cw / 2).saturating_sub(label.len() * GLYPH as usize / 2);
        let ly = (cy + ch / 2).saturating_sub(GLYPH as usize / 2) + band as usize;
        draw_text(&mut img, lx as u32, ly as u32, &label, [255, 255, 255]);
    }
    let [nx, ny] = summary.tiles_xy;
    draw_text(
        &mut img,
        4,
        4,
        &format!("atlas {nx}x{ny} tiles, {} m px", summary.pixel_m),
        [255, 255, 255],
    );
    draw_text(
        &mut img,
        4,
        GLYPH + 8,
        &format!(
            "core <={} px (tint), margin {} px",
            summary.layout.core_px, summary.layout.margin_px
        ),
        [200, 200, 200],
    );
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cores_split_the_grid_evenly_without_gaps() {
        assert_eq!(splits(800, 200), vec![0, 200, 400, 600, 800]);
        assert_eq!(splits(801, 200), vec![0, 160, 320, 480, 640, 801]);
        assert_eq!(splits(150, 200), vec![0, 150]);
    }
}
