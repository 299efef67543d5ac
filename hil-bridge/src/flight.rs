//! The flight configuration both ends use, defined once in [`nav_core::flight`]: the firmware
//! sizes its buffers with these constants and the host runner builds the identical navigator
//! workspace, keyframe and hazard map, so "bit-exact" compares the same computation.

pub use nav_core::flight::{
    ATLAS_TILES, ATLAS_TILES_PER_FRAME, HazardMap, Keyframe, MAX_FRAME_PX, MAX_FRAME_WIDTH,
    MAX_KEYPOINTS, MAX_MATCHES, Workspace,
};
