//! GeoTIFF reading and writing: round trips, real LOLA files, unsupported layouts.

// Test helpers outside #[test] functions may unwrap too: a failure is a test failure.
#![allow(clippy::unwrap_used)]

use std::io::Cursor;
use std::path::PathBuf;

use ground_sim::dem::{
    Dem, DemError, GeoForm, GeoKeys, GeoRef, GeoTransform, SampleKind, read_geotiff,
    read_geotiff_bytes, write_geotiff, write_geotiff_bytes,
};
use tiff::encoder::{TiffEncoder, colortype};

/// `../shared/data` seen from the workspace root (this crate is one level below it).
fn shared_data() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!(
            "skipped: ../shared/data not found (looked in {})",
            dir.display()
        );
        None
    }
}

/// Polar-stereographic-like keys with double and ASCII parameters, to check they are kept.
fn polar_keys() -> GeoKeys {
    GeoKeys {
        directory: vec![
            1, 1, 0, 5, //
            1024, 0, 1, 1, //
            1025, 0, 1, 1, //
            1026, 34737, 22, 0, //
            3078, 34736, 1, 0, //
            3076, 0, 1, 9001,
        ],
        doubles: Some(vec![-90.0, 1_737_400.0]),
        ascii: Some("Moon south polar test|".into()),
    }
}

fn dem_with(kind: SampleKind, nodata: Option<f64>, geo: GeoRef) -> Dem {
    let (w, h) = (37usize, 23usize);
    let z: Vec<f32> = (0..w * h)
        .map(|i| match kind {
            SampleKind::F32 => (i as f32).sin() * 1234.567 - 50.25,
            SampleKind::I16 => (i as f32 * 7.0) - 3000.0,
            SampleKind::U16 => i as f32 * 13.0,
        })
        .collect();
    let mut d = Dem::new(w, h, z, geo).unwrap();
    d.sample = kind;
    d.nodata = nodata;
    if nodata.is_some() {
        d.heights_m_mut()[5] = f32::NAN;
        d.heights_m_mut()[w * h - 1] = f32::NAN;
    }
    d
}

fn assert_same(a: &Dem, b: &Dem) {
    assert_eq!((a.width(), a.height()), (b.width(), b.height()));
    for (x, y) in a.heights_m().iter().zip(b.heights_m()) {
        assert!(
            x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
            "{x} vs {y}"
        );
    }
    assert_eq!(a.geo, b.geo);
    assert_eq!(a.sample, b.sample);
    match (a.nodata, b.nodata) {
        (Some(x), Some(y)) => assert!(x == y || (x.is_nan() && y.is_nan())),
        (x, y) => assert_eq!(x, y),
    }
}

#[test]
fn round_trip_is_bit_exact_for_all_sample_types_and_georeferencing() {
    let scale_tie = GeoRef {
        transform: GeoTransform::north_up(75_360.0, 39_640.0, 5.0),
        keys: Some(polar_keys()),
        form: GeoForm::ScaleTiepoint {
            z_scale: 0.0,
            tie_z: 0.0,
        },
    };
    let mut matrix = scale_tie.clone();
    matrix.form = GeoForm::Matrix {
        m: [
            5.0, 0.0, 0.0, 75_360.0, 0.0, -5.0, 0.0, 39_640.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0,
            1.0,
        ],
    };
    // PixelIsPoint: the file's tie point names the first pixel's centre.
    let mut point = scale_tie.clone();
    if let Some(k) = point.keys.as_mut() {
        k.directory[11] = 2;
    }
    for (kind, nodata) in [
        (SampleKind::F32, None),
        (SampleKind::F32, Some(f64::NAN)),
        (SampleKind::F32, Some(-9999.0)),
        (SampleKind::I16, None),
        (SampleKind::I16, Some(-32768.0)),
        (SampleKind::U16, None),
        (SampleKind::U16, Some(65535.0)),
    ] {
        for geo in [&scale_tie, &matrix, &point] {
            let d = dem_with(kind, nodata, geo.clone());
            let bytes = write_geotiff_bytes(&d, None).unwrap();
            let back = read_geotiff_bytes(&bytes).unwrap();
            assert_same(&d, &back);
            // And once more through the file system.
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("d.tif");
            write_geotiff(&back, &path, None).unwrap();
            assert_same(&d, &read_geotiff(&path).unwrap());
        }
    }
    // Pixel-is-point: the file's tie point names the first pixel's centre, half a pixel from the
    // corner (GDAL's reading).
    let d = dem_with(SampleKind::F32, None, point);
    let bytes = write_geotiff_bytes(&d, None).unwrap();
    let mut dec = tiff::decoder::Decoder::new(Cursor::new(bytes)).unwrap();
    let tie = dec
        .get_tag_f64_vec(tiff::tags::Tag::ModelTiepointTag)
        .unwrap();
    assert_eq!(&tie[3..5], &[75_362.5, 39_637.5]);
}

