//! Closed loop through the CLI: reference folder from a generated DEM, one TRN frame, a small
//! eval campaign and a short descent campaign. Figures are asserted with floors near what these
//! seeds give (the full campaigns are recorded in docs/results.md).

use std::path::Path;
use std::process::Command;

fn run(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(args)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "ground-sim {args:?} failed:\n{text}");
    text
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

#[test]
fn tile_trn_eval_and_descent_on_a_generated_scene() {
    let dir = tempfile::tempdir().unwrap();
    let d = |f: &str| dir.path().join(f).to_str().unwrap().to_string();
    // An 8 km Shoemaker-like floor at 10 m: room for 2-3 km hops with 2 km frames.
    run(&[
        "terrain",
        "--preset",
        "shoemaker",
        "--seed",
        "3",
        "--size-m",
        "8000",
        "--pixel-m",
        "10",
        "--out",
        &d("dem.tif"),
    ]);
    run(&["tile", "--dem", &d("dem.tif"), "--out", &d("ref")]);
    let meta = json(&dir.path().join("ref/tile.json"));
    assert!(meta["features"].as_u64().unwrap() > 300, "{meta}");

    // The paper's geometry: a 10 m frame against the 20 m reference, rotated 45°.
    let (tile, dem) = (d("ref"), d("dem.tif"));
    let frame = [
        "trn",
        "--tile",
        &tile,
        "--dem",
        &dem,
        "--heading-deg",
        "45",
        "--x-m",
        "300",
        "--y-m",
        "-200",
    ];
    // With the flight budget, lost in space against this whole 8 km tile (over 1 000 features,
    // where the flyer's atlas tiles cover 4 km): matching every tile feature leaves no room for
    // consensus and refinement inside the 20 M work budget, and the frame says so.
    run(&[&frame[..], &["--json", &d("trn-flight.json")]].concat());
    let t = json(&dir.path().join("trn-flight.json"));
    assert_eq!(t["fix"], false, "{t}");
    assert_eq!(
        t["no_fix_reason"], "no room left in the frame's work budget",
        "{t}"
    );
    // With the host budget (no work budget) the feature path runs whole.
    let (png, trn_json) = (d("trn.png"), d("trn.json"));
    let text = run(&[
        &frame[..],
        &["--budget", "host", "--png", &png, "--json", &trn_json],
    ]
    .concat());
    println!("{text}");
    let t = json(&dir.path().join("trn.json"));
    for k in [
        "matches",
        "inliers",
        "rotation_deg",
        "heading_err_deg",
        "scale",
        "pos_err_mean_px",
        "pos_err_max_px",
        "pos_err_m",
    ] {
        assert!(!t[k].is_null(), "trn JSON lacks {k}: {t}");
    }
    assert!(t["heading_err_deg"].as_f64().unwrap().abs() < 0.5, "{t}");
    assert!(t["pos_err_mean_px"].as_f64().unwrap() < 0.5, "{t}");
    assert!(t["pos_err_max_px"].as_f64().unwrap() < 1.0, "{t}");
    assert!(dir.path().join("trn.png").exists());

    // The flight budget (the default, what flies) must never give a false fix; the chain's
    // success bar is asserted with the host budget it was set for (docs/results.md has both).
    for (budget, file) in [("flight", "eval-flight.json"), ("host", "eval.json")] {
        let text = run(&[
            "eval",
            "--tile",
            &d("ref"),
            "--dem",
            &d("dem.tif"),
            "--trials",
            "40",
            "--seed",
            "5",
            "--budget",
            budget,
            "--json",
            &d(file),
        ]);
        println!("{text}");
        let e = json(&dir.path().join(file));
        assert_eq!(e["false_fixes"], 0, "{e}");
        assert!(e["budget"].as_str().unwrap().starts_with(budget), "{e}");
    }
    let e = json(&dir.path().join("eval.json"));
    for k in [
        "trials",
        "success_rate",
        "false_fix_rate",
        "pos_err_p50_m",
        "pos_err_p95_m",
        "heading_err_p95_deg",
    ] {
        assert!(!e[k].is_null(), "eval JSON lacks {k}: {e}");
    }
    assert_eq!(e["trials"], 40);
    assert_eq!(e["false_fix_rate"].as_f64().unwrap(), 0.0, "{e}");
    assert!(e["success_rate"].as_f64().unwrap() >= 0.95, "{e}");
    assert!(e["pos_err_p95_m"].as_f64().unwrap() <= 20.0, "{e}");
    let csv = std::fs::read_to_string(dir.path().join("eval.csv")).unwrap();
    assert_eq!(csv.lines().count(), 41);

    let text = run(&[
        "descent",
        "--tile",
        &d("ref"),
        "--dem",
        &d("dem.tif"),
        "--runs",
        "2",
        "--seed",
        "2",
        "--hop-min-m",
        "2000",
        "--hop-max-m",
        "3000",
        "--json",
        &d("descent.json"),
    ]);
    println!("{text}");
    let s = json(&dir.path().join("descent.json"));
    for k in [
        "runs",
        "landing_err_p50_m",
        "landing_err_p95_m",
        "nav_err_at_landing_p95_m",
        "nav_err_rms_m",
        "fixes",
        "rejected_fixes",
        "nees_in_band_frac",
    ] {
        assert!(!s[k].is_null(), "descent JSON lacks {k}: {s}");
    }
    assert!(s["fixes"].as_u64().unwrap() > 50, "{s}");
    assert!(s["landing_err_p95_m"].as_f64().unwrap() < 10.0, "{s}");
    // Below the TRN floor the frames go to the keyframe odometry, over the landing zone laid
    // around each target, on which every touchdown is judged.
    assert!(s["keyframes"].as_u64().unwrap() >= 2, "{s}");
    assert!(s["odometry_fixes"].as_u64().unwrap() > 20, "{s}");
    assert_eq!(s["touchdowns_judged"], 2, "{s}");
    assert!(s["last_aid_agl_p50_m"].as_f64().unwrap() < 200.0, "{s}");
    assert!(dir.path().join("descent-trajectory.png").exists());
    // Each run maps its landing zone; a run that chose a site confirms it on a finer frame.
    // Unsafe touchdowns are all accounted for, on an unsafe spot or off a safe one.
    assert!(s["hazard_maps"].as_u64().unwrap() >= 2, "{s}");
    if s["runs_retargeted"].as_u64().unwrap() > 0 {
        assert!(s["confirm_maps"].as_u64().unwrap() >= 1, "{s}");
    }
    let unsafe_runs = (2.0 * (1.0 - s["safe_landing_frac"].as_f64().unwrap())).round() as u64;
    assert_eq!(
        s["unsafe_on_unsafe_site"].as_u64().unwrap() + s["unsafe_on_safe_site"].as_u64().unwrap(),
        unsafe_runs,
        "{s}"
    );
    assert!(s["open_zone_runs"].as_u64().unwrap() <= 2, "{s}");
    assert!(dir.path().join("descent-hazard.png").exists());
}
