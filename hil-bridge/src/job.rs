//! The frame jobs of a descent, as both ends run them: the firmware between its measurement
//! markers, the host runner for the bit-exact comparison. One function, so the two compare the
//! same computation.
//!
//! A frame is one of: TRN on the reference tile ([`FrameJob::Locate`]), a keyframe capture
//! ([`FrameJob::Keyframe`]), odometry on the held keyframe ([`FrameJob::Odometry`]) or the hazard
//! map and its decision for the aim ([`FrameJob::Hazard`]), or its confirmation over a window
//! around the chosen aim on a finer frame ([`FrameJob::Confirm`]). One job per frame keeps every frame
//! within the instruction budget: a keyframe capture (≈ 13.7 M) and a hazard map (7–15 M)
//! together would not be. The keyframe and the hazard map persist between frames in [`FinalPhase`].

use crate::flight::{HazardMap, Keyframe, Workspace};
use nav_core::atlas::{AtlasConfig, AtlasNavError, AtlasNavigator, AtlasReport, MappedAtlas};

/// The flight atlas as the target holds it: every tile parsed once at boot.
pub type Atlas<'a> = MappedAtlas<'a, { crate::flight::ATLAS_TILES }>;
use crate::msg::{FrameHeader, FrameJob};
use nav_core::frame::FrameError;
use nav_core::hazard::{AimDecision, HazardConfig, HazardError, HazardStats};
use nav_core::odometry::{KeyframePose, OdometryError, OdometryReport, locate_on_keyframe};
use nav_core::{DemPatch, FrameReport, NavError, Navigator};

/// What the final phase keeps between frames: the keyframe (≈ 25 KB) and the last hazard map
/// (≈ 20 KB). A `static` on the target.
pub struct FinalPhase {
    /// The keyframe odometry registers against.
    pub keyframe: Keyframe,
    /// The last hazard map.
    pub hazards: HazardMap,
}

impl Default for FinalPhase {
    fn default() -> Self {
        Self::new()
    }
}

impl FinalPhase {
    /// No keyframe, an empty map (`const`, so it can be a `static`).
    pub const fn new() -> Self {
        Self {
            keyframe: Keyframe::new(),
            hazards: HazardMap::new(),
        }
    }

    /// Size in bytes.
    pub const fn footprint_bytes() -> usize {
        core::mem::size_of::<Self>()
    }
}

/// Why an atlas job gave no report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AtlasJobError {
    /// No atlas is linked.
    NoAtlas,
    /// The frame came without the prior that picks the tile.
    NoPrior,
    /// The frame, the configuration or a tile.
    Nav(AtlasNavError),
}

/// What one frame's job gave (turned into a wire result by [`crate::convert::job_result`],
/// outside the measured window).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JobOutput {
    /// TRN on the reference tile.
    Locate(Result<FrameReport, NavError>),
    /// TRN on the flight atlas.
    AtlasLocate(Result<AtlasReport, AtlasJobError>),
    /// Keyframe capture.
    Keyframe(Result<(), OdometryError>),
    /// Odometry on the keyframe.
    Odometry(Result<OdometryReport, OdometryError>),
    /// The hazard map.
    Hazard(HazardOutcome),
}

/// What the hazard job made of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HazardOutcome {
    /// A map: its counts, and its decision for the aim.
    Map(HazardStats, AimDecision),
    /// The map refused the frame.
    Refused(HazardError),
    /// The frame itself is malformed.
    BadFrame(FrameError),
}

/// Run `header`'s job on the frame `heights_m` (row-major metres, NaN = no data) with the flight
/// navigator `nav` (its tile's SURF settings also make the keyframes), scratch `ws` and the
/// persistent state `fp`. Never panics; a malformed frame is a refusal in the output.
pub fn execute(
    nav: &Navigator<'_>,
    atlas: Option<&Atlas<'_>>,
    ws: &mut Workspace,
    fp: &mut FinalPhase,
    header: &FrameHeader,
    heights_m: &[f32],
) -> JobOutput {
    let dem = DemPatch::new_checked(
        heights_m,
        header.width as usize,
        header.height as usize,
        header.pixel_m,
    );
    let px = header.pixel_m as f64;
    let prior = header.prior.as_ref().map(crate::convert::prior);
    match (&dem, &header.job) {
        (Err(e), FrameJob::Locate) => JobOutput::Locate(Err(NavError::Frame(*e))),
        (Err(e), FrameJob::AtlasLocate) => JobOutput::AtlasLocate(Err(AtlasJobError::Nav(
            AtlasNavError::Nav(NavError::Frame(*e)),
        ))),
        (Err(e), FrameJob::Keyframe(_)) => JobOutput::Keyframe(Err(OdometryError::Frame(*e))),
        (Err(e), FrameJob::Odometry(_)) => JobOutput::Odometry(Err(OdometryError::Frame(*e))),
        (Err(e), FrameJob::Hazard(_) | FrameJob::Confirm(_)) => {
            JobOutput::Hazard(HazardOutcome::BadFrame(*e))
        }
        (Ok(d), FrameJob::Locate) => JobOutput::Locate(nav.locate_dem(ws, d, prior.as_ref())),
        (Ok(d), FrameJob::AtlasLocate) => JobOutput::AtlasLocate(match (atlas, prior.as_ref()) {
            (None, _) => Err(AtlasJobError::NoAtlas),
            (_, None) => Err(AtlasJobError::NoPrior),
            (Some(a), Some(p)) => {
                let an = AtlasNavigator::new(AtlasConfig {
                    nav: *nav.config(),
                    max_tiles_per_frame: crate::flight::ATLAS_TILES_PER_FRAME,
                });
                an.locate_dem(&mut &*a, ws, d, p)
                    .map_err(AtlasJobError::Nav)
            }
        }),
        (Ok(d), FrameJob::Keyframe(k)) => {
            let pose = KeyframePose {
                heading_rad: k.heading_rad,
                heading_sigma_rad: k.heading_sigma_rad,
                pixel_m: px,
                pixel_rel_sigma: k.pixel_rel_sigma,
            };
            let surf = nav.tile().header().surf_config();
            JobOutput::Keyframe(fp.keyframe.capture(ws, d, &pose, &surf))
        }
        (Ok(d), FrameJob::Odometry(o)) => {
            let c = o.offset_cov_m2;
            let r = fp
                .keyframe
                .prior(
                    o.offset_m,
                    [[c[0], c[1]], [c[2], c[3]]],
                    o.heading_rad,
                    o.heading_sigma_rad,
                    px,
                    o.pixel_rel_sigma,
                )
                .and_then(|p| locate_on_keyframe(&fp.keyframe, nav.config(), ws, d, &p));
            JobOutput::Odometry(r)
        }
        (Ok(d), FrameJob::Hazard(aim)) => {
            let cfg = HazardConfig::default();
            JobOutput::Hazard(match fp.hazards.build(d, &cfg) {
                Ok(stats) => {
                    HazardOutcome::Map(stats, fp.hazards.decide(aim.aim_px, aim.target_px, &cfg))
                }
                Err(e) => HazardOutcome::Refused(e),
            })
        }
        (Ok(d), FrameJob::Confirm(aim)) => JobOutput::Hazard(
            match fp.hazards.confirm(d, &HazardConfig::confirmation(), *aim) {
                Ok((stats, decision)) => HazardOutcome::Map(stats, decision),
                Err(e) => HazardOutcome::Refused(e),
            },
        ),
    }
}
