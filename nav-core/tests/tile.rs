//! Tile format: golden bytes, round trip, and every kind of damage gives its typed error.

use nav_core::tile::{
    TILE_FORMAT_VERSION, Tile, TileError, TileHeader, tile_len, tile_len_with_raster, write_tile,
    write_tile_with_raster,
};
use nav_core::{DESCRIPTOR_LEN, Feature, Keypoint};
use nav_core::{SLOPE_NODATA, SlopePx};
use proptest::prelude::*;

fn header(n: usize) -> TileHeader<'static> {
    TileHeader {
        width_px: 200,
        height_px: 150,
        origin_x_m: 75_360.0,
        origin_y_m: 39_640.0,
        pixel_x_m: 20.0,
        pixel_y_m: -20.0,
        projection: "polar stereographic south, R=1737400",
        feature_count: n as u32,
        octaves: 3,
        layers: 4,
        threshold: 1.0,
        min_scale_px: 0.0,
        upright: false,
        smoothing_m: 40.0,
        reference_sigma_m: [1.5, 2.0],
        height_noise_m: 1.25,
    }
}

fn feature(i: usize) -> Feature {
    let mut descriptor = [0.0f32; DESCRIPTOR_LEN];
    for (j, v) in descriptor.iter_mut().enumerate() {
        *v = ((i * 64 + j) as f32 * 0.37).sin() * 0.125;
    }
    Feature {
        keypoint: Keypoint {
            x_px: 10.25 + i as f32 * 3.5,
            y_px: 20.5 + i as f32,
            scale_px: 2.75,
            orientation_rad: 1.5,
            response: 4.0 + i as f32,
            laplacian_positive: i % 2 == 1,
        },
        descriptor,
    }
}

fn build(n: usize) -> Vec<u8> {
    let feats: Vec<Feature> = (0..n).map(feature).collect();
    let mut buf = vec![0u8; tile_len(512, n)];
    let len = write_tile(&header(n), &feats, &mut buf).unwrap();
    buf.truncate(len);
    buf
}

/// Slope raster for `header(_)`'s 200 × 150 pixels: a ramp with one no-data pixel.
fn raster() -> Vec<SlopePx> {
    let mut r: Vec<SlopePx> = (0..200 * 150)
        .map(|i| SlopePx::from_bits((i % 46_080) as u16))
        .collect();
    r[777] = SLOPE_NODATA;
    r
}

