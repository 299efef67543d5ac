//! Bad input never panics, and the same input always gives the same bits.

use nav_core::frame::{SlopePx, slope_from_deg};
use nav_core::slope::slope_into;
use nav_core::{
    DemPatch, DetectorConfig, Features, FrameError, SLOPE_NODATA, SlopeImage, SurfConfig,
    SurfError, SurfWorkspace, extract,
};
use proptest::prelude::*;

const CAP_W: usize = 96;
const CAP_PX: usize = CAP_W * CAP_W;

/// Run the whole chain (DEM → slope → SURF) on arbitrary heights; returns the feature count.
fn chain(
    heights: &[f32],
    w: usize,
    h: usize,
    pixel_m: f32,
    cfg: &SurfConfig,
) -> Result<usize, String> {
    let dem = DemPatch::new_checked(heights, w, h, pixel_m).map_err(|e| e.to_string())?;
    let mut slope = vec![SLOPE_NODATA; w * h];
    let img = slope_into(&dem, &mut slope).map_err(|e| e.to_string())?;
    let mut ws = Box::new(SurfWorkspace::<CAP_PX, CAP_W>::new());
    let mut out = Features::<64>::new();
    extract(&img, cfg, ws.scratch(), &mut out).map_err(|e| e.to_string())?;
    for f in out.as_slice() {
        let k = f.keypoint;
        assert!(k.x_px.is_finite() && k.y_px.is_finite() && k.scale_px > 0.0);
        assert!((0.0..std::f32::consts::TAU).contains(&k.orientation_rad));
        assert!(f.descriptor.iter().all(|v| v.is_finite()));
    }
    Ok(out.len())
}

fn height_strategy() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -5000.0f32..5000.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(f32::MAX),
        1 => Just(-9999.0),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_dems_never_panic(
        (w, h, hs) in (1usize..120, 1usize..120).prop_flat_map(|(w, h)| {
            (Just(w), Just(h), proptest::collection::vec(height_strategy(), w * h))
        }),
        pixel_m in prop_oneof![Just(0.0f32), Just(-1.0), Just(f32::NAN), 0.01f32..100.0],
        threshold in prop_oneof![Just(0.0f32), 0.0f32..5.0, Just(f32::NAN), Just(-1.0)],
        octaves in 0u8..6,
        layers in 0u8..7,
        upright in any::<bool>(),
    ) {
        let cfg = SurfConfig { detector: DetectorConfig { octaves, layers, threshold, min_scale_px: 0.0, max_lazy_responses: u32::MAX }, upright };
        // Any outcome is fine except a panic; errors must be the typed ones.
        let _ = chain(&hs, w, h, pixel_m, &cfg);
    }

    #[test]
    fn arbitrary_slope_pixels_never_panic(
        w in 1usize..100,
        h in 1usize..100,
        raw in proptest::collection::vec(any::<u16>(), 1..10_000),
    ) {
        let n = w * h;
        let px: Vec<SlopePx> = (0..n).map(|i| SlopePx::from_bits(raw[i % raw.len()])).collect();
        let img = SlopeImage::new_checked(&px, w, h, 10.0).unwrap();
        let mut ws = Box::new(SurfWorkspace::<CAP_PX, CAP_W>::new());
        let mut out = Features::<32>::new();
        let r = extract(&img, &SurfConfig::default(), ws.scratch(), &mut out);
        // Frames wider than the workspace, or with more pixels than it holds (h may exceed
        // CAP_W), are refused; everything else must extract.
        prop_assert!(r.is_ok() || w > CAP_W || w * h > CAP_PX, "{w}×{h}: {r:?}");
    }

    #[test]
    fn arbitrary_hazard_frames_and_targets_never_panic(
        (w, h, hs) in (1usize..80, 1usize..80).prop_flat_map(|(w, h)| {
            (Just(w), Just(h), proptest::collection::vec(height_strategy(), w * h))
        }),
        pixel_m in prop_oneof![Just(f32::NAN), 0.01f32..3.0],
        footprint_m in prop_oneof![Just(0.0f32), Just(f32::INFINITY), 0.1f32..10.0],
        target in proptest::array::uniform2(prop_oneof![Just(f32::NAN), -1e6f32..1e6]),
    ) {
        use nav_core::hazard::{HazardConfig, HazardMap};
        let Ok(dem) = DemPatch::new_checked(&hs, w, h, pixel_m) else { return Ok(()) };
        let cfg = HazardConfig { footprint_m, ..HazardConfig::default() };
        let mut map = Box::new(HazardMap::<400>::new());
        if let Ok(s) = map.build(&dem, &cfg) {
            prop_assert_eq!(s.safe + s.too_steep + s.too_rough + s.no_data, s.sites);
            let (c, r) = map.size();
            prop_assert!(c * r <= 400);
        }
        if let Some(site) = map.choose(target, &cfg) {
            prop_assert!(site.clearance_m > 0.0 && site.from_target_m <= cfg.max_reach_m);
        }
        let _ = map.nearest_site(target);
        // A confirmation window anywhere (off the frame, not finite) never panics either.
        if let Ok(s) = map.build_around(&dem, &cfg, target, footprint_m * 2.0) {
            prop_assert_eq!(s.safe + s.too_steep + s.too_rough + s.no_data, s.sites);
            let _ = map.decide(target, target, &cfg);
        }
    }

    #[test]
    fn arbitrary_keyframes_and_offsets_never_panic(
        (w, h, hs) in (1usize..60, 1usize..60).prop_flat_map(|(w, h)| {
            (Just(w), Just(h), proptest::collection::vec(height_strategy(), w * h))
        }),
        pixel_m in prop_oneof![Just(f32::NAN), 0.01f32..20.0],
        heading in prop_oneof![Just(f64::NAN), -10.0f64..10.0],
        offset in proptest::array::uniform2(prop_oneof![Just(f64::INFINITY), -1e4f64..1e4]),
    ) {
        use nav_core::odometry::{Keyframe, KeyframePose, keyframe_bytes, locate_on_keyframe};
        use nav_core::{NavConfig, NavWorkspace};
        let Ok(dem) = DemPatch::new_checked(&hs, w, h, pixel_m) else { return Ok(()) };
        let mut ws = Box::new(NavWorkspace::<CAP_PX, CAP_W, 16, 32>::new());
        let mut key = Box::new(Keyframe::<{ keyframe_bytes(CAP_PX, 16) }>::new());
        let pose = KeyframePose {
            heading_rad: heading,
            heading_sigma_rad: 1e-3,
            pixel_m: pixel_m as f64,
            pixel_rel_sigma: 1e-3,
        };
        if key.capture(ws.as_mut(), &dem, &pose, &SurfConfig::default()).is_ok() {
            if let Ok(prior) = key.prior(offset, [[4.0, 0.0], [0.0, 4.0]], heading, 0.01, pixel_m as f64, 1e-3)
                && let Ok(r) = locate_on_keyframe(key.as_ref(), &NavConfig::default(), ws.as_mut(), &dem, &prior)
                && let Some(o) = r.offset
            {
                prop_assert!(o.east_m.is_finite() && o.north_m.is_finite());
            }
        } else {
            prop_assert!(key.tile().is_err());
        }
    }
}

