//! `ground-sim eval`: a Monte-Carlo campaign of single frames at random positions, headings and
//! scales inside the tile, scored against the truth; parallel on all cores.

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, anyhow, bail};
use ground_sim::dem::read_geotiff;
use ground_sim::evaluation::trn::{TrnScore, score};
use ground_sim::flyer::frames::{
    FramePose, SensorModel, centre_extent, frame_reach_m, synth_frame,
};
use ground_sim::flyer::onboard::{FrameInput, WORKSPACE_STACK, new_workspace, run_frame};
use ground_sim::reference::load;
use nav_core::{NavConfig, Navigator, Tile};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

/// Arguments of `ground-sim eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder (tile.bin, slope.tif).
    #[arg(long)]
    pub tile: PathBuf,
    /// Truth DEM (GeoTIFF).
    #[arg(long)]
    pub dem: PathBuf,
    /// Number of frames.
    #[arg(long, default_value_t = 500)]
    pub trials: usize,
    /// Campaign seed (positions, headings, scales, noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Smallest frame pixel size, metres.
    #[arg(long, default_value_t = 9.0)]
    pub pixel_min_m: f64,
    /// Largest frame pixel size, metres.
    #[arg(long, default_value_t = 11.0)]
    pub pixel_max_m: f64,
    /// The flyer's ranging sensor.
    #[command(flatten)]
    pub sensor: super::SensorArgs,
    /// Summary JSON.
    #[arg(long)]
    pub json: PathBuf,
    /// One CSV row per trial (default: next to the JSON, `.csv`).
    #[arg(long)]
    pub csv: Option<PathBuf>,
}

/// Campaign summary (the JSON of `ground-sim eval`).
#[derive(Debug, Serialize)]
pub struct EvalSummary {
    /// Frames flown.
    pub trials: usize,
    /// Campaign seed.
    pub seed: u64,
    /// Fraction of frames with a correct fix (≤ 3 reference px).
    pub success_rate: f64,
    /// Fraction of frames with a fix more than 3 reference px off.
    pub false_fix_rate: f64,
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
    /// Fraction of fixes whose centre error lies within the reported 3σ.
    pub within_3sigma_frac: f64,
    /// Mean onboard time per frame on this host, ms.
    pub time_ms_mean: f64,
    /// No-fix reasons and their counts.
    pub no_fix_reasons: std::collections::BTreeMap<String, usize>,
    /// Fraction of fixes refined densely against the tile's slope raster.
    pub refined_frac: f64,
    /// Mean of (centre error / refinement's own σ per axis)² over refined correct fixes: 2 if
    /// the refinement's statistical covariance were consistent (the fixes report the feature
    /// covariance; see docs/registration.md).
    pub refined_nees_mean: f64,
    /// Why fixes were not refined, and how often.
    pub refine_notes: std::collections::BTreeMap<String, usize>,
    /// Frame pixel size range, metres.
    pub pixel_range_m: [f64; 2],
    /// Sensor model.
    pub sensor: SensorModel,
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let k = ((v.len() - 1) as f64 * p).round() as usize;
    v[k.min(v.len() - 1)]
}

