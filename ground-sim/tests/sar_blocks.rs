//! `ground-sim sar` in blocks: every block's SLCs are the same bytes whether the blocks run in
//! one process or one at a time (`--block I/N`), blocks sit in the whole scene's SAR frame, and
//! bad requests are refused with a reason.

mod common;

use common::{refused, run};
use std::path::Path;

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// A 1.2 km bowl at 10 m (121 × 121 px) cut at 64 px (+8): 2 × 2 blocks.
const SCENE: [&str; 8] = [
    "sar",
    "--synthetic",
    "bowl",
    "--size-m",
    "1200",
    "--synthetic-pixel-m",
    "10",
    "--no-progress",
];

#[test]
fn blocks_alone_are_the_blocks_of_one_run_and_share_the_scene_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (all, one) = (dir.path().join("all"), dir.path().join("one"));
    let blocks = ["--block-px", "64", "--block-overlap-px", "8"];
    let mut args: Vec<&str> = SCENE.to_vec();
    args.extend(blocks);
    let all_s = all.to_str().unwrap();
    let mut a = args.clone();
    a.extend(["--out", all_s]);
    let log = run(&a);
    assert!(log.contains("2 × 2 blocks"), "{log}");
    let one_s = one.to_str().unwrap();
    let mut b = args.clone();
    b.extend(["--out", one_s, "--block", "3/4"]);
    run(&b);

    // Block 3 alone: the same SLC bytes (thermal noise included: seeded per block).
    let b3 = |root: &Path| root.join("blocks/block-003");
    let mut slcs = 0;
    for e in std::fs::read_dir(b3(&all)).unwrap() {
        let name = e.unwrap().file_name();
        if name.to_string_lossy().ends_with(".bin") {
            let x = std::fs::read(b3(&all).join(&name)).unwrap();
            let y = std::fs::read(b3(&one).join(&name)).unwrap();
            assert!(x == y, "{name:?} differs between the two runs");
            slcs += 1;
        }
    }
    assert_eq!(slcs, 4, "two antennas × two polarisations");
    assert!(
        !one.join("blocks/block-000").exists(),
        "--block 3/4 ran only block 3"
    );

    // Blocks sit in the scene's frame: a block further in range starts further in range, one
    // further in azimuth starts further in azimuth; the track is the scene's (same antenna
    // positions in every block).
    let rec = |i: usize| json(&all.join(format!("blocks/block-{i:03}/block.json")));
    let rep = |i: usize| json(&all.join(format!("blocks/block-{i:03}/report.json")));
    let slc0 = |i: usize, k: &str| rep(i)["slcs"][0][k].as_f64().unwrap();
    assert_eq!(rec(0)["origin_m"][0].as_f64(), Some(0.0));
    assert!(rec(1)["origin_m"][1].as_f64().unwrap() > 0.0);
    assert!(rec(2)["origin_m"][0].as_f64().unwrap() > 0.0);
    assert!(slc0(1, "first_range_m") > slc0(0, "first_range_m") + 100.0);
    assert!(slc0(2, "first_azimuth_m") > slc0(0, "first_azimuth_m") + 100.0);
    assert_eq!(
        rep(0)["slcs"][0]["antenna_yz_m"],
        rep(3)["slcs"][0]["antenna_yz_m"]
    );
    assert_eq!(rec(0)["scene_centre_m"], rec(3)["scene_centre_m"]);
    // Each block is smaller than the scene: memory follows the block.
    let facets = |i: usize| rec(i)["facets"].as_u64().unwrap();
    let whole_scene_facets = 2 * 240 * 240; // 5 m mesh over 1.2 km
    assert!((0..4).all(|i| facets(i) < whole_scene_facets / 2));
}

#[test]
fn block_requests_that_do_not_fit_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x");
    let out_s = out.to_str().unwrap();
    let mut a: Vec<&str> = SCENE.to_vec();
    a.extend([
        "--block-px",
        "64",
        "--block-overlap-px",
        "8",
        "--block",
        "0/3",
        "--out",
        out_s,
    ]);
    let e = refused(&a);
    assert!(e.contains("cuts into 4 blocks"), "{e}");
    let mut b: Vec<&str> = SCENE.to_vec();
    b.extend(["--block-px", "400", "--block", "0/1", "--out", out_s]);
    let e = refused(&b);
    assert!(e.contains("fits one block"), "{e}");
    let mut c: Vec<&str> = SCENE.to_vec();
    c.extend(["--block", "0/1", "--out", out_s]);
    let e = refused(&c);
    // clap refuses it: `--block` requires an explicit `--block-px`.
    assert!(
        e.contains("required arguments were not provided") && e.contains("--block-px"),
        "{e}"
    );
    assert!(!out.join("blocks").exists());
}
