//! The hazard map on frames whose answer is known: flat ground, a tilted plane, one rock, a
//! hole in the data, and the map's decision for the aim.

use nav_core::DemPatch;
use nav_core::flight::HazardMap;
use nav_core::hazard::{AimDecision, HazardConfig, HazardError};

const SIDE: usize = 120;
const PX: f32 = 0.4;

fn frame(f: impl Fn(f32, f32) -> f32) -> Vec<f32> {
    (0..SIDE * SIDE)
        .map(|k| f((k % SIDE) as f32 * PX, (k / SIDE) as f32 * PX))
        .collect()
}

#[test]
fn flat_ground_is_safe_and_the_centre_is_chosen() {
    let z = frame(|x, y| 100.0 + 0.01 * x - 0.02 * y);
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let mut map = Box::new(HazardMap::new());
    let cfg = HazardConfig::default();
    let s = map.build(&dem, &cfg).unwrap();
    assert_eq!(s.safe, s.sites);
    let (cols, rows) = map.size();
    // Clearance grows from the lattice edge inwards.
    assert!(map.clearance_m(0, 0) < map.clearance_m(cols / 2, rows / 2));
    let c = [(SIDE as f32 - 1.0) / 2.0; 2];
    let site = map.choose(c, &cfg).unwrap();
    assert!(site.from_target_m < 1.0, "{site:?}");
}

#[test]
fn a_plane_steeper_than_the_limit_is_unsafe() {
    let t = 15f32.to_radians().tan();
    let z = frame(|x, _| t * x);
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let mut map = Box::new(HazardMap::new());
    let cfg = HazardConfig::default();
    let s = map.build(&dem, &cfg).unwrap();
    assert_eq!(s.safe, 0);
    assert_eq!(s.too_steep, s.sites);
    assert!(map.choose([60.0, 60.0], &cfg).is_none());
    // 6° is within the map's 8° (the lander's 10° less the sensing margin).
    let t = 6f32.to_radians().tan();
    let z = frame(|x, _| t * x);
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    assert_eq!(map.build(&dem, &cfg).unwrap().too_steep, 0);
}

/// A 0.5 m half-ellipsoid rock, 1.6 m across, centred in the frame: (its centre in metres, the
/// heights).
fn rock_frame() -> (f32, Vec<f32>) {
    let c = (SIDE as f32 - 1.0) / 2.0 * PX;
    let z = frame(|x, y| {
        let r = (x - c).hypot(y - c) / 0.8;
        if r < 1.0 {
            0.5 * (1.0 - r * r).sqrt()
        } else {
            0.0
        }
    });
    (c, z)
}

#[test]
fn a_rock_at_the_target_moves_the_site_off_it() {
    let (c, z) = rock_frame();
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let mut map = Box::new(HazardMap::new());
    let cfg = HazardConfig::default();
    let s = map.build(&dem, &cfg).unwrap();
    assert!(s.too_rough > 0 && s.safe > 0, "{s:?}");
    let target = [c / PX; 2];
    let site = map.choose(target, &cfg).unwrap();
    // The footprints over the rock are unsafe; the chosen site keeps its 2 m clearance from
    // them, so it lies more than that from the rock, and not much farther.
    let (cols, rows) = map.size();
    assert!(!map.is_safe(cols / 2, rows / 2));
    assert!(
        site.from_target_m > cfg.clearance_m + 1.0 && site.from_target_m < 7.5,
        "{site:?}"
    );
    assert!(site.clearance_m >= cfg.clearance_m);
}

