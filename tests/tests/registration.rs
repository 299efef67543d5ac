//! Known transforms: frames cut from a reference slope image (rotation 0–345° every 15° and the
//! paper's 0/45/60°, scale 0.4–0.7 with 0.5 as in the paper, translation, 0.25° sensor noise)
//! registered by the full Navigator against a tile built from that reference.
//!
//! Registration error is measured against the true transform at every inlier's frame position,
//! in reference pixels (stricter than the residuals against the matched keypoints, also printed).

use ground_sim::tile::{GeoGrid, build_tile};
use nav_core::{NavConfig, NavWorkspace, Navigator, NoFix, Prior, SlopeImage, SurfConfig, Tile};
use umbra_tests::{
    CraterField, FramePose, SplitMix64, add_slope_noise, render_slope, resample_slope,
};

const SEED: u64 = 7_2023;
const REF_W: usize = 256;
const REF_PX_M: f64 = 20.0;
const FRAME_W: usize = 200;

type Ws = NavWorkspace<{ FRAME_W * FRAME_W }, FRAME_W, 256, 128>;

struct Case {
    rot_err_deg: f64,
    scale_err: f64,
    mean_err_px: f64,
    max_err_px: f64,
    mean_resid_px: f64,
    max_resid_px: f64,
    inliers: u16,
    matches: u16,
}

fn reference() -> (Vec<nav_core::SlopePx>, Vec<u8>) {
    let field = CraterField::new(SEED, 8000.0, 1600, 30.0, 500.0);
    let pose = FramePose {
        x_m: 0.0,
        y_m: 0.0,
        heading_rad: 0.0,
        pixel_m: REF_PX_M,
    };
    let slope = render_slope(&field, &pose, REF_W, REF_W);
    let img = SlopeImage::new_checked(&slope, REF_W, REF_W, REF_PX_M as f32).unwrap();
    let grid = GeoGrid {
        origin_x_m: 1000.0,
        origin_y_m: 2000.0,
        pixel_x_m: REF_PX_M,
        pixel_y_m: -REF_PX_M,
        projection: "test grid".into(),
    };
    let tile = build_tile(
        &img,
        &grid,
        &SurfConfig::default(),
        ground_sim::tile::MAX_TILE_FEATURES,
        // Slope frames are compared as given: no terrain smoothing.
        0.0,
    )
    .unwrap();
    (slope, tile)
}

/// Register one frame with true map X = s·R(θ)·(x − c) + t (frame px → reference px).
fn register(
    ref_slope: &[nav_core::SlopePx],
    nav: &Navigator<'_>,
    ws: &mut Ws,
    theta_deg: f64,
    s: f64,
    t: (f64, f64),
    rng: &mut SplitMix64,
) -> Result<Case, NoFix> {
    let (sn, cs) = theta_deg.to_radians().sin_cos();
    let c = (FRAME_W as f64 - 1.0) / 2.0;
    let truth = |x: f64, y: f64| {
        let (u, v) = (x - c, y - c);
        (s * (cs * u - sn * v) + t.0, s * (sn * u + cs * v) + t.1)
    };
    let mut frame = resample_slope(ref_slope, REF_W, REF_W, FRAME_W, FRAME_W, truth);
    add_slope_noise(&mut frame, 0.25, rng);
    let img = SlopeImage::new_checked(&frame, FRAME_W, FRAME_W, (REF_PX_M * s) as f32).unwrap();
    let report = nav.locate_slope(ws, &img, None).unwrap();
    let fix = report.outcome?;
    let mut rot_err = (fix.similarity.rotation_rad.to_degrees() - theta_deg).rem_euclid(360.0);
    if rot_err > 180.0 {
        rot_err -= 360.0;
    }
    let (mut sum, mut max, mut rsum, mut rmax, mut n) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let feats = ws.features().as_slice();
    for (m, _) in ws.matches().iter().zip(ws.inliers()).filter(|(_, f)| **f) {
        let k = feats[m.frame as usize].keypoint;
        let (ex, ey) = fix.affine.apply(k.x_px as f64, k.y_px as f64);
        let (tx, ty) = truth(k.x_px as f64, k.y_px as f64);
        let e = (ex - tx).hypot(ey - ty);
        let tk = nav.tile().keypoint(m.tile as usize);
        let r = (ex - tk.x_px as f64).hypot(ey - tk.y_px as f64);
        sum += e;
        max = max.max(e);
        rsum += r;
        rmax = rmax.max(r);
        n += 1.0;
    }
    Ok(Case {
        rot_err_deg: rot_err.abs(),
        scale_err: (fix.similarity.scale / s - 1.0).abs(),
        mean_err_px: sum / n,
        max_err_px: max,
        mean_resid_px: rsum / n,
        max_resid_px: rmax,
        inliers: fix.inliers,
        matches: report.matches,
    })
}

