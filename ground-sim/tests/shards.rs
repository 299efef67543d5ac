//! Sharded campaigns: `eval` and `descent` split into N = 1, 3, 7 shards (background processes
//! through `tools/local-shards.sh`) and merged give byte for byte the summary, CSV and pictures
//! of the single run; `tools/slurm-campaign.sh`'s job scripts do the same under a stand-in
//! `sbatch` (no Slurm here); `merge` refuses gaps, duplicates and shards of another campaign;
//! `--shard` refuses malformed text.

mod common;

use common::{refused, run};
use std::path::{Path, PathBuf};
use std::process::Command;

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// `tools/local-shards.sh N OUT CMD ARGS...` with this build's binary.
fn local_shards(n: usize, out: &Path, cmd: &str, args: &[&str]) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/local-shards.sh");
    let o = Command::new("bash")
        .arg(script)
        .arg(n.to_string())
        .arg(out)
        .arg(cmd)
        .args(args)
        .env("GROUND_SIM", env!("CARGO_BIN_EXE_ground-sim"))
        .output()
        .expect("bash runs");
    assert!(
        o.status.success(),
        "local-shards {n} {cmd} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// `tools/slurm-campaign.sh N OUT CMD ARGS...` with this build's binary and a stand-in
/// `sbatch` (`common::FAKE_SBATCH`).
fn slurm_campaign(n: usize, out: &Path, cmd: &str, args: &[&str], bin_dir: &Path) {
    std::fs::create_dir_all(bin_dir).unwrap();
    common::install_fake_sbatch(bin_dir);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/slurm-campaign.sh");
    let path = format!("{}:{}", bin_dir.display(), std::env::var("PATH").unwrap());
    let o = Command::new("bash")
        .arg(script)
        .arg(n.to_string())
        .arg(out)
        .arg(cmd)
        .args(args)
        .env("GROUND_SIM", env!("CARGO_BIN_EXE_ground-sim"))
        .env("PATH", path)
        .output()
        .expect("bash runs");
    assert!(
        o.status.success(),
        "slurm-campaign {n} {cmd} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let job = std::fs::read_to_string(out.join("slurm/shard.sbatch")).unwrap();
    assert!(
        job.contains(&format!("#SBATCH --array=0-{}", n - 1)),
        "{job}"
    );
}

fn assert_same_bytes(a: &Path, b: &Path) {
    let (x, y) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(
        x == y,
        "{} and {} differ:\n{}\n---\n{}",
        a.display(),
        b.display(),
        String::from_utf8_lossy(&x),
        String::from_utf8_lossy(&y)
    );
}

/// A generated 8 km floor and its reference folder (as `closed_loop`).
fn scene(dir: &Path) -> (PathBuf, PathBuf) {
    let (dem, reference) = (dir.join("dem.tif"), dir.join("ref"));
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
        s(&dem),
    ]);
    run(&["tile", "--dem", s(&dem), "--out", s(&reference)]);
    (dem, reference)
}

