//! Monte-Carlo TRN campaigns: frames at random positions, headings and scales inside a tile,
//! flown through the flight code and scored against the truth; parallel on all cores, every
//! trial seeded on its own so the result does not depend on the thread count. `eval` runs one,
//! `suite` runs one per scene, tile kind and prior mode.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, anyhow, bail};
use indicatif::ProgressBar;
use nav_core::{NavConfig, Navigator, Prior, Tile};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::dem::Dem;
use crate::evaluation::trn::{TrnScore, expected_rotation_rad, score};
use crate::flyer::frames::{FramePose, SensorModel, centre_extent, frame_reach_m, synth_frame};
use crate::flyer::onboard::{
    Budget, FrameInput, WORKSPACE_STACK, Workspace, new_workspace, run_frame,
};

/// The prior a campaign hands the navigator with every frame: what the nav filter would know in
/// flight, drawn around the truth with these 1σ (Gaussian, per frame, seeded with the trial).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PriorSpec {
    /// 1σ position error of the prior per axis, metres.
    pub sigma_m: f64,
    /// 1σ heading error of the prior, degrees.
    pub heading_sigma_deg: f64,
    /// 1σ relative scale error (the altimeter's), e.g. 0.02.
    pub scale_sigma: f64,
}

/// What a campaign flies.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct CampaignSpec {
    /// Number of frames.
    pub trials: usize,
    /// Campaign seed (positions, headings, scales, noise, prior draws).
    pub seed: u64,
    /// Smallest frame pixel size, metres.
    pub pixel_min_m: f64,
    /// Largest frame pixel size, metres.
    pub pixel_max_m: f64,
    /// The flyer's ranging sensor.
    pub sensor: SensorModel,
    /// The prior given with each frame; `None`: lost in space.
    pub prior: Option<PriorSpec>,
    /// The navigator budget (the flight one unless asked otherwise).
    pub budget: Budget,
    /// Record each frame's onboard time on this host; `false` records 0 ms so that outputs
    /// repeat byte for byte (the only field that changes from run to run).
    pub host_time: bool,
}

pub(crate) use crate::dem::spectrum::normal;

/// A prior around the truth `pose` with `spec`'s errors, in the tile's pixel axes.
pub fn prior_around(
    tile: &Tile<'_>,
    pose: &FramePose,
    spec: &PriorSpec,
    rng: &mut impl RngExt,
) -> Prior {
    let h = tile.header();
    let (ex, ey) = (spec.sigma_m * normal(rng), spec.sigma_m * normal(rng));
    let dh = spec.heading_sigma_deg.to_radians() * normal(rng);
    let ds = spec.scale_sigma * normal(rng);
    let scale = pose.pixel_m / h.pixel_m();
    Prior {
        center_tile_px: [
            ((pose.x_m + ex - h.origin_x_m) / h.pixel_x_m) as f32,
            ((pose.y_m + ey - h.origin_y_m) / h.pixel_y_m) as f32,
        ],
        sigma_px: (spec.sigma_m / h.pixel_m()) as f32,
        heading_rad: expected_rotation_rad(h, pose.heading_rad + dh) as f32,
        heading_sigma_rad: spec.heading_sigma_deg.to_radians() as f32,
        scale: (scale * (1.0 + ds)) as f32,
        // The navigator's scale gate divides by it: at least 0.1 %.
        scale_sigma: spec.scale_sigma.max(1e-3) as f32,
    }
}

/// Frame centres a campaign may draw: inside both the tile and the DEM, a frame's reach from
/// every edge. `(x0, x1, y0, y1)` in geo metres.
pub fn centre_box(
    tile: &Tile<'_>,
    dem: &Dem,
    spec: &CampaignSpec,
) -> anyhow::Result<(f64, f64, f64, f64)> {
    let h = tile.header();
    let (tx0, ty0) = h.pixel_to_geo(0.0, 0.0);
    let (tx1, ty1) = h.pixel_to_geo(h.width_px as f64 - 1.0, h.height_px as f64 - 1.0);
    let (dx0, dx1, dy0, dy1) = centre_extent(dem);
    let reach = frame_reach_m(&spec.sensor, spec.pixel_max_m);
    let (x0, x1) = (tx0.min(tx1).max(dx0) + reach, tx0.max(tx1).min(dx1) - reach);
    let (y0, y1) = (ty0.min(ty1).max(dy0) + reach, ty0.max(ty1).min(dy1) - reach);
    if !(x1 > x0 && y1 > y0) {
        bail!(
            "the tile and DEM overlap leaves no room for a {}-px frame at {} m",
            spec.sensor.width_px.max(spec.sensor.height_px),
            spec.pixel_max_m
        );
    }
    Ok((x0, x1, y0, y1))
}

