//! Conversions from nav-core's results to their wire mirrors. Every float is copied, never
//! recomputed, so the wire bytes of a result are a bit-exact image of the navigator's output.

use crate::job::{AtlasJobError, FinalPhase, HazardOutcome, JobOutput};
use crate::msg::{
    FrameResult, WireAimDecision, WireAtlas, WireFix, WireHazard, WireHazardError, WireHazardStats,
    WireKeyframe, WireMatchStats, WireNavError, WireNoFix, WireOffset, WireOutcome, WireSafeSite,
};
use nav_core::atlas::AtlasNavError;
use nav_core::frame::FrameError;
use nav_core::hazard::{AimDecision, HazardError, HazardStats};
use nav_core::odometry::{OdometryError, OffsetFix};
use nav_core::{FrameReport, NavError, NoFix, SurfError};

/// The wire form of one navigator call's result for frame `frame_id`.
pub fn frame_result(frame_id: u32, r: &Result<FrameReport, NavError>) -> FrameResult {
    match r {
        Ok(rep) => FrameResult {
            frame_id,
            outcome: match &rep.outcome {
                Ok(f) => WireOutcome::Fix(WireFix {
                    affine: f.affine.to_array(),
                    rotation_rad: f.similarity.rotation_rad,
                    scale: f.similarity.scale,
                    non_similar: f.similarity.non_similar,
                    center_tile_px: f.center_tile_px,
                    center_geo_m: f.center_geo_m,
                    heading_rad: f.heading_rad,
                    center_cov_tile_px2: flat(&f.center_cov_tile_px2),
                    center_cov_geo_m2: flat(&f.center_cov_geo_m2),
                    heading_sigma_rad: f.heading_sigma_rad,
                    scale_sigma: f.scale_sigma,
                    inliers: f.inliers,
                    residual_rms_px: f.residual_rms_px,
                    refined: f.refined,
                    area_search: f.area_search,
                }),
                Err(n) => WireOutcome::NoFix(no_fix(*n)),
            },
            features: rep.features,
            features_dropped: rep.features_dropped,
            matches: rep.matches,
            inliers: rep.inliers,
            msac_iterations: rep.msac_iterations,
            affine: rep.affine.map(|a| a.to_array()),
            match_stats: WireMatchStats {
                tile_candidates: rep.match_stats.tile_candidates,
                comparisons: rep.match_stats.comparisons,
                rejected_ratio: rep.match_stats.rejected_ratio,
                rejected_mutual: rep.match_stats.rejected_mutual,
                dropped: rep.match_stats.dropped,
            },
            offset: None,
            hazard: None,
            atlas: None,
        },
        Err(e) => refused(frame_id, nav_error(e)),
    }
}

/// A result for a frame the navigator never saw (refused before navigation).
pub fn refused(frame_id: u32, e: WireNavError) -> FrameResult {
    blank(frame_id, WireOutcome::Refused(e))
}

/// A result with `outcome` and every counter zero.
fn blank(frame_id: u32, outcome: WireOutcome) -> FrameResult {
    FrameResult {
        frame_id,
        outcome,
        features: 0,
        features_dropped: 0,
        matches: 0,
        inliers: 0,
        msac_iterations: 0,
        affine: None,
        match_stats: WireMatchStats::default(),
        offset: None,
        hazard: None,
        atlas: None,
    }
}

/// The wire result of a frame job ([`crate::job::execute`]) for frame `frame_id`; `fp` is the
/// state the job left (the keyframe's CRC and the map's clearances are digested here, outside
/// the measured window).
pub fn job_result(frame_id: u32, out: &JobOutput, fp: &FinalPhase) -> FrameResult {
    match out {
        JobOutput::Locate(r) => frame_result(frame_id, r),
        JobOutput::AtlasLocate(Ok(a)) => match &a.report {
            Some(rep) => FrameResult {
                atlas: a.tile.map(|tile| WireAtlas {
                    tile,
                    tile_offset_px: a.tile_offset_px,
                    candidates: a.candidates.count,
                    tried: a.tried,
                    straddles: a.candidates.straddles,
                }),
                ..frame_result(frame_id, &Ok(*rep))
            },
            None => refused(frame_id, WireNavError::OutsideAtlas),
        },
        JobOutput::AtlasLocate(Err(e)) => refused(
            frame_id,
            match e {
                AtlasJobError::Nav(AtlasNavError::Nav(n)) => nav_error(n),
                _ => WireNavError::Atlas,
            },
        ),
        JobOutput::Keyframe(Ok(())) => {
            let bytes = fp.keyframe.as_bytes();
            let features = fp.keyframe.tile().map_or(0, |t| t.len());
            let crc = nav_core::tile::stored_crc(bytes).unwrap_or(0);
            let features = features.min(u16::MAX as usize) as u16;
            FrameResult {
                features,
                ..blank(
                    frame_id,
                    WireOutcome::Keyframe(WireKeyframe {
                        features,
                        tile_bytes: bytes.len() as u32,
                        tile_crc: crc,
                    }),
                )
            }
        }
        JobOutput::Keyframe(Err(e)) => refused(frame_id, odometry_error(e)),
        JobOutput::Odometry(Ok(o)) => FrameResult {
            offset: o.offset.as_ref().map(offset),
            ..frame_result(frame_id, &Ok(o.report))
        },
        JobOutput::Odometry(Err(e)) => refused(frame_id, odometry_error(e)),
        JobOutput::Hazard(HazardOutcome::BadFrame(e)) => {
            refused(frame_id, nav_error(&NavError::Frame(*e)))
        }
        JobOutput::Hazard(HazardOutcome::Map(stats, decision)) => FrameResult {
            hazard: Some(hazard_map(stats, decision, fp)),
            ..blank(frame_id, WireOutcome::Hazard)
        },
        JobOutput::Hazard(HazardOutcome::Refused(e)) => FrameResult {
            hazard: Some(WireHazard::Refused(match e {
                HazardError::BadConfig => WireHazardError::BadConfig,
                HazardError::TooCoarse => WireHazardError::TooCoarse,
                HazardError::TooFine => WireHazardError::TooFine,
                HazardError::TooSmall => WireHazardError::TooSmall,
                HazardError::TooManySites { .. } => WireHazardError::TooManySites,
                HazardError::WindowOutside => WireHazardError::WindowOutside,
            })),
            ..blank(frame_id, WireOutcome::Hazard)
        },
    }
}

