//! `ground-sim descent`: a campaign of closed-loop hops (dynamics, IMU, TRN frames, nav filter,
//! guidance) over the truth terrain against a reference tile.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, anyhow, bail};
use ground_sim::dem::read_geotiff;
use ground_sim::evaluation::campaign::percentile;
use ground_sim::evaluation::descent::{DescentConfig, RunResult, fly};
use ground_sim::flyer::frames::{centre_extent, frame_reach_m};
use ground_sim::flyer::onboard::{WORKSPACE_STACK, new_workspace};
use ground_sim::pictures::plot::{Plot, Series, Style};
use ground_sim::reference::load;
use nav_core::{NavConfig, Navigator, Tile};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

/// Arguments of `ground-sim descent`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder (tile.bin).
    #[arg(long)]
    pub tile: PathBuf,
    /// Truth DEM (GeoTIFF); it must be large enough for the hops.
    #[arg(long)]
    pub dem: PathBuf,
    /// Campaign seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of hops.
    #[arg(long, default_value_t = 1)]
    pub runs: usize,
    /// Shortest hop, m.
    #[arg(long, default_value_t = DescentConfig::default().hop_min_m)]
    pub hop_min_m: f64,
    /// Longest hop, m (clipped to what the DEM allows).
    #[arg(long, default_value_t = DescentConfig::default().hop_max_m)]
    pub hop_max_m: f64,
    /// TRN frames per second.
    #[arg(long, default_value_t = DescentConfig::default().frame_rate_hz)]
    pub frame_rate_hz: f64,
    /// Fly without the Doppler velocimeter (TRN, IMU, altimeter, star tracker only).
    #[arg(long)]
    pub no_velocimeter: bool,
    /// Fly without the star tracker.
    #[arg(long)]
    pub no_star_tracker: bool,
    /// Summary JSON.
    #[arg(long)]
    pub json: PathBuf,
    /// Folder for the trajectory and error pictures of the first run (default: beside the JSON).
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// The navigator budget.
    #[command(flatten)]
    pub budget: super::BudgetArgs,
}

/// Campaign summary (the JSON of `ground-sim descent`).
#[derive(Debug, Serialize)]
pub struct DescentSummary {
    /// Hops flown.
    pub runs: usize,
    /// Campaign seed.
    pub seed: u64,
    /// The navigator budget the frames were flown with (`flight` is what flies).
    pub budget: String,
    /// Median landing error, m.
    pub landing_err_p50_m: f64,
    /// 95th percentile landing error, m.
    pub landing_err_p95_m: f64,
    /// Largest landing error, m.
    pub landing_err_max_m: f64,
    /// RMS horizontal navigation error over all runs and frame times, m.
    pub nav_err_rms_m: f64,
    /// Fixes accepted by the filter (all runs).
    pub fixes: usize,
    /// Fixes rejected by the filter's gate.
    pub rejected_fixes: usize,
    /// Frames without a fix.
    pub no_fixes: usize,
    /// Fraction of frame times with the horizontal NEES in the 95 % χ²(2) band.
    pub nees_in_band_frac: f64,
    /// Mean horizontal NEES over all runs (2 for a consistent filter).
    pub nees_mean: f64,
    /// Mean hop length, m.
    pub hop_mean_m: f64,
    /// Mean flight time, s.
    pub flight_mean_s: f64,
    /// Settings.
    pub config: DescentConfig,
    /// Per-run results.
    pub per_run: Vec<RunResult>,
}

