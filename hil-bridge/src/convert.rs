//! Conversions from nav-core's results to their wire mirrors. Every float is copied, never
//! recomputed, so the wire bytes of a result are a bit-exact image of the navigator's output.

use crate::msg::{FrameResult, WireFix, WireMatchStats, WireNavError, WireNoFix, WireOutcome};
use nav_core::frame::FrameError;
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
        },
        Err(e) => refused(frame_id, nav_error(e)),
    }
}

/// A result for a frame the navigator never saw (refused before navigation).
pub fn refused(frame_id: u32, e: WireNavError) -> FrameResult {
    FrameResult {
        frame_id,
        outcome: WireOutcome::Refused(e),
        features: 0,
        features_dropped: 0,
        matches: 0,
        inliers: 0,
        msac_iterations: 0,
        affine: None,
        match_stats: WireMatchStats::default(),
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