#[test]
fn degenerate_frames_give_empty_results_or_typed_errors() {
    let cfg = SurfConfig::default();
    // All NaN, all nodata, constant.
    assert_eq!(chain(&vec![f32::NAN; 64 * 64], 64, 64, 10.0, &cfg), Ok(0));
    let dem = vec![-9999.0f32; 64 * 64];
    let patch = DemPatch::new_checked(&dem, 64, 64, 10.0)
        .unwrap()
        .with_nodata(-9999.0);
    let mut slope = vec![SLOPE_NODATA; 64 * 64];
    let img = slope_into(&patch, &mut slope).unwrap();
    assert!(img.pixels().iter().all(|p| *p == SLOPE_NODATA));
    assert_eq!(chain(&vec![1234.5f32; 64 * 64], 64, 64, 10.0, &cfg), Ok(0));
    // Smaller than the smallest filter.
    assert_eq!(chain(&vec![0.0f32; 8 * 8], 8, 8, 10.0, &cfg), Ok(0));
    assert_eq!(chain(&[5.0], 1, 1, 10.0, &cfg), Ok(0));
    // Zero or negative pixel size.
    assert!(
        chain(&[0.0f32; 16], 4, 4, 0.0, &cfg)
            .unwrap_err()
            .contains("pixel size")
    );
    assert!(chain(&[0.0f32; 16], 4, 4, -5.0, &cfg).is_err());
    // Larger than the workspace.
    let px = vec![slope_from_deg(3.0); (CAP_W + 1) * 10];
    let img = SlopeImage::new_checked(&px, CAP_W + 1, 10, 10.0).unwrap();
    let mut ws = Box::new(SurfWorkspace::<CAP_PX, CAP_W>::new());
    let mut out = Features::<8>::new();
    assert!(matches!(
        extract(&img, &cfg, ws.scratch(), &mut out),
        Err(SurfError::Frame(FrameError::TooLarge { .. }))
    ));
    // Bad configurations are typed errors.
    let img = SlopeImage::new_checked(&px[..CAP_W * 10], CAP_W, 10, 10.0).unwrap();
    for bad in [
        DetectorConfig {
            octaves: 0,
            ..DetectorConfig::default()
        },
        DetectorConfig {
            octaves: 9,
            ..DetectorConfig::default()
        },
        DetectorConfig {
            layers: 2,
            ..DetectorConfig::default()
        },
        DetectorConfig {
            threshold: f32::NAN,
            ..DetectorConfig::default()
        },
        DetectorConfig {
            min_scale_px: -1.0,
            ..DetectorConfig::default()
        },
    ] {
        let cfg = SurfConfig {
            detector: bad,
            upright: false,
        };
        assert!(matches!(
            extract(&img, &cfg, ws.scratch(), &mut out),
            Err(SurfError::Config(_))
        ));
    }
}