#[test]
fn missing_data_is_unsafe_and_bad_settings_are_refused() {
    let mut z = frame(|_, _| 0.0);
    // One lost cell inside the frame reads as its neighbours: every site stays safe ...
    z[60 * SIDE + 60] = f32::NAN;
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let mut map = Box::new(HazardMap::new());
    let s = map.build(&dem, &HazardConfig::default()).unwrap();
    assert_eq!((s.safe, s.no_data), (s.sites, 0), "{s:?}");
    // ... two side by side are a hole, and so is one on the frame's edge.
    z[60 * SIDE + 61] = f32::NAN;
    z[29 * SIDE] = f32::NAN;
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let s = map.build(&dem, &HazardConfig::default()).unwrap();
    assert!(s.no_data > 0 && s.no_data < s.sites, "{s:?}");
    let (cols, rows) = map.size();
    let site_of = |col: f32, row: f32| map.nearest_site([col, row]);
    let (i, j) = site_of(60.0, 60.0);
    assert!(!map.is_safe(i, j));
    let (i, j) = site_of(5.0, 29.0);
    assert!(!map.is_safe(i, j), "{:?} {:?}", (i, j), map.site_px(i, j));
    assert!(map.is_safe(cols / 2, rows - 1));
    // A no-data sentinel marks ground outside the data, not a lost return: a hole.
    let mut z = frame(|_, _| 1.0);
    z[40 * SIDE + 40] = -9999.0;
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX)
        .unwrap()
        .with_nodata(-9999.0);
    let s = map.build(&dem, &HazardConfig::default()).unwrap();
    assert!(s.no_data > 0 && s.no_data < s.sites, "{s:?}");
    // Lost returns scattered more densely than one in 32 cells of a footprint are a hole too,
    // each of them fillable: every other cell of every other row around (60, 60).
    let mut z = frame(|_, _| 0.0);
    for r in (50..70).step_by(2) {
        for c in (50..70).step_by(2) {
            z[r * SIDE + c] = f32::NAN;
        }
    }
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let s = map.build(&dem, &HazardConfig::default()).unwrap();
    let (i, j) = map.nearest_site([60.0, 60.0]);
    assert!(!map.is_safe(i, j) && s.no_data > 0, "{s:?}");
    // Two in one 0.4 m footprint (81 cells) are within the bound: (60, 60) and (62, 60).
    let mut z = frame(|_, _| 0.0);
    z[60 * SIDE + 60] = f32::NAN;
    z[60 * SIDE + 62] = f32::NAN;
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let s = map.build(&dem, &HazardConfig::default()).unwrap();
    assert_eq!((s.safe, s.no_data), (s.sites, 0), "{s:?}");
    let bad = HazardConfig {
        max_relief_m: f32::NAN,
        ..HazardConfig::default()
    };
    assert_eq!(map.build(&dem, &bad), Err(HazardError::BadConfig));
    let coarse = DemPatch::new_checked(&z, SIDE, SIDE, 2.0).unwrap();
    assert_eq!(
        map.build(&coarse, &HazardConfig::default()),
        Err(HazardError::TooCoarse)
    );
    let fine = DemPatch::new_checked(&z, SIDE, SIDE, 0.05).unwrap();
    assert_eq!(
        map.build(&fine, &HazardConfig::default()),
        Err(HazardError::TooFine)
    );
    let small = DemPatch::new_checked(&z[..8 * 8], 8, 8, PX).unwrap();
    assert_eq!(
        map.build(&small, &HazardConfig::default()),
        Err(HazardError::TooSmall)
    );
    // A failed build leaves no map to choose from.
    assert!(map.choose([4.0, 4.0], &HazardConfig::default()).is_none());
}

/// A lost cell on the rock's top hides none of it: the neighbours the fill reads are on the
/// rock too, and the cells around them still stand out of the plane.
#[test]
fn a_rock_with_its_top_lost_is_still_seen() {
    let (c, mut z) = rock_frame();
    let k = (c / PX) as usize;
    let (mut a, mut b) = (Box::new(HazardMap::new()), Box::new(HazardMap::new()));
    let cfg = HazardConfig::default();
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let whole = a.build(&dem, &cfg).unwrap();
    z[k * SIDE + k] = f32::NAN;
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let lost = b.build(&dem, &cfg).unwrap();
    assert_eq!(lost.no_data, 0);
    assert_eq!(lost.safe, whole.safe, "{whole:?} {lost:?}");
    let (cols, rows) = a.size();
    assert!(!b.is_safe(cols / 2, rows / 2));
    for j in 0..rows {
        for i in 0..cols {
            assert_eq!(a.is_safe(i, j), b.is_safe(i, j), "site ({i}, {j})");
        }
    }
}

#[test]
fn a_tight_gap_is_taken_only_when_nothing_roomier_is_in_reach() {
    // Rough ground (0.6 m bumps every 2 m) everywhere except a smooth 5 m square right of
    // the target and a wide smooth field far left.
    let smooth = |x: f32, y: f32| {
        let gap = (x - 32.0).abs() < 2.5 && (y - 24.0).abs() < 2.5;
        let field = x < 12.0;
        gap || field
    };
    let z = frame(|x, y| {
        if smooth(x, y) {
            0.0
        } else {
            0.3 * ((x * std::f32::consts::PI).sin() + (y * std::f32::consts::PI).sin())
        }
    });
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let mut map = Box::new(HazardMap::new());
    let cfg = HazardConfig::default();
    map.build(&dem, &cfg).unwrap();
    let target = [30.0 / PX, 24.0 / PX];
    // The field (≥ 4 m clear) is 18+ m away, within the 30 m reach: it wins over the gap.
    let far = map.choose(target, &cfg).unwrap();
    assert!(far.frame_px[0] * PX < 12.0, "{far:?}");
    assert!(far.clearance_m >= cfg.preferred_clearance_m, "{far:?}");
    // With a 10 m reach only the gap is left, tight as it is.
    let near = HazardConfig {
        max_reach_m: 10.0,
        ..cfg
    };
    let gap = map.choose(target, &near).unwrap();
    assert!((gap.frame_px[0] * PX - 32.0).abs() < 2.5, "{gap:?}");
    assert!(gap.clearance_m < cfg.clearance_m, "{gap:?}");
    assert!(map.nearest_with(target, cfg.clearance_m, &near).is_none());
}

