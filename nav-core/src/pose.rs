//! From the affine map to a navigation fix: rotation and scale (eq 19) by polar decomposition,
//! position in tile pixels and geo metres, covariance from the residuals, and the quality gate.

use crate::msac::{Affine, MsacResult};
use crate::tile::TileHeader;
use core::fmt;

/// Rotation and scale of an affine map's linear part.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Similarity {
    /// Rotation φ of eq 19, radians in (−π, π]: the frame's +x axis points along φ in tile
    /// pixel axes (from tile +x towards tile +y).
    pub rotation_rad: f64,
    /// Scale s of eq 19: tile pixels per frame pixel.
    pub scale: f64,
    /// How far the linear part is from a similarity: ‖A − s·R(φ)‖_F / (s·√2), 0 for a pure
    /// similarity. Shear or anisotropic scale shows here.
    pub non_similar: f64,
}

/// Closest rotation·scale to the linear part of `a` (the polar decomposition's rotation for a
/// 2 × 2 map with positive determinant; for a reflection the rotation of the nearest similarity).
pub fn similarity(a: &Affine) -> Similarity {
    let c = 0.5 * (a.m1 + a.n2);
    let s = 0.5 * (a.m2 - a.n1);
    let scale = libm::hypot(c, s);
    let rotation_rad = libm::atan2(s, c);
    let (dm1, dn1, dm2, dn2) = (a.m1 - c, a.n1 + s, a.m2 - s, a.n2 - c);
    let resid = libm::sqrt(dm1 * dm1 + dn1 * dn1 + dm2 * dm2 + dn2 * dn2);
    let non_similar = if scale > 0.0 {
        resid / (scale * core::f64::consts::SQRT_2)
    } else {
        f64::INFINITY
    };
    Similarity {
        rotation_rad,
        scale,
        non_similar,
    }
}

/// Gate settings: when a transform is good enough to be a fix.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GateConfig {
    /// Fewest putative matches worth running MSAC on.
    pub min_matches: u16,
    /// Fewest inliers for a fix. Three points always fit an affine exactly, so a fix needs
    /// redundancy: the default asks for 6.
    pub min_inliers: u16,
    /// Largest RMS transfer error of the inliers, tile pixels.
    pub max_residual_rms_px: f32,
    /// Largest [`Similarity::non_similar`]: the flyer's map is a similarity up to sensor
    /// distortion; a strongly sheared affine means a wrong consensus.
    pub max_non_similar: f32,
    /// Accepted scale range, tile pixels per frame pixel.
    pub scale_min: f32,
    /// Accepted scale range, tile pixels per frame pixel.
    pub scale_max: f32,
    /// Largest relative gap between the scale of a feature fix that stands unrefined and the
    /// scale the frame's own pixel size implies ([`crate::refine::FrameInfo::scale`]), when the
    /// frame states one. The ranging sensor grids its frame in metres to about 0.5 %
    /// ([`crate::refine::RefineConfig::frame_scale_sigma`]), so such a fix 10 % off is a wrong
    /// one. Why: the refinement, which pulls the scale to the frame's, cannot run where the
    /// reference under the frame is mostly invalid, and such a fix stood on its features alone:
    /// over the Shackleton wall's 128 m-baseline map (terrain seed 1) 9 inliers on layover
    /// streaks gave scale 0.41 for 0.51, heading 20° and position 490 m off. Not applied to
    /// feature fixes the refinement goes on to refine: on the suite two thin consensus more
    /// than 10 % off in scale were right in position, and refined to good fixes.
    pub max_scale_error: f32,
    /// Fewest inliers for a fix that the dense refinement confirms ([`crate::refine`]: applied,
    /// with a correlation of at least `verify_min_ncc`). Between this and `min_inliers`, or
    /// with inliers too clustered for `min_inlier_spread_px`, the feature consensus alone is
    /// too thin to trust; a frame-wide slope correlation is not. 0 (or a tile without a slope
    /// raster) disables it.
    pub min_inliers_verified: u16,
    /// Smallest refined correlation that confirms a fix of fewer than `min_inliers` inliers.
    pub verify_min_ncc: f32,
    /// Refuse any feature fix the dense refinement contradicts: it converged to a correlation
    /// below `verify_min_ncc`, correlated worse than the feature fix, or slid away from it.
    /// True alignments of cratered terrain correlate at 0.9–0.97 (truth and InSAR tiles), wrong
    /// ones at ≤ 0.15; a false fix is worse than no fix. (An InSAR map of smooth plains
    /// correlates lower at the truth, 0.6–0.7; the area search confirms its hits at its own
    /// `SearchConfig::confirm_min_ncc`.)
    pub reject_contradicted: bool,
    /// Smallest spread of the inliers in the frame: the square root of the smaller eigenvalue of
    /// their covariance, frame pixels. Clustered or collinear inliers constrain rotation poorly.
    pub min_inlier_spread_px: f32,
}

