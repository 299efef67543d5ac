//! The terrain suite and the navigability map: `suite --quick` writes a table, a picture, JSON and
//! per-frame CSVs that agree with each other; the navmap's footprint sums match a brute-force
//! count; `eval` takes a prior; bad input gives a clear error.

// Test helpers outside #[test] functions may unwrap too: a failure is a test failure.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::{Command, Output};

use ground_sim::evaluation::navmap::{GO_SUCCESS_BAR, NavMap, NavmapThresholds, agreement_ceiling};
use ground_sim::reference::{Smoothing, load, reference_dem, surf_config_for, write_reference};
use ground_sim::terrain::{Preset, TerrainParams, generate};
use indicatif::ProgressBar;
use nav_core::Tile;

fn ground_sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(args)
        .output()
        .expect("ground-sim runs")
}

fn run(args: &[&str]) -> String {
    let out = ground_sim(args);
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "ground-sim {args:?} failed:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

#[test]
fn quick_suite_outputs_agree_with_each_other() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("suite");
    run(&[
        "suite",
        "--quick",
        "--scenes",
        "lola,fresh-rim",
        "--out",
        path(&out),
    ]);
    let r = json(&out.join("suite.json"));
    let rows = r["rows"].as_array().unwrap();
    // 2 scenes × {truth, InSAR tile} × {no prior, prior}.
    assert_eq!(rows.len(), 8, "{r}");
    for sc in r["scenes"].as_array().unwrap() {
        // The InSAR tile's accuracy is carried into the report (the default radar, thermal
        // noise at −25 dB and both looks: metres, not tens of metres).
        let h = sc["insar_height_rmse_m"].as_f64().unwrap();
        assert!(h > 0.0 && h < 10.0, "{sc}");
    }
    // The default radar is recorded: the mission design, noisy, both looks, a second pair.
    let radar = &r["spec"]["radar"];
    assert_eq!(radar["baseline_m"], 32.0, "{radar}");
    assert_eq!(radar["noise_equivalent_sigma0_db"], -25.0, "{radar}");
    assert_eq!(r["spec"]["looks"], "both", "{}", r["spec"]);
    assert_eq!(r["spec"]["long_baseline_m"], 128.0, "{}", r["spec"]);
    assert!(out.join("suite.png").exists() && out.join("suite.md").exists());
    let table = std::fs::read_to_string(out.join("suite.md")).unwrap();
    assert!(table.contains("| lola | truth") && table.contains("| fresh-rim | insar"));
    assert!(table.contains(" ground) |"), "{table}");
    assert!(table.contains("budget flight"), "{table}");
    for row in rows {
        let scene = row["scene"].as_str().unwrap();
        let s = &row["summary"];
        let kind = row["kind"].as_str().unwrap();
        // Only an InSAR tile counts its ground (a truth tile is all ground), and never more
        // than it holds.
        let ground = &row["tile_features_on_truth"];
        match kind {
            "insar" => assert!(
                ground.as_u64().unwrap() <= row["tile_features"].as_u64().unwrap(),
                "{row}"
            ),
            _ => assert!(ground.is_null(), "{row}"),
        }
        let tag = if s["prior"].is_null() {
            format!("{kind}-noprior")
        } else {
            assert_eq!(s["prior"]["sigma_m"], 50.0);
            format!("{kind}-prior50m2deg")
        };
        let csv = std::fs::read_to_string(out.join(scene).join(format!("{tag}.csv"))).unwrap();
        let lines: Vec<&str> = csv.lines().skip(1).collect();
        assert_eq!(lines.len(), 40, "{scene} {tag}");
        // Success in the summary = fixes that are not false in the per-frame CSV.
        let ok = lines
            .iter()
            .filter(|l| {
                let c: Vec<&str> = l.split(',').collect();
                c[5] == "true" && c[6] == "false"
            })
            .count();
        let rate = s["success_rate"].as_f64().unwrap();
        assert!((rate - ok as f64 / 40.0).abs() < 1e-12, "{scene} {tag}");
        // The navmap score counts the same frames as its per-frame CSV.
        let nm =
            std::fs::read_to_string(out.join(scene).join(format!("{tag}-navmap.csv"))).unwrap();
        assert!(nm.starts_with(
            "trial,features,valid_frac,texture_deg,go,rehearsal_success,rehearsal_go,success\n"
        ));
        // (footprint go, rehearsal success fraction, rehearsal go, success)
        let go: Vec<(bool, f64, bool, bool)> = nm
            .lines()
            .skip(1)
            .map(|l| {
                let c: Vec<&str> = l.split(',').collect();
                (
                    c[4] == "true",
                    c[5].parse().unwrap(),
                    c[6] == "true",
                    c[7] == "true",
                )
            })
            .collect();
        assert_eq!(go.len(), 40);
        assert_eq!(go.iter().filter(|g| g.3).count(), ok);
        for (key, pick) in [
            (
                "navmap",
                (|g: &(bool, f64, bool, bool)| g.0) as fn(&_) -> bool,
            ),
            ("rehearsal", |g| g.2),
        ] {
            let n = &row[key];
            assert_eq!(
                n["go_frames"].as_u64().unwrap() as usize,
                go.iter().filter(|g| pick(g)).count(),
                "{scene} {tag} {key}"
            );
            assert_eq!(
                n["go_success"].as_u64().unwrap() as usize,
                go.iter().filter(|g| pick(g) && g.3).count(),
                "{scene} {tag} {key}"
            );
        }
        // The best agreement any map could reach is the one its frames' chances give (the
        // CSV rounds them to 3 decimals, which may move a frame across the go bar), within 0–1.
        let chances: Vec<f64> = go.iter().map(|g| g.1).collect();
        let ceiling = row["rehearsal_agreement_ceiling"].as_f64().unwrap();
        let from_csv = agreement_ceiling(&chances, GO_SUCCESS_BAR);
        assert!(
            (0.0..=1.0).contains(&ceiling) && (ceiling - from_csv).abs() < 0.03,
            "{scene} {tag}: {ceiling} against {from_csv} from the CSV"
        );
        // Every campaign frame lies inside the rehearsal's sites (the same centre box), and
        // "go" is the success fraction against the recorded threshold.
        let min = r["spec"]["rehearsal"]["min_success"].as_f64().unwrap();
        for g in &go {
            assert!((0.0..=1.0).contains(&g.1), "{scene} {tag} {g:?}");
            // (The CSV rounds the fraction to 3 decimals: skip frames at the threshold.)
            if (g.1 - min).abs() > 1e-3 {
                assert_eq!(g.2, g.1 >= min, "{scene} {tag} {g:?}");
            }
        }
        for f in [
            format!("navmap-{kind}.tif"),
            format!("navmap-{kind}.png"),
            format!("rehearsal-{tag}.tif"),
            format!("rehearsal-{tag}.png"),
            format!("rehearsal-{tag}-success.tif"),
            format!("rehearsal-{tag}-sites.json"),
        ] {
            assert!(out.join(scene).join(&f).exists(), "{scene}/{f}");
        }
    }
}