/// Fly the campaign: one scored row per trial, in trial order.
pub fn run_campaign(
    tile: Tile<'_>,
    config: NavConfig,
    dem: &Dem,
    spec: &CampaignSpec,
    progress: &ProgressBar,
) -> anyhow::Result<Vec<TrnScore>> {
    let all: Vec<usize> = (0..spec.trials).collect();
    run_trials(tile, config, dem, spec, &all, progress)
}

/// Fly the campaign's trials `trials` (indices below `spec.trials`, e.g. one shard's): one
/// scored row per index, in the given order. A trial's draws depend on (`spec.seed`, index) only,
/// so it flies the same in any subset.
pub fn run_trials(
    tile: Tile<'_>,
    config: NavConfig,
    dem: &Dem,
    spec: &CampaignSpec,
    trials: &[usize],
    progress: &ProgressBar,
) -> anyhow::Result<Vec<TrnScore>> {
    if spec.trials == 0 {
        bail!("a campaign needs at least one trial");
    }
    if !(spec.pixel_min_m > 0.0 && spec.pixel_max_m >= spec.pixel_min_m) {
        bail!("need 0 < smallest frame pixel ≤ largest frame pixel");
    }
    if let Some(&k) = trials.iter().find(|&&k| k >= spec.trials) {
        bail!("trial {k} is outside a campaign of {} trials", spec.trials);
    }
    let (x0, x1, y0, y1) = centre_box(&tile, dem, spec)?;
    let nav = Navigator::new(tile, config);
    let done = AtomicUsize::new(0);
    let pool = rayon::ThreadPoolBuilder::new()
        .stack_size(WORKSPACE_STACK)
        .build()?;
    let rows: Vec<anyhow::Result<TrnScore>> = pool.install(|| {
        trials
            .par_iter()
            .map_init(
                || new_workspace(spec.budget),
                |ws, &i| {
                    // Each trial has its own seed: results do not depend on the thread count.
                    let mut rng = rand_pcg::Pcg64::seed_from_u64(
                        spec.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ i as u64,
                    );
                    let pose = FramePose {
                        x_m: x0 + (x1 - x0) * rng.random::<f64>(),
                        y_m: y0 + (y1 - y0) * rng.random::<f64>(),
                        heading_rad: std::f64::consts::TAU * rng.random::<f64>(),
                        pixel_m: spec.pixel_min_m
                            + (spec.pixel_max_m - spec.pixel_min_m) * rng.random::<f64>(),
                    };
                    let mut row = fly_posed(&nav, ws, dem, &pose, spec, &mut rng)
                        .with_context(|| format!("trial {i}"))?;
                    progress.set_position(done.fetch_add(1, Ordering::Relaxed) as u64 + 1);
                    if !spec.host_time {
                        row.time_ms = 0.0;
                    }
                    Ok(row)
                },
            )
            .collect()
    });
    rows.into_iter().collect()
}

/// Fly one frame at `pose` over `dem` as a campaign does: synthesise it with `spec`'s sensor
/// (noise seeded from `rng`), draw `spec`'s prior around the truth if any, run the flight code
/// and score it. The prior draws come after the frame's, so a campaign without a prior flies the
/// very frames of the same campaign with one.
pub fn fly_posed(
    nav: &Navigator<'_>,
    ws: &mut Workspace,
    dem: &Dem,
    pose: &FramePose,
    spec: &CampaignSpec,
    rng: &mut impl RngExt,
) -> anyhow::Result<TrnScore> {
    let frame = synth_frame(dem, pose, &spec.sensor, rng.random::<u64>())?;
    let prior = spec.prior.map(|p| prior_around(nav.tile(), pose, &p, rng));
    let run = run_frame(
        nav,
        ws,
        FrameInput::Dem(&frame.heights_m, frame.width, frame.height, pose.pixel_m),
        prior.as_ref(),
    )
    .map_err(|e| anyhow!("{e}"))?;
    let mut s = score(nav.tile(), &run, pose, frame.width, frame.height);
    s.m4_instructions_est = Some(u64::from(run.report.work));
    // The host budget runs without a work budget: nothing to cut, the column stays empty.
    s.budget_cut = (spec.budget == Budget::Flight).then_some(run.report.over_budget);
    Ok(s)
}

