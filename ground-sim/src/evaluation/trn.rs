//! One TRN frame scored against the truth: where the frame really was versus what the onboard
//! chain said.

use nav_core::{Fix, Tile, TileHeader};
use serde::{Deserialize, Serialize};

use crate::flyer::frames::FramePose;
use crate::flyer::onboard::FrameRun;

/// Truth map from frame pixels to tile pixels for a frame taken at `pose`.
pub fn truth_to_tile(
    h: &TileHeader<'_>,
    pose: &FramePose,
    w: usize,
    hgt: usize,
    x: f64,
    y: f64,
) -> (f64, f64) {
    let (gx, gy) = pose.frame_to_geo(x, y, w, hgt);
    (
        (gx - h.origin_x_m) / h.pixel_x_m,
        (gy - h.origin_y_m) / h.pixel_y_m,
    )
}

/// Scores of one frame (the JSON of `ground-sim trn`, one row of `eval`).
// Option<f64> fields keep ±∞/NaN through JSON (`opt_f64`): campaign shards must read back the
// very values a summary counts.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct TrnScore {
    /// Whether the gate gave a fix.
    pub fix: bool,
    /// Why not.
    pub no_fix_reason: Option<String>,
    /// A fix more than 3 reference pixels from the truth.
    pub false_fix: bool,
    /// Frame features.
    pub features: u16,
    /// Putative matches.
    pub matches: u16,
    /// Inliers.
    pub inliers: u16,
    /// Whether the fix was refined densely against the tile's slope raster.
    pub refined: bool,
    /// The fix came from the prior-aided area search (`nav_core::search`), not from features.
    pub area_search: bool,
    /// Why a fix was not refined (it then stands as the features gave it).
    pub refine_note: Option<String>,
    /// Normalised cross-correlation of frame and reference slope under the refined transform.
    pub ncc: Option<f32>,
    /// The refinement's own statistical 1σ of the centre per axis, metres (`Refined`'s
    /// covariance; the fix itself reports the feature covariance in `center_sigma_m`).
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub refined_sigma_m: Option<f64>,
    /// Gauss–Newton updates the applied refinement made (`Refined::iterations`).
    #[serde(default)]
    pub refine_iterations: Option<u8>,
    /// Lag-1 correlation ρ of the applied refinement's residuals along a row
    /// (`Refined::correlation`, 0–0.9): it sets how much the refinement inflates its covariance,
    /// so campaigns can check that inflation against the fixes' errors.
    #[serde(default)]
    pub refine_rho: Option<f32>,
    /// The work nav-core metered for the frame (`FrameReport::work`: estimated Cortex-M4
    /// instructions, `nav_core::cost`); campaigns fill it.
    #[serde(default)]
    pub m4_instructions_est: Option<u64>,
    /// The navigator's work budget skipped a stage or capped one's samples or passes in this
    /// frame (`FrameReport::over_budget`); campaigns fill it.
    #[serde(default)]
    pub budget_cut: Option<bool>,
    /// Estimated rotation, degrees.
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub rotation_deg: Option<f64>,
    /// Heading error, degrees (wrapped to ±180).
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub heading_err_deg: Option<f64>,
    /// Estimated scale (tile px per frame px).
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub scale: Option<f64>,
    /// True scale.
    pub scale_truth: f64,
    /// Mean registration error over the inliers, reference pixels (fix map vs truth map at each
    /// inlier's frame position).
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub pos_err_mean_px: Option<f64>,
    /// Max registration error over the inliers, reference pixels.
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub pos_err_max_px: Option<f64>,
    /// Error of the frame centre, reference pixels.
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub center_err_px: Option<f64>,
    /// Error of the frame centre, metres.
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub pos_err_m: Option<f64>,
    /// Error of the fix's geo centre along the projection's x (east), metres (fix − truth):
    /// with `err_north_m`, shows whether errors share a direction (a map offset) or scatter.
    #[serde(default, with = "crate::evaluation::shard::opt_f64")]
    pub err_east_m: Option<f64>,
    /// Error of the fix's geo centre along the projection's y (north), metres (fix − truth).
    #[serde(default, with = "crate::evaluation::shard::opt_f64")]
    pub err_north_m: Option<f64>,
    /// Reported 1σ of the centre, metres (the larger principal axis of its covariance).
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub center_sigma_m: Option<f64>,
    /// Normalised estimation error squared of the centre: `eᵀ C⁻¹ e` with `e` the geo error
    /// (metres, east/north) and `C` the fix's reported covariance; 2 on average (2 dof) when
    /// the covariance is consistent, ≤ 9 (the 3σ ellipse) for 98.9 % of consistent fixes.
    #[serde(with = "crate::evaluation::shard::opt_f64")]
    pub nees: Option<f64>,
    /// Reported 1σ of the heading, degrees (the fix's `heading_sigma_rad`): with
    /// `heading_err_deg` it shows whether the heading's uncertainty is honest.
    #[serde(default, with = "crate::evaluation::shard::opt_f64")]
    pub heading_sigma_deg: Option<f64>,
    /// Onboard time on this host, ms.
    pub time_ms: f64,
    /// Truth pose.
    pub truth: Option<FramePose>,
}

