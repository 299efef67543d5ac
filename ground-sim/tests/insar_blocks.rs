//! `ground-sim insar` in blocks: a map made block by block in separate processes and joined
//! with `--mosaic` is the same bytes as the one-process run, its seams hold, and bad requests
//! are refused with a reason.

mod common;

use common::{refused, run};
use std::path::Path;
use std::process::Command;

/// `bash tools/SCRIPT ARGS...` with this build's binary, `bin_dir` (a stand-in `sbatch`) first
/// on `PATH`.
fn script(name: &str, args: &[&str], bin_dir: &Path) -> String {
    let path = format!("{}:{}", bin_dir.display(), std::env::var("PATH").unwrap());
    let o = Command::new("bash")
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../tools")
                .join(name),
        )
        .args(args)
        .env("GROUND_SIM", env!("CARGO_BIN_EXE_ground-sim"))
        .env("PATH", path)
        .output()
        .expect("bash runs");
    assert!(
        o.status.success(),
        "{name} {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).to_string()
}

/// Every file under `a` also under `b` with the same bytes (JSON: the same but for timings).
fn assert_same_products(a: &Path, b: &Path) {
    let (fa, fb) = (files(a), files(b));
    assert_eq!(fa, fb, "{a:?} and {b:?} hold different files");
    assert!(fa.iter().any(|f| f.ends_with("tile.bin")), "{fa:?}");
    for f in &fa {
        let (x, y) = (
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
        );
        if f.extension().is_some_and(|e| e == "json") {
            let (jx, jy): (serde_json::Value, serde_json::Value) = (
                serde_json::from_slice(&x).unwrap(),
                serde_json::from_slice(&y).unwrap(),
            );
            assert_eq!(without_timings(jx), without_timings(jy), "{f:?} differs");
        } else {
            assert!(x == y, "{f:?} differs between {a:?} and {b:?}");
        }
    }
}

fn refs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// JSON with every timing (`*_s`) and memory figure removed: what must not differ between runs.
fn without_timings(v: serde_json::Value) -> serde_json::Value {
    match v {
        serde_json::Value::Object(m) => m
            .into_iter()
            .filter(|(k, _)| !(k.ends_with("_s") || k == "peak_rss_mib"))
            .map(|(k, v)| (k, without_timings(v)))
            .collect(),
        serde_json::Value::Array(a) => a.into_iter().map(without_timings).collect(),
        other => other,
    }
}

fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

/// A 1.6 km scene at 10 m of `preset`, terrain seed `seed`, written as `DIR/dem.tif`.
fn scene(dir: &Path, preset: &str, seed: &str) -> std::path::PathBuf {
    let dem = dir.join("dem.tif");
    run(&[
        "terrain",
        "--preset",
        preset,
        "--seed",
        seed,
        "--size-m",
        "1600",
        "--pixel-m",
        "10",
        "--out",
        path(&dem),
    ]);
    dem
}

/// `DIR/report.json` of an `insar` run.
fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

