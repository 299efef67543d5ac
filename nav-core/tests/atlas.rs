//! Atlas format: golden index bytes, round trip, tile selection, both tile sources alike, and
//! every kind of damage gives its typed error (never a panic).

use nav_core::atlas::{
    ATLAS_FORMAT_VERSION, Atlas, AtlasEntry, AtlasError, AtlasHeader, BufferedAtlas,
    MAX_ATLAS_CANDIDATES, MappedAtlas, TileSource, atlas_index_len, write_atlas_index,
};
use nav_core::tile::{TileHeader, tile_len_with_raster, write_tile_with_raster};
use nav_core::{DESCRIPTOR_LEN, Feature, Keypoint, Prior, SlopePx};
use proptest::prelude::*;

const PROJ: &str = "polar stereographic south";

fn atlas_header() -> AtlasHeader<'static> {
    AtlasHeader {
        width_px: 300,
        height_px: 200,
        origin_x_m: 1000.0,
        origin_y_m: 5000.0,
        pixel_x_m: 20.0,
        pixel_y_m: -20.0,
        projection: PROJ,
        margin_px: 20,
        smoothing_m: 40.0,
        octaves: 3,
        layers: 4,
        threshold: 0.5,
        min_scale_px: 0.0,
        upright: false,
    }
}

/// A tile of `w × h` px at atlas pixel `(c0, r0)` with two features and a ramp raster.
fn tile_at(c0: i32, r0: i32, w: u32, h: u32) -> Vec<u8> {
    let a = atlas_header();
    let header = TileHeader {
        width_px: w,
        height_px: h,
        origin_x_m: a.origin_x_m + c0 as f64 * a.pixel_x_m,
        origin_y_m: a.origin_y_m + r0 as f64 * a.pixel_y_m,
        pixel_x_m: a.pixel_x_m,
        pixel_y_m: a.pixel_y_m,
        projection: PROJ,
        feature_count: 2,
        octaves: a.octaves,
        layers: a.layers,
        threshold: a.threshold,
        min_scale_px: a.min_scale_px,
        upright: a.upright,
        smoothing_m: a.smoothing_m,
        reference_sigma_m: [0.0, 0.0],
        height_noise_m: 0.0,
    };
    let feats: Vec<Feature> = (0..2)
        .map(|i| Feature {
            keypoint: Keypoint {
                x_px: 5.0 + i as f32,
                y_px: 7.0,
                scale_px: 2.5,
                orientation_rad: 0.5,
                response: 1.0,
                laplacian_positive: i == 1,
            },
            descriptor: [0.125; DESCRIPTOR_LEN],
        })
        .collect();
    let raster: Vec<SlopePx> = (0..w * h)
        .map(|i| SlopePx::from_bits((i % 4000) as u16))
        .collect();
    let mut buf = vec![0u8; tile_len_with_raster(512, 2, raster.len())];
    let n = write_tile_with_raster(&header, &feats, Some(&raster), &mut buf).unwrap();
    buf.truncate(n);
    buf
}

