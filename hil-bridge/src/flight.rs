//! The flight configuration both ends use: the firmware sizes its buffers with these constants
//! and the host runner builds the identical navigator workspace, so "bit-exact" compares the same
//! computation. One place, so the two can never drift apart.

use nav_core::NavWorkspace;

/// Widest frame the firmware accepts, pixels.
pub const MAX_FRAME_WIDTH: usize = 200;
/// Largest frame the firmware accepts, pixels (200 × 200).
pub const MAX_FRAME_PX: usize = MAX_FRAME_WIDTH * 200;
/// Frame keypoint budget on the target: the strongest keypoints are kept, the rest counted in
/// `features_dropped`.
///
/// **A trade-off for the instruction budget** (see `docs/bounds.md`, firmware section): each kept
/// keypoint costs ≈ 0.13 M instructions to describe and ≈ 0.08 M to match against the
/// 457-feature tile, on top of ≈ 11–17 M per frame for slope and detection. Measured worst case
/// over the recorded set: 19.05 M at 16, 19.85 M at 20, 21.1 M at 24, 22.6 M at 32, 67.6 M at 256
/// keypoints. At 16 the terrain frames keep the same fixes as at 256 (12 of 18) with 0–3 fewer
/// inliers; the registration tests on the host keep using 256.
pub const MAX_KEYPOINTS: usize = 16;
/// Putative-match budget per frame.
pub const MAX_MATCHES: usize = 128;

/// The navigator workspace of the flight configuration (≈ 0.3 MB; a `static` on the target).
pub type Workspace = NavWorkspace<MAX_FRAME_PX, MAX_FRAME_WIDTH, MAX_KEYPOINTS, MAX_MATCHES>;