/// Run `ground-sim descent`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    if a.runs == 0 {
        bail!("--runs must be ≥ 1");
    }
    let reference = load(&a.tile)?;
    let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
    let dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let d = DescentConfig::default();
    let cfg = DescentConfig {
        hop_min_m: a.hop_min_m,
        hop_max_m: a.hop_max_m,
        frame_rate_hz: a.frame_rate_hz,
        velocimeter_sigma_mps: if a.no_velocimeter {
            0.0
        } else {
            d.velocimeter_sigma_mps
        },
        star_tracker_sigma_rad: if a.no_star_tracker {
            0.0
        } else {
            d.star_tracker_sigma_rad
        },
        ..d
    };
    // Release points and targets: inside the DEM, a cruise frame's reach from the edges.
    let (x0, x1, y0, y1) = centre_extent(&dem);
    let m = frame_reach_m(&cfg.sensor, cfg.cruise_agl_m * cfg.ifov_rad * 1.3);
    let (x0, x1, y0, y1) = (x0 + m, x1 - m, y0 + m, y1 - m);
    let diag = (x1 - x0).hypot(y1 - y0);
    if !(x1 > x0 && y1 > y0) || diag < cfg.hop_min_m {
        bail!(
            "the DEM is too small for {:.0} m hops with {:.0} m frames",
            cfg.hop_min_m,
            2.0 * m
        );
    }
    let hop_max = cfg.hop_max_m.min(0.9 * diag);
    let nav = Navigator::new(tile, NavConfig::default());
    let pool = rayon::ThreadPoolBuilder::new()
        .stack_size(WORKSPACE_STACK)
        .build()?;
    let pb = super::progress(a.runs as u64, "descent");
    let done = AtomicUsize::new(0);
    let results: Vec<anyhow::Result<RunResult>> = pool.install(|| {
        (0..a.runs)
            .into_par_iter()
            .map_init(
                || new_workspace(a.budget.budget),
                |ws, i| {
                    let mut rng = rand_pcg::Pcg64::seed_from_u64(
                        a.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ (i as u64 + 1),
                    );
                    // Draw a release point and a target at a hop length in range, both inside.
                    let mut pick = None;
                    for _ in 0..1000 {
                        let r = [
                            x0 + (x1 - x0) * rng.random::<f64>(),
                            y0 + (y1 - y0) * rng.random::<f64>(),
                        ];
                        let d = cfg.hop_min_m
                            + (hop_max - cfg.hop_min_m).max(0.0) * rng.random::<f64>();
                        let b = std::f64::consts::TAU * rng.random::<f64>();
                        let t = [r[0] + d * b.cos(), r[1] + d * b.sin()];
                        if (x0..=x1).contains(&t[0]) && (y0..=y1).contains(&t[1]) {
                            pick = Some((r, t));
                            break;
                        }
                    }
                    let (r, t) = pick.ok_or_else(|| anyhow!("run {i}: no hop fits the DEM"))?;
                    let out = fly(i, &dem, &nav, ws, &cfg, r, t, rng.random::<u64>());
                    pb.set_position(done.fetch_add(1, Ordering::Relaxed) as u64 + 1);
                    out
                },
            )
            .collect()
    });
    pb.finish_and_clear();
    let per_run: Vec<RunResult> = results.into_iter().collect::<anyhow::Result<_>>()?;
    let mut land: Vec<f64> = per_run.iter().map(|r| r.landing_err_m).collect();
    let samples: usize = per_run.iter().map(|r| r.history.len()).sum();
    let sq: f64 = per_run
        .iter()
        .flat_map(|r| r.history.iter())
        .map(|s| (s.truth_m[0] - s.est_m[0]).powi(2) + (s.truth_m[1] - s.est_m[1]).powi(2))
        .sum();
    let in_band = per_run
        .iter()
        .flat_map(|r| r.history.iter())
        .filter(|s| (0.0506..=7.378).contains(&s.nees))
        .count();
    let summary = DescentSummary {
        runs: per_run.len(),
        seed: a.seed,
        budget: a.budget.budget.label(),
        landing_err_p50_m: percentile(&mut land.clone(), 0.5),
        landing_err_p95_m: percentile(&mut land.clone(), 0.95),
        landing_err_max_m: land.iter().copied().fold(0.0, f64::max),
        nav_err_rms_m: (sq / samples.max(1) as f64).sqrt(),
        fixes: per_run.iter().map(|r| r.fixes).sum(),
        rejected_fixes: per_run.iter().map(|r| r.rejected_fixes).sum(),
        no_fixes: per_run.iter().map(|r| r.no_fixes).sum(),
        nees_in_band_frac: in_band as f64 / samples.max(1) as f64,
        nees_mean: per_run
            .iter()
            .flat_map(|r| r.history.iter())
            .map(|s| s.nees)
            .filter(|v| v.is_finite())
            .sum::<f64>()
            / samples.max(1) as f64,
        hop_mean_m: per_run.iter().map(|r| r.hop_m).sum::<f64>() / per_run.len() as f64,
        flight_mean_s: per_run.iter().map(|r| r.flight_s).sum::<f64>() / per_run.len() as f64,
        config: cfg,
        per_run,
    };
    land.clear();
    println!(
        "runs         {} (seed {}), mean hop {:.0} m, mean flight {:.0} s",
        summary.runs, summary.seed, summary.hop_mean_m, summary.flight_mean_s
    );
    println!(
        "landing      p50 {:.2} m  p95 {:.2} m  max {:.2} m",
        summary.landing_err_p50_m, summary.landing_err_p95_m, summary.landing_err_max_m
    );
    println!(
        "navigation   RMS {:.2} m; fixes {} accepted, {} rejected by the gate, {} frames without a fix",
        summary.nav_err_rms_m, summary.fixes, summary.rejected_fixes, summary.no_fixes
    );
    println!(
        "consistency  {:.1} % of horizontal NEES values in the 95 % band",
        summary.nees_in_band_frac * 100.0
    );
    super::write_json(&a.json, &summary)?;
    println!("json         {}", a.json.display());
    let dir = a
        .png
        .clone()
        .unwrap_or_else(|| a.json.parent().map(|p| p.to_path_buf()).unwrap_or_default());
    if let Some(r) = summary.per_run.first() {
        write_pictures(r, &dir)?;
    }
    Ok(())
}