/// The rotation (radians) a perfect fix reports for a frame whose +x axis points `heading_rad`
/// clockwise from east: the heading itself in a north-up tile (pixel y pointing south, the
/// frame heading's own axes), its negative otherwise.
pub fn expected_rotation_rad(h: &TileHeader<'_>, heading_rad: f64) -> f64 {
    if h.pixel_y_m < 0.0 {
        heading_rad
    } else {
        -heading_rad
    }
}

/// Wrap degrees to (−180, 180].
pub fn wrap_deg(d: f64) -> f64 {
    let r = d.rem_euclid(360.0);
    if r > 180.0 { r - 360.0 } else { r }
}

/// Score a frame run against its truth pose. `frame_w`, `frame_h` in pixels.
pub fn score(
    tile: &Tile<'_>,
    run: &FrameRun,
    pose: &FramePose,
    frame_w: usize,
    frame_h: usize,
) -> TrnScore {
    let h = tile.header();
    let scale_truth = pose.pixel_m / h.pixel_m();
    let mut s = TrnScore {
        fix: run.report.outcome.is_ok(),
        no_fix_reason: run.report.outcome.err().map(|e| match run.report.search {
            // The search ran first and the feature path after it: the features' verdict is
            // the outcome, the search's why it did not settle the frame.
            Some(Err(se)) if run.report.search_first => format!("{e} (area search first: {se})"),
            Some(Ok(_)) if run.report.search_first => {
                format!("{e} (area search first: a hit its refinement or a gate refused)")
            }
            // The search ran after the feature path failed: its verdict is the last word.
            Some(Err(se)) => format!("area search: {se}"),
            Some(Ok(_)) => match &run.report.refine {
                Some(Err(re)) => format!("area search: not confirmed by the refinement ({re})"),
                _ => "area search: refused by the scale or prior gate".to_string(),
            },
            None => e.to_string(),
        }),
        features: run.report.features,
        matches: run.report.matches,
        inliers: run.report.inliers,
        scale_truth,
        time_ms: run.time_ms,
        truth: Some(*pose),
        ..Default::default()
    };
    if let Ok(f) = run.report.outcome {
        fill_fix(&mut s, &f, h, pose, frame_w, frame_h, run);
        match run.report.refine {
            Some(Ok(r)) if f.refined => {
                s.ncc = Some(r.ncc_after);
                s.refine_iterations = Some(r.iterations);
                s.refine_rho = Some(r.correlation);
                let c = r.center_cov_tile_px2;
                s.refined_sigma_m = Some((0.5 * (c[0][0] + c[1][1])).max(0.0).sqrt() * h.pixel_m());
            }
            Some(Err(e)) => s.refine_note = Some(e.to_string()),
            _ => {}
        }
        s.refined = f.refined;
        s.area_search = f.area_search;
    }
    s
}