/// Campaign summary (the JSON of `ground-sim eval`, one row of `suite`).
#[derive(Debug, Clone, Serialize)]
pub struct EvalSummary {
    /// Frames flown.
    pub trials: usize,
    /// Campaign seed.
    pub seed: u64,
    /// The prior given with each frame (`null`: none).
    pub prior: Option<PriorSpec>,
    /// The navigator budget the frames were flown with (`flight` is what flies).
    pub budget: String,
    /// Fraction of frames with a correct fix (≤ 3 reference px).
    pub success_rate: f64,
    /// Fraction of frames with a fix more than 3 reference px off.
    pub false_fix_rate: f64,
    /// Number of such false fixes.
    pub false_fixes: usize,
    /// Fraction of frames without a fix.
    pub no_fix_rate: f64,
    /// Median position error of correct fixes, metres.
    pub pos_err_p50_m: f64,
    /// 95th percentile position error of correct fixes, metres.
    pub pos_err_p95_m: f64,
    /// Largest position error of any fix, metres.
    pub pos_err_max_m: f64,
    /// 95th percentile |heading error| of fixes, degrees.
    pub heading_err_p95_deg: f64,
    /// Largest |heading error| of fixes, degrees.
    pub heading_err_max_deg: f64,
    /// 95th percentile |scale error| of fixes, relative.
    pub scale_err_p95: f64,
    /// Mean of the per-frame mean registration error, reference pixels.
    pub reg_err_mean_px: f64,
    /// Fraction of fixes whose centre error lies inside their 3σ ellipse (NEES ≤ 9; a
    /// consistent covariance puts 98.9 % there).
    pub within_3sigma_frac: f64,
    /// Mean NEES of the fixes' centres (2 dof: 2 when consistent, less when padded, more when
    /// optimistic).
    pub nees_mean: f64,
    /// The correct fixes' common offset: their mean signed error east and north, metres (fix −
    /// truth). Frames over the same map share what the map gets wrong; an offset the fixes'
    /// residuals cannot see shows here and not in any single fix (docs/registration.md,
    /// "What an InSAR fix's σ covers").
    pub err_mean_m: [f64; 2],
    /// The correct fixes' scatter about that offset: standard deviation east and north, metres
    /// (dividing by the number of fixes, so offset² + scatter² is their mean squared error).
    pub err_sd_m: [f64; 2],
    /// Share of the correct fixes' mean squared error that the common offset accounts for,
    /// 0–1 (0: the errors scatter about the truth; 1: every fix is off alike). NaN without
    /// fixes.
    pub common_error_share: f64,
    /// Mean onboard time per frame on this host, ms.
    pub time_ms_mean: f64,
    /// No-fix reasons and their counts.
    pub no_fix_reasons: BTreeMap<String, usize>,
    /// Fraction of fixes refined densely against the tile's slope raster.
    pub refined_frac: f64,
    /// Fraction of fixes that came from the prior-aided area search (0 without a prior).
    pub area_search_frac: f64,
    /// Mean of (centre error / refinement's own σ per axis)² over refined correct fixes: 2 if
    /// the refinement's statistical covariance were consistent (the fixes report the feature
    /// covariance; see docs/registration.md).
    pub refined_nees_mean: f64,
    /// Why fixes were not refined, and how often.
    pub refine_notes: BTreeMap<String, usize>,
    /// Work the navigator metered per frame (`FrameReport::work`: estimated Cortex-M4
    /// instructions, `nav_core::cost`, checked against the HIL's measured counts): 95th
    /// percentile over all frames.
    pub m4_instructions_p95: f64,
    /// Fraction of all frames whose work exceeds the flyer's budget
    /// (`nav_core::cost::FLIGHT_BUDGET`, 20 M): frames that would overrun on the target (none
    /// with the flight configuration on frames binned by 2 or more, whose work budget bounds
    /// every stage after the first; a navigator without one, `--budget host`, shows them).
    pub over_budget_frac: f64,
    /// The same among the fixes.
    pub fixes_over_budget_frac: f64,
    /// Fraction of all frames in which the navigator's work budget skipped a stage or capped
    /// one (`FrameReport::over_budget`).
    #[serde(default)]
    pub budget_cut_frac: f64,
    /// Frame pixel size range, metres.
    pub pixel_range_m: [f64; 2],
    /// Sensor model.
    pub sensor: SensorModel,
}