fn write_pictures(r: &RunResult, dir: &std::path::Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let h = &r.history;
    let km = |v: f64| v / 1000.0;
    let traj = Plot {
        width: 900,
        height: 800,
        title: format!(
            "hop {} : {:.1} km, landing error {:.1} m",
            r.run,
            r.hop_m / 1000.0,
            r.landing_err_m
        ),
        x_label: "east (km)".into(),
        y_label: "north".into(),
        equal_axes: true,
        series: vec![
            Series {
                label: "truth".into(),
                colour: [30, 30, 30],
                points: h
                    .iter()
                    .map(|s| (km(s.truth_m[0]), km(s.truth_m[1])))
                    .collect(),
                style: Style::Line,
            },
            Series {
                label: "estimate".into(),
                colour: [30, 90, 220],
                points: h.iter().map(|s| (km(s.est_m[0]), km(s.est_m[1]))).collect(),
                style: Style::Line,
            },
            Series {
                label: "TRN fixes".into(),
                colour: [30, 170, 60],
                points: h
                    .iter()
                    .filter_map(|s| s.fix_m.map(|f| (km(f[0]), km(f[1]))))
                    .collect(),
                style: Style::Dots(3),
            },
            Series {
                label: "target".into(),
                colour: [220, 40, 40],
                points: vec![(km(r.target_m[0]), km(r.target_m[1]))],
                style: Style::Dots(6),
            },
        ],
    };
    let p1 = dir.join("descent-trajectory.png");
    traj.render()
        .save(&p1)
        .with_context(|| format!("writing {}", p1.display()))?;
    let err = Plot {
        width: 1000,
        height: 600,
        title: format!("hop {}: east error with its 3-sigma envelope", r.run),
        x_label: "time (s)".into(),
        y_label: "m".into(),
        equal_axes: false,
        series: vec![
            Series {
                label: "+3 sigma".into(),
                colour: [150, 150, 150],
                points: h.iter().map(|s| (s.t_s, 3.0 * s.sigma_m[0])).collect(),
                style: Style::Line,
            },
            Series {
                label: "-3 sigma".into(),
                colour: [150, 150, 150],
                points: h.iter().map(|s| (s.t_s, -3.0 * s.sigma_m[0])).collect(),
                style: Style::Line,
            },
            Series {
                label: "east error".into(),
                colour: [30, 90, 220],
                points: h
                    .iter()
                    .map(|s| (s.t_s, s.truth_m[0] - s.est_m[0]))
                    .collect(),
                style: Style::Line,
            },
            Series {
                label: "north error".into(),
                colour: [220, 120, 30],
                points: h
                    .iter()
                    .map(|s| (s.t_s, s.truth_m[1] - s.est_m[1]))
                    .collect(),
                style: Style::Line,
            },
        ],
    };
    let p2 = dir.join("descent-error.png");
    err.render()
        .save(&p2)
        .with_context(|| format!("writing {}", p2.display()))?;
    println!("pictures     {} {}", p1.display(), p2.display());
    Ok(())
}