#[test]
fn merged_shards_equal_the_single_run_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let (dem, reference) = scene(dir.path());
    let t0 = std::time::Instant::now();

    // eval: host time off, the only figure that differs from run to run.
    // With a prior, as in flight: lost in space against this whole 8 km tile (over 1 000
    // features) the flyer's work budget leaves no room past matching.
    let eval_args = [
        "--tile",
        s(&reference),
        "--dem",
        s(&dem),
        "--trials",
        "21",
        "--seed",
        "5",
        "--prior-sigma-m",
        "50",
        "--prior-heading-sigma-deg",
        "2",
        "--no-host-time",
    ];
    let single = dir.path().join("eval-single");
    let json = single.join("eval.json");
    run(&[&["eval"][..], &eval_args, &["--json", s(&json)]].concat());
    for n in [1, 3, 7] {
        let out = dir.path().join(format!("eval-{n}"));
        local_shards(n, &out, "eval", &eval_args);
        assert_same_bytes(&json, &out.join("eval.json"));
        assert_same_bytes(&single.join("eval.csv"), &out.join("eval.csv"));
    }
    // The Slurm job scripts (a stand-in sbatch runs them here).
    let out = dir.path().join("eval-slurm-3");
    slurm_campaign(3, &out, "eval", &eval_args, &dir.path().join("fake-bin"));
    assert_same_bytes(&json, &out.join("eval.json"));
    assert_same_bytes(&single.join("eval.csv"), &out.join("eval.csv"));
    println!("eval: {:.1} s", t0.elapsed().as_secs_f64());
    // The figures are real: some frames were flown and fixed.
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(e["trials"], 21, "{e}");
    assert!(e["success_rate"].as_f64().unwrap() > 0.5, "{e}");

    let t1 = std::time::Instant::now();
    let descent_args = [
        "--tile",
        s(&reference),
        "--dem",
        s(&dem),
        "--runs",
        "4",
        "--seed",
        "2",
        "--hop-min-m",
        "2000",
        "--hop-max-m",
        "2500",
    ];
    let single = dir.path().join("descent-single");
    let json = single.join("descent.json");
    // With every run's history as CSV too: the summary must not change (the shards have none).
    let histories = single.join("histories.csv");
    run(&[
        &["descent"][..],
        &descent_args,
        &["--json", s(&json), "--histories", s(&histories)],
    ]
    .concat());
    for n in [1, 3, 7] {
        let out = dir.path().join(format!("descent-{n}"));
        local_shards(n, &out, "descent", &descent_args);
        assert_same_bytes(&json, &out.join("descent.json"));
        for png in [
            "descent-trajectory.png",
            "descent-error.png",
            "descent-hazard.png",
        ] {
            assert_same_bytes(&single.join(png), &out.join(png));
        }
        // The confirmation map's picture, when run 0 made one: the same from shards too.
        let png = "descent-confirm.png";
        assert_eq!(single.join(png).exists(), out.join(png).exists());
        if single.join(png).exists() {
            assert_same_bytes(&single.join(png), &out.join(png));
        }
    }
    println!("descent: {:.1} s", t1.elapsed().as_secs_f64());
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(d["runs"], 4, "{d}");
    assert!(d["fixes"].as_u64().unwrap() > 20, "{d}");
    // The histories hold every run, and their accepted fixes (state 1) are the summary's.
    let csv = std::fs::read_to_string(&histories).unwrap();
    let mut lines = csv.lines();
    assert!(lines.next().unwrap().starts_with("run,t_s,truth_e_m"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let runs: std::collections::BTreeSet<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(runs.into_iter().collect::<Vec<_>>(), ["0", "1", "2", "3"]);
    let accepted = rows.iter().filter(|r| r[11] == "1").count() as u64;
    assert_eq!(accepted, d["fixes"].as_u64().unwrap());
    for r in &rows {
        assert_eq!(r.len(), 19, "{r:?}");
        // A TRN fix (accepted or gated) carries its covariance, an offset its displacement too.
        let has = |i: usize| !r[i].is_empty();
        match r[11] {
            "1" | "2" => assert!(has(12) && has(14) && !has(17), "{r:?}"),
            "4" | "5" => assert!(has(12) && has(14) && has(17) && has(18), "{r:?}"),
            _ => assert!(!has(12) && !has(14) && !has(17), "{r:?}"),
        }
    }

    // merge refuses what is not one whole campaign.
    let sh = |n: usize, i: usize| dir.path().join(format!("eval-{n}/shards/shard-{i}.json"));
    let e = refused(&[
        "merge",
        "--json",
        s(&dir.path().join("x.json")),
        s(&sh(3, 0)),
        s(&sh(3, 2)),
    ]);
    assert!(e.contains("shard(s) 1/3 missing"), "{e}");
    let e = refused(&[
        "merge",
        "--json",
        s(&dir.path().join("x.json")),
        s(&sh(3, 0)),
        s(&sh(3, 1)),
        s(&sh(3, 1)),
    ]);
    assert!(e.contains("shard 1/3 given twice"), "{e}");
    let e = refused(&[
        "merge",
        "--json",
        s(&dir.path().join("x.json")),
        s(&sh(3, 0)),
        s(&sh(7, 1)),
    ]);
    assert!(
        e.contains("different campaigns") && e.contains("shard count N"),
        "{e}"
    );
    let other = dir.path().join("other-seed.json");
    run(&[
        &["eval"][..],
        &eval_args[..6],
        &[
            "--seed",
            "6",
            "--no-host-time",
            "--shard",
            "1/3",
            "--json",
            s(&other),
        ],
    ]
    .concat());
    let e = refused(&[
        "merge",
        "--json",
        s(&dir.path().join("x.json")),
        s(&sh(3, 0)),
        s(&other),
        s(&sh(3, 2)),
    ]);
    assert!(
        e.contains("different campaigns") && e.contains("seed: 5 vs 6"),
        "{e}"
    );
    let e = refused(&[
        "merge",
        "--json",
        s(&dir.path().join("x.json")),
        s(&dir.path().join("descent-1/shards/shard-0.json")),
        s(&sh(1, 0)),
    ]);
    assert!(e.contains("holds a `eval` shard, not `descent`"), "{e}");
}

#[test]
fn shard_text_is_checked() {
    for (bad, why) in [
        ("3/3", "out of range"),
        ("0/0", "at least 1"),
        ("1-3", "malformed"),
        ("-1/3", "malformed"),
        ("a/b", "malformed"),
    ] {
        // `=` so that clap reads `-1/3` as the value, not as a flag.
        let flag = format!("--shard={bad}");
        let e = refused(&["eval", "--tile", "x", "--dem", "y", "--json", "z", &flag]);
        assert!(e.contains(why), "--shard {bad}: {e}");
    }
}