/// Nearest-rank percentile `p` ∈ [0, 1] of `v` (sorted in place); NaN when empty.
pub fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let k = ((v.len() - 1) as f64 * p).round() as usize;
    v[k.min(v.len() - 1)]
}

/// The common offset of signed errors `(east, north)` (metres), their scatter about it and the
/// share of the mean squared error the offset accounts for: `([mean], [sd], share)`; NaN
/// when empty.
pub fn error_split(errors: &[(f64, f64)]) -> ([f64; 2], [f64; 2], f64) {
    if errors.is_empty() {
        return ([f64::NAN; 2], [f64::NAN; 2], f64::NAN);
    }
    let n = errors.len() as f64;
    let me = errors.iter().map(|e| e.0).sum::<f64>() / n;
    let mn = errors.iter().map(|e| e.1).sum::<f64>() / n;
    let ve = errors.iter().map(|e| (e.0 - me).powi(2)).sum::<f64>() / n;
    let vn = errors.iter().map(|e| (e.1 - mn).powi(2)).sum::<f64>() / n;
    let common = me * me + mn * mn;
    let total = common + ve + vn;
    let share = if total > 0.0 { common / total } else { 0.0 };
    ([me, mn], [ve.sqrt(), vn.sqrt()], share)
}

/// Summarise a campaign's rows.
pub fn summarize(rows: &[TrnScore], spec: &CampaignSpec) -> EvalSummary {
    let n = rows.len().max(1) as f64;
    let fixes: Vec<&TrnScore> = rows.iter().filter(|r| r.fix).collect();
    let good: Vec<&TrnScore> = fixes.iter().copied().filter(|r| !r.false_fix).collect();
    let mut pos: Vec<f64> = good.iter().filter_map(|r| r.pos_err_m).collect();
    let head: Vec<f64> = fixes
        .iter()
        .filter_map(|r| r.heading_err_deg.map(f64::abs))
        .collect();
    let mut scl: Vec<f64> = fixes
        .iter()
        .filter_map(|r| r.scale.map(|s| (s / r.scale_truth - 1.0).abs()))
        .collect();
    let reg: Vec<f64> = fixes.iter().filter_map(|r| r.pos_err_mean_px).collect();
    let nees: Vec<f64> = fixes.iter().filter_map(|r| r.nees).collect();
    let signed: Vec<(f64, f64)> = good
        .iter()
        .filter_map(|r| Some((r.err_east_m?, r.err_north_m?)))
        .collect();
    let (err_mean_m, err_sd_m, common_error_share) = error_split(&signed);
    let mut reasons = BTreeMap::new();
    for r in rows.iter().filter(|r| !r.fix) {
        *reasons
            .entry(r.no_fix_reason.clone().unwrap_or_default())
            .or_insert(0) += 1;
    }
    let mut refine_notes = BTreeMap::new();
    for r in &fixes {
        if let Some(note) = &r.refine_note {
            *refine_notes.entry(note.clone()).or_insert(0) += 1;
        }
    }
    let refined_nees: Vec<f64> = good
        .iter()
        .filter_map(|r| Some((r.pos_err_m? / r.refined_sigma_m?).powi(2)))
        .collect();
    let m4: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.m4_instructions_est.map(|v| v as f64))
        .collect();
    let budget = nav_core::cost::FLIGHT_BUDGET as f64;
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    EvalSummary {
        trials: rows.len(),
        seed: spec.seed,
        prior: spec.prior,
        budget: spec.budget.label(),
        success_rate: good.len() as f64 / n,
        false_fix_rate: (fixes.len() - good.len()) as f64 / n,
        false_fixes: fixes.len() - good.len(),
        no_fix_rate: (rows.len() - fixes.len()) as f64 / n,
        pos_err_p50_m: percentile(&mut pos.clone(), 0.5),
        pos_err_p95_m: percentile(&mut pos, 0.95),
        pos_err_max_m: fixes.iter().filter_map(|r| r.pos_err_m).fold(0.0, f64::max),
        heading_err_p95_deg: percentile(&mut head.clone(), 0.95),
        heading_err_max_deg: head.iter().copied().fold(0.0, f64::max),
        scale_err_p95: percentile(&mut scl, 0.95),
        reg_err_mean_px: mean(&reg),
        within_3sigma_frac: nees.iter().filter(|&&d| d <= 9.0).count() as f64
            / fixes.len().max(1) as f64,
        nees_mean: mean(&nees),
        err_mean_m,
        err_sd_m,
        common_error_share,
        time_ms_mean: rows.iter().map(|r| r.time_ms).sum::<f64>() / n,
        no_fix_reasons: reasons,
        refined_frac: fixes.iter().filter(|r| r.refined).count() as f64 / fixes.len().max(1) as f64,
        area_search_frac: fixes.iter().filter(|r| r.area_search).count() as f64
            / fixes.len().max(1) as f64,
        refine_notes,
        refined_nees_mean: mean(&refined_nees),
        m4_instructions_p95: percentile(&mut m4.clone(), 0.95),
        over_budget_frac: m4.iter().filter(|&&v| v > budget).count() as f64 / n,
        fixes_over_budget_frac: fixes
            .iter()
            .filter(|r| r.m4_instructions_est.is_some_and(|v| v as f64 > budget))
            .count() as f64
            / fixes.len().max(1) as f64,
        budget_cut_frac: rows.iter().filter(|r| r.budget_cut == Some(true)).count() as f64 / n,
        pixel_range_m: [spec.pixel_min_m, spec.pixel_max_m],
        sensor: spec.sensor,
    }
}

