//! The flight configuration: the frame and keypoint budgets the firmware is built with. The
//! firmware sizes its buffers with these constants, the HIL host runner builds the identical
//! workspace, and the ground segment's campaigns (`eval`, `suite`, `descent`, `results`) use it
//! by default, so every published figure measures what flies. One place, so they never drift.

use crate::NavWorkspace;

/// Widest frame the firmware accepts, pixels.
pub const MAX_FRAME_WIDTH: usize = 200;
/// Largest frame the firmware accepts, pixels (200 × 200).
pub const MAX_FRAME_PX: usize = MAX_FRAME_WIDTH * 200;
/// Frame keypoint budget on the target: the strongest keypoints are kept, the rest counted in
/// `features_dropped`.
///
/// **A trade-off for the instruction budget** (see `docs/bounds.md`, firmware section): each kept
/// keypoint costs ≈ 0.13 M instructions to describe and ≈ 0.05 M to match against a 300-feature
/// tile, on top of ≈ 9.5 M per frame for slope and detection (≈ 12 M until session 41, when the
/// detector's lazy layers took 2.3–2.7 M off every frame that detects). 24 since session 41
/// (16 before): on the terrain suite's InSAR tiles without a prior (seeds 1 and 2, 5 400
/// frames), 24 keypoints fix 3 637 frames, 16 fixed 3 482 with lazy layers (3 454 before them)
/// and 32 fix 3 478 (the 20 M budget then cuts their refinements); no false fix in any
/// (docs/registration.md, "Lazy layers, 24 keypoints").
pub const MAX_KEYPOINTS: usize = 24;
/// Putative-match budget per frame.
pub const MAX_MATCHES: usize = 128;

/// The navigator workspace of the flight configuration (≈ 0.3 MB; a `static` on the target).
pub type Workspace = NavWorkspace<MAX_FRAME_PX, MAX_FRAME_WIDTH, MAX_KEYPOINTS, MAX_MATCHES>;

/// Bytes of the flight keyframe (one 200 × 200 px frame binned by 2, its keypoints, header and
/// CRC): [`crate::odometry::keyframe_bytes`].
pub const KEYFRAME_BYTES: usize = crate::odometry::keyframe_bytes(MAX_FRAME_PX, MAX_KEYPOINTS);

/// The keyframe of the flight configuration (≈ 25 KB; a `static` on the target).
pub type Keyframe = crate::odometry::Keyframe<KEYFRAME_BYTES>;

/// Sites of the flight hazard map: a 200 px frame at 0.4 m pixels and 1 m site spacing needs
/// about 64² (a site every 3 pixels); 100² leaves room down to 0.5 m site spacing.
pub const MAX_HAZARD_SITES: usize = 100 * 100;

/// The hazard map of the flight configuration (20 KB).
pub type HazardMap = crate::hazard::HazardMap<MAX_HAZARD_SITES>;

/// Tiles of the flight atlas the target keeps parsed ([`crate::atlas::MappedAtlas`]): a 16 km
/// corridor in 4 km cores. ≈ 0.2 KB of RAM per tile handle; the tiles stay in flash.
pub const ATLAS_TILES: usize = 16;

/// Most atlas tiles one frame is located on ([`crate::atlas::AtlasConfig::max_tiles_per_frame`]):
/// the deepest tile, then one neighbour when the frame straddles a tile edge and the first gave
/// no fix. The neighbour's try reuses the frame's extraction and skips the area search, so it
/// costs matching, consensus and refinement only (docs/bounds.md, atlas frames).
pub const ATLAS_TILES_PER_FRAME: u8 = 2;