fn build_with_raster(n: usize) -> Vec<u8> {
    let feats: Vec<Feature> = (0..n).map(feature).collect();
    let mut buf = vec![0u8; tile_len_with_raster(512, n, 200 * 150)];
    let len = write_tile_with_raster(&header(n), &feats, Some(&raster()), &mut buf).unwrap();
    buf.truncate(len);
    buf
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// The first 76 bytes (preamble, header start) and the CRC of a one-feature tile without a
/// raster, as written by format version 5 (version 4 had no `height_noise_m`, version 3 no
/// `reference_sigma_m`, version 2 no raster count in the preamble, version 1 no `smoothing_m`).
/// A change here is a format change: bump `TILE_FORMAT_VERSION` and `docs/tile-format.md`.
const GOLDEN_HEAD: &str = "554d42524154494c050065000100000000000000c8019601000000000066f24000000000005be340000000000000344000000000000034c024706f6c61722073746572656f67726170686963";
const GOLDEN_CRC: &str = "1dd775f4";

#[test]
fn golden_bytes() {
    let t = build(1);
    assert_eq!(t.len(), 408);
    assert_eq!(t.len(), tile_len(t[10] as usize | (t[11] as usize) << 8, 1));
    assert_eq!(&t[..8], b"UMBRATIL");
    assert_eq!(u16::from_le_bytes([t[8], t[9]]), TILE_FORMAT_VERSION);
    assert_eq!(hex(&t[..76]), GOLDEN_HEAD);
    assert_eq!(hex(&t[t.len() - 4..]), GOLDEN_CRC);
    // The header ends (byte 20 + 101) with smoothing_m 40.0, reference_sigma_m [1.5, 2.0] and
    // height_noise_m 1.25, f32 little-endian, then padding to 124.
    assert_eq!(hex(&t[105..124]), "000020420000c03f000000400000a03f000000");
    // With the raster: its pixel count in the preamble, 2 bytes per pixel after the
    // descriptors, and nothing else moves.
    let r = build_with_raster(1);
    assert_eq!(r.len(), 408 + 60_000);
    assert_eq!(hex(&r[16..20]), "30750000");
    assert_eq!(hex(&r[20..404]), hex(&t[20..404]));
    assert_eq!(hex(&r[404..410]), "000001000200");
    assert_eq!(hex(&r[r.len() - 4..]), GOLDEN_RASTER_CRC);
}

const GOLDEN_RASTER_CRC: &str = "af155b12";

#[test]
fn raster_round_trips() {
    let bytes = build_with_raster(3);
    let tile = Tile::parse(&bytes).unwrap();
    let r = tile.slope_raster().unwrap();
    assert_eq!((r.width(), r.height()), (200, 150));
    let want = raster();
    for row in 0..150 {
        for col in 0..200 {
            assert_eq!(r.get(col, row), want[row * 200 + col]);
        }
    }
    assert_eq!(r.get(200, 0), SLOPE_NODATA);
    assert_eq!(r.get(0, 150), SLOPE_NODATA);
    assert!(Tile::parse(&build(3)).unwrap().slope_raster().is_none());
    // A raster of the wrong size is refused by the writer.
    let mut buf = vec![0u8; tile_len_with_raster(512, 1, 200 * 150)];
    assert_eq!(
        write_tile_with_raster(&header(1), &[feature(0)], Some(&raster()[1..]), &mut buf),
        Err(TileError::BadGeometry)
    );
}

#[test]
fn round_trip_is_exact() {
    for n in [0usize, 1, 7] {
        let bytes = build(n);
        let tile = Tile::parse(&bytes).unwrap();
        assert_eq!(*tile.header(), header(n));
        assert_eq!(tile.len(), n);
        for i in 0..n {
            let f = feature(i);
            assert_eq!(tile.keypoint(i), f.keypoint);
            assert_eq!(tile.descriptor(i), f.descriptor);
        }
    }
}

fn reseal(b: &mut [u8]) {
    let n = b.len();
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn damage_gives_typed_errors() {
    let good = build(3);
    // Truncated anywhere.
    for cut in [0, 10, 19, good.len() - 1] {
        assert!(
            matches!(Tile::parse(&good[..cut]), Err(TileError::Truncated { .. })),
            "cut {cut}"
        );
    }
    // One flipped bit in the body.
    let mut b = good.clone();
    b[200] ^= 0x10;
    assert!(matches!(
        Tile::parse(&b),
        Err(TileError::BadChecksum { .. })
    ));
    // Wrong magic.
    let mut b = good.clone();
    b[0] = b'X';
    assert_eq!(Tile::parse(&b).unwrap_err(), TileError::BadMagic);
    // Wrong version (even with a valid checksum).
    let mut b = good.clone();
    b[8] = 1;
    reseal(&mut b);
    assert_eq!(
        Tile::parse(&b).unwrap_err(),
        TileError::WrongVersion { found: 1 }
    );
    // A NaN, negative or huge terrain smoothing, reference σ or height noise (the header's
    // last four f32: smoothing_m, reference_sigma_m x, y, height_noise_m) behind a valid
    // checksum.
    let h_end = 20 + (good[10] as usize | (good[11] as usize) << 8);
    for field_end in [h_end - 12, h_end - 8, h_end - 4, h_end] {
        for bad in [f32::NAN, -1.0, f32::INFINITY, 2e4] {
            let mut b = good.clone();
            b[field_end - 4..field_end].copy_from_slice(&bad.to_le_bytes());
            reseal(&mut b);
            assert_eq!(
                Tile::parse(&b).unwrap_err(),
                TileError::BadGeometry,
                "{bad} ending at {field_end}"
            );
        }
    }
    let mut buf = vec![0u8; tile_len(512, 1)];
    for bad in 0..4 {
        let mut h = header(1);
        match bad {
            0 => h.smoothing_m = -1.0,
            1 => h.reference_sigma_m[0] = f32::NAN,
            2 => h.reference_sigma_m[1] = -0.5,
            _ => h.height_noise_m = f32::INFINITY,
        }
        assert_eq!(
            write_tile(&h, &[feature(0)], &mut buf),
            Err(TileError::BadGeometry)
        );
    }
    // A NaN descriptor value behind a valid checksum.
    let mut b = good.clone();
    let at = b.len() - 4 - 8;
    b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    reseal(&mut b);
    assert_eq!(
        Tile::parse(&b).unwrap_err(),
        TileError::BadFeature { index: 2 }
    );
    // A keypoint outside the tile.
    let feats: Vec<Feature> = (0..2)
        .map(|i| {
            let mut f = feature(i);
            f.keypoint.x_px = 500.0;
            f
        })
        .collect();
    let mut buf = vec![0u8; tile_len(512, 2)];
    let len = write_tile(&header(2), &feats, &mut buf).unwrap();
    assert_eq!(
        Tile::parse(&buf[..len]).unwrap_err(),
        TileError::BadFeature { index: 0 }
    );
    // Header count disagreeing with the features, zero pixel size.
    assert!(write_tile(&header(5), &feats, &mut buf).is_err());
    let mut h = header(2);
    h.pixel_x_m = 0.0;
    let len = write_tile(&h, &[feature(0), feature(1)], &mut buf).unwrap();
    assert_eq!(
        Tile::parse(&buf[..len]).unwrap_err(),
        TileError::BadGeometry
    );
    // A raster whose pixel count is not width × height, behind a consistent length and a valid
    // checksum.
    let mut b = build_with_raster(1);
    let n = b.len();
    b.truncate(n - 8);
    b[16..20].copy_from_slice(&(200u32 * 150 - 2).to_le_bytes());
    b.extend_from_slice(&[0; 4]);
    reseal(&mut b);
    assert_eq!(Tile::parse(&b).unwrap_err(), TileError::BadGeometry);
    // A raster count the blob is too short for.
    let mut b = build(1);
    b[16..20].copy_from_slice(&(200u32 * 150).to_le_bytes());
    reseal(&mut b);
    assert!(matches!(Tile::parse(&b), Err(TileError::Truncated { .. })));
    // Writer buffer too small.
    let mut small = vec![0u8; 40];
    assert!(matches!(
        write_tile(&header(1), &[feature(0)], &mut small),
        Err(TileError::BufferTooSmall { .. })
    ));
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let _ = Tile::parse(&bytes);
    }

    #[test]
    fn mutated_tiles_never_panic(pos in 0usize..2000, val in any::<u8>(), reseal_it in any::<bool>(), with_raster in any::<bool>()) {
        let mut b = if with_raster { build_with_raster(5) } else { build(5) };
        let p = pos % b.len();
        b[p] = val;
        if reseal_it {
            reseal(&mut b);
        }
        let _ = Tile::parse(&b);
    }
}
