//! `ground-sim hazard-calibrate`: the map's misses against the truth, per relief threshold.

// Test helpers outside #[test] functions may unwrap too: a failure is a test failure.
#![allow(clippy::unwrap_used)]

use std::process::Command;

/// Run `hazard-calibrate` with `args` (plus `--json`) in a fresh folder; its JSON.
fn calibrate(args: &[&std::ffi::OsStr]) -> (tempfile::TempDir, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("calib.json");
    let out = Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .arg("hazard-calibrate")
        .args(args)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    (dir, v)
}

fn os(args: &[&'static str]) -> Vec<&'static std::ffi::OsStr> {
    args.iter().map(|a| std::ffi::OsStr::new(*a)).collect()
}

#[test]
fn a_stricter_map_offers_less_ground_and_misses_no_more() {
    let (dir, v) = calibrate(&os(&[
        "--presets",
        "plains",
        "--zones",
        "1",
        "--frames",
        "1",
        "--relief-m",
        "0.3,0.2,0.1",
    ]));
    let json = dir.path().join("calib.json");
    let rows: Vec<&serde_json::Value> = v["rows"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["scene"] == "plains")
        .collect();
    assert_eq!(rows.len(), 3);
    let n = |r: &serde_json::Value, k: &str| r["counts"][k].as_u64().unwrap();
    for w in rows.windows(2) {
        // The same frame and truth: a lower threshold judges a subset of the sites safe.
        assert_eq!(n(w[0], "sites"), n(w[1], "sites"));
        assert!(n(w[0], "sites") > 1000);
        assert!(n(w[1], "judged_safe") <= n(w[0], "judged_safe"));
        assert!(n(w[1], "missed") <= n(w[0], "missed"));
    }
    // The trade-off picture lands beside the JSON.
    let png = image::open(json.with_extension("png")).unwrap();
    assert!(png.width() >= 800 && png.height() >= 400);
    // The 0.4 m frame under-reads rocks: a map judging with the lander's own 0.3 m misses some.
    assert!(n(rows[0], "missed") > 0, "{:?}", rows[0]);
    let bad = Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(["hazard-calibrate", "--relief-m", "0", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("finite and positive"));
}

#[test]
fn a_real_dem_is_a_scene_of_its_own() {
    let real = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/lola-south-pole-site-5m-256.tif");
    if !real.exists() {
        eprintln!(
            "SKIPPED a_real_dem_is_a_scene_of_its_own: {} is absent (../shared/data)",
            real.display()
        );
        return;
    }
    let mut args = os(&[
        "--presets",
        "plains",
        "--zones",
        "1",
        "--frames",
        "1",
        "--relief-m",
        "0.2",
        "--dem",
    ]);
    args.push(real.as_os_str());
    let (_dir, v) = calibrate(&args);
    let scenes: Vec<&str> = v["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["scene"].as_str().unwrap())
        .collect();
    assert_eq!(scenes, ["plains", "lola-south-pole-site-5m-256", "all"]);
    let real_row = &v["rows"][1]["counts"];
    assert!(real_row["sites"].as_u64().unwrap() > 1000, "{real_row}");
}