impl Default for GateConfig {
    fn default() -> Self {
        Self {
            // Three matches can hold the thin consensus that the dense refinement confirms
            // (`min_inliers_verified`); 5 refused frames of 3–4 matches before MSAC, 106 of
            // the 249 failing frames of the smooth fresh-crater floor (seed 1, truth tile;
            // docs/registration.md, "MSAC's inlier threshold and the fewest matches"). It also
            // sets the fewest frame features and guided matches, and which atlas frames try a
            // neighbour tile.
            min_matches: 3,
            min_inliers: 6,
            min_inliers_verified: 3,
            verify_min_ncc: 0.7,
            reject_contradicted: true,
            // MSAC's default inlier threshold, so that it refuses no consensus of inliers alone:
            // left at 1.5 px under a 2.5 px threshold it refused 14 right consensus of the
            // suite's 16 200 frames (seeds 1–3, no prior) and no wrong one.
            max_residual_rms_px: crate::msac::MsacConfig::default().threshold_px,
            max_non_similar: 0.08,
            scale_min: 0.2,
            scale_max: 2.0,
            max_scale_error: 0.1,
            min_inlier_spread_px: 8.0,
        }
    }
}

/// Why a frame gave no fix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NoFix {
    /// The frame gave fewer features than `min_matches`.
    TooFewFeatures,
    /// Fewer putative matches than `min_matches`.
    TooFewMatches,
    /// MSAC found no consensus of at least `min_inliers`.
    TooFewInliers,
    /// Inliers collinear or clustered (spread below `min_inlier_spread_px`).
    DegenerateGeometry,
    /// The affine is far from a similarity.
    NonSimilar,
    /// Scale outside `scale_min..=scale_max`, or (a fix left unrefined) more than
    /// `max_scale_error` from the scale the frame's pixel size implies.
    ScaleOutOfRange,
    /// RMS residual above `max_residual_rms_px`.
    ResidualTooLarge,
    /// The fix disagrees with the prior beyond its gate.
    InconsistentWithPrior,
    /// The dense slope correlation did not back the fix: a thin consensus (fewer than
    /// `min_inliers`) it did not confirm, or (with `reject_contradicted`) a fix it contradicted.
    Unconfirmed,
    /// The frame's work budget ([`crate::NavConfig::work_budget`]) had no room for the stage
    /// that could have fixed it (the feature path after a failed area search, or MSAC) or for
    /// the refinement that checks a feature fix (an unchecked fix does not stand).
    OverBudget,
}

impl fmt::Display for NoFix {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::TooFewFeatures => "too few features in the frame",
            Self::TooFewMatches => "too few matches",
            Self::TooFewInliers => "no consensus: too few inliers",
            Self::DegenerateGeometry => "inliers collinear or clustered",
            Self::NonSimilar => "transform far from a similarity",
            Self::ScaleOutOfRange => "scale out of range",
            Self::ResidualTooLarge => "residual too large",
            Self::InconsistentWithPrior => "fix inconsistent with the prior",
            Self::Unconfirmed => "not confirmed by the slope correlation",
            Self::OverBudget => "no room left in the frame's work budget",
        })
    }
}