#[test]
fn integer_writes_refuse_what_does_not_fit() {
    let mut d = dem_with(SampleKind::F32, None, GeoRef::local(0.0, 0.0, 5.0, "t"));
    // Negative heights cannot be uint16; NaN without a nodata value cannot be int16.
    assert!(matches!(
        write_geotiff_bytes(&d, Some(SampleKind::U16)),
        Err(DemError::Invalid(_))
    ));
    d.heights_m_mut()[0] = f32::NAN;
    let e = write_geotiff_bytes(&d, Some(SampleKind::I16)).unwrap_err();
    assert!(e.to_string().contains("nodata"), "{e}");
}

#[test]
fn real_lola_tile_has_polar_stereographic_georeferencing() {
    let Some(dir) = shared_data() else { return };
    let d = read_geotiff(&dir.join("lola-south-pole-site-5m-256.tif")).unwrap();
    assert_eq!((d.width(), d.height()), (256, 256));
    assert_eq!(d.pixel_m().unwrap(), 5.0);
    assert_eq!(d.origin_m(), (75_360.0, 39_640.0));
    assert_eq!(d.sample, SampleKind::F32);
    assert!(d.geo.keys.as_ref().is_some_and(|k| k.directory.len() > 4));
    let (lo, hi) = d
        .heights_m()
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(
        (467.0..469.0).contains(&lo) && (593.0..594.0).contains(&hi),
        "{lo} {hi}"
    );
    // Written back, the GeoKeys and values are unchanged.
    let back = read_geotiff_bytes(&write_geotiff_bytes(&d, None).unwrap()).unwrap();
    assert_same(&d, &back);
    println!("LOLA tile: 256x256, 5 m, origin (75360, 39640) m, {lo}..{hi} m");
}

#[test]
fn real_shackleton_files_read() {
    let Some(dir) = shared_data() else { return };
    for (name, px, lo, hi) in [
        ("shackleton-overview-200m-256.tif", 200.0, -3551.0, 1874.0),
        ("shackleton-ridge-zoom-40m-256.tif", 40.0, -350.0, 1790.0),
    ] {
        let d = read_geotiff(&dir.join(name)).unwrap();
        assert_eq!((d.width(), d.height()), (256, 256), "{name}");
        assert_eq!(d.pixel_m().unwrap(), px, "{name}");
        let s = ground_sim::dem::stats::dem_stats(&d).unwrap();
        assert!(s.elev_min_m >= lo && s.elev_max_m <= hi, "{name}: {s:?}");
    }
}

