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
    assert!(report["height_rmse_m"].as_f64().unwrap() < 5.0);
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

    // SLCs from `sar` give the same product as simulating inside.
    let sar = dir.path().join("sar");
    run(&[
        "sar",
        "--dem",
        path(&dem),
        "--out",
        path(&sar),
        "--pol",
        "HH",
        "--no-noise",
        "--no-progress",
    ]);
    let ins2 = dir.path().join("insar2");
    run(&[
        "insar",
        "--dem",
        path(&dem),
        "--slc-dir",
        path(&sar),
        "--out",
        path(&ins2),
    ]);
    let r2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ins2.join("report.json")).unwrap()).unwrap();
    let (a, b) = (
        report["height_rmse_m"].as_f64().unwrap(),
        r2["height_rmse_m"].as_f64().unwrap(),
    );
    assert!((a - b).abs() < 1e-6, "{a} vs {b}");
}