/// A navigation fix.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Fix {
    /// Frame pixels → tile pixels.
    pub affine: Affine,
    /// Rotation φ and scale s of the fitted transform; `non_similar` is that of the
    /// least-squares affine on the same inliers (eq 18).
    pub similarity: Similarity,
    /// Frame centre in tile pixels `[x, y]`.
    pub center_tile_px: [f64; 2],
    /// Frame centre in geo metres `[x, y]` (the tile's projection).
    pub center_geo_m: [f64; 2],
    /// Heading: direction of the frame's +x axis in tile pixel axes, radians in [0, 2π) (same
    /// angle as `similarity.rotation_rad`, wrapped).
    pub heading_rad: f64,
    /// Covariance of `center_tile_px`, tile pixels² (row-major 2 × 2).
    pub center_cov_tile_px2: [[f64; 2]; 2],
    /// Covariance of `center_geo_m`, m² (row-major 2 × 2).
    pub center_cov_geo_m2: [[f64; 2]; 2],
    /// Standard deviation of the heading, radians.
    pub heading_sigma_rad: f64,
    /// Standard deviation of the scale.
    pub scale_sigma: f64,
    /// Inliers used.
    pub inliers: u16,
    /// RMS transfer error of the inliers, tile pixels.
    pub residual_rms_px: f64,
    /// Whether `affine` (and everything derived from it) comes from the dense refinement over
    /// the frame's pixels ([`crate::refine`]) rather than from the feature inliers alone. A
    /// refined fix's covariances are the refinement's (inflated for correlated residuals) plus
    /// the tile's reference error; an unrefined one's come from a handful of inlier residuals
    /// and are the less trustworthy (`docs/registration.md`, Covariance).
    pub refined: bool,
    /// The fix comes from the prior-aided area search ([`crate::search`]) and its refinement,
    /// not from feature matches: `inliers` and `residual_rms_px` are 0, and the covariances
    /// are the refinement's own ([`crate::refine::Refined::center_cov_tile_px2`]).
    pub area_search: bool,
    /// The tile's height-noise power ([`TileHeader::noise_power_m4`]), m⁴: with the frame's
    /// own, it says how much of this fix's error successive fixes of the same ground share
    /// (`filter::map_noise_share`). 0 on a map that claims no noise.
    pub map_noise_power_m4: f64,
}

impl Fix {
    /// The same fix with a refined transform: position, heading, rotation, scale and their
    /// covariances follow the refinement (plus the tile's reference error); the gate figures
    /// (`non_similar`, residual, inliers) stay those of the feature fix.
    pub fn with_refinement(
        &self,
        r: &crate::refine::Refined,
        header: &TileHeader<'_>,
        frame_w: usize,
        frame_h: usize,
    ) -> Self {
        let affine = r.affine;
        let sim = similarity(&affine);

        let (cx, cy) = ((frame_w as f64 - 1.0) * 0.5, (frame_h as f64 - 1.0) * 0.5);
        let (tx, ty) = affine.apply(cx, cy);
        let (gx, gy) = header.pixel_to_geo(tx, ty);
        let mut heading = sim.rotation_rad;
        if heading < 0.0 {
            heading += core::f64::consts::TAU;
        }
        let (cov_px, cov_m) = with_reference_error(r.center_cov_tile_px2, header);
        Self {
            affine,
            similarity: Similarity {
                non_similar: self.similarity.non_similar,
                ..sim
            },
            center_tile_px: [tx, ty],
            center_geo_m: [gx, gy],
            heading_rad: heading,
            center_cov_tile_px2: cov_px,
            center_cov_geo_m2: cov_m,
            heading_sigma_rad: r.rotation_sigma_rad,
            scale_sigma: r.scale_sigma,
            refined: true,
            map_noise_power_m4: header.noise_power_m4(),
            ..*self
        }
    }
}

/// A centre covariance in tile pixels² plus the tile's reference error
/// ([`TileHeader::reference_sigma_m`]), in tile pixels² and in geo metres² (the geo axes are
/// the tile axes scaled by the signed pixel sizes).
pub fn with_reference_error(
    c: [[f64; 2]; 2],
    header: &TileHeader<'_>,
) -> ([[f64; 2]; 2], [[f64; 2]; 2]) {
    let [vx, vy] = header.reference_var_px2();
    let c = [[c[0][0] + vx, c[0][1]], [c[1][0], c[1][1] + vy]];
    let (px, py) = (header.pixel_x_m, header.pixel_y_m);
    let m = [
        [c[0][0] * px * px, c[0][1] * px * py],
        [c[1][0] * px * py, c[1][1] * py * py],
    ];
    (c, m)
}