#[test]
fn nodata_never_produces_features() {
    // A smooth frame with a hole: keypoints must keep their filter footprints off the hole.
    let (w, h) = (96usize, 96usize);
    let mut z = vec![0.0f32; w * h];
    for r in 0..h {
        for c in 0..w {
            let (x, y) = (c as f32, r as f32);
            z[r * w + c] = 30.0 * ((x / 7.0).sin() * (y / 9.0).cos()) + 0.5 * x;
        }
    }
    for r in 40..50 {
        for c in 30..60 {
            z[r * w + c] = f32::NAN;
        }
    }
    let dem = DemPatch::new_checked(&z, w, h, 10.0).unwrap();
    let mut slope = vec![SLOPE_NODATA; w * h];
    let img = slope_into(&dem, &mut slope).unwrap();
    let mut ws = Box::new(SurfWorkspace::<CAP_PX, CAP_W>::new());
    let mut out = Features::<128>::new();
    extract(&img, &SurfConfig::default(), ws.scratch(), &mut out).unwrap();
    assert!(
        out.stats.rejected_nodata > 0,
        "the hole should have suppressed some maxima"
    );
    for f in out.as_slice() {
        let k = f.keypoint;
        // Distance from the keypoint to the hole (rows 39..=50, cols 29..=60 after slope masking).
        let dx = (29.0 - k.x_px).max(k.x_px - 60.0).max(0.0);
        let dy = (39.0 - k.y_px).max(k.y_px - 50.0).max(0.0);
        assert!(dx.hypot(dy) > 4.0, "keypoint {k:?} sits on the hole");
    }
}

#[test]
fn lazy_layers_stop_at_their_cap_on_noise() {
    // White slope noise with a zero threshold: nearly every position is a candidate, far more
    // of them need the lazy layers than any terrain frame (≤ 804 on the HIL sets). Detection
    // stops computing them at the cap, counts what it refused and still returns keypoints.
    const W: usize = 200;
    let mut rng = nav_core::rng::Pcg32::new(41, 2);
    let px: Vec<SlopePx> = (0..W * W)
        .map(|_| slope_from_deg((rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32 * 60.0))
        .collect();
    let img = SlopeImage::new_checked(&px, W, W, 20.0).unwrap();
    let cfg = SurfConfig {
        detector: DetectorConfig {
            threshold: 0.0,
            max_lazy_responses: nav_core::detector::MAX_LAZY_RESPONSES,
            ..DetectorConfig::default()
        },
        upright: false,
    };
    let mut ws = Box::new(SurfWorkspace::<{ W * W }, W>::new());
    let mut out = Features::<32>::new();
    extract(&img, &cfg, ws.scratch(), &mut out).unwrap();
    let s = out.stats;
    assert_eq!(
        s.lazy_responses,
        nav_core::detector::MAX_LAZY_RESPONSES,
        "{s:?}"
    );
    assert!(s.lazy_refused > 0, "{s:?}");
    assert!(s.maxima > 0 && !out.is_empty(), "{s:?}");
}

/// FNV-1a over the bits of every keypoint field and descriptor value.
fn hash_features<const N: usize>(f: &Features<N>) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |bits: u32| {
        for b in bits.to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x100_0000_01b3);
        }
    };
    for feat in f.as_slice() {
        let k = feat.keypoint;
        for v in [k.x_px, k.y_px, k.scale_px, k.orientation_rad, k.response] {
            eat(v.to_bits());
        }
        eat(k.laplacian_positive as u32);
        for v in feat.descriptor {
            eat(v.to_bits());
        }
    }
    eat(f.dropped);
    h
}

#[test]
fn same_input_gives_identical_bits() {
    let (w, h) = (CAP_W, CAP_W);
    let mut z = vec![0.0f32; w * h];
    let mut s = 0x1234_5678u32;
    for (i, v) in z.iter_mut().enumerate() {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        let (x, y) = ((i % w) as f32, (i / w) as f32);
        *v = 40.0 * (x / 6.0).sin() * (y / 8.0).cos() + (s % 1000) as f32 * 0.01;
    }
    let dem = DemPatch::new_checked(&z, w, h, 10.0).unwrap();
    let mut slope = vec![SLOPE_NODATA; w * h];
    let img = slope_into(&dem, &mut slope).unwrap();
    let mut hashes = Vec::new();
    for _ in 0..3 {
        let mut ws = Box::new(SurfWorkspace::<CAP_PX, CAP_W>::new());
        let mut out = Features::<48>::new();
        extract(&img, &SurfConfig::default(), ws.scratch(), &mut out).unwrap();
        assert!(out.len() > 10, "scene should give features");
        hashes.push(hash_features(&out));
    }
    assert!(hashes.windows(2).all(|p| p[0] == p[1]));
    println!("feature hash {:016x}", hashes[0]);
}
