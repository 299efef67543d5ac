//! `ground-sim suite`: every scene of the terrain suite × {truth-built, InSAR tile} × {no prior,
//! prior} as `eval` campaigns, one table, one picture, JSON; the navigability map of every tile
//! scored against the same frames.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::bail;
use ground_sim::evaluation::campaign::PriorSpec;
use ground_sim::evaluation::navmap::NavmapThresholds;
use ground_sim::evaluation::rehearsal::{REHEARSAL_FRAMES, REHEARSAL_STEP_M, RehearsalSpec};
use ground_sim::evaluation::suite::{
    SHARED_DATA_DIR, SuiteReport, SuiteSpec, TileKind, default_scenes, run_scene, suite_picture,
    table_markdown,
};
use ground_sim::sar::cli::RadarArgs;

/// Arguments of `ground-sim suite`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Output folder: one sub-folder per scene (DEM, tiles, campaign CSV/JSON, navmaps) and
    /// `suite.json`, `suite.md`, `suite.png`.
    #[arg(long, default_value = "out/suite")]
    pub out: PathBuf,
    /// Frames per campaign.
    #[arg(long, default_value_t = 300)]
    pub trials: usize,
    /// Campaign seed (frame poses, noise, prior draws; `--seed` is the radar's noise seed).
    #[arg(long, default_value_t = 1)]
    pub campaign_seed: u64,
    /// Terrain seed of the synthetic scenes.
    #[arg(long, default_value_t = 1)]
    pub terrain_seed: u64,
    /// Side of every scene, metres.
    #[arg(long, default_value_t = 4000.0)]
    pub size_m: f64,
    /// CI size: 3 km scenes, 120-px frames, 40 frames per campaign, rehearsal sites 250 m apart
    /// (overrides those flags).
    #[arg(long)]
    pub quick: bool,
    /// Only these scenes (names as in the table; default all).
    #[arg(long, value_delimiter = ',')]
    pub scenes: Vec<String>,
    /// Tile kinds to fly.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [TileKind::Truth, TileKind::Insar])]
    pub kinds: Vec<TileKind>,
    /// Position σ of the prior mode, metres (0: fly without a prior only).
    #[arg(long, default_value_t = 50.0)]
    pub prior_sigma_m: f64,
    /// Heading σ of the prior mode, degrees.
    #[arg(long, default_value_t = 2.0)]
    pub prior_heading_sigma_deg: f64,
    /// Frame side, pixels.
    #[arg(long, default_value_t = 200)]
    pub size_px: usize,
    /// Folder of real DEMs that join the suite when present.
    #[arg(long, default_value = SHARED_DATA_DIR)]
    pub shared: PathBuf,
    /// Radar of the InSAR tiles (as `insar`: the mission design at NESZ −25 dB unless told
    /// otherwise; `--radar paper` for the paper's noise-free model).
    #[command(flatten)]
    pub radar: RadarArgs,
    /// Look directions of the InSAR tiles (`both`: a second, west-looking pass fused in).
    /// Default: the radar preset's (`mission` both, `paper` one).
    #[arg(long, value_enum)]
    pub looks: Option<ground_sim::insar::pipeline::LookDirections>,
    /// Passes of one track stacked per look for the InSAR tiles (1–16; receiver noise
    /// independent per pass, the same ground; each pass adds its SAR time).
    #[arg(long, default_value_t = 1)]
    pub passes: usize,
    /// A second, longer baseline for the InSAR tiles, m (0 = none; `insar --long-baseline-m`).
    /// Default: the radar preset's (`mission` 128 m, `paper` none).
    #[arg(long)]
    pub long_baseline_m: Option<f64>,
    /// σ of the long pair's DEM filter, output pixels (`insar --long-filter-sigma-px`;
    /// default the short pair's).
    #[arg(long)]
    pub long_filter_sigma_px: Option<f64>,
    /// Kernel of the InSAR tiles' DEM filter, at its default σ (`quadratic`: the local
    /// quadratic fit at 2 px; docs/insar.md, "A filter without curvature bias").
    #[arg(long, value_enum, default_value_t = ground_sim::insar::InsarConfig::default().dem_filter)]
    pub dem_filter: ground_sim::insar::pipeline::DemFilterKind,
    /// InSAR tiles' features detected on their DEM as it is, holes and all (`insar
    /// --keep-tile-holes`; the default fills the small holes first).
    #[arg(long)]
    pub keep_tile_holes: bool,
    /// Spacing of the navigability map's rehearsal sites, metres (0: no rehearsal, the
    /// footprint rule only).
    #[arg(long, default_value_t = REHEARSAL_STEP_M)]
    pub rehearsal_step_m: f64,
    /// Rehearsal frames per site.
    #[arg(long, default_value_t = REHEARSAL_FRAMES)]
    pub rehearsal_frames: usize,
    /// Simulation-only diagnostic: rehearse from the scene's true terrain instead of a draw
    /// from the map and its error (separates what the map's error model misses from the go
    /// rule's own limit; docs/navmap.md). Recorded in suite.json's spec.
    #[arg(long)]
    pub rehearse_on_truth: bool,
    /// The navigator budget.
    #[command(flatten)]
    pub budget: super::BudgetArgs,
}

