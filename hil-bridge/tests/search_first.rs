//! With a prior, the navigator runs the area search first on a DEM frame
//! (`NavConfig::search_first`): a frame the search fixes is never run through SURF, and one it
//! cannot fix goes on to the feature path, the search's verdict kept in the report. On the HIL
//! set's own terrain, tile (50 m smoothing) and frames.

use hil_bridge::convert::prior;
use hil_bridge::flight;
use hil_bridge::host::frames::{FRAME_PIXEL_M, generate_set};
use hil_bridge::host::runner::Workspace;
use nav_core::{DemPatch, NavConfig, Navigator, Tile};

#[test]
fn the_search_goes_first_with_a_prior_and_the_features_follow_when_it_fails() {
    let set = generate_set(6).expect("frame set");
    let tile = Tile::parse(&set.tile).expect("tile");
    let mut ws = Box::new(Workspace::new());
    let frame = |name: &str| {
        set.frames
            .iter()
            .find(|f| f.meta.name.starts_with(name))
            .unwrap_or_else(|| panic!("no frame {name}"))
    };
    let first = Navigator::new(tile, NavConfig::default());
    // Features first, without a work budget: the order as it was (this frame then cost 27.9 M
    // instructions on the target, session 28).
    let after = Navigator::new(
        tile,
        NavConfig {
            search_first: false,
            work_budget: u32::MAX,
            ..NavConfig::default()
        },
    );
    let after_flight = Navigator::new(
        tile,
        NavConfig {
            search_first: false,
            ..NavConfig::default()
        },
    );
    // A noisy frame (8 m of correlated height noise): a keypoint budget whose matches agree on
    // nothing, a slope the search still reads.
    let f = frame("noisy-02");
    let dem = DemPatch::new_checked(&f.heights_m, 200, 200, FRAME_PIXEL_M).unwrap();
    let p = prior(&f.meta.prior.expect("a prior"));
    let a = first.locate_dem(&mut ws, &dem, Some(&p)).unwrap();
    assert!(!a.detected && a.features == 0, "{a:?}");
    let fix_a = a.outcome.expect("a search fix");
    assert!(fix_a.area_search);
    // Features first under the flight work budget: after a whole keypoint budget no room is
    // left for the search, and the frame says so instead of overrunning.
    let bf = after_flight.locate_dem(&mut ws, &dem, Some(&p)).unwrap();
    assert!(bf.over_budget && bf.outcome.is_err(), "{bf:?}");
    assert_eq!(bf.search, Some(Err(nav_core::SearchError::OverBudget)));
    assert!(bf.work <= after_flight.config().work_budget, "{}", bf.work);
    let b = after.locate_dem(&mut ws, &dem, Some(&p)).unwrap();
    assert!(
        b.detected && b.features as usize == flight::MAX_KEYPOINTS,
        "{b:?}"
    );
    let fix_b = b.outcome.expect("a search fix after the feature path");
    assert!(fix_b.area_search);
    // The same hit and the same refinement: the same fix, whatever ran before it.
    assert_eq!(fix_a.center_tile_px, fix_b.center_tile_px);
    let t = f.meta.truth.expect("truth");
    let err = |c: [f64; 2]| (c[0] - t.center_tile_px[0]).hypot(c[1] - t.center_tile_px[1]);
    assert!(
        err(fix_a.center_tile_px) < 1.0,
        "{}",
        err(fix_a.center_tile_px)
    );
    // A prior whose window misses the frame (40 px off at σ 2.5 px): the search finds nothing
    // there, the features run, and what they make of it meets the prior gate or is refused.
    let off = nav_core::Prior {
        center_tile_px: [p.center_tile_px[0] + 40.0, p.center_tile_px[1]],
        ..p
    };
    let terrain = frame("terrain-00");
    let dem = DemPatch::new_checked(&terrain.heights_m, 200, 200, FRAME_PIXEL_M).unwrap();
    let c = first.locate_dem(&mut ws, &dem, Some(&off)).unwrap();
    assert!(c.detected && c.features > 0, "{c:?}");
    assert!(matches!(c.search, Some(Err(_))), "{:?}", c.search);
    assert!(c.outcome.is_err(), "{:?}", c.outcome);
    // Without a prior nothing changes: features only.
    let d = first.locate_dem(&mut ws, &dem, None).unwrap();
    assert!(
        d.detected && d.search.is_none() && d.outcome.is_ok(),
        "{d:?}"
    );
}
