//! Keyframe odometry on synthetic cratered terrain: a frame located on a keyframe of the same
//! ground, finer, turned and moved, gives back its displacement within its stated σ.

use nav_core::DetectorConfig;
use nav_core::flight::{KEYFRAME_BYTES, Keyframe, Workspace};
use nav_core::odometry::{KeyframePose, OdometryError, locate_on_keyframe};
use nav_core::rng::Pcg32;
use nav_core::{DemPatch, NavConfig, SurfConfig};

/// Bowl craters with raised rims on a gentle swell, heights in metres at (east, north) metres.
struct Ground {
    craters: Vec<(f64, f64, f64)>,
}

impl Ground {
    fn new(seed: u64) -> Self {
        let mut r = Pcg32::new(seed, 3);
        let mut u = || r.next_u32() as f64 / 4_294_967_296.0;
        let craters = (0..700)
            .map(|_| {
                let radius = 8.0 * (80.0f64 / 8.0).powf(u() * u());
                (-1500.0 + 3000.0 * u(), -1500.0 + 3000.0 * u(), radius)
            })
            .collect();
        Self { craters }
    }
    fn height(&self, x: f64, y: f64) -> f64 {
        let mut z = 20.0 * (x / 700.0).sin() * (y / 900.0).cos();
        for &(cx, cy, r) in &self.craters {
            let rho = (x - cx).hypot(y - cy) / r;
            if rho < 1.0 {
                z += r * (0.04 - 0.2 * (1.0 - rho * rho));
            } else if rho < 2.0 {
                z += r * 0.04 * (2.0 - rho).powi(2);
            }
        }
        z
    }
    /// A `side × side` frame centred at (x, y) with +x `heading` clockwise from east, `px` m
    /// pixels (2 × 2 samples per pixel) and white range noise of `noise_m`.
    fn frame(&self, x: f64, y: f64, heading: f64, px: f64, side: usize, noise_m: f64) -> Vec<f32> {
        let mut r = Pcg32::new((x * 10.0) as u64 ^ 0x5eed, 9);
        let (s, c) = heading.sin_cos();
        let half = (side as f64 - 1.0) / 2.0;
        let mut z = Vec::with_capacity(side * side);
        for row in 0..side {
            for col in 0..side {
                let mut acc = 0.0;
                for (di, dj) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                    let u = (col as f64 + di - half) * px;
                    let v = (row as f64 + dj - half) * px;
                    acc += self.height(x + u * c - v * s, y - u * s - v * c);
                }
                let g = {
                    let a = (r.next_u32() as f64 + 1.0) / 4_294_967_297.0;
                    let b = r.next_u32() as f64 / 4_294_967_296.0;
                    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
                };
                z.push((acc / 4.0 + noise_m * g) as f32);
            }
        }
        z
    }
}

fn surf() -> SurfConfig {
    SurfConfig {
        detector: DetectorConfig {
            octaves: 3,
            layers: 4,
            threshold: 4.3e-4,
            min_scale_px: 0.0,
            max_lazy_responses: u32::MAX,
        },
        upright: false,
    }
}