/// Print the summary's headline figures.
pub fn print_summary(s: &EvalSummary) {
    println!(
        "trials      {} (seed {}), budget {}{}",
        s.trials,
        s.seed,
        s.budget,
        s.prior.map_or(String::from(", no prior"), |p| format!(
            ", prior σ {} m, heading σ {}°",
            p.sigma_m, p.heading_sigma_deg
        ))
    );
    println!(
        "success     {:.2} %  false fix {:.2} %  no fix {:.2} %",
        s.success_rate * 100.0,
        s.false_fix_rate * 100.0,
        s.no_fix_rate * 100.0
    );
    println!(
        "M4 work     p95 {:.1} M instructions (nav_core::cost); over the {} M budget: {:.1} % \
         of frames, {:.1} % of fixes; a stage cut by the work budget in {:.1} % of frames",
        s.m4_instructions_p95 / 1e6,
        nav_core::cost::FLIGHT_BUDGET / 1_000_000,
        s.over_budget_frac * 100.0,
        s.fixes_over_budget_frac * 100.0,
        s.budget_cut_frac * 100.0
    );
    if s.budget_cut_frac > 0.25 && s.prior.is_none() {
        // Lost in space, every tile feature is a matching candidate: on a large tile that alone
        // can exhaust the flyer's budget (docs/bounds.md, the per-frame work budget).
        println!(
            "            most frames ran out of the flyer's work budget: lost in space, matching \
             reads every tile feature; the flyer's atlas tiles cover 4 km, a prior \
             (--prior-sigma-m) restricts matching to its footprint, --budget host measures \
             without a budget"
        );
    }
    println!(
        "position    p50 {:.2} m  p95 {:.2} m  max {:.2} m",
        s.pos_err_p50_m, s.pos_err_p95_m, s.pos_err_max_m
    );
    println!(
        "heading     p95 {:.3}°  max {:.3}°;  scale error p95 {:.3} %",
        s.heading_err_p95_deg,
        s.heading_err_max_deg,
        s.scale_err_p95 * 100.0
    );
    println!(
        "consistency {:.1} % of fixes inside their 3σ ellipse, mean NEES {:.2} (2 = consistent); mean onboard time {:.2} ms",
        s.within_3sigma_frac * 100.0,
        s.nees_mean,
        s.time_ms_mean
    );
    if s.common_error_share.is_finite() {
        println!(
            "error split common offset east {:+.2} m, north {:+.2} m ({:.0} % of the mean squared \
             error); scatter about it σ {:.2} / {:.2} m",
            s.err_mean_m[0],
            s.err_mean_m[1],
            s.common_error_share * 100.0,
            s.err_sd_m[0],
            s.err_sd_m[1]
        );
    }
    if !s.no_fix_reasons.is_empty() {
        println!("no fix      {:?}", s.no_fix_reasons);
    }
    println!(
        "refined     {:.1} % of fixes (their own covariance: mean NEES {:.2}, 2 = consistent){}",
        s.refined_frac * 100.0,
        s.refined_nees_mean,
        if s.refine_notes.is_empty() {
            String::new()
        } else {
            format!(" (not refined: {:?})", s.refine_notes)
        }
    );
}