/// A plain TIFF written by the `tiff` crate (no GeoTIFF tags unless added).
fn plain_tiff<C: colortype::ColorType>(data: &[C::Inner], w: u32, h: u32) -> Vec<u8>
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut c = Cursor::new(Vec::new());
    let mut enc = TiffEncoder::new(&mut c).unwrap();
    let mut img = enc.new_image::<C>(w, h).unwrap();
    img.encoder()
        .write_tag(tiff::tags::Tag::ModelPixelScaleTag, &[5.0f64, 5.0, 0.0][..])
        .unwrap();
    img.encoder()
        .write_tag(
            tiff::tags::Tag::ModelTiepointTag,
            &[0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0][..],
        )
        .unwrap();
    img.write_data(data).unwrap();
    c.into_inner()
}

/// Patch the SHORT value of `tag` in the first IFD of a little-endian classic TIFF.
fn patch_short(bytes: &mut [u8], tag: u16, value: u16) {
    let ifd = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes(bytes[ifd..ifd + 2].try_into().unwrap()) as usize;
    for i in 0..n {
        let e = ifd + 2 + 12 * i;
        if u16::from_le_bytes(bytes[e..e + 2].try_into().unwrap()) == tag {
            bytes[e + 8..e + 10].copy_from_slice(&value.to_le_bytes());
            return;
        }
    }
    panic!("tag {tag} not found");
}

#[test]
fn unsupported_layouts_are_named() {
    let rgb = plain_tiff::<colortype::RGB8>(&[0u8; 4 * 4 * 3], 4, 4);
    let e = read_geotiff_bytes(&rgb).unwrap_err();
    assert!(matches!(e, DemError::Unsupported(_)));
    assert!(e.to_string().contains("3 bands"), "{e}");

    let gray8 = plain_tiff::<colortype::Gray8>(&[0u8; 16], 4, 4);
    let e = read_geotiff_bytes(&gray8).unwrap_err();
    assert!(e.to_string().contains("sample format uint8"), "{e}");

    let f64s = plain_tiff::<colortype::Gray64Float>(&[0f64; 16], 4, 4);
    let e = read_geotiff_bytes(&f64s).unwrap_err();
    assert!(e.to_string().contains("float64"), "{e}");

    let mut jpeg = plain_tiff::<colortype::Gray32Float>(&[0f32; 16], 4, 4);
    patch_short(&mut jpeg, 259, 7);
    let e = read_geotiff_bytes(&jpeg).unwrap_err();
    assert!(e.to_string().contains("compression JPEG"), "{e}");

    // A float TIFF without any georeferencing.
    let mut c = Cursor::new(Vec::new());
    TiffEncoder::new(&mut c)
        .unwrap()
        .write_image::<colortype::Gray32Float>(4, 4, &[0f32; 16])
        .unwrap();
    let e = read_geotiff_bytes(c.get_ref()).unwrap_err();
    assert!(e.to_string().contains("no georeferencing"), "{e}");

    assert!(matches!(
        read_geotiff_bytes(b"not a tiff at all"),
        Err(DemError::Format(_))
    ));
    let e = read_geotiff(std::path::Path::new("/nonexistent/dem.tif")).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/dem.tif"), "{e}");
}

#[test]
fn geo_crop_of_a_written_dem_keeps_values_and_moves_the_origin() {
    let d = dem_with(
        SampleKind::F32,
        None,
        GeoRef::local(1000.0, 5000.0, 5.0, "t"),
    );
    let back = read_geotiff_bytes(&write_geotiff_bytes(&d, None).unwrap()).unwrap();
    // Pixel centres x = 1002.5 + 5c, y = 4997.5 − 5r: keep cols 4..=9, rows 2..=6.
    let c = back.crop_geo(1021.0, 4965.0, 1050.0, 4990.0).unwrap();
    assert_eq!((c.width(), c.height()), (6, 5));
    assert_eq!(c.origin_m(), (1020.0, 4990.0));
    for r in 0..5 {
        for col in 0..6 {
            assert_eq!(c.get(col, r), d.get(col + 4, r + 2));
        }
    }
    assert_eq!(c.geo.keys, d.geo.keys);
}