#[test]
fn the_decision_keeps_a_roomy_aim_and_moves_one_on_a_rock() {
    // The rock of `a_rock_at_the_target_moves_the_site_off_it`, and an aim 10 m from it.
    let (c, z) = rock_frame();
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let mut map = Box::new(HazardMap::new());
    let cfg = HazardConfig::default();
    map.build(&dem, &cfg).unwrap();
    let on_rock = [c / PX; 2];
    let clear = [(c - 10.0) / PX, c / PX];
    match map.decide(clear, on_rock, &cfg) {
        AimDecision::Keep { clearance_m } => assert!(clearance_m >= cfg.clearance_m),
        other => panic!("a roomy aim must be kept: {other:?}"),
    }
    match map.decide(on_rock, on_rock, &cfg) {
        AimDecision::Move(site) => {
            assert_eq!(Some(site), map.choose(on_rock, &cfg));
            assert!(site.clearance_m >= cfg.clearance_m, "{site:?}");
        }
        other => panic!("an aim on the rock must move: {other:?}"),
    }
    // Nothing safe within a 0.5 m reach of the rock: the aim stays, and says so.
    let short = HazardConfig {
        max_reach_m: 0.5,
        ..cfg
    };
    assert_eq!(map.decide(on_rock, on_rock, &short), AimDecision::NoSite);
    // A non-finite aim or target decides nothing (it arrives over a link on the target).
    assert_eq!(
        map.decide([f32::NAN, 1.0], on_rock, &cfg),
        AimDecision::NoSite
    );
    assert_eq!(
        map.decide(clear, [f32::INFINITY, 0.0], &cfg),
        AimDecision::NoSite
    );
    assert_eq!(map.nearest_with([f32::NAN; 2], 0.0, &cfg), None);
}

#[test]
fn a_window_judges_its_sites_as_the_whole_frame_does() {
    use nav_core::hazard::CONFIRM_HALF_WINDOW_M;
    let (c, z) = rock_frame();
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let cfg = HazardConfig::confirmation();
    let mut whole = Box::new(HazardMap::new());
    let mut part = Box::new(HazardMap::new());
    let s_whole = whole.build(&dem, &cfg).unwrap();
    let centre = [(c - 3.0) / PX, (c + 2.0) / PX];
    let s_part = part
        .build_around(&dem, &cfg, centre, CONFIRM_HALF_WINDOW_M)
        .unwrap();
    assert!(s_part.sites < s_whole.sites, "{s_part:?} {s_whole:?}");
    let (cols, rows) = part.size();
    let step = part.site_px(1, 1)[0] - part.site_px(0, 0)[0];
    // Every window site is a site of the whole lattice with the same verdict, and lies
    // within the window.
    for j in 0..rows {
        for i in 0..cols {
            let p = part.site_px(i, j);
            assert!((p[0] - centre[0]).abs() * PX <= CONFIRM_HALF_WINDOW_M + 1e-3);
            assert!((p[1] - centre[1]).abs() * PX <= CONFIRM_HALF_WINDOW_M + 1e-3);
            let (wi, wj) = whole.nearest_site(p);
            assert_eq!(whole.site_px(wi, wj), p);
            assert_eq!(whole.is_safe(wi, wj), part.is_safe(i, j), "site {p:?}");
        }
    }
    // The window reaches its edge sites: one step more would leave it.
    let last = part.site_px(cols - 1, rows - 1);
    assert!((last[0] + step - centre[0]) * PX > CONFIRM_HALF_WINDOW_M);
    // The rock under the aim moves it, within the confirmation's reach: `confirm` is the
    // window map and the decision with the aim as its own target.
    let on_rock = [c / PX; 2];
    let (stats, decision) = part.confirm(&dem, &cfg, on_rock).unwrap();
    assert!(stats.too_rough > 0, "{stats:?}");
    assert_eq!(decision, part.decide(on_rock, on_rock, &cfg));
    match decision {
        AimDecision::Move(site) => {
            assert!(site.from_target_m <= cfg.max_reach_m, "{site:?}");
            assert!(site.clearance_m >= cfg.clearance_m, "{site:?}");
        }
        other => panic!("an aim on the rock must move: {other:?}"),
    }
}

#[test]
fn a_window_off_the_frame_or_not_finite_is_refused() {
    let z = frame(|_, _| 0.0);
    let dem = DemPatch::new_checked(&z, SIDE, SIDE, PX).unwrap();
    let cfg = HazardConfig::confirmation();
    let mut map = Box::new(HazardMap::new());
    for (c, hw) in [
        ([-100.0, 50.0], 5.0),
        ([50.0, 1000.0], 5.0),
        ([f32::NAN, 50.0], 5.0),
        ([50.0, 50.0], f32::INFINITY),
        ([50.0, 50.0], -1.0),
    ] {
        assert_eq!(
            map.build_around(&dem, &cfg, c, hw),
            Err(HazardError::WindowOutside),
            "{c:?} {hw}"
        );
        assert_eq!(map.size(), (0, 0));
    }
    // A window reaching past the frame keeps the sites inside it.
    let s = map.build_around(&dem, &cfg, [2.0, 2.0], 6.0).unwrap();
    assert!(s.sites > 0 && s.safe == s.sites, "{s:?}");
    assert_eq!(map.site_px(0, 0), [5.0, 5.0]);
}