/// The map's counts, a CRC of every site's clearance, and the decision.
fn hazard_map(stats: &HazardStats, decision: &AimDecision, fp: &FinalPhase) -> WireHazard {
    let (cols, rows) = fp.hazards.size();
    let mut digest = crate::packet::CRC32.digest();
    for j in 0..rows {
        for i in 0..cols {
            digest.update(&fp.hazards.clearance_m(i, j).to_le_bytes());
        }
    }
    WireHazard::Map(
        WireHazardStats {
            sites: stats.sites,
            safe: stats.safe,
            too_steep: stats.too_steep,
            too_rough: stats.too_rough,
            no_data: stats.no_data,
            cols: cols.min(u16::MAX as usize) as u16,
            rows: rows.min(u16::MAX as usize) as u16,
            clearance_crc: digest.finalize(),
        },
        match decision {
            AimDecision::Keep { clearance_m } => WireAimDecision::Keep(*clearance_m),
            AimDecision::Move(s) => WireAimDecision::Move(WireSafeSite {
                frame_px: s.frame_px,
                clearance_m: s.clearance_m,
                from_target_m: s.from_target_m,
            }),
            AimDecision::NoSite => WireAimDecision::NoSite,
        },
    )
}

fn offset(o: &OffsetFix) -> WireOffset {
    WireOffset {
        east_m: o.east_m,
        north_m: o.north_m,
        cov_m2: flat(&o.cov_m2),
        footprint_m: o.footprint_m,
        rotation_rad: o.rotation_rad,
        scale: o.scale,
    }
}

/// Wire form of a keyframe or odometry refusal.
pub fn odometry_error(e: &OdometryError) -> WireNavError {
    match e {
        OdometryError::Frame(f) => nav_error(&NavError::Frame(*f)),
        OdometryError::Surf(s) => nav_error(&NavError::Surf(*s)),
        OdometryError::Tile(_) => WireNavError::KeyframeTile,
        OdometryError::NoKeyframe => WireNavError::NoKeyframe,
        OdometryError::BadPose => WireNavError::BadPose,
    }
}

fn flat(m: &[[f64; 2]; 2]) -> [f64; 4] {
    [m[0][0], m[0][1], m[1][0], m[1][1]]
}

/// Wire form of a no-fix reason.
pub fn no_fix(n: NoFix) -> WireNoFix {
    match n {
        NoFix::TooFewFeatures => WireNoFix::TooFewFeatures,
        NoFix::TooFewMatches => WireNoFix::TooFewMatches,
        NoFix::TooFewInliers => WireNoFix::TooFewInliers,
        NoFix::DegenerateGeometry => WireNoFix::DegenerateGeometry,
        NoFix::NonSimilar => WireNoFix::NonSimilar,
        NoFix::ScaleOutOfRange => WireNoFix::ScaleOutOfRange,
        NoFix::ResidualTooLarge => WireNoFix::ResidualTooLarge,
        NoFix::InconsistentWithPrior => WireNoFix::InconsistentWithPrior,
        NoFix::Unconfirmed => WireNoFix::Unconfirmed,
        NoFix::OverBudget => WireNoFix::OverBudget,
    }
}

/// Wire form of a navigator refusal.
pub fn nav_error(e: &NavError) -> WireNavError {
    let frame = |f: &FrameError| match f {
        FrameError::Empty => WireNavError::Empty,
        FrameError::SizeMismatch { .. } => WireNavError::SizeMismatch,
        FrameError::TooLarge { .. } => WireNavError::TooLarge,
        FrameError::BadPixelSize => WireNavError::BadPixelSize,
    };
    match e {
        NavError::Frame(f) | NavError::Surf(SurfError::Frame(f)) => frame(f),
        NavError::Surf(SurfError::Config(_)) => WireNavError::SurfConfig,
    }
}

/// The prior the navigator gets from a wire prior.
pub fn prior(p: &crate::msg::WirePrior) -> nav_core::Prior {
    nav_core::Prior {
        center_tile_px: p.center_tile_px,
        sigma_px: p.sigma_px,
        heading_rad: p.heading_rad,
        heading_sigma_rad: p.heading_sigma_rad,
        scale: p.scale,
        scale_sigma: p.scale_sigma,
    }
}