fn fill_fix(
    s: &mut TrnScore,
    f: &Fix,
    h: &TileHeader<'_>,
    pose: &FramePose,
    w: usize,
    hh: usize,
    run: &FrameRun,
) {
    let rot = f.similarity.rotation_rad.to_degrees();
    let expect = expected_rotation_rad(h, pose.heading_rad).to_degrees();
    s.rotation_deg = Some(rot);
    s.heading_err_deg = Some(wrap_deg(rot - expect));
    s.heading_sigma_deg = Some(f.heading_sigma_rad.to_degrees());
    s.scale = Some(f.similarity.scale);
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (hh as f64 - 1.0) / 2.0);
    let (tx, ty) = truth_to_tile(h, pose, w, hh, cx, cy);
    let ce = (f.center_tile_px[0] - tx).hypot(f.center_tile_px[1] - ty);
    s.center_err_px = Some(ce);
    s.pos_err_m = Some(ce * h.pixel_m());
    let c = f.center_cov_geo_m2;
    let (tr, det) = (c[0][0] + c[1][1], c[0][0] * c[1][1] - c[0][1] * c[1][0]);
    let big = 0.5 * tr + (0.25 * tr * tr - det).max(0.0).sqrt();
    s.center_sigma_m = Some(big.max(0.0).sqrt());
    // The pose is the frame centre's true geo position.
    let (ex, ey) = (f.center_geo_m[0] - pose.x_m, f.center_geo_m[1] - pose.y_m);
    s.err_east_m = Some(ex);
    s.err_north_m = Some(ey);
    // eᵀ C⁻¹ e with the 2 × 2 inverse written out; a singular covariance gives no figure.
    s.nees = (det > 0.0)
        .then(|| (c[1][1] * ex * ex - (c[0][1] + c[1][0]) * ex * ey + c[0][0] * ey * ey) / det);
    let errs: Vec<f64> = run
        .pairs
        .iter()
        .filter(|p| p.4)
        .map(|&(x, y, _, _, _)| {
            let (ex, ey) = f.affine.apply(x as f64, y as f64);
            let (tx, ty) = truth_to_tile(h, pose, w, hh, x as f64, y as f64);
            (ex - tx).hypot(ey - ty)
        })
        .collect();
    if !errs.is_empty() {
        s.pos_err_mean_px = Some(errs.iter().sum::<f64>() / errs.len() as f64);
        s.pos_err_max_px = Some(errs.iter().copied().fold(0.0, f64::max));
    }
    s.false_fix = ce > 3.0;
}

/// One synthetic frame flown through the onboard chain and scored (what `trn` and `demo` do).
pub struct FrameCheck {
    /// The synthesised frame.
    pub frame: crate::flyer::frames::Frame,
    /// The onboard result.
    pub run: FrameRun,
    /// Its scores against the truth.
    pub score: TrnScore,
    /// The tile's terrain smoothing σ, metres (the picture shows the frame smoothed alike).
    pub smoothing_m: f32,
}

/// Synthesise the frame at `pose` from `dem`, locate it against `tile` with the default
/// navigator settings (no prior) within `budget` and score it.
pub fn check_frame(
    dem: &crate::dem::Dem,
    tile: &Tile<'_>,
    pose: &FramePose,
    sensor: &crate::flyer::frames::SensorModel,
    seed: u64,
    budget: crate::flyer::onboard::Budget,
) -> anyhow::Result<FrameCheck> {
    use crate::flyer::onboard::{FrameInput, new_workspace, run_frame, with_big_stack};
    let frame = crate::flyer::frames::synth_frame(dem, pose, sensor, seed)?;
    let nav = nav_core::Navigator::new(*tile, nav_core::NavConfig::default());
    let run = with_big_stack(|| {
        let mut ws = new_workspace(budget);
        let input = FrameInput::Dem(&frame.heights_m, frame.width, frame.height, pose.pixel_m);
        run_frame(&nav, &mut ws, input, None).map_err(|e| anyhow::anyhow!("{e}"))
    })?;
    let score = score(tile, &run, pose, frame.width, frame.height);
    Ok(FrameCheck {
        frame,
        run,
        score,
        smoothing_m: tile.header().smoothing_m,
    })
}

impl FrameCheck {
    /// The paper's Fig. 7 picture: this frame's slope (left) and the reference slope map
    /// (degrees, right) with the match lines.
    pub fn picture(&self, ref_slope: &crate::dem::Dem) -> image::RgbImage {
        let fs = crate::flyer::frames::frame_slope_deg(&self.frame, f64::from(self.smoothing_m));
        crate::pictures::matchplot::match_picture(
            (&fs, self.frame.width, self.frame.height),
            (ref_slope.heights_m(), ref_slope.width(), ref_slope.height()),
            &self.run.pairs,
        )
    }
}