#[test]
fn navmap_footprint_sums_match_a_brute_force_count() {
    let mut p = TerrainParams::new(Preset::Lola);
    p.size_m = 2000.0;
    let (dem, _) = generate(&p, &ProgressBar::hidden()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let r = reference_dem(&dem, 20.0).unwrap();
    write_reference(
        &r,
        dir.path(),
        &surf_config_for(
            &ground_sim::reference::noise_floor::FrameNoise::default_sensor(),
            20.0,
            ground_sim::reference::DEFAULT_SMOOTHING_M,
        )
        .unwrap(),
        1000,
        Smoothing::default_for_truth(),
    )
    .unwrap();
    let reference = load(dir.path()).unwrap();
    let tile = Tile::parse(&reference.tile_bytes).unwrap();
    assert!(tile.len() > 10, "{} features", tile.len());
    let radius_m = 300.0;
    let m = NavMap::build(&tile, radius_m, NavmapThresholds::default()).unwrap();
    let rad = radius_m / 20.0;
    let raster = tile.slope_raster().unwrap();
    for &(c, r) in &[(0usize, 0usize), (15, 15), (50, 40), (99, 99), (30, 70)] {
        let i = r * m.width + c;
        let brute = (0..tile.len())
            .filter(|&k| {
                let kp = tile.keypoint(k);
                let (dc, dr) = (
                    kp.x_px.round() as f64 - c as f64,
                    kp.y_px.round() as f64 - r as f64,
                );
                // The map's disk: rows within the radius, columns within the row's half-chord.
                dr.abs() <= rad.floor() && dc.abs() <= (rad * rad - dr * dr).max(0.0).sqrt().floor()
            })
            .count();
        assert_eq!(m.features[i] as usize, brute, "cell ({c}, {r})");
        let inside = c as f64 >= rad.floor()
            && r as f64 >= rad.floor()
            && ((c as f64 + rad.floor()) as usize) < m.width
            && ((r as f64 + rad.floor()) as usize) < m.height;
        assert_eq!(m.inside[i], inside, "cell ({c}, {r})");
        if inside {
            // Inside the map the whole disk is on valid raster except its border row/column.
            assert!(m.valid_frac[i] > 0.9, "cell ({c}, {r}) {}", m.valid_frac[i]);
        }
    }
    assert!(raster.width() == m.width && raster.height() == m.height);
    // Off-map cells are never "go" and are NaN in the go layer.
    let layer = m.go_layer();
    assert!(layer[0].is_nan() && !m.go(0));
    // A stricter feature threshold can only shrink the "go" area.
    let strict = NavMap::build(
        &tile,
        radius_m,
        NavmapThresholds {
            min_features: 1e9,
            ..NavmapThresholds::default()
        },
    )
    .unwrap();
    assert_eq!(strict.go_fraction(), 0.0);
    assert!(m.go_fraction() >= strict.go_fraction());
}

/// `navmap` by rehearsal from a reference folder alone: high on a cratered plain's truth-built
/// tile, nothing on a featureless one (both with the quick suite's 120-px frames on 3 km maps
/// and a 50 m prior, the mode in which such small frames fix on the plain: the quick suite's
/// campaign there gets 100 %, 55 % without the prior).
#[test]
fn navmap_rehearsal_tells_textured_from_featureless_ground() {
    use ground_sim::dem::{Dem, GeoRef, write_geotiff};
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("suite");
    run(&[
        "suite",
        "--quick",
        "--scenes",
        "lola",
        "--kinds",
        "truth",
        "--prior-sigma-m",
        "0",
        "--rehearsal-step-m",
        "0",
        "--out",
        path(&out),
    ]);
    // The quick size without rehearsal: the suite writes none.
    assert!(
        !out.join("lola")
            .join("rehearsal-truth-noprior.tif")
            .exists()
    );
    let flat = Dem::new(
        600,
        600,
        vec![-2000.0f32; 600 * 600],
        GeoRef::local(0.0, 3000.0, 5.0, "flat"),
    )
    .unwrap();
    let flat_tif = dir.path().join("flat.tif");
    write_geotiff(&flat, &flat_tif, None).unwrap();
    let flat_ref = dir.path().join("flat");
    run(&["tile", "--dem", path(&flat_tif), "--out", path(&flat_ref)]);
    for (reference, lo, hi) in [
        (out.join("lola").join("truth"), 0.8, 1.0),
        (flat_ref, 0.0, 0.0),
    ] {
        let nm = dir.path().join("nm");
        let text = run(&[
            "navmap",
            "--tile",
            path(&reference),
            "--out",
            path(&nm),
            "--size-px",
            "120",
            "--step-m",
            "250",
            "--frames-per-site",
            "4",
            "--prior-sigma-m",
            "50",
        ]);
        assert!(text.contains("rehearsal (prior 50 m, 2°)"), "{text}");
        let j = json(&nm.join("navmap.json"));
        let go = j["go_fraction"].as_f64().unwrap();
        assert!((lo..=hi).contains(&go), "{}: go {go}", reference.display());
        // The mean chance agrees with the sites it was averaged from.
        let sites = json(&nm.join("navmap-sites.json"));
        let p: Vec<f64> = sites["success"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let mean = j["mean_predicted_success"].as_f64().unwrap();
        assert!((mean - p.iter().sum::<f64>() / p.len() as f64).abs() < 1e-6);
        assert!(
            (lo..=hi).contains(&mean),
            "{}: mean {mean}",
            reference.display()
        );
        assert_eq!(j["frames"].as_u64(), Some(4 * j["sites"].as_u64().unwrap()));
        for f in [
            "navmap.tif",
            "navmap-success.tif",
            "navmap.png",
            "navmap-sites.json",
        ] {
            assert!(nm.join(f).exists(), "{f}");
        }
    }
}

#[test]
fn suite_and_navmap_refuse_bad_input_clearly() {
    let out = ground_sim(&["suite", "--quick", "--scenes", "nowhere", "--out", "/tmp/x"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no scene named \"nowhere\""), "{err}");
    let scratch = tempfile::tempdir().unwrap();
    let out = ground_sim(&[
        "suite",
        "--quick",
        "--rehearsal-step-m",
        "0",
        "--rehearse-on-truth",
        "--out",
        path(scratch.path()),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--rehearse-on-truth needs the rehearsal"),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let out = ground_sim(&[
        "navmap",
        "--tile",
        path(dir.path()),
        "--out",
        path(dir.path()),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("tile.bin"));
    // A reference folder without its DEM: the rehearsal says what it needs.
    let flat = ground_sim::dem::Dem::new(
        200,
        200,
        vec![0.0f32; 200 * 200],
        ground_sim::dem::GeoRef::local(0.0, 1000.0, 5.0, "flat"),
    )
    .unwrap();
    let tif = dir.path().join("flat.tif");
    ground_sim::dem::write_geotiff(&flat, &tif, None).unwrap();
    let r = dir.path().join("ref");
    run(&["tile", "--dem", path(&tif), "--out", path(&r)]);
    std::fs::remove_file(r.join("reference-dem.tif")).unwrap();
    let out = ground_sim(&["navmap", "--tile", path(&r), "--out", path(dir.path())]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("reference-dem.tif is missing"), "{err}");
    let out = ground_sim(&[
        "navmap",
        "--tile",
        path(&r),
        "--out",
        path(dir.path()),
        "--method",
        "footprint",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn trade_refuses_bad_input_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let out = ground_sim(&["trade", "--scenes", "nowhere", "--out", path(dir.path())]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no scene named \"nowhere\""), "{err}");
    let out = ground_sim(&["trade", "--baseline-m", "0", "--out", path(dir.path())]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--baseline-m positive"));
    let out = ground_sim(&["trade", "--trials", "0", "--out", path(dir.path())]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--trials must be"));
    let out = ground_sim(&["trade", "--passes", "1,0", "--out", path(dir.path())]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--passes must be 1–16, got 0"), "{err}");
    // Nothing was written for refused input.
    assert!(!dir.path().join("trade.json").exists());
}

#[test]
fn trade_runs_a_design_point_end_to_end() {
    // One noise-free point of the paper's radar on the 4 km lola scene (200-px frames at up to
    // 11 m need it): the whole chain and a short campaign, then the three outputs with figures
    // a person can check.
    let dir = tempfile::tempdir().unwrap();
    let text = run(&[
        "trade",
        "--scenes",
        "lola",
        "--nesz-db=-inf",
        "--baseline-m",
        "8",
        "--looks",
        "one",
        "--diffuse-db=-inf",
        "--trials",
        "6",
        "--size-m",
        "4000",
        "--out",
        path(dir.path()),
    ]);
    assert!(text.contains("trade: 1 points"), "{text}");
    let j = json(&dir.path().join("trade.json"));
    assert_eq!(j["trials"].as_u64(), Some(6));
    assert_eq!(j["size_m"].as_f64(), Some(4000.0));
    let pts = j["points"].as_array().unwrap();
    assert_eq!(pts.len(), 1);
    let p = &pts[0];
    assert!(
        p["nesz_db"].is_null(),
        "no thermal noise is recorded as null"
    );
    assert!(j["diffuse_db"].is_null(), "the paper's surface: {j}");
    let crlb = p["crlb_height_m"].as_f64().unwrap();
    let rmse = p["height_rmse_m"].as_f64().unwrap();
    // Noise-free, the 8 m radar maps lola to about a metre (1.09 m on the 4 km scene).
    assert!(crlb > 0.0 && crlb < 5.0, "CRLB {crlb}");
    assert!(rmse > 0.0 && rmse < 3.0, "height RMSE {rmse}");
    let feats = p["tile_features"].as_u64().unwrap();
    assert!(feats > 20);
    // Noise-free at 8 m most of the map's blobs are ground (measured 135 of 206), and never
    // more than it has.
    let ground = p["tile_features_on_truth"].as_u64().unwrap();
    assert!(ground <= feats && 2 * ground > feats, "{ground} of {feats}");
    let success = p["success_rate"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&success));
    assert_eq!(p["false_fixes"].as_u64(), Some(0));
    let table = std::fs::read_to_string(dir.path().join("trade.md")).unwrap();
    assert_eq!(
        p["passes"].as_u64(),
        Some(1),
        "one pass unless --passes says more"
    );
    assert!(table.contains("| lola | one | 1 | 8 m | none |"), "{table}");
    let png = std::fs::read(dir.path().join("trade.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"));
}