#[test]
fn a_frame_finds_its_displacement_on_the_keyframe() {
    const SIDE: usize = 200;
    let ground = Ground::new(11);
    let mut ws = Box::new(Workspace::new());
    let mut key = Box::new(Keyframe::new());
    assert!(Keyframe::footprint_bytes() >= KEYFRAME_BYTES);
    assert!(key.needs_refresh(4.0));
    let (kx, ky, kh, kpx) = (40.0, -30.0, 0.4, 5.0);
    let z = ground.frame(kx, ky, kh, kpx, SIDE, 0.2);
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, kpx as f32).unwrap();
    let pose = KeyframePose {
        heading_rad: kh,
        heading_sigma_rad: 1e-4,
        pixel_m: kpx,
        pixel_rel_sigma: 1e-3,
    };
    key.capture(ws.as_mut(), &dem, &pose, &surf()).unwrap();
    assert!(!key.needs_refresh(4.0));
    assert!(key.needs_refresh(2.7));
    let cfg = NavConfig::default();
    let mut worst_nees = 0.0f64;
    // Frames 7–25 % finer, moved up to 90 m and turned up to 10°, as a descent makes them.
    for (k, (dx, dy, dh, px)) in [
        (12.0, -8.0, 0.02, 4.6),
        (-35.0, 20.0, -0.08, 4.2),
        (60.0, 65.0, 0.17, 3.8),
    ]
    .into_iter()
    .enumerate()
    {
        let f = ground.frame(kx + dx, ky + dy, kh + dh, px, SIDE, 0.2);
        let dem = DemPatch::new_checked(&f, SIDE, SIDE, px as f32).unwrap();
        // The filter's prediction: 3 m off the truth, σ 4 m.
        let prior = key
            .prior(
                [dx + 3.0, dy - 2.0],
                [[16.0, 0.0], [0.0, 16.0]],
                kh + dh,
                0.01,
                px,
                1e-3,
            )
            .unwrap();
        let r = locate_on_keyframe(key.as_ref(), &cfg, ws.as_mut(), &dem, &prior).unwrap();
        let o = r
            .offset
            .unwrap_or_else(|| panic!("frame {k}: no fix: {:?}", r.report.outcome));
        let (ex, ey) = (o.east_m - dx, o.north_m - dy);
        let c = o.cov_m2;
        let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
        let nees = (c[1][1] * ex * ex - 2.0 * c[0][1] * ex * ey + c[0][0] * ey * ey) / det;
        assert!(
            ex.hypot(ey) < 1.5,
            "frame {k}: error ({ex:.2}, {ey:.2}) m, σ ({:.2}, {:.2})",
            c[0][0].sqrt(),
            c[1][1].sqrt()
        );
        assert!(
            (o.rotation_rad - dh).abs() < 0.01,
            "frame {k}: rotation {}",
            o.rotation_rad
        );
        assert!(
            (o.scale - px / (2.0 * kpx)).abs() < 0.01,
            "frame {k}: scale {}",
            o.scale
        );
        worst_nees = worst_nees.max(nees);
    }
    // χ²(2) exceeds 13.8 once in a thousand.
    assert!(
        worst_nees < 13.8,
        "an offset outside its stated σ: NEES {worst_nees:.1}"
    );
}

#[test]
fn no_keyframe_and_bad_poses_are_typed_errors() {
    const SIDE: usize = 64;
    let ground = Ground::new(2);
    let mut ws = Box::new(Workspace::new());
    let mut key = Box::new(Keyframe::new());
    assert_eq!(key.tile().err(), Some(OdometryError::NoKeyframe));
    assert_eq!(
        key.prior([0.0; 2], [[1.0, 0.0], [0.0, 1.0]], 0.0, 0.01, 1.0, 1e-3)
            .err(),
        Some(OdometryError::NoKeyframe)
    );
    let z = ground.frame(0.0, 0.0, 0.0, 2.0, SIDE, 0.0);
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, 2.0).unwrap();
    let bad = KeyframePose {
        heading_rad: f64::NAN,
        heading_sigma_rad: 0.0,
        pixel_m: 2.0,
        pixel_rel_sigma: 0.0,
    };
    assert_eq!(
        key.capture(ws.as_mut(), &dem, &bad, &surf()),
        Err(OdometryError::BadPose)
    );
    let good = KeyframePose {
        heading_rad: 0.0,
        ..bad
    };
    key.capture(ws.as_mut(), &dem, &good, &surf()).unwrap();
    assert!(key.tile().is_ok());
    assert_eq!(
        key.prior(
            [f64::NAN, 0.0],
            [[1.0, 0.0], [0.0, 1.0]],
            0.0,
            0.01,
            1.0,
            1e-3
        )
        .err(),
        Some(OdometryError::BadPose)
    );
    // A frame whose keyframe would not fit the buffer is refused, not truncated, and clears
    // the keyframe.
    let big = vec![0.0f32; 256 * 256];
    let dem = DemPatch::new_checked(&big, 256, 256, 1.0).unwrap();
    assert!(matches!(
        key.capture(ws.as_mut(), &dem, &good, &surf()),
        Err(OdometryError::Tile(
            nav_core::TileError::BufferTooSmall { .. }
        ))
    ));
    assert_eq!(key.tile().err(), Some(OdometryError::NoKeyframe));
}
