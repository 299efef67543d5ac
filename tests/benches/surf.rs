//! Host speed of the flight SURF chain on a 200 × 200 frame: slope + integral + detect + describe.
//! Scene: the seeded analytic crater field of `umbra_tests`, 10 m pixels.

use criterion::{Criterion, criterion_group, criterion_main};
use nav_core::slope::slope_into;
use nav_core::{DemPatch, Features, SLOPE_NODATA, SurfConfig, SurfWorkspace, extract};
use std::hint::black_box;
use umbra_tests::{CraterField, FramePose, render_dem};

const W: usize = 200;

fn bench_surf(c: &mut Criterion) {
    let field = CraterField::new(20_231_107, 6000.0, 900, 30.0, 500.0);
    let pose = FramePose {
        x_m: 180.0,
        y_m: -130.0,
        heading_rad: 0.4,
        pixel_m: 10.0,
    };
    let z = render_dem(&field, &pose, W, W);
    let dem = DemPatch::new_checked(&z, W, W, 10.0).expect("valid frame");
    let mut slope = vec![SLOPE_NODATA; W * W];
    let mut ws = Box::new(SurfWorkspace::<{ W * W }, W>::new());
    let mut out = Box::new(Features::<256>::new());
    let cfg = SurfConfig::default();
    // Report the keypoint count once so the ns/frame figure has its context.
    {
        let img = slope_into(&dem, &mut slope).expect("slope");
        extract(&img, &cfg, ws.scratch(), &mut out).expect("extract");
        println!(
            "200x200 frame: {} keypoints ({} dropped)",
            out.len(),
            out.dropped
        );
    }
    c.bench_function("surf_200x200_slope_detect_describe", |b| {
        b.iter(|| {
            let img = slope_into(black_box(&dem), &mut slope).expect("slope");
            extract(&img, &cfg, ws.scratch(), &mut out).expect("extract");
            black_box(out.len())
        })
    });
}

criterion_group!(benches, bench_surf);
criterion_main!(benches);
