//! `ground-sim register` end to end: generated scenes (always run) and the real LOLA tile against
//! a rotated, resampled copy of itself (skipped, saying so, where ../shared is absent).

use std::path::{Path, PathBuf};
use std::process::Command;

use ground_sim::dem::{Dem, GeoRef, read_geotiff, write_geotiff};
use ground_sim::terrain::{Preset, TerrainParams, generate};

/// Bilinear sample of a DEM at pixel coordinates (NaN outside).
fn sample(dem: &Dem, x: f64, y: f64) -> f32 {
    let (w, h) = (dem.width(), dem.height());
    if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64) {
        return f32::NAN;
    }
    let (x0, y0) = ((x as usize).min(w - 2), (y as usize).min(h - 2));
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let z = |c, r| dem.get(c, r).unwrap_or(f32::NAN);
    let top = z(x0, y0) * (1.0 - fx) + z(x0 + 1, y0) * fx;
    let bot = z(x0, y0 + 1) * (1.0 - fx) + z(x0 + 1, y0 + 1) * fx;
    top * (1.0 - fy) + bot * fy
}

/// A `w × h` frame cut from `src`, each pixel the mean of `k × k` bilinear samples over its
/// footprint (a real sensor averages), frame pixels `step_px` source pixels apart, rotated by
/// `theta_deg`, centred on source pixel `(cx, cy)`.
fn cut(src: &Dem, cx: f64, cy: f64, theta_deg: f64, step_px: f64, w: usize, h: usize) -> Dem {
    let (s, c) = theta_deg.to_radians().sin_cos();
    let k = step_px.ceil().max(1.0) as usize;
    let mut z = vec![0.0f32; w * h];
    for row in 0..h {
        for col in 0..w {
            let mut acc = 0.0f64;
            for j in 0..k {
                for i in 0..k {
                    let u = (col as f64 - (w as f64 - 1.0) / 2.0 + (i as f64 + 0.5) / k as f64
                        - 0.5)
                        * step_px;
                    let v = (row as f64 - (h as f64 - 1.0) / 2.0 + (j as f64 + 0.5) / k as f64
                        - 0.5)
                        * step_px;
                    acc += sample(src, cx + c * u - s * v, cy + s * u + c * v) as f64;
                }
            }
            z[row * w + col] = (acc / (k * k) as f64) as f32;
        }
    }
    let px = src.pixel_m().unwrap() * step_px;
    Dem::new(w, h, z, GeoRef::local(0.0, 0.0, px, "frame")).unwrap()
}