#[test]
fn known_transforms_are_recovered() {
    let (ref_slope, tile_bytes) = reference();
    let tile = Tile::parse(&tile_bytes).unwrap();
    println!("tile: {} features", tile.len());
    let nav = Navigator::new(tile, NavConfig::default());
    let mut ws = Box::new(Ws::new());
    let mut rng = SplitMix64::new(SEED);
    let mut angles: Vec<f64> = (0..24).map(|k| k as f64 * 15.0).collect();
    angles.push(60.0);
    angles.push(45.0);
    // Floors per scale, a little above the worst figures this test prints with this seed (they
    // are regression floors, not the bar: rotation ≤ 0.2° is met at scale 0.7 only):
    // rotation error °, scale error, mean and max registration error in reference pixels.
    let floors = [
        (0.4, 0.8, 0.016, 0.55, 0.9),
        (0.5, 0.4, 0.006, 0.25, 0.45),
        (0.6, 0.3, 0.006, 0.35, 0.6),
        (0.7, 0.2, 0.003, 0.25, 0.4),
    ];
    let (mut fixes, mut total) = (0, 0);
    for &(s, rot_floor, scale_floor, mean_floor, max_floor) in &floors {
        let (mut worst_rot, mut worst_scale, mut worst_mean, mut worst_max, mut sum_mean, mut n) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for &theta in &angles {
            total += 1;
            // Translation: frame centre somewhere in the reference's middle half.
            let t = (rng.range(96.0, 160.0), rng.range(96.0, 160.0));
            match register(&ref_slope, &nav, &mut ws, theta, s, t, &mut rng) {
                Ok(c) => {
                    fixes += 1;
                    println!(
                        "s {s:.1} θ {theta:5.1}°: {:3} matches {:3} inliers, φ err {:.3}°, s err {:.3} %, reg err mean {:.2} max {:.2} px (resid mean {:.2} max {:.2})",
                        c.matches,
                        c.inliers,
                        c.rot_err_deg,
                        c.scale_err * 100.0,
                        c.mean_err_px,
                        c.max_err_px,
                        c.mean_resid_px,
                        c.max_resid_px
                    );
                    worst_rot = worst_rot.max(c.rot_err_deg);
                    worst_scale = worst_scale.max(c.scale_err);
                    worst_mean = worst_mean.max(c.mean_err_px);
                    worst_max = worst_max.max(c.max_err_px);
                    sum_mean += c.mean_err_px;
                    n += 1.0;
                }
                Err(e) => println!("s {s:.1} θ {theta:5.1}°: no fix ({e})"),
            }
        }
        println!(
            "seed {SEED} scale {s:.1}: {n} fixes; worst φ err {worst_rot:.3}°, scale err {:.3} %, reg err: mean of means {:.3} px, worst mean {worst_mean:.3} px, worst max {worst_max:.3} px",
            worst_scale * 100.0,
            sum_mean / n
        );
        assert!(
            worst_rot <= rot_floor,
            "scale {s}: rotation error {worst_rot}°"
        );
        assert!(
            worst_scale <= scale_floor,
            "scale {s}: scale error {worst_scale}"
        );
        assert!(
            worst_mean <= mean_floor,
            "scale {s}: mean registration error {worst_mean} px"
        );
        assert!(
            worst_max <= max_floor,
            "scale {s}: max registration error {worst_max} px"
        );
    }
    println!("{fixes}/{total} fixes");
    // Every frame must fix (measured: 104 of 104), and none wrongly (the floors above).
    assert_eq!(fixes, total, "{fixes}/{total} fixes");
}

#[test]
fn prior_restricts_matching_to_the_footprint_and_still_fixes() {
    let (ref_slope, tile_bytes) = reference();
    let tile = Tile::parse(&tile_bytes).unwrap();
    let n_tile = tile.len();
    let nav = Navigator::new(tile, NavConfig::default());
    let mut ws = Box::new(Ws::new());
    let (theta, s, t) = (45.0f64, 0.5, (120.0, 140.0));
    let (sn, cs) = theta.to_radians().sin_cos();
    let c = (FRAME_W as f64 - 1.0) / 2.0;
    let frame = resample_slope(&ref_slope, REF_W, REF_W, FRAME_W, FRAME_W, |x, y| {
        let (u, v) = (x - c, y - c);
        (s * (cs * u - sn * v) + t.0, s * (sn * u + cs * v) + t.1)
    });
    let img = SlopeImage::new_checked(&frame, FRAME_W, FRAME_W, 10.0).unwrap();
    let prior = Prior {
        center_tile_px: [t.0 as f32 + 4.0, t.1 as f32 - 3.0],
        sigma_px: 5.0,
        heading_rad: (theta as f32 + 3.0).to_radians(),
        heading_sigma_rad: 5f32.to_radians(),
        scale: 0.5,
        scale_sigma: 0.02,
    };
    let free = nav.locate_slope(&mut ws, &img, None).unwrap();
    let guided = nav.locate_slope(&mut ws, &img, Some(&prior)).unwrap();
    println!(
        "tile {n_tile} features; without prior: {} candidates, {} comparisons; with prior: {} candidates, {} comparisons",
        free.match_stats.tile_candidates,
        free.match_stats.comparisons,
        guided.match_stats.tile_candidates,
        guided.match_stats.comparisons
    );
    // The footprint (radius 94 px here) covers 42 % of the 256 × 256 tile; measured 361 of 635.
    assert!(guided.match_stats.tile_candidates * 10 < free.match_stats.tile_candidates * 6);
    assert!(guided.match_stats.comparisons * 10 < free.match_stats.comparisons * 6);
    let fix = guided.outcome.unwrap();
    assert!((fix.center_tile_px[0] - t.0).hypot(fix.center_tile_px[1] - t.1) < 1.0);
    // A prior far from the truth must not be "confirmed": the fix is refused or absent.
    let wrong = Prior {
        center_tile_px: [60.0, 200.0],
        sigma_px: 3.0,
        ..prior
    };
    let r = nav.locate_slope(&mut ws, &img, Some(&wrong)).unwrap();
    assert!(r.outcome.is_err(), "{:?}", r.outcome);
}