/// Run `ground-sim suite`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let (trials, size_m, size_px, rehearsal_step_m) = if a.quick {
        {
            let step = if a.rehearsal_step_m == 0.0 {
                0.0
            } else {
                // What was asked must make sense even where the quick size overrides it.
                RehearsalSpec {
                    step_m: a.rehearsal_step_m,
                    ..RehearsalSpec::default()
                }
                .validate()?;
                250.0
            };
            (40, 3000.0, 120, step)
        }
    } else {
        (a.trials, a.size_m, a.size_px, a.rehearsal_step_m)
    };
    if trials == 0 {
        bail!("--trials must be ≥ 1");
    }
    let (radar, polarisation) = super::insar::radar_config(&a.radar)?;
    let long_baseline_m =
        super::insar::long_baseline_or_preset(a.long_baseline_m, &a.radar, &radar);
    let passes = ground_sim::insar::InsarConfig {
        passes: a.passes,
        long_baseline_m,
        long_filter_sigma_px: a.long_filter_sigma_px,
        ..Default::default()
    };
    passes.validate()?;
    if a.long_baseline_m.is_some_and(|b| b > 0.0) && !a.kinds.contains(&TileKind::Insar) {
        bail!("--long-baseline-m is a radar option of the InSAR tiles: give --kinds insar too");
    }
    if a.passes > 1 && !a.kinds.contains(&TileKind::Insar) {
        bail!("--passes stacks the radar's passes of the InSAR tiles: give --kinds insar too");
    }
    let shared = a.shared.is_dir().then_some(a.shared.as_path());
    if shared.is_none() {
        println!(
            "note: {} is absent: the real-DEM scenes are left out",
            a.shared.display()
        );
    }
    let mut scenes = default_scenes(a.terrain_seed, size_m, shared);
    if !a.scenes.is_empty() {
        for n in &a.scenes {
            if !scenes.iter().any(|s| &s.name == n) {
                let all: Vec<&str> = scenes.iter().map(|s| s.name.as_str()).collect();
                bail!("no scene named {n:?}; the suite has {}", all.join(", "));
            }
        }
        scenes.retain(|s| a.scenes.contains(&s.name));
    }
    // 0 turns the rehearsal off; anything else must be a spacing it can fly (checked before
    // the first scene, not after its first campaign).
    let rehearsal = (rehearsal_step_m != 0.0)
        .then(|| RehearsalSpec {
            step_m: rehearsal_step_m,
            frames_per_site: a.rehearsal_frames,
            seed: a.campaign_seed,
            ..RehearsalSpec::default()
        })
        .map(|r| r.validate().map(|()| r))
        .transpose()?;
    if a.rehearse_on_truth && rehearsal.is_none() {
        bail!("--rehearse-on-truth needs the rehearsal (a --rehearsal-step-m other than 0)");
    }
    let mut priors = vec![None];
    if a.prior_sigma_m > 0.0 {
        priors.push(Some(PriorSpec {
            sigma_m: a.prior_sigma_m,
            heading_sigma_deg: a.prior_heading_sigma_deg,
            scale_sigma: 0.02,
        }));
    }
    let sensor = ground_sim::flyer::frames::SensorModel {
        width_px: size_px,
        height_px: size_px,
        ..Default::default()
    };
    ground_sim::insar::pipeline::check_long_baseline(&radar, &passes)?;
    let spec = SuiteSpec {
        trials,
        seed: a.campaign_seed,
        pixel_range_m: [9.0, 11.0],
        sensor,
        kinds: a.kinds.clone(),
        priors,
        reference_pixel_m: 20.0,
        radar,
        polarisation,
        looks: super::insar::looks_or_preset(a.looks, &a.radar),
        passes: a.passes,
        long_baseline_m,
        long_filter_sigma_px: a.long_filter_sigma_px,
        dem_filter: a.dem_filter,
        fill_tile_holes: !a.keep_tile_holes,
        navmap: NavmapThresholds::default(),
        rehearsal,
        rehearse_on_truth: a.rehearse_on_truth,
        budget: a.budget.budget,
    };
    let n_campaigns = scenes.len() * spec.kinds.len() * spec.priors.len();
    let pb = super::progress(n_campaigns as u64, "suite");
    let mut report = SuiteReport {
        spec,
        scenes: Vec::new(),
        rows: Vec::new(),
        seconds: 0.0,
    };
    for scene in &scenes {
        let (sr, rows) = run_scene(scene, &report.spec, &a.out.join(&scene.name), &pb)?;
        // Printed whether or not the bar shows (a hidden bar's println prints nothing).
        let line = format!(
            "{:<18} {:>5.1} s  {}",
            scene.name,
            sr.seconds,
            rows.iter()
                .map(|r| format!(
                    "{}{}: {:.1} %",
                    r.kind.name(),
                    if r.summary.prior.is_some() {
                        "+prior"
                    } else {
                        ""
                    },
                    100.0 * r.summary.success_rate
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
        pb.suspend(|| println!("{line}"));
        report.scenes.push(sr);
        report.rows.extend(rows);
    }
    pb.finish_and_clear();
    report.seconds = t0.elapsed().as_secs_f64();
    let table = table_markdown(&report);
    println!("\n{table}");
    println!(
        "suite: {} campaigns in {:.0} s",
        report.rows.len(),
        report.seconds
    );
    write_outputs(&report, &table, &a.out)
}

fn write_outputs(report: &SuiteReport, table: &str, out: &Path) -> anyhow::Result<()> {
    super::write_json(&out.join("suite.json"), report)?;
    std::fs::write(out.join("suite.md"), table)?;
    suite_picture(report).save(out.join("suite.png"))?;
    println!(
        "json {}\ntable {}\npicture {}",
        out.join("suite.json").display(),
        out.join("suite.md").display(),
        out.join("suite.png").display()
    );
    Ok(())
}