fn run(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(args)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Check the JSON against the truth: rotation θ, scale, and where the frame centre lies.
fn check(j: &serde_json::Value, theta_deg: f64, scale: f64, centre: (f64, f64), tol_px: f64) {
    for key in [
        "matches",
        "inliers",
        "rotation_deg",
        "scale",
        "affine",
        "frame_center_in_reference_px",
        "residual_rms_px",
        "time_ms",
    ] {
        assert!(!j[key].is_null(), "missing {key} in {j}");
    }
    assert_eq!(j["affine"].as_array().unwrap().len(), 6);
    let rot = j["rotation_deg"].as_f64().unwrap();
    let d = (rot - theta_deg).rem_euclid(360.0);
    assert!(d.min(360.0 - d) < 1.0, "rotation {rot} vs {theta_deg}");
    assert!(
        (j["scale"].as_f64().unwrap() / scale - 1.0).abs() < 0.02,
        "scale {} vs {scale}",
        j["scale"]
    );
    let c = j["frame_center_in_reference_px"].as_array().unwrap();
    let (x, y) = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
    assert!(
        (x - centre.0).hypot(y - centre.1) < tol_px,
        "centre ({x}, {y}) vs {centre:?}"
    );
}

#[test]
fn register_generated_dems_and_slopes() {
    let dir = tempfile::tempdir().unwrap();
    let mut p = TerrainParams::new(Preset::Shoemaker);
    p.seed = 11;
    p.size_m = 4000.0;
    p.pixel_m = 5.0;
    let (truth, _) = generate(&p, &indicatif::ProgressBar::hidden()).unwrap();
    // Reference: 20 m pixels over the whole 4 km; frame: 10 m pixels, rotated 45°, 2 km wide,
    // centred 300 m east and 200 m south of the scene centre.
    let reference = cut(&truth, 399.5, 399.5, 0.0, 4.0, 200, 200);
    let (theta, fx, fy) = (45.0, 399.5 + 60.0, 399.5 + 40.0);
    let frame = cut(&truth, fx, fy, theta, 2.0, 200, 200);
    let (rp, fp) = (dir.path().join("ref.tif"), dir.path().join("frame.tif"));
    write_geotiff(&reference, &rp, None).unwrap();
    write_geotiff(&frame, &fp, None).unwrap();
    let js = dir.path().join("r.json");
    let png = dir.path().join("r.png");
    let (ok, text) = run(&[
        "register",
        "--reference",
        rp.to_str().unwrap(),
        "--frame",
        fp.to_str().unwrap(),
        "--dem",
        "--json",
        js.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
    ]);
    println!("{text}");
    assert!(ok, "{text}");
    // Frame centre in reference pixels: source (fx, fy) at 5 m → reference at 20 m.
    let centre = ((fx - 1.5) / 4.0, (fy - 1.5) / 4.0);
    check(&json(&js), theta, 0.5, centre, 1.0);
    assert!(png.exists());
    // UMBRA_KEEP=DIR keeps the match picture for a person to look at.
    if let Ok(keep) = std::env::var("UMBRA_KEEP") {
        std::fs::create_dir_all(&keep).unwrap();
        std::fs::copy(&png, Path::new(&keep).join("register-shoemaker-45deg.png")).unwrap();
    }

    // The same as slope GeoTIFFs (what the ground segment's tile is made from).
    let slope = |d: &Dem| {
        let s = ground_sim::dem::stats::slope_deg(d).unwrap();
        Dem::new(d.width(), d.height(), s, d.geo.clone()).unwrap()
    };
    let (rs, fs) = (
        dir.path().join("ref-slope.tif"),
        dir.path().join("frame-slope.tif"),
    );
    write_geotiff(&slope(&reference), &rs, None).unwrap();
    write_geotiff(&slope(&frame), &fs, None).unwrap();
    let (ok, text) = run(&[
        "register",
        "--reference",
        rs.to_str().unwrap(),
        "--frame",
        fs.to_str().unwrap(),
        "--json",
        js.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    check(&json(&js), theta, 0.5, centre, 1.0);
}

#[test]
fn register_refuses_bad_input_and_reports_no_fix() {
    let dir = tempfile::tempdir().unwrap();
    // Missing file.
    let (ok, text) = run(&[
        "register",
        "--reference",
        "/nonexistent.tif",
        "--frame",
        "/nonexistent.tif",
    ]);
    assert!(!ok && text.contains("nonexistent"), "{text}");
    // Unsupported extension.
    let bogus = dir.path().join("x.jpg");
    std::fs::write(&bogus, b"not an image").unwrap();
    let (ok, text) = run(&[
        "register",
        "--reference",
        bogus.to_str().unwrap(),
        "--frame",
        bogus.to_str().unwrap(),
    ]);
    assert!(!ok && text.contains("expected a .tif"), "{text}");
    // A PNG without a pixel size.
    let img =
        image::GrayImage::from_fn(64, 64, |x, y| image::Luma([((x * 7 + y * 13) % 200) as u8]));
    let png = dir.path().join("a.png");
    img.save(&png).unwrap();
    let (ok, text) = run(&[
        "register",
        "--reference",
        png.to_str().unwrap(),
        "--frame",
        png.to_str().unwrap(),
    ]);
    assert!(!ok && text.contains("pixel size"), "{text}");
    // A featureless frame against a featureless reference: no fix, non-zero exit, JSON says why.
    let flat = image::GrayImage::from_pixel(120, 120, image::Luma([40]));
    let fpng = dir.path().join("flat.png");
    flat.save(&fpng).unwrap();
    let js = dir.path().join("nofix.json");
    let (ok, text) = run(&[
        "register",
        "--reference",
        fpng.to_str().unwrap(),
        "--frame",
        fpng.to_str().unwrap(),
        "--reference-pixel-m",
        "20",
        "--frame-pixel-m",
        "10",
        "--json",
        js.to_str().unwrap(),
    ]);
    assert!(!ok && text.contains("no fix"), "{text}");
    let j = json(&js);
    assert_eq!(j["fix"], false);
    assert!(j["no_fix_reason"].is_string());
}

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

#[test]
fn register_real_lola_tile_against_a_rotated_resampled_copy() {
    let Some(data) = shared_data() else { return };
    let lola = read_geotiff(&data.join("lola-south-pole-site-5m-256.tif")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // Reference: the LOLA tile itself (5 m). Frame: 7.5 m pixels, rotated 30°, 110 px square,
    // centred 10 px right of and 6 px above the tile centre.
    let (theta, cx, cy) = (30.0, 127.5 + 10.0, 127.5 - 6.0);
    let frame = cut(&lola, cx, cy, theta, 1.5, 110, 110);
    let fp = dir.path().join("lola-frame.tif");
    write_geotiff(&frame, &fp, None).unwrap();
    let js = dir.path().join("lola.json");
    let lola_path = data.join("lola-south-pole-site-5m-256.tif");
    let (ok, text) = run(&[
        "register",
        "--reference",
        lola_path.to_str().unwrap(),
        "--frame",
        fp.to_str().unwrap(),
        "--dem",
        "--json",
        js.to_str().unwrap(),
    ]);
    println!("{text}");
    assert!(ok, "{text}");
    // Measured: 0.95 px (4.8 m) from the truth with 10 inliers on this smooth real relief.
    check(&json(&js), theta, 1.5, (cx, cy), 1.5);
}
