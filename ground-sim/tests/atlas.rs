//! The flight atlas end to end: a generated map cut into 2 × 2 tiles; frames flown across the
//! tile edges are located on the atlas (both tile sources, bit for bit alike) as well as on the
//! single tile; `ground-sim atlas` and `descent --atlas` through the CLI, and their refusals.

// Test helpers outside #[test] functions may unwrap too: a failure is a test failure.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

use ground_sim::flyer::frames::{FramePose, SensorModel, synth_frame};
use ground_sim::reference::atlas::{AtlasLayout, build_atlas, build_atlas_within};
use ground_sim::reference::{Smoothing, load, reference_dem, surf_config_for, write_reference};
use ground_sim::terrain::{Preset, TerrainParams, generate};
use indicatif::ProgressBar;
use nav_core::atlas::{AtlasConfig, AtlasNavigator, BufferedAtlas, MappedAtlas, TileSource};
use nav_core::{DemPatch, NavConfig, Navigator, Prior, Tile};

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_ground-sim"))
        .args(args)
        .output()
        .expect("ground-sim runs")
}

fn p(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn frames_across_tile_edges_fix_on_the_atlas_as_on_the_single_tile() {
    // A 6 km crater floor at 10 m, its 20 m reference (300 × 300 px) cut into 2 × 2 tiles of
    // 150 px cores with 30 px (600 m) margins: a 200 px frame at 8 m reaches 1.13 km from its
    // centre, so frames near the middle straddle tile edges.
    let mut tp = TerrainParams::new(Preset::Shoemaker);
    tp.seed = 3;
    tp.size_m = 6000.0;
    tp.pixel_m = 10.0;
    let (dem, _) = generate(&tp, &ProgressBar::hidden()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let r = reference_dem(&dem, 20.0).unwrap();
    let cfg = surf_config_for(
        &ground_sim::reference::noise_floor::FrameNoise::default_sensor(),
        20.0,
        ground_sim::reference::DEFAULT_SMOOTHING_M,
    )
    .unwrap();
    write_reference(&r, dir.path(), &cfg, 8192, Smoothing::default_for_truth()).unwrap();
    let single_bytes = load(dir.path()).unwrap().tile_bytes;
    let layout = AtlasLayout {
        core_px: 150,
        margin_px: 30,
    };
    let (bytes, summary) = build_atlas(&single_bytes, layout, 8192).unwrap();
    assert_eq!(summary.tiles_xy, [2, 2]);
    assert_eq!(summary.tiles.len(), 4);
    assert!(
        summary
            .tiles
            .iter()
            .all(|t| t.width == 180 && t.height == 180)
    );
    // A byte budget shrinks the cores until every tile fits; an impossible one is an error.
    let budget = summary.largest_tile_bytes * 3 / 4;
    let (_, small) = build_atlas_within(&single_bytes, layout, 8192, budget).unwrap();
    assert!(
        small.largest_tile_bytes <= budget,
        "{}",
        small.largest_tile_bytes
    );
    assert!(small.tiles.len() > 4 && small.layout.core_px < 150);
    let err = build_atlas_within(&single_bytes, layout, 8192, 1000).unwrap_err();
    assert!(err.to_string().contains("no core size"), "{err}");

    let single = Navigator::new(Tile::parse(&single_bytes).unwrap(), NavConfig::default());
    let mapped = MappedAtlas::<16>::new(&bytes).unwrap();
    let mut store = vec![0u8; summary.largest_tile_bytes];
    let mut buffered = BufferedAtlas::new(&bytes[..], &bytes[..], &mut store).unwrap();
    let nav = AtlasNavigator::new(AtlasConfig::default());
    let ah = *mapped.atlas().header();
    let mut ws = Box::new(nav_core::flight::Workspace::new());
    let sensor = SensorModel::default();
    let (cx, cy) = ah.pixel_to_geo(150.0, 150.0);
    let (mut atlas_fixes, mut single_fixes, mut straddled, mut tiles) = (0, 0, 0, Vec::new());
    let n = 12;
    for i in 0..n {
        // A diagonal pass through the atlas centre, where all four tiles meet.
        let t = -1.0 + 2.0 * i as f64 / (n - 1) as f64;
        let pose = FramePose {
            x_m: cx + 1100.0 * t,
            y_m: cy + 900.0 * t + 150.0,
            heading_rad: 0.4 + 0.3 * t,
            pixel_m: 8.0,
        };
        let frame = synth_frame(&dem, &pose, &sensor, 100 + i as u64).unwrap();
        let patch = DemPatch::new_checked(&frame.heights_m, 200, 200, 8.0).unwrap();
        let (px, py) = ah.geo_to_pixel(pose.x_m + 25.0, pose.y_m - 15.0);
        let prior = Prior {
            center_tile_px: [px as f32, py as f32],
            sigma_px: 2.0,
            heading_rad: pose.heading_rad as f32,
            heading_sigma_rad: 0.05,
            scale: 8.0 / 20.0,
            scale_sigma: 0.02,
        };
        let on_mapped = nav
            .locate_dem(&mut &mapped, ws.as_mut(), &patch, &prior)
            .unwrap();
        let on_buffered = nav
            .locate_dem(&mut buffered, ws.as_mut(), &patch, &prior)
            .unwrap();
        assert_eq!(
            on_mapped, on_buffered,
            "frame {i}: the two tile sources disagree"
        );
        let single_report = single
            .locate_dem(ws.as_mut(), &patch, Some(&prior))
            .unwrap();
        straddled += usize::from(on_mapped.candidates.straddles);
        if let Some(t) = on_mapped.tile {
            tiles.push(t);
        }
        if let Ok(f) = single_report.outcome {
            single_fixes += 1;
            let e = (f.center_geo_m[0] - pose.x_m).hypot(f.center_geo_m[1] - pose.y_m);
            assert!(e < 10.0, "frame {i}: single-tile fix {e:.1} m off");
        }
        if let Some(Ok(f)) = on_mapped.report.map(|r| r.outcome) {
            atlas_fixes += 1;
            let e = (f.center_geo_m[0] - pose.x_m).hypot(f.center_geo_m[1] - pose.y_m);
            assert!(e < 10.0, "frame {i}: atlas fix {e:.1} m off");
            // Tile pixels plus the tile's offset are atlas pixels, and the geo follows.
            let c = on_mapped.center_atlas_px().unwrap();
            let (gx, gy) = ah.pixel_to_geo(c[0], c[1]);
            assert!((gx - f.center_geo_m[0]).abs() < 1e-6 && (gy - f.center_geo_m[1]).abs() < 1e-6);
        }
    }
    tiles.sort_unstable();
    tiles.dedup();
    println!(
        "atlas fixes {atlas_fixes}/{n}, single-tile fixes {single_fixes}/{n}, {straddled} frames straddled, tiles used {tiles:?}"
    );
    assert!(straddled >= n / 2, "the pass must cross tile edges");
    assert!(tiles.len() >= 3, "tiles used: {tiles:?}");
    assert!(
        atlas_fixes + 1 >= single_fixes,
        "{atlas_fixes} vs {single_fixes}"
    );
    assert!(atlas_fixes >= n * 3 / 4, "{atlas_fixes} of {n}");
}

#[test]
fn atlas_and_descent_over_it_through_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let d = |f: &str| dir.path().join(f);
    let ok = |args: &[&str]| {
        let o = run(args);
        assert!(
            o.status.success(),
            "{args:?}: {}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8_lossy(&o.stdout).to_string()
    };
    ok(&[
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
        p(&d("dem.tif")),
    ]);
    ok(&["tile", "--dem", p(&d("dem.tif")), "--out", p(&d("ref"))]);
    let text = ok(&[
        "atlas",
        "--tile",
        p(&d("ref")),
        "--core-px",
        "200",
        "--margin-px",
        "60",
        "--out",
        p(&d("atlas")),
    ]);
    assert!(text.contains("2 × 2 tiles"), "{text}");
    for f in ["atlas.bin", "atlas.json", "atlas.png"] {
        assert!(d("atlas").join(f).exists(), "{f} missing");
    }
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d("atlas/atlas.json")).unwrap()).unwrap();
    assert_eq!(j["tiles"].as_array().unwrap().len(), 4, "{j}");
    let text = ok(&[
        "descent",
        "--atlas",
        p(&d("atlas/atlas.bin")),
        "--dem",
        p(&d("dem.tif")),
        "--runs",
        "2",
        "--seed",
        "2",
        "--hop-min-m",
        "2000",
        "--hop-max-m",
        "3000",
        "--json",
        p(&d("descent.json")),
    ]);
    assert!(text.contains("atlas of 4 tiles"), "{text}");
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d("descent.json")).unwrap()).unwrap();
    assert_eq!(s["reference"], "atlas of 4 tiles", "{s}");
    assert!(s["fixes"].as_u64().unwrap() > 10, "{s}");
    // Refusals: both references at once; an atlas that is not one.
    let o = run(&[
        "descent",
        "--atlas",
        p(&d("atlas/atlas.bin")),
        "--tile",
        p(&d("ref")),
        "--dem",
        p(&d("dem.tif")),
        "--json",
        p(&d("x.json")),
    ]);
    assert!(!o.status.success());
    let o = run(&[
        "descent",
        "--atlas",
        p(&d("dem.tif")),
        "--dem",
        p(&d("dem.tif")),
        "--json",
        p(&d("x.json")),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not an Umbra atlas"), "{err}");
}