#[test]
fn blocks_in_separate_processes_mosaic_to_the_one_process_map() {
    let dir = tempfile::tempdir().unwrap();
    let dem = scene(dir.path(), "lola", "5");
    let (one, blocked, split) = (
        dir.path().join("one"),
        dir.path().join("blocked"),
        dir.path().join("split"),
    );
    // One look of the paper's radar: the mosaic path without a look fusion (the default radar's
    // two noisy looks are `both_look_directions_in_blocks` below).
    let common = |out: &Path| -> Vec<String> {
        [
            "insar",
            "--dem",
            path(&dem),
            "--out",
            path(out),
            "--no-progress",
            "--radar",
            "paper",
            "--block-cells",
            "40",
            "--block-overlap-cells",
            "8",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let args = |v: &[String], extra: &[&str]| -> Vec<String> {
        v.iter()
            .cloned()
            .chain(extra.iter().map(|s| s.to_string()))
            .collect()
    };

    let text = run(&refs(&common(&blocked)));
    assert!(text.contains("blocks     2x2 blocks"), "{text}");
    // The same blocks, each in its own process, in reverse order, then joined.
    for i in (0..4).rev() {
        let b = format!("{i}/4");
        let t = run(&refs(&args(&common(&split), &["--block", &b])));
        assert!(t.contains(&format!("block {i}/4")), "{t}");
    }
    run(&refs(&args(&common(&split), &["--mosaic"])));
    assert_same_products(&blocked, &split);

    // The job scripts: local worker processes, and Slurm's job array + mosaic job (a stand-in
    // sbatch runs them here; no Slurm on this machine).
    let flags = [
        "--dem",
        path(&dem),
        "--radar",
        "paper",
        "--block-cells",
        "40",
        "--block-overlap-cells",
        "8",
    ];
    let local = dir.path().join("local");
    let mut a = vec!["2", path(&local)];
    a.extend(flags);
    script("local-blocks.sh", &a, dir.path());
    std::fs::remove_dir_all(local.join("logs")).unwrap();
    assert_same_products(&blocked, &local);
    let bin_dir = dir.path().join("bin");
    common::install_fake_sbatch(&bin_dir);
    let slurm = dir.path().join("slurm-out");
    let mut a = vec![path(&slurm)];
    a.extend(flags);
    let text = script("slurm-insar-blocks.sh", &a, &bin_dir);
    assert!(text.contains("4 tasks"), "{text}");
    let job = std::fs::read_to_string(slurm.join("slurm/block.sbatch")).unwrap();
    assert!(job.contains("#SBATCH --array=0-3"), "{job}");
    std::fs::remove_dir_all(slurm.join("slurm")).unwrap();
    assert_same_products(&blocked, &slurm);

    // Seams: no whole-cycle disagreement, the blend zones as good as the rest, the mosaic as
    // good as the map made in one piece.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(blocked.join("report.json")).unwrap())
            .unwrap();
    let b = &report["blocks"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    assert_eq!(b["overlap_cycle_disagreements"], 0, "{b}");
    assert!(b["overlap_cells_compared"].as_u64().unwrap() > 1000, "{b}");
    let (zone, rest) = (
        f(&b["height_rmse_blend_zone_m"]),
        f(&b["height_rmse_elsewhere_m"]),
    );
    assert!(
        zone <= 1.5 * rest,
        "blend zones {zone} m vs elsewhere {rest} m"
    );
    run(&[
        "insar",
        "--dem",
        path(&dem),
        "--out",
        path(&one),
        "--no-progress",
        "--radar",
        "paper",
        "--block-cells",
        "0",
    ]);
    let single: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(one.join("report.json")).unwrap()).unwrap();
    let (mosaic_rmse, one_rmse) = (f(&report["height_rmse_m"]), f(&single["height_rmse_m"]));
    assert!(
        mosaic_rmse <= 1.3 * one_rmse + 0.2,
        "mosaic {mosaic_rmse} m vs one piece {one_rmse} m"
    );
    assert!(
        f(&report["valid_fraction"]) >= f(&single["valid_fraction"]) - 0.02,
        "{report}"
    );
    assert!(report["tile_features"].as_u64().unwrap() > 0);
    assert!(single.get("blocks").is_none());

    // Refusals, each with its reason.
    let e = refused(&refs(&args(&common(&split), &["--block", "0/3"])));
    assert!(e.contains("N must be 4"), "{e}");
    let e = refused(&refs(&args(&common(&split), &["--block", "4/4"])));
    assert!(e.contains("out of range"), "{e}");
    let empty = dir.path().join("empty");
    let e = refused(&refs(&args(&common(&empty), &["--mosaic"])));
    assert!(
        e.contains("block 0 missing") && e.contains("--block 0/4"),
        "{e}"
    );
    let e = refused(&refs(&args(
        &common(&split),
        &["--mosaic", "--min-coherence", "0.4"],
    )));
    assert!(e.contains("other settings"), "{e}");
    // Blocks made and joined in other processes belong to their look directions.
    let e = refused(&refs(&args(
        &common(&split),
        &["--mosaic", "--looks", "both"],
    )));
    assert!(e.contains("other settings"), "{e}");
    let e = refused(&[
        "insar",
        "--dem",
        path(&dem),
        "--out",
        path(&one),
        "--no-progress",
        "--block",
        "0/1",
    ]);
    assert!(e.contains("fits one block"), "{e}");
}

/// The default radar (both looks, each with its second pair) in blocks, split across processes
/// and joined, against one piece.
#[test]
fn both_look_directions_in_blocks() {
    let dir = tempfile::tempdir().unwrap();
    let dem = scene(dir.path(), "shoemaker", "2");
    let (blocked, split, one) = (
        dir.path().join("blocked"),
        dir.path().join("split"),
        dir.path().join("one"),
    );
    let common = |out: &Path| -> Vec<String> {
        [
            "insar",
            "--dem",
            path(&dem),
            "--out",
            path(out),
            "--no-progress",
            "--looks",
            "both",
            "--block-cells",
            "40",
            "--block-overlap-cells",
            "8",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    run(&refs(&common(&blocked)));
    for i in 0..4 {
        let mut a = common(&split);
        a.extend(["--block".to_string(), format!("{i}/4")]);
        run(&refs(&a));
    }
    let mut a = common(&split);
    a.push("--mosaic".into());
    run(&refs(&a));
    assert_same_products(&blocked, &split);
    run(&[
        "insar",
        "--dem",
        path(&dem),
        "--out",
        path(&one),
        "--no-progress",
        "--looks",
        "both",
        "--block-cells",
        "0",
    ]);
    let (b, o) = (report(&blocked), report(&one));
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    // Both passes fused in every block, as in one piece.
    assert!(f(&b["looks"]["both_valid"]) > 0.8, "{}", b["looks"]);
    assert!(
        f(&b["valid_fraction"]) >= f(&o["valid_fraction"]) - 0.02,
        "{b} vs {o}"
    );
    assert!(
        f(&b["height_rmse_m"]) <= 1.3 * f(&o["height_rmse_m"]) + 0.2,
        "{} vs {}",
        b["height_rmse_m"],
        o["height_rmse_m"]
    );
    assert_eq!(b["blocks"]["overlap_cycle_disagreements"], 0);
    // The default radar's second 128 m pair flew in every block, for each look, as in one piece.
    for r in [&b, &o] {
        let l = r["baselines"].as_array().expect("baselines recorded");
        assert_eq!(l.len(), 2, "{l:?}");
        assert!(
            l.iter()
                .all(|x| x["long_baseline_m"].as_f64() == Some(128.0)),
            "{l:?}"
        );
    }
    // Both maps claim the reference error of their one-look share, blocked as in one piece.
    let sigma = |d: &Path| -> f64 {
        let t: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("tile.json")).unwrap()).unwrap();
        t["reference_sigma_m"][0].as_f64().unwrap()
    };
    let (sb, so) = (sigma(&blocked), sigma(&one));
    assert!(sb < 0.9 && so < 0.9, "blocked {sb} m, one piece {so} m");
    assert!((sb - so).abs() < 0.1, "blocked {sb} m vs one piece {so} m");
}

/// Stacked passes in blocks: every block flies its passes (its own noise per pass), the block
/// records go through `block.json` and back into the mosaic, and the map counts the passes'
/// looks; the coarse prior DEM chose each block's cycles.
#[test]
fn stacked_passes_in_blocks() {
    let dir = tempfile::tempdir().unwrap();
    let dem = scene(dir.path(), "lola", "3");
    let (stacked, single) = (dir.path().join("stacked"), dir.path().join("single"));
    run(&[
        "insar",
        "--dem",
        path(&dem),
        "--out",
        path(&stacked),
        "--no-progress",
        "--looks",
        "one",
        // The stacking alone (the default radar's second pair is `both_look_directions_in_blocks`).
        "--long-baseline-m",
        "0",
        "--passes",
        "2",
        "--block-cells",
        "40",
        "--block-overlap-cells",
        "8",
    ]);
    run(&[
        "insar",
        "--dem",
        path(&dem),
        "--out",
        path(&single),
        "--no-progress",
        "--looks",
        "one",
        "--long-baseline-m",
        "0",
        "--block-cells",
        "0",
    ]);
    let (s, o) = (report(&stacked), report(&single));
    let looks = |r: &serde_json::Value| r["effective_looks"].as_f64().unwrap();
    assert!(
        (looks(&s) / looks(&o) - 2.0).abs() < 1e-9,
        "{} {}",
        looks(&s),
        looks(&o)
    );
    let rmse = |r: &serde_json::Value| r["height_rmse_m"].as_f64().unwrap();
    assert!(
        rmse(&s) < 1.1 * rmse(&o),
        "stacked {} vs one pass {}",
        rmse(&s),
        rmse(&o)
    );
    assert!(s["valid_fraction"].as_f64().unwrap() > 0.95, "{s}");
    assert!(
        s["unwrap"]["prior"]["ran"].as_bool().unwrap_or(false),
        "{}",
        s["unwrap"]
    );
}