/// Run `ground-sim eval`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    if a.trials == 0 {
        bail!("--trials must be ≥ 1");
    }
    if !(a.pixel_min_m > 0.0 && a.pixel_max_m >= a.pixel_min_m) {
        bail!("need 0 < --pixel-min-m ≤ --pixel-max-m");
    }
    let reference = load(&a.tile)?;
    let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
    let dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let sensor = a.sensor.model();
    // Frame centres: inside both the tile and the DEM, a frame's reach from every edge.
    let h = tile.header();
    let (tx0, ty0) = h.pixel_to_geo(0.0, 0.0);
    let (tx1, ty1) = h.pixel_to_geo(h.width_px as f64 - 1.0, h.height_px as f64 - 1.0);
    let (dx0, dx1, dy0, dy1) = centre_extent(&dem);
    let reach = frame_reach_m(&sensor, a.pixel_max_m);
    let (x0, x1) = (tx0.min(tx1).max(dx0) + reach, tx0.max(tx1).min(dx1) - reach);
    let (y0, y1) = (ty0.min(ty1).max(dy0) + reach, ty0.max(ty1).min(dy1) - reach);
    if !(x1 > x0 && y1 > y0) {
        bail!(
            "the tile and DEM overlap leaves no room for a {}-px frame at {} m",
            a.sensor.size_px,
            a.pixel_max_m
        );
    }
    let nav = Navigator::new(tile, NavConfig::default());
    let pb = super::progress(a.trials as u64, "eval");
    let done = AtomicUsize::new(0);
    let pool = rayon::ThreadPoolBuilder::new()
        .stack_size(WORKSPACE_STACK)
        .build()?;
    let rows: Vec<anyhow::Result<TrnScore>> = pool.install(|| {
        (0..a.trials)
            .into_par_iter()
            .map_init(new_workspace, |ws, i| {
                // Each trial has its own seed: results do not depend on the thread count.
                let mut rng = rand_pcg::Pcg64::seed_from_u64(
                    a.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ i as u64,
                );
                let pose = FramePose {
                    x_m: x0 + (x1 - x0) * rng.random::<f64>(),
                    y_m: y0 + (y1 - y0) * rng.random::<f64>(),
                    heading_rad: std::f64::consts::TAU * rng.random::<f64>(),
                    pixel_m: a.pixel_min_m + (a.pixel_max_m - a.pixel_min_m) * rng.random::<f64>(),
                };
                let frame = synth_frame(&dem, &pose, &sensor, rng.random::<u64>())?;
                let run = run_frame(
                    &nav,
                    ws,
                    FrameInput::Dem(&frame.heights_m, frame.width, frame.height, pose.pixel_m),
                    None,
                )
                .map_err(|e| anyhow!("trial {i}: {e}"))?;
                pb.set_position(done.fetch_add(1, Ordering::Relaxed) as u64 + 1);
                Ok(score(nav.tile(), &run, &pose, frame.width, frame.height))
            })
            .collect()
    });
    pb.finish_and_clear();
    let rows: Vec<TrnScore> = rows.into_iter().collect::<anyhow::Result<_>>()?;
    let n = rows.len() as f64;
    let fixes: Vec<&TrnScore> = rows.iter().filter(|r| r.fix).collect();
    let good: Vec<&TrnScore> = fixes.iter().copied().filter(|r| !r.false_fix).collect();
    let mut pos: Vec<f64> = good.iter().filter_map(|r| r.pos_err_m).collect();
    let mut head: Vec<f64> = fixes
        .iter()
        .filter_map(|r| r.heading_err_deg.map(f64::abs))
        .collect();
    let mut scl: Vec<f64> = fixes
        .iter()
        .filter_map(|r| r.scale.map(|s| (s / r.scale_truth - 1.0).abs()))
        .collect();
    let reg: Vec<f64> = fixes.iter().filter_map(|r| r.pos_err_mean_px).collect();
    let within = fixes
        .iter()
        .filter(|r| matches!((r.pos_err_m, r.center_sigma_m), (Some(e), Some(s)) if e <= 3.0 * s))
        .count();
    let mut reasons = std::collections::BTreeMap::new();
    for r in rows.iter().filter(|r| !r.fix) {
        *reasons
            .entry(r.no_fix_reason.clone().unwrap_or_default())
            .or_insert(0) += 1;
    }
    let mut refine_notes = std::collections::BTreeMap::new();
    for r in &fixes {
        if let Some(note) = &r.refine_note {
            *refine_notes.entry(note.clone()).or_insert(0) += 1;
        }
    }
    let summary = EvalSummary {
        trials: rows.len(),
        seed: a.seed,
        success_rate: good.len() as f64 / n,
        false_fix_rate: (fixes.len() - good.len()) as f64 / n,
        no_fix_rate: (rows.len() - fixes.len()) as f64 / n,
        pos_err_p50_m: percentile(&mut pos.clone(), 0.5),
        pos_err_p95_m: percentile(&mut pos, 0.95),
        pos_err_max_m: fixes.iter().filter_map(|r| r.pos_err_m).fold(0.0, f64::max),
        heading_err_p95_deg: percentile(&mut head.clone(), 0.95),
        heading_err_max_deg: head.iter().copied().fold(0.0, f64::max),
        scale_err_p95: percentile(&mut scl, 0.95),
        reg_err_mean_px: reg.iter().sum::<f64>() / reg.len().max(1) as f64,
        within_3sigma_frac: within as f64 / fixes.len().max(1) as f64,
        time_ms_mean: rows.iter().map(|r| r.time_ms).sum::<f64>() / n,
        no_fix_reasons: reasons,
        refined_frac: fixes.iter().filter(|r| r.refined).count() as f64 / fixes.len().max(1) as f64,
        refine_notes,
        refined_nees_mean: {
            let v: Vec<f64> = good
                .iter()
                .filter_map(|r| Some((r.pos_err_m? / r.refined_sigma_m?).powi(2)))
                .collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        },
        pixel_range_m: [a.pixel_min_m, a.pixel_max_m],
        sensor,
    };
    head.clear();
    println!("trials      {} (seed {})", summary.trials, summary.seed);
    println!(
        "success     {:.2} %  false fix {:.2} %  no fix {:.2} %",
        summary.success_rate * 100.0,
        summary.false_fix_rate * 100.0,
        summary.no_fix_rate * 100.0
    );
    println!(
        "position    p50 {:.2} m  p95 {:.2} m  max {:.2} m",
        summary.pos_err_p50_m, summary.pos_err_p95_m, summary.pos_err_max_m
    );
    println!(
        "heading     p95 {:.3}°  max {:.3}°;  scale error p95 {:.3} %",
        summary.heading_err_p95_deg,
        summary.heading_err_max_deg,
        summary.scale_err_p95 * 100.0
    );
    println!(
        "consistency {:.1} % of fixes within their 3σ; mean onboard time {:.2} ms",
        summary.within_3sigma_frac * 100.0,
        summary.time_ms_mean
    );
    if !summary.no_fix_reasons.is_empty() {
        println!("no fix      {:?}", summary.no_fix_reasons);
    }
    println!(
        "refined     {:.1} % of fixes (their own covariance: mean NEES {:.2}, 2 = consistent){}",
        summary.refined_frac * 100.0,
        summary.refined_nees_mean,
        if summary.refine_notes.is_empty() {
            String::new()
        } else {
            format!(" (not refined: {:?})", summary.refine_notes)
        }
    );
    super::write_json(&a.json, &summary)?;
    let csv_path = a
        .csv
        .clone()
        .unwrap_or_else(|| a.json.with_extension("csv"));
    let mut csv = std::io::BufWriter::new(
        std::fs::File::create(&csv_path)
            .with_context(|| format!("creating {}", csv_path.display()))?,
    );
    writeln!(
        csv,
        "trial,x_m,y_m,heading_deg,pixel_m,fix,false_fix,features,matches,inliers,rotation_deg,heading_err_deg,scale,scale_truth,pos_err_m,center_err_px,reg_err_mean_px,reg_err_max_px,center_sigma_m,time_ms,refined,ncc,refined_sigma_m,refine_note,no_fix_reason"
    )?;
    let o = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x:.6}"));
    for (i, r) in rows.iter().enumerate() {
        let t = r.truth.unwrap_or(FramePose {
            x_m: f64::NAN,
            y_m: f64::NAN,
            heading_rad: f64::NAN,
            pixel_m: f64::NAN,
        });
        writeln!(
            csv,
            "{i},{:.3},{:.3},{:.4},{:.4},{},{},{},{},{},{},{},{},{:.6},{},{},{},{},{},{:.3},{},{},{},{},{}",
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
            o(r.center_err_px),
            o(r.pos_err_mean_px),
            o(r.pos_err_max_px),
            o(r.center_sigma_m),
            r.time_ms,
            r.refined,
            o(r.ncc.map(f64::from)),
            o(r.refined_sigma_m),
            r.refine_note.as_deref().unwrap_or(""),
            r.no_fix_reason.as_deref().unwrap_or("")
        )?;
    }
    println!(
        "json        {}\ncsv         {}",
        a.json.display(),
        csv_path.display()
    );
    Ok(())
}
