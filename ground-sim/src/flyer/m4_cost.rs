//! Estimated Cortex-M4 instructions of one TRN frame (`Navigator::locate_dem`), from what its
//! report says the navigator did. Ground campaigns run nav-core on the host, where time says
//! little about the flyer; this model says which of their frames would overrun the flyer's
//! per-frame budget. Its constants come from HIL profiles under QEMU (the TCG plugin's
//! per-block counts, session 28: 200 × 200 frames binned to 100 × 100, 50 m smoothing), and
//! every HIL run compares it with the measured count of each TRN frame (`hil-bridge`, the
//! `estimated_instructions` of its report), so a change of nav-core's costs that the model
//! misses shows there.
//!
//! Upper-leaning where the report does not say: a search that failed is charged its whole
//! coarse lattice and (unless no cell had enough valid reference) its fine level, a refused
//! refinement its sample cap times its pass cap (`FrameReport::refine_sample_passes`).

use nav_core::{FrameReport, Navigator, SearchError};

/// The flyer's budget per frame, instructions (issue 15; asserted by the HIL run).
pub const FLIGHT_BUDGET: u64 = 20_000_000;
/// Slope, 50 m smoothing and detection, per binned frame pixel, for a frame with relief (10.93
/// M for a featureless 100 × 100 binned frame, about 1.2 M more where the detector finds
/// maxima to examine).
pub const PER_BINNED_PX: u64 = 1_220;
/// Binning, 50 m smoothing and slope alone, per binned frame pixel: a frame the area search
/// fixed before any detection (`FrameReport::detected` false; 5.35 M for 100 × 100).
pub const SLOPE_PER_BINNED_PX: u64 = 560;
/// Per frame keypoint kept: its sub-pixel refinement in the detector, orientation, descriptor
/// and matching (16 keypoints against 1 on the same frame class: +3.3 M; 0.24 M fits the
/// set's terrain frames).
pub const PER_KEYPOINT: u64 = 240_000;
/// Bounds of estimate / measured that every HIL TRN frame on the tile must meet (session 28:
/// 0.94–1.16 over 31 frames; the featureless stress frames are overestimated).
pub const HIL_RATIO_BOUNDS: (f64, f64) = (0.90, 1.20);
/// MSAC per sample drawn (the minimal solve, `f64`, software on the M4).
pub const MSAC_PER_SAMPLE: u64 = 700;
/// MSAC per correspondence scored (`f32`).
pub const MSAC_PER_POINT: u64 = 30;
/// Area search per coarse lattice cell (49 samples, ≈ 28 instructions each).
pub const SEARCH_PER_COARSE_CELL: u64 = 1_400;
/// Area search: fine level of the winner and the runners, climbs and valley paths.
pub const SEARCH_FINE: u64 = 2_300_000;
/// Dense refinement per sample and pass (the pass' sums, its `f64` row flushes and normal
/// equations: 0.57 M a pass of 800 samples).
pub const REFINE_PER_SAMPLE_PASS: u64 = 715;

/// Estimated instructions of `nav`'s work on a `frame_w × frame_h` DEM frame of
/// `frame_pixel_m` metres, from the `report` it gave (binned as `nav` bins it; its MSAC
/// settings).
pub fn estimate(
    report: &FrameReport,
    nav: &Navigator<'_>,
    (frame_w, frame_h): (usize, usize),
    frame_pixel_m: f32,
) -> u64 {
    let cfg = nav.config();
    let k = nav.bin_factor(frame_pixel_m).max(1);
    let binned_px = (frame_w / k) * (frame_h / k);
    let per_px = if report.detected {
        PER_BINNED_PX
    } else {
        SLOPE_PER_BINNED_PX
    };
    let mut n = per_px * binned_px as u64 + PER_KEYPOINT * report.features as u64;
    // MSAC: what it drew, or, where it gave nothing back, what matches that agree on nothing
    // cost it (the adaptive stop at a best consensus of 2 of n, within the sample cap).
    let m = report.matches as u64;
    if m >= 3 {
        let samples = if report.msac_iterations > 0 {
            report.msac_iterations as u64
        } else {
            let w = 2.0 / m as f64;
            let need = (1.0 - cfg.msac.confidence as f64).ln() / (1.0 - w * w).ln();
            (need.ceil().max(1.0) as u64).min(cfg.msac.max_iterations as u64)
        };
        n += samples * (MSAC_PER_SAMPLE + MSAC_PER_POINT * m);
    }
    let full_lattice = (nav_core::search::MAX_OFFSETS.pow(2)
        * nav_core::search::MAX_HEADINGS
        * nav_core::search::MAX_SCALES) as u64;
    n += match &report.search {
        None => 0,
        Some(Ok(hit)) => SEARCH_PER_COARSE_CELL * hit.coarse_cells as u64 + SEARCH_FINE,
        Some(Err(
            SearchError::Disabled
            | SearchError::NoRaster
            | SearchError::PriorTooWide
            | SearchError::FlatFrame,
        )) => 0,
        // No cell with enough valid reference: the coarse lattice ran, nothing after it.
        Some(Err(SearchError::NoCandidate)) => SEARCH_PER_COARSE_CELL * full_lattice,
        Some(Err(_)) => SEARCH_PER_COARSE_CELL * full_lattice + SEARCH_FINE,
    };
    // Every refinement the frame ran (a search hit's and a feature fix's), as the navigator
    // counted it.
    n + REFINE_PER_SAMPLE_PASS * report.refine_sample_passes as u64
}
