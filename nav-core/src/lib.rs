//! # nav-core — Umbra's flight software
//!
//! Terrain-relative navigation for a lunar flyer inside permanently shadowed craters, where no
//! camera sees anything: the flyer's own DEM patch (from its ranging sensor) is turned into a
//! slope image and matched against a reference tile of SURF features precomputed on the ground
//! from a simulated InSAR DEM (Liu & Jin, IEEE JSTARS 2023).
//!
//! ## Pipeline (per frame)
//!
//! 1. [`frame::DemPatch`] (heights, m) → [`slope::slope_into`] (Horn 3×3, fixed-point degrees).
//! 2. [`integral::Integral`]: `u32` integral image with exact box sums.
//! 3. [`detector`]: fast-Hessian keypoints, 3×3×3 non-maximum suppression, sub-pixel and
//!    sub-scale Newton refinement.
//! 4. [`describe`]: orientation (sliding 60° window) and 64-d descriptor.
//! 5. [`surf::extract`] ties these together and keeps the `N` strongest keypoints.
//! 6. [`matching`]: exhaustive SSD against the reference [`tile::Tile`] (Laplacian-sign gate,
//!    distance threshold, ratio test, mutual check).
//! 7. [`msac`]: 3-point affine MSAC with a seeded PRNG and a fixed iteration budget, then
//!    least-squares affine on the inliers (eq 18).
//! 8. [`pose`]: rotation and scale (eq 19), position in tile pixels and geo metres, covariance,
//!    and the quality gate (`Fix` or a typed [`pose::NoFix`]).
//! 9. [`refine`]: the fix aligned over every frame pixel (on a sample grid) to the tile's
//!    reference slope raster (Gauss–Newton, similarity and photometric gain/offset); thin
//!    consensus confirmed, contradicted fixes refused.
//! 10. [`navigator::Navigator`]: one call per frame with a caller-owned [`navigator::NavWorkspace`].
//! 11. [`filter::NavFilter`]: error-state Kalman filter fusing IMU propagation with the fixes.
//! 12. [`odometry`]: below the tile's reach, frames located on a keyframe (an earlier frame of
//!     the flyer's own, turned into a tile in RAM) with the same navigator; the displacement
//!     goes to the filter as a relative measurement against its cloned keyframe position.
//! 13. [`atlas`]: the reference of a whole corridor as bounded tiles plus an index; the tile
//!     under the prior is selected (neighbours tried when a frame straddles a tile edge).
//! 14. [`hazard`]: near the ground, a hazard map of a frame (plane tilt and relief over the
//!     lander's footprint, clearance to the nearest hazard) and the safe site nearest the target.
//!
//! ## Rules this crate keeps
//!
//! * `#![no_std]`, no `alloc`: every buffer is caller-owned with a const-generic or caller-given
//!   capacity ([`surf::SurfWorkspace`], [`frame::SlopeBuffer`], [`surf::Features`]).
//! * No panic on any input: malformed frames and configurations give typed errors.
//! * Deterministic and bit-identical across targets: integer box sums, `f32` in a fixed order,
//!   `libm` for transcendental functions, bounded loops.
//! * Conventions: `x` = column (right), `y` = row (down), pixel centres at integer coordinates;
//!   slope in degrees, lengths in metres or pixels as named.
//!
//! ## Features
//!
//! * `defmt`: derive `defmt::Format` on public types.
//!
//! Memory bounds for each buffer are tabulated in `docs/bounds.md`.

#![no_std]
#![forbid(unsafe_code)]
// Flight code must not hide panics behind these.
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]

#[cfg(test)]
extern crate std;

pub mod atlas;
pub mod cost;
pub mod describe;
pub mod detector;
pub mod filter;
pub mod flight;
pub mod frame;
pub mod hazard;
pub mod integral;
pub mod matching;
pub mod msac;
pub mod navigator;
pub mod odometry;
pub mod pose;
pub mod refine;
pub mod rng;
pub mod search;
pub mod slope;
pub mod surf;
pub mod tile;

pub use describe::{DESCRIPTOR_LEN, Descriptor};
pub use detector::{DetectorConfig, Keypoint};
pub use frame::{DemPatch, FrameError, SLOPE_NODATA, SlopeBuffer, SlopeImage, SlopePx};
pub use matching::{Match, MatchConfig};
pub use msac::{Affine, MsacConfig};
pub use navigator::{FrameReport, NavConfig, NavError, NavWorkspace, Navigator, Prior};
pub use pose::{Fix, GateConfig, NoFix};
pub use search::{SearchConfig, SearchError, SearchHit};
pub use surf::{Feature, Features, SurfConfig, SurfError, SurfWorkspace, extract};
pub use tile::{Tile, TileError, TileHeader};