/// Two tiles side by side (150 px cores, 40 px overlap), as the ground writes them.
fn build() -> Vec<u8> {
    let places = [(0, 0, 170, 200), (130, 0, 170, 200)];
    let blobs: Vec<Vec<u8>> = places
        .iter()
        .map(|&(c, r, w, h)| tile_at(c, r, w, h))
        .collect();
    let mut entries: Vec<AtlasEntry> = places
        .iter()
        .map(|&(c, r, w, h)| AtlasEntry {
            col0: c,
            row0: r,
            width: w,
            height: h,
            offset: 0,
            length: 0,
            crc: 0,
        })
        .collect();
    let mut scratch = vec![0u8; atlas_index_len(512, 2)];
    let index_len = write_atlas_index(&atlas_header(), &entries, &mut scratch).unwrap();
    let mut at = index_len;
    for (e, b) in entries.iter_mut().zip(&blobs) {
        e.offset = at as u32;
        e.length = b.len() as u32;
        e.crc = nav_core::tile::stored_crc(b).unwrap();
        at = (at + b.len()).next_multiple_of(4);
    }
    let mut out = vec![0u8; at];
    write_atlas_index(&atlas_header(), &entries, &mut out).unwrap();
    for (e, b) in entries.iter().zip(&blobs) {
        out[e.offset as usize..e.offset as usize + b.len()].copy_from_slice(b);
    }
    out
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn prior(x: f32, y: f32, sigma: f32) -> Prior {
    Prior {
        center_tile_px: [x, y],
        sigma_px: sigma,
        heading_rad: 0.0,
        heading_sigma_rad: 0.1,
        scale: 0.5,
        scale_sigma: 0.02,
    }
}

/// The preamble, the header's first fields and the index CRC of `build()`, as written by atlas
/// format version 1. A change here is a format change: bump `ATLAS_FORMAT_VERSION` and
/// docs/tile-format.md.
const GOLDEN_HEAD: &str =
    "554d42524141544c01004e0002000000ac02c8010000000000408f40000000000088b340";
/// Stored little-endian: CRC-32 0x06ca4b15 (zlib.crc32 of the 152 bytes before it agrees). The
/// index holds the tiles' lengths, so a tile format change moves it too (tile version 5).
const GOLDEN_INDEX_CRC: &str = "154bca06";

#[test]
fn golden_index_bytes() {
    let b = build();
    let a = Atlas::parse(&b).unwrap();
    assert_eq!(&b[..8], b"UMBRAATL");
    assert_eq!(u16::from_le_bytes([b[8], b[9]]), ATLAS_FORMAT_VERSION);
    assert_eq!(hex(&b[..36]), GOLDEN_HEAD);
    let n = a.index_len();
    assert_eq!(n, 16 + 80 + 2 * 28 + 4);
    assert_eq!(hex(&b[n - 4..n]), GOLDEN_INDEX_CRC);
    // Entry 1: col0 130, row0 0, 170 × 200 px, its blob right after tile 0's (4-aligned).
    let e = a.entry(1).unwrap();
    assert_eq!((e.col0, e.row0, e.width, e.height), (130, 0, 170, 200));
    assert_eq!(e.offset as usize % 4, 0);
    assert_eq!(
        e.offset as usize,
        (n + a.entry(0).unwrap().length as usize).next_multiple_of(4)
    );
}

#[test]
fn round_trip_and_both_sources_give_the_same_tiles() {
    let b = build();
    let mapped = MappedAtlas::<4>::new(&b).unwrap();
    assert_eq!(mapped.atlas().len(), 2);
    let mut store = vec![0u8; 100_000];
    let mut buffered = BufferedAtlas::new(&b[..], &b[..], &mut store).unwrap();
    for i in [0u16, 1, 1, 0] {
        let t = mapped.get(i).unwrap();
        let u = buffered.tile(i).unwrap();
        assert_eq!(t.header(), u.header());
        assert_eq!(t.len(), u.len());
        assert_eq!(buffered.loaded(), Some(i));
    }
    assert_eq!(
        mapped.get(2).unwrap_err(),
        AtlasError::NoSuchTile { index: 2 }
    );
    // A buffer smaller than a tile is a typed error, not a truncated read.
    let mut little = [0u8; 1_000];
    let mut small = BufferedAtlas::new(&b[..], &b[..], &mut little).unwrap();
    assert!(matches!(
        small.tile(0).unwrap_err(),
        AtlasError::TooLarge { index: 0, .. }
    ));
    // More tiles than the mapped capacity.
    assert!(matches!(
        MappedAtlas::<1>::new(&b).unwrap_err(),
        AtlasError::TooLarge { needed: 2, .. }
    ));
}

#[test]
fn selection_ranks_by_depth_and_widens_only_when_a_frame_straddles() {
    let b = build();
    let a = Atlas::parse(&b).unwrap();
    // Deep inside tile 0 (x 60, y 100), a 40 × 40 px frame at scale 0.5 reaches 14 px + 3σ.
    let c = a.select(&prior(60.0, 100.0, 2.0), 40, 40);
    assert_eq!(c.as_slice(), &[0]);
    assert!(!c.straddles);
    // On the overlap's middle (x 149.5) both tiles are as deep (20 px): ties go to the lower
    // index, and a reach beyond 20 px brings the neighbour in.
    let c = a.select(&prior(149.5, 100.0, 10.0), 40, 40);
    assert_eq!(c.as_slice(), &[0, 1]);
    assert!(c.straddles);
    // Right of it tile 1 is deeper.
    let c = a.select(&prior(160.0, 100.0, 10.0), 40, 40);
    assert_eq!(c.as_slice(), &[1, 0]);
    // Outside the atlas beyond any reach: nothing.
    let c = a.select(&prior(-500.0, 100.0, 1.0), 40, 40);
    assert_eq!(c.count, 0);
    // Non-finite prior: nothing, no panic.
    let c = a.select(&prior(f32::NAN, 100.0, 1.0), 40, 40);
    assert_eq!(c.count, 0);
    assert!(c.as_slice().len() <= MAX_ATLAS_CANDIDATES);
}

#[test]
fn damage_gives_typed_errors() {
    let good = build();
    let n = Atlas::parse(&good).unwrap().index_len();
    assert_eq!(
        Atlas::parse(&good[..10]).unwrap_err(),
        AtlasError::Truncated {
            expected: 20,
            got: 10
        }
    );
    assert!(matches!(
        Atlas::parse(&good[..n - 1]).unwrap_err(),
        AtlasError::Truncated { .. }
    ));
    let mut b = good.clone();
    b[0] = b'X';
    assert_eq!(Atlas::parse(&b).unwrap_err(), AtlasError::BadMagic);
    let mut b = good.clone();
    b[8] = 9;
    assert_eq!(
        Atlas::parse(&b).unwrap_err(),
        AtlasError::WrongVersion { found: 9 }
    );
    let mut b = good.clone();
    b[40] ^= 1;
    assert!(matches!(
        Atlas::parse(&b).unwrap_err(),
        AtlasError::BadChecksum { .. }
    ));
    // A damaged tile: the index is fine, the mapped atlas names the tile.
    let mut b = good.clone();
    let e1 = Atlas::parse(&good).unwrap().entry(1).unwrap();
    b[e1.offset as usize + 100] ^= 0x10;
    assert!(matches!(
        MappedAtlas::<4>::new(&b).unwrap_err(),
        AtlasError::Tile { index: 1, .. }
    ));
    let mut store = vec![0u8; 100_000];
    let mut buf = BufferedAtlas::new(&b[..], &b[..], &mut store).unwrap();
    assert!(buf.tile(0).is_ok());
    assert!(matches!(
        buf.tile(1).unwrap_err(),
        AtlasError::Tile { index: 1, .. }
    ));
    assert_eq!(buf.loaded(), None, "a refused tile is not kept");
}

#[test]
fn a_tile_placed_elsewhere_than_its_entry_says_is_refused() {
    // Tile 1's blob placed where the index says tile 0 is: each parses, neither matches.
    let good = build();
    let a = Atlas::parse(&good).unwrap();
    let (e0, e1) = (a.entry(0).unwrap(), a.entry(1).unwrap());
    assert_eq!(e0.length, e1.length);
    let mut b = good.clone();
    let t1 = good[e1.offset as usize..(e1.offset + e1.length) as usize].to_vec();
    b[e0.offset as usize..(e0.offset + e0.length) as usize].copy_from_slice(&t1);
    assert_eq!(
        MappedAtlas::<4>::new(&b).unwrap_err(),
        AtlasError::TileMismatch { index: 0 }
    );
}

#[test]
fn an_entry_out_of_range_is_refused_even_under_a_good_crc() {
    let good = build();
    let n = Atlas::parse(&good).unwrap().index_len();
    let e_start = n - 4 - 2 * 28;
    let fix_crc = |b: &mut Vec<u8>| {
        let crc = crc32(&b[..n - 4]);
        b[n - 4..n].copy_from_slice(&crc.to_le_bytes());
    };
    // Entry 1's width 170 → 171: past the 300 px grid.
    let mut b = good.clone();
    b[e_start + 28 + 8] = 171;
    fix_crc(&mut b);
    assert_eq!(
        Atlas::parse(&b).unwrap_err(),
        AtlasError::BadEntry { index: 1 }
    );
    // Entry 0's offset inside the index.
    let mut b = good.clone();
    b[e_start + 16..e_start + 20].copy_from_slice(&8u32.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(
        Atlas::parse(&b).unwrap_err(),
        AtlasError::BadEntry { index: 0 }
    );
    // Entry 0's offset unaligned.
    let mut b = good.clone();
    let off = u32::from_le_bytes(b[e_start + 16..e_start + 20].try_into().unwrap()) + 2;
    b[e_start + 16..e_start + 20].copy_from_slice(&off.to_le_bytes());
    fix_crc(&mut b);
    assert_eq!(
        Atlas::parse(&b).unwrap_err(),
        AtlasError::BadEntry { index: 0 }
    );
}

/// CRC-32/ISO-HDLC, bit by bit (independent of the crate's table).
fn crc32(b: &[u8]) -> u32 {
    let mut c = !0u32;
    for &x in b {
        c ^= u32::from(x);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

#[test]
fn grid_border_edges_do_not_make_a_frame_straddle() {
    let b = build();
    let a = Atlas::parse(&b).unwrap();
    // 5 px from the grid's top border, deep in tile 0 otherwise: one tile, no straddle.
    let c = a.select(&prior(60.0, 5.0, 2.0), 40, 40);
    assert_eq!(c.as_slice(), &[0]);
    assert!(!c.straddles);
    // A prior just outside the grid's left border is still served by tile 0.
    let c = a.select(&prior(-3.0, 100.0, 2.0), 40, 40);
    assert_eq!(c.as_slice(), &[0]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn arbitrary_bytes_never_panic(b in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = Atlas::parse(&b);
        let _ = MappedAtlas::<4>::new(&b);
    }

    #[test]
    fn mutated_atlases_never_panic(at in 0usize..400, v in any::<u8>(), cut in 0usize..2) {
        let mut b = build();
        let i = at % b.len();
        b[i] = v;
        let b = if cut == 1 { b[..b.len() - at.min(b.len())].to_vec() } else { b };
        if let Ok(a) = Atlas::parse(&b) {
            let _ = a.select(&prior(at as f32, 50.0, 3.0), 40, 40);
        }
        let _ = MappedAtlas::<4>::new(&b);
        let mut store = vec![0u8; 100_000];
        if let Ok(mut s) = BufferedAtlas::new(&b[..], &b[..], &mut store) {
            let _ = s.tile(0).map(|t| t.len());
            let _ = s.tile(1).map(|t| t.len());
        }
    }

    #[test]
    fn selection_is_bounded_and_deepest_first(x in -400.0f32..700.0, y in -300.0f32..500.0, s in 0.0f32..200.0) {
        let b = build();
        let a = Atlas::parse(&b).unwrap();
        let c = a.select(&prior(x, y, s), 100, 100);
        prop_assert!(c.as_slice().len() <= MAX_ATLAS_CANDIDATES);
        for w in c.depth_px[..c.count as usize].windows(2) {
            prop_assert!(w[0] >= w[1]);
        }
    }
}
