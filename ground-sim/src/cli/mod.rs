//! Subcommands of the `ground-sim` binary, one file each. To add one: write `cli/NAME.rs` with
//! an `Args` struct (clap `Args`) and a `run(&Args) -> anyhow::Result<()>`, then add a variant to
//! `Commands` in `main.rs`.

pub mod atlas;
pub mod demo;
pub mod descent;
pub mod eval;
pub mod hazard_calibrate;
pub mod info;
pub mod insar;
pub mod landing;
pub mod merge;
pub mod navmap;
pub mod register;
pub mod resample;
pub mod results;
pub mod suite;
pub mod terrain;
pub mod tile;
pub mod trade;
pub mod trn;

use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar on stderr for a step of `len` units (hidden when stderr is not a terminal).
pub fn progress(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    let style =
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
    pb.set_style(style);
    pb.set_prefix(what.to_string());
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

pub use ground_sim::{ensure_parent, write_json};

/// Print DEM statistics as a two-column table.
pub fn print_stats(title: &str, s: &ground_sim::dem::stats::DemStats) {
    println!("{title}");
    let rows: Vec<(&str, String)> = vec![
        ("size", format!("{} x {} px", s.width, s.height)),
        ("pixel", format!("{} m", s.pixel_m)),
        (
            "origin (UL corner)",
            format!("x {:.3} m, y {:.3} m", s.origin_x_m, s.origin_y_m),
        ),
        (
            "extent",
            format!(
                "{:.0} x {:.0} m",
                s.extent_m[2] - s.extent_m[0],
                s.extent_m[3] - s.extent_m[1]
            ),
        ),
        ("nodata", format!("{}", s.nodata_count)),
        (
            "elevation",
            format!(
                "{:.1} .. {:.1} m (mean {:.1}, std {:.1})",
                s.elev_min_m, s.elev_max_m, s.elev_mean_m, s.elev_std_m
            ),
        ),
        (
            "slope p50/p90/p99/max",
            format!(
                "{:.1} / {:.1} / {:.1} / {:.1} deg",
                s.slope_p50_deg, s.slope_p90_deg, s.slope_p99_deg, s.slope_max_deg
            ),
        ),
        (
            "slope < 30 / < 35 deg",
            format!(
                "{:.2} % / {:.2} %",
                100.0 * s.slope_lt30_frac,
                100.0 * s.slope_lt35_frac
            ),
        ),
    ];
    let mut rows = rows;
    if let Some(c) = &s.main_crater {
        rows.push((
            "main crater",
            format!(
                "D {:.0} m, depth {:.0} m, d/D {:.3}",
                c.diameter_m, c.depth_m, c.d_over_d
            ),
        ));
    }
    let deps: Vec<String> = s
        .depressions
        .iter()
        .filter(|b| b.count > 0)
        .map(|b| format!("{:.0}-{:.0} m: {}", b.d_min_m, b.d_max_m, b.count))
        .collect();
    rows.push(("depressions", deps.join(", ")));
    for (k, v) in rows {
        println!("  {k:<24} {v}");
    }
}

/// The navigator budget as `trn`, `eval`, `descent` and `suite` take it on the command line.
#[derive(Debug, Clone, clap::Args)]
pub struct BudgetArgs {
    /// Navigator budget: `flight` (the firmware's, what flies) or `host` (bigger than what
    /// flies; labelled in every output).
    #[arg(long, value_enum, default_value_t = ground_sim::flyer::onboard::Budget::Flight)]
    pub budget: ground_sim::flyer::onboard::Budget,
}

/// The flyer's ranging sensor as `trn` and `eval` take it on the command line.
#[derive(Debug, Clone, clap::Args)]
pub struct SensorArgs {
    /// Frame side, pixels.
    #[arg(long, default_value_t = 200)]
    pub size_px: usize,
    /// Range noise 1σ, metres.
    #[arg(long, default_value_t = ground_sim::flyer::frames::SensorModel::default().range_noise_m)]
    pub noise_m: f64,
    /// Fraction of dropped pixels.
    #[arg(long, default_value_t = ground_sim::flyer::frames::SensorModel::default().dropout_frac)]
    pub dropout: f64,
}

impl SensorArgs {
    /// The sensor model these flags describe (square frames, other settings default).
    pub fn model(&self) -> ground_sim::flyer::frames::SensorModel {
        ground_sim::flyer::frames::SensorModel {
            width_px: self.size_px,
            height_px: self.size_px,
            range_noise_m: self.noise_m,
            dropout_frac: self.dropout,
            ..ground_sim::flyer::frames::SensorModel::default()
        }
    }
}

/// How `eval` and `descent` split a campaign over processes or machines.
#[derive(Debug, Clone, clap::Args)]
pub struct ShardArgs {
    /// Fly only shard I/N of the campaign: the trials k with k mod N = I, I 0-based
    /// (0 ≤ I < N, as Slurm's SLURM_ARRAY_TASK_ID with --array=0-(N-1)). `--json` then receives
    /// the shard file (campaign identity and per-trial records) that `ground-sim merge` joins.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<ground_sim::evaluation::shard::Shard>,
}
