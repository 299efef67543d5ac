//! `ground-sim insar` writes a reference folder that `trn` and `eval` take unchanged, and a
//! report with the keys; `sar` SLCs can be fed back in with `--slc-dir`.

use std::path::Path;
use std::process::Command;

fn run(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(args)
        .output()
        .expect("ground-sim runs");
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "ground-sim {args:?} failed:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// Run `ground-sim` expecting a refusal; its stderr.
fn refused(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(args)
        .output()
        .expect("ground-sim runs");
    assert!(!out.status.success(), "ground-sim {args:?} was not refused");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

#[test]
fn insar_folder_works_with_trn_and_eval() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dir.path().join("dem.tif");
    let ins = dir.path().join("insar");
    run(&[
        "terrain",
        "--preset",
        "shoemaker",
        "--size-m",
        "1200",
        "--out",
        path(&dem),
    ]);
    let text = run(&[
        "insar",
        "--dem",
        path(&dem),
        "--out",
        path(&ins),
        "--no-progress",
    ]);
    assert!(text.contains("height     RMSE"), "{text}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ins.join("report.json")).unwrap()).unwrap();
    for k in [
        "height_rmse_m",
        "height_bias_m",
        "slope_rmse_deg",
        "valid_fraction",
        "coherence_mean",
        "crlb_height_m",
        "tile_features",
    ] {
        assert!(report.get(k).is_some_and(|v| v.is_number()), "no {k}");
    }
    // The default radar is the mission design: both looks, each with its second 128 m pair.
    let b = report["baselines"].as_array().expect("baselines recorded");
    assert_eq!(b.len(), 2, "one second pair per look: {b:?}");
    for l in b {
        assert_eq!(l["long_baseline_m"].as_f64(), Some(128.0), "{l}");
        assert!(l["long_share"].as_f64().unwrap() > 0.0, "{l}");
    }
    assert!(report["height_rmse_m"].as_f64().unwrap() < 5.0);
    // The default radar is the mission design: thermal noise at −25 dB, 32 m, both looks.
    let sar_cfg = &report["sar"]["config"];
    assert_eq!(sar_cfg["noise_equivalent_sigma0_db"], -25.0, "{sar_cfg}");
    assert_eq!(sar_cfg["baseline_m"], 32.0, "{sar_cfg}");
    assert_eq!(sar_cfg["diffuse_sigma0_db"], -17.0, "{sar_cfg}");
    assert!(
        report["looks"]["both_valid"].as_f64().unwrap() > 0.5,
        "{report}"
    );
    for f in [
        "tile.bin",
        "slope.tif",
        "reference-dem.tif",
        "tile.json",
        "mask.tif",
        "coherence.tif",
    ] {
        assert!(ins.join(f).exists(), "{f}");
    }
    // The closed-loop tools accept the folder as it is.
    run(&[
        "trn",
        "--tile",
        path(&ins),
        "--dem",
        path(&dem),
        "--size-px",
        "60",
    ]);
    let json = dir.path().join("eval.json");
    run(&[
        "eval",
        "--tile",
        path(&ins),
        "--dem",
        path(&dem),
        "--trials",
        "3",
        "--size-px",
        "60",
        "--json",
        path(&json),
    ]);
    assert!(json.exists());

    // SLCs from `sar` (one pass, the same default radar and noise) give the same product as
    // simulating that pass inside.
    let sar = dir.path().join("sar");
    run(&[
        "sar",
        "--dem",
        path(&dem),
        "--out",
        path(&sar),
        "--pol",
        "HH",
        "--no-progress",
    ]);
    let (ins1, ins2) = (dir.path().join("insar1"), dir.path().join("insar2"));
    run(&[
        "insar",
        "--dem",
        path(&dem),
        "--looks",
        "one",
        // The radar's own pair alone, as one pair of SLCs gives it (`--slc-dir` falls back
        // to no second baseline).
        "--long-baseline-m",
        "0",
        "--out",
        path(&ins1),
        "--no-progress",
    ]);
    run(&[
        "insar",
        "--dem",
        path(&dem),
        "--slc-dir",
        path(&sar),
        "--out",
        path(&ins2),
    ]);
    let read = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("report.json")).unwrap()).unwrap()
    };
    let (r1, r2) = (read(&ins1), read(&ins2));
    let (a, b) = (
        r1["height_rmse_m"].as_f64().unwrap(),
        r2["height_rmse_m"].as_f64().unwrap(),
    );
    assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    assert!(r2["looks"].is_null(), "one pass of SLCs is one look: {r2}");
    // Both runs chose their cycles with the coarse prior DEM (the datum rule was right on this
    // small scene: nothing moved).
    for r in [&r1, &r2] {
        let p = &r["unwrap"]["prior"];
        assert_eq!(p["ran"].as_bool(), Some(true), "{r}");
        assert!(p["patches"].as_u64().unwrap() >= 1, "{p}");
        assert_eq!(p["patches_shifted"].as_u64(), Some(0), "{p}");
        assert!(p["median_residual_m"].as_f64().unwrap() < 20.0, "{p}");
    }
    // One pass of SLCs cannot be stacked.
    let err = refused(&[
        "insar",
        "--dem",
        path(&dem),
        "--slc-dir",
        path(&sar),
        "--passes",
        "2",
        "--out",
        path(&dir.path().join("insar3")),
    ]);
    assert!(
        err.contains("--passes 2 simulates its passes itself"),
        "{err}"
    );
    // Nor given a second pair: asked for, it is refused (the default falls back, above).
    let err = refused(&[
        "insar",
        "--dem",
        path(&dem),
        "--slc-dir",
        path(&sar),
        "--long-baseline-m",
        "128",
        "--out",
        path(&dir.path().join("insar4")),
    ]);
    assert!(
        err.contains("--long-baseline-m simulates its second pair itself"),
        "{err}"
    );
    // The map's own error the tiles claim: a one-look map the whole blur term (0.08 × 22.4 m),
    // the two-look map only its share of cells made by one look alone; both add, in
    // quadrature, the term of their height noise against their slope signal.
    let summary = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("tile.json")).unwrap()).unwrap()
    };
    let sigma = |d: &Path| summary(d)["reference_sigma_m"][0].as_f64().unwrap();
    let noise_term = |d: &Path| summary(d)["map_noise_sigma_m"].as_f64().unwrap();
    let (fused, one) = (sigma(&ins), sigma(&ins1));
    let blur_one = (one * one - noise_term(&ins1).powi(2)).max(0.0).sqrt();
    assert!((blur_one - 0.08 * 22.36).abs() < 0.01, "one look: {one}");
    let blur_fused = (fused * fused - noise_term(&ins).powi(2)).max(0.0).sqrt();
    assert!(blur_fused < 0.5 * blur_one, "two looks: {fused} vs {one}");
    assert!(noise_term(&ins) > 0.0 && noise_term(&ins1) > 0.0);
}