/// Write one CSV row per trial, numbered from 0.
pub fn write_csv(path: &Path, rows: &[TrnScore]) -> anyhow::Result<()> {
    let trials: Vec<usize> = (0..rows.len()).collect();
    write_csv_trials(path, &trials, rows)
}

/// Write one CSV row per trial; `trials[k]` is row `k`'s campaign trial index (a shard's rows
/// keep the campaign's numbering).
pub fn write_csv_trials(path: &Path, trials: &[usize], rows: &[TrnScore]) -> anyhow::Result<()> {
    if trials.len() != rows.len() {
        bail!("{} trial indices for {} rows", trials.len(), rows.len());
    }
    crate::ensure_parent(path)?;
    let mut csv = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    writeln!(
        csv,
        "trial,x_m,y_m,heading_deg,pixel_m,fix,false_fix,features,matches,inliers,rotation_deg,heading_err_deg,scale,scale_truth,pos_err_m,err_east_m,err_north_m,center_err_px,reg_err_mean_px,reg_err_max_px,center_sigma_m,nees,heading_sigma_deg,time_ms,refined,ncc,refined_sigma_m,refine_iterations,refine_rho,refine_note,area_search,m4_instructions_est,budget_cut,no_fix_reason"
    )?;
    let o = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x:.6}"));
    for (i, r) in trials.iter().zip(rows) {
        let t = r.truth.unwrap_or(FramePose {
            x_m: f64::NAN,
            y_m: f64::NAN,
            heading_rad: f64::NAN,
            pixel_m: f64::NAN,
        });
        writeln!(
            csv,
            "{i},{:.3},{:.3},{:.4},{:.4},{},{},{},{},{},{},{},{},{:.6},{},{},{},{},{},{},{},{},{},{:.3},{},{},{},{},{},{},{},{},{},{}",
            t.x_m,
            t.y_m,
            t.heading_rad.to_degrees(),
            t.pixel_m,
            r.fix,
            r.false_fix,
            r.features,
            r.matches,
            r.inliers,
            o(r.rotation_deg),
            o(r.heading_err_deg),
            o(r.scale),
            r.scale_truth,
            o(r.pos_err_m),
            o(r.err_east_m),
            o(r.err_north_m),
            o(r.center_err_px),
            o(r.pos_err_mean_px),
            o(r.pos_err_max_px),
            o(r.center_sigma_m),
            o(r.nees),
            o(r.heading_sigma_deg),
            r.time_ms,
            r.refined,
            o(r.ncc.map(f64::from)),
            o(r.refined_sigma_m),
            r.refine_iterations.map_or(String::new(), |n| n.to_string()),
            o(r.refine_rho.map(f64::from)),
            r.refine_note.as_deref().unwrap_or(""),
            r.area_search,
            r.m4_instructions_est
                .map_or(String::new(), |v| v.to_string()),
            r.budget_cut.map_or(String::new(), |v| v.to_string()),
            r.no_fix_reason.as_deref().unwrap_or("")
        )?;
    }
    csv.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::error_split;

    #[test]
    fn the_error_split_separates_a_shared_offset_from_scatter() {
        // Every fix off by the same (3, −4) m: all of the error is the common offset.
        let (m, sd, share) = error_split(&[(3.0, -4.0); 5]);
        assert_eq!(m, [3.0, -4.0]);
        assert_eq!(sd, [0.0, 0.0]);
        assert_eq!(share, 1.0);
        // Errors symmetric about the truth: no offset, scatter √½ m per axis (1 m RMS radially).
        let (m, sd, share) = error_split(&[(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)]);
        assert_eq!(m, [0.0, 0.0]);
        assert!((sd[0] - 0.5f64.sqrt()).abs() < 1e-12 && (sd[1] - 0.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(share, 0.0);
        // Offset 1 m east and scatter ±1 m east: offset 1 of a mean squared error of 2.
        let (m, sd, share) = error_split(&[(0.0, 0.0), (2.0, 0.0)]);
        assert_eq!(m, [1.0, 0.0]);
        assert_eq!(sd, [1.0, 0.0]);
        assert_eq!(share, 0.5);
        let (m, _, share) = error_split(&[]);
        assert!(m[0].is_nan() && share.is_nan());
    }
}
