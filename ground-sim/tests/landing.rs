//! `ground-sim landing-zone`: outputs, georeferencing, determinism and errors of the command.

// Test helpers outside #[test] functions may unwrap too: a failure is a test failure.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::{Command, Output};

use ground_sim::dem::read_geotiff;

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .arg("landing-zone")
        .args(args)
        .output()
        .unwrap()
}

fn json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("landing_zone.json")).unwrap()).unwrap()
}

/// A small zone over a small `plains` scene: 64 m at 0.5 m, taper 8 m, sites every 2 m.
fn small_zone(out: &Path, extra: &[&str]) -> Output {
    let out = out.to_str().unwrap();
    let mut args = vec![
        "--preset",
        "plains",
        "--seed",
        "3",
        "--scene-size-m",
        "1000",
        "--scene-pixel-m",
        "5",
        "--side-m",
        "64",
        "--pixel-m",
        "0.5",
        "--taper-m",
        "8",
        "--step-m",
        "2",
        "--png-px",
        "128",
        "--out",
        out,
    ];
    args.extend_from_slice(extra);
    run(&args)
}

#[test]
fn writes_geotiff_png_and_json_and_is_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a");
    let out = small_zone(&a, &["--centre-m", "-100,150"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("landing zone 64 m at 0.5 m (128 px)"),
        "{stdout}"
    );

    let zone = read_geotiff(&a.join("landing_zone.tif")).unwrap();
    assert_eq!((zone.width(), zone.height()), (128, 128));
    assert_eq!(zone.pixel_m().unwrap(), 0.5);
    assert_eq!(zone.origin_m(), (-132.0, 182.0));
    assert_eq!(zone.nodata_count(), 0);
    assert!(a.join("landing_zone.png").exists());

    let j = json(&a);
    let z = &j["zone"];
    assert_eq!(z["seed"], 3);
    assert_eq!(z["side_px"], 128);
    assert_eq!(z["config"]["side_m"], 64.0);
    assert_eq!(z["config"]["rock_k"], 0.08);
    // The plains' roughness continues into the zone; craters join the 5 m scene's 15 m ones.
    assert_eq!(z["roughness"]["hurst"], 0.8);
    assert_eq!(z["roughness"]["nu5_m"], 0.1);
    assert_eq!(z["crater_range_m"][1], 15.0);
    assert!(z["rocks_drawn"].as_u64().unwrap() > 100);
    assert!(z["craters_drawn"].as_u64().unwrap() > 100);
    let s = &j["safety"];
    let f = s["safe_fraction"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&f), "{f}");
    // (64 − 2·8) / 2 = 24 sites a side.
    assert_eq!(s["sites"], 576);
    assert_eq!(s["thresholds"]["footprint_m"], 4.0);
    assert!(j["timing"]["zone_s"].as_f64().unwrap() > 0.0);

    // Same inputs, same bytes.
    let b = dir.path().join("b");
    assert!(small_zone(&b, &["--centre-m", "-100,150"]).status.success());
    for f in ["landing_zone.tif", "landing_zone.png"] {
        assert!(
            std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(),
            "{f} differs"
        );
    }

    // A zone over a GeoTIFF (here: a finer zone inside the first one), centred by default.
    let c = dir.path().join("c");
    let dem = a.join("landing_zone.tif");
    let out = run(&[
        "--dem",
        dem.to_str().unwrap(),
        "--side-m",
        "24",
        "--pixel-m",
        "0.1",
        "--taper-m",
        "4",
        "--png-px",
        "120",
        "--out",
        c.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j = json(&c);
    assert_eq!(j["zone"]["centre_m"][0], -100.0);
    assert_eq!(j["zone"]["centre_m"][1], 150.0);
    assert_eq!(j["coarse"]["pixel_m"], 0.5);
    // Craters up to 10 m (3 coarse pixels would be 1.5 m, below the 10 m floor).
    assert_eq!(j["zone"]["crater_range_m"][1], 10.0);
}

#[test]
fn bad_input_fails_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let err = |out: Output| String::from_utf8_lossy(&out.stderr).to_string();

    let out = small_zone(&dir.path().join("x"), &["--centre-m", "5000,0"]);
    assert!(!out.status.success());
    assert!(err(out).contains("not inside the coarse DEM"));

    let out = small_zone(&dir.path().join("x"), &["--centre-m", "12"]);
    assert!(!out.status.success());
    assert!(err(out).contains("X,Y"));

    let x = dir.path().join("x");
    let out = run(&[
        "--preset",
        "plains",
        "--scene-size-m",
        "1000",
        "--pixel-m",
        "0",
        "--out",
        x.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(err(out).contains("finite and > 0"));

    let out = run(&["--side-m", "64", "--out", "x"]);
    assert!(!out.status.success());
    assert!(err(out).contains("--preset"));

    let out = run(&["--dem", "/nonexistent/coarse.tif", "--out", "x"]);
    assert!(!out.status.success());
    assert!(err(out).contains("/nonexistent/coarse.tif"));
}
