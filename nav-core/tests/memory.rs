//! Memory for one 256 × 256 frame: slope frame + integral image + response ring + keypoints.
//! Sizes come from `size_of`, so they are exact and the same on every run.

use nav_core::{Features, NavWorkspace, SlopeBuffer, SurfWorkspace};

/// Largest frame side the flight configuration supports.
const SIDE: usize = 256;
/// Keypoint budget per frame in the flight configuration.
const KEYPOINTS: usize = 256;

#[test]
fn memory_for_a_256_frame_fits_512_kib() {
    let slope = size_of::<SlopeBuffer<{ SIDE * SIDE }>>();
    let workspace = SurfWorkspace::<{ SIDE * SIDE }, SIDE>::footprint_bytes();
    let features = Features::<KEYPOINTS>::footprint_bytes();
    let total = slope + workspace + features;
    println!("slope frame      {slope:>7} B");
    println!(
        "SURF workspace   {workspace:>7} B (integral {} B + response ring {} B)",
        4 * SIDE * SIDE,
        workspace - 4 * SIDE * SIDE
    );
    println!("features ({KEYPOINTS})   {features:>7} B");
    println!(
        "total            {total:>7} B = {:.1} KiB",
        total as f64 / 1024.0
    );
    assert!(total <= 512 * 1024, "{total} B exceeds 512 KiB");
}

#[test]
fn navigator_workspace_for_a_256_frame() {
    // Slope buffer + SURF workspace + 256 features + 128 matches with their correspondences.
    let ws = NavWorkspace::<{ SIDE * SIDE }, SIDE, KEYPOINTS, 128>::footprint_bytes();
    println!(
        "NavWorkspace<256x256, 256 keypoints, 128 matches> {ws} B = {:.1} KiB",
        ws as f64 / 1024.0
    );
    assert!(ws <= 512 * 1024, "{ws} B exceeds 512 KiB");
}

#[test]
fn the_final_phase_fits_beside_the_flight_workspace() {
    use nav_core::flight::{HazardMap, Keyframe, MAX_FRAME_PX, Workspace};
    // What the firmware holds for a frame near the ground: the heights it receives, the
    // navigator's workspace, the keyframe the frame is located on and the hazard map.
    let heights = 4 * MAX_FRAME_PX;
    let ws = Workspace::footprint_bytes();
    let key = Keyframe::footprint_bytes();
    let hazard = HazardMap::footprint_bytes();
    let total = heights + ws + key + hazard;
    println!("frame heights    {heights:>7} B");
    println!("flight workspace {ws:>7} B");
    println!("keyframe         {key:>7} B");
    println!("hazard map       {hazard:>7} B");
    println!(
        "total            {total:>7} B = {:.1} KiB",
        total as f64 / 1024.0
    );
    assert!(total <= 512 * 1024, "{total} B exceeds 512 KiB");
}