impl Fix {
    /// A fix from a refined area-search alignment: transform, position and heading from the
    /// refinement, covariances from its Gauss–Newton model plus the tile's reference error.
    pub fn from_area_search(
        r: &crate::refine::Refined,
        header: &TileHeader<'_>,
        frame_w: usize,
        frame_h: usize,
    ) -> Self {
        let sim = similarity(&r.affine);
        let (cx, cy) = ((frame_w as f64 - 1.0) * 0.5, (frame_h as f64 - 1.0) * 0.5);
        let (tx, ty) = r.affine.apply(cx, cy);
        let (gx, gy) = header.pixel_to_geo(tx, ty);
        let (c, cm) = with_reference_error(r.center_cov_tile_px2, header);
        let mut heading = sim.rotation_rad;
        if heading < 0.0 {
            heading += core::f64::consts::TAU;
        }
        Self {
            affine: r.affine,
            similarity: sim,
            center_tile_px: [tx, ty],
            center_geo_m: [gx, gy],
            heading_rad: heading,
            center_cov_tile_px2: c,
            center_cov_geo_m2: cm,
            heading_sigma_rad: r.rotation_sigma_rad,
            scale_sigma: r.scale_sigma,
            inliers: 0,
            residual_rms_px: 0.0,
            refined: true,
            area_search: true,
            map_noise_power_m4: header.noise_power_m4(),
        }
    }
}

/// Build a fix (or refuse one) from an MSAC result. `inlier_pts` yields the frame positions of
/// the inliers (for the spread test); `frame_w`, `frame_h` are the frame size in pixels.
pub fn make_fix(
    r: &MsacResult,
    header: &TileHeader<'_>,
    frame_w: usize,
    frame_h: usize,
    gate: &GateConfig,
    inlier_pts: impl Iterator<Item = (f32, f32)> + Clone,
) -> Result<Fix, NoFix> {
    if r.inliers < gate.min_inliers {
        return Err(NoFix::TooFewInliers);
    }
    // Spread: smaller eigenvalue of the inliers' 2 × 2 covariance.
    let (mut n, mut mx, mut my) = (0.0f64, 0.0f64, 0.0f64);
    for (x, y) in inlier_pts.clone() {
        n += 1.0;
        mx += x as f64;
        my += y as f64;
    }
    if n < 3.0 {
        return Err(NoFix::TooFewInliers);
    }
    mx /= n;
    my /= n;
    let (mut sxx, mut syy, mut sxy) = (0.0f64, 0.0f64, 0.0f64);
    for (x, y) in inlier_pts {
        let (dx, dy) = (x as f64 - mx, y as f64 - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    let (sxx, syy, sxy) = (sxx / n, syy / n, sxy / n);
    let half_tr = 0.5 * (sxx + syy);
    let disc = libm::sqrt(libm::fmax(
        0.25 * (sxx - syy) * (sxx - syy) + sxy * sxy,
        0.0,
    ));
    let lambda_min = half_tr - disc;
    if !(lambda_min >= (gate.min_inlier_spread_px as f64) * (gate.min_inlier_spread_px as f64)) {
        return Err(NoFix::DegenerateGeometry);
    }
    let sim = similarity(&r.affine);
    if !(similarity(&r.affine_ls).non_similar <= gate.max_non_similar as f64) {
        return Err(NoFix::NonSimilar);
    }
    if !(sim.scale >= gate.scale_min as f64 && sim.scale <= gate.scale_max as f64) {
        return Err(NoFix::ScaleOutOfRange);
    }
    if !(r.residual_rms_px <= gate.max_residual_rms_px as f64) {
        return Err(NoFix::ResidualTooLarge);
    }
    let (cx, cy) = ((frame_w as f64 - 1.0) * 0.5, (frame_h as f64 - 1.0) * 0.5);
    let (tx, ty) = r.affine.apply(cx, cy);
    let (gx, gy) = header.pixel_to_geo(tx, ty);
    let var_px = r.sigma2_px2 * r.design.point_variance(cx, cy);
    let (cov_px, cov_m) = with_reference_error([[var_px, 0.0], [0.0, var_px]], header);
    let var_ab = r.sigma2_px2 * r.design.rotation_scale_variance();
    let mut heading = sim.rotation_rad;
    if heading < 0.0 {
        heading += core::f64::consts::TAU;
    }
    Ok(Fix {
        affine: r.affine,
        similarity: Similarity {
            non_similar: similarity(&r.affine_ls).non_similar,
            ..sim
        },
        center_tile_px: [tx, ty],
        center_geo_m: [gx, gy],
        heading_rad: heading,
        center_cov_tile_px2: cov_px,
        center_cov_geo_m2: cov_m,
        heading_sigma_rad: libm::sqrt(var_ab) / sim.scale.max(f64::MIN_POSITIVE),
        scale_sigma: libm::sqrt(var_ab),
        inliers: r.inliers,
        residual_rms_px: r.residual_rms_px,
        refined: false,
        area_search: false,
        map_noise_power_m4: header.noise_power_m4(),
    })
}
