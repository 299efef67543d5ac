//! Host speed of one full `Navigator` call (slope → SURF → match → MSAC → gate) on a 200 × 200
//! DEM frame against a 512-feature tile. Scene: seeded analytic crater field; reference at 20 m,
//! frame at 10 m rotated by 30°. Three configurations: the host's (256 keypoints, no work
//! budget), and the flight configuration (`nav_core::flight`: its workspace, 24 keypoints, the
//! 20 M work budget) without and with a prior (σ 50 m, 2°, 2 % around the host's fix).

use criterion::{Criterion, criterion_group, criterion_main};
use ground_sim::reference::tile::{GeoGrid, build_tile};
use nav_core::{DemPatch, NavConfig, NavWorkspace, Navigator, SurfConfig, Tile};
use std::hint::black_box;
use umbra_tests::{CraterField, FramePose, render_dem};

const W: usize = 200;

fn bench_navigator(c: &mut Criterion) {
    let field = CraterField::new(7_2023, 8000.0, 1600, 30.0, 500.0);
    let ref_pose = FramePose {
        x_m: 0.0,
        y_m: 0.0,
        heading_rad: 0.0,
        pixel_m: 20.0,
    };
    // The reference as ground-sim builds it: DEM smoothed by the default terrain σ, so the
    // frame path below runs its Gaussian stage as on the flyer.
    let smoothing_m = ground_sim::reference::DEFAULT_SMOOTHING_M;
    let ref_dem = render_dem(&field, &ref_pose, 256, 256);
    let ref_patch =
        DemPatch::new_checked(&ref_dem, 256, 256, 20.0).unwrap_or_else(|e| panic!("{e}"));
    let mut slope = vec![nav_core::SLOPE_NODATA; 256 * 256];
    let img = nav_core::slope::slope_into_binned_smoothed::<256>(
        &ref_patch,
        1,
        (smoothing_m / 20.0) as f32,
        &mut slope,
        false,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let grid = GeoGrid {
        origin_x_m: 0.0,
        origin_y_m: 0.0,
        pixel_x_m: 20.0,
        pixel_y_m: 20.0,
        projection: "bench".into(),
    };
    let detector = nav_core::DetectorConfig {
        threshold: 0.1,
        ..Default::default()
    };
    let cfg = SurfConfig {
        detector,
        upright: false,
    };
    let tile_bytes = build_tile(&img, &grid, &cfg, 512, smoothing_m, [0.0; 2], 0.0, None)
        .unwrap_or_else(|e| panic!("{e}"));
    let tile = Tile::parse(&tile_bytes).unwrap_or_else(|e| panic!("{e}"));
    // A 256-keypoint host workspace: without the flyer's per-frame work budget, which its
    // keypoints alone would pass (nav_core::cost).
    let nav = Navigator::new(
        tile,
        NavConfig {
            work_budget: u32::MAX,
            ..NavConfig::default()
        },
    );
    let pose = FramePose {
        x_m: 150.0,
        y_m: -200.0,
        heading_rad: 30f64.to_radians(),
        pixel_m: 10.0,
    };
    let z = render_dem(&field, &pose, W, W);
    let dem = DemPatch::new_checked(&z, W, W, 10.0).unwrap_or_else(|e| panic!("{e}"));
    let mut ws = Box::new(NavWorkspace::<{ W * W }, W, 256, 128>::new());
    let report = nav
        .locate_dem(&mut ws, &dem, None)
        .unwrap_or_else(|e| panic!("{e}"));
    println!(
        "tile {} features; frame {} features, {} matches, {} inliers, outcome {}",
        nav.tile().len(),
        report.features,
        report.matches,
        report.inliers,
        match report.outcome {
            Ok(f) => format!(
                "fix at ({:.1}, {:.1}) px, heading {:.2}°",
                f.center_tile_px[0],
                f.center_tile_px[1],
                f.heading_rad.to_degrees()
            ),
            Err(e) => format!("no fix: {e}"),
        }
    );
    c.bench_function("navigator_200x200_vs_512_tile", |b| {
        b.iter(|| {
            black_box(
                nav.locate_dem(&mut ws, black_box(&dem), None)
                    .map(|r| r.inliers),
            )
        })
    });
    // What flies: the firmware's workspace and NavConfig::default()'s work budget.
    let flight = Navigator::new(tile, NavConfig::default());
    let mut fws = Box::new(nav_core::flight::Workspace::new());
    let Ok(fix) = report.outcome else {
        panic!("the bench frame must fix on the host");
    };
    let prior = nav_core::Prior {
        center_tile_px: [fix.center_tile_px[0] as f32, fix.center_tile_px[1] as f32],
        sigma_px: 50.0 / 20.0,
        heading_rad: fix.heading_rad as f32,
        heading_sigma_rad: 2f32.to_radians(),
        scale: fix.similarity.scale as f32,
        scale_sigma: 0.02,
    };
    for (name, prior) in [
        ("navigator_flight_200x200_vs_512_tile", None),
        ("navigator_flight_prior_200x200_vs_512_tile", Some(&prior)),
    ] {
        let r = flight
            .locate_dem(&mut fws, &dem, prior)
            .unwrap_or_else(|e| panic!("{e}"));
        // A frame that stopped fixing would time a different path: refuse it.
        assert!(r.outcome.is_ok(), "{name}: no fix ({:?})", r.outcome);
        println!(
            "{name}: {} keypoints, {} matches, {} inliers, fix",
            r.features, r.matches, r.inliers
        );
        c.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    flight
                        .locate_dem(&mut fws, black_box(&dem), prior)
                        .map(|r| r.inliers),
                )
            })
        });
    }
}

criterion_group!(benches, bench_navigator);
criterion_main!(benches);
