//! `ground-sim trade`: the radar design trade of issue 16. Sweeps thermal noise × baseline ×
//! look directions over suite scenes; at every point the whole chain runs (SAR, InSAR, tile)
//! and a short `eval` campaign flies the flight navigator against the tile. One JSON, one
//! Markdown table, one picture (TRN success against NESZ, one curve per design).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use ground_sim::evaluation::campaign::PriorSpec;
use ground_sim::evaluation::navmap::NavmapThresholds;
use ground_sim::evaluation::suite::{SuiteSpec, TileKind, default_scenes, run_scene};
use ground_sim::insar::pipeline::LookDirections;
use ground_sim::pictures::plot::{PALETTE, Plot, Series, Style};
use ground_sim::sar::{Polarisation, SarConfig};
use serde::Serialize;

/// Arguments of `ground-sim trade`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Output folder: `trade.json`, `trade.md`, `trade.png` and one sub-folder per point.
    #[arg(long, default_value = "out/trade")]
    pub out: PathBuf,
    /// Suite scenes to map (names as `suite` prints them).
    #[arg(long, value_delimiter = ',', default_value = "lola")]
    pub scenes: Vec<String>,
    /// Noise-equivalent σ0 values, dB (`-inf` for no thermal noise).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = [-30.0, -25.0, -20.0])]
    pub nesz_db: Vec<f64>,
    /// Baseline lengths, m (the paper's radar otherwise; 30° tilt).
    #[arg(long, value_delimiter = ',', default_values_t = [8.0, 16.0, 32.0])]
    pub baseline_m: Vec<f64>,
    /// Look directions.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [LookDirections::One, LookDirections::Both])]
    pub looks: Vec<LookDirections>,
    /// Passes of one track stacked per look (1–16; independent receiver noise, the same
    /// ground).
    #[arg(long, value_delimiter = ',', default_values_t = [1usize])]
    pub passes: Vec<usize>,
    /// Diffuse surface backscatter at normal incidence, dB, for every point (default the
    /// Moon's, as the default mission radar flies; `-inf`: none, the paper's two-scale
    /// surface; docs/insar.md, "Walls under noise").
    #[arg(long, allow_hyphen_values = true, default_value_t = ground_sim::sar::MOON_DIFFUSE_DB)]
    pub diffuse_db: f64,
    /// Frames per TRN campaign.
    #[arg(long, default_value_t = 100)]
    pub trials: usize,
    /// Position σ of a prior, metres (0: lost in space, no prior).
    #[arg(long, default_value_t = 0.0)]
    pub prior_sigma_m: f64,
    /// Terrain seed of the scenes.
    #[arg(long, default_value_t = 1)]
    pub terrain_seed: u64,
    /// Side of every scene, metres (the suite's 4 km by default).
    #[arg(long, default_value_t = 4000.0)]
    pub size_m: f64,
    /// Campaign seed (frame poses and noise).
    #[arg(long, default_value_t = 1)]
    pub campaign_seed: u64,
    /// The navigator budget.
    #[command(flatten)]
    pub budget: super::BudgetArgs,
}

/// One design point's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct TradePoint {
    /// Scene name.
    pub scene: String,
    /// Noise-equivalent σ0, dB (null: no thermal noise).
    pub nesz_db: Option<f64>,
    /// Baseline, m.
    pub baseline_m: f64,
    /// Look directions.
    pub looks: LookDirections,
    /// Passes stacked per look.
    pub passes: usize,
    /// RMS per-pixel Cramér–Rao height bound of the chosen processing, m (for `both`, of the
    /// fused map: inverse-variance combination where both looks are valid).
    pub crlb_height_m: f64,
    /// Measured height RMSE against the truth, m.
    pub height_rmse_m: f64,
    /// Measured slope RMSE, degrees.
    pub slope_rmse_deg: f64,
    /// Valid fraction of the map.
    pub valid_fraction: f64,
    /// Features in the tile.
    pub tile_features: usize,
    /// Of those, the ones a truth-built tile on the same grid holds too (the map's blobs that
    /// are ground; `insar::products::features_on_truth`).
    pub tile_features_on_truth: usize,
    /// TRN success rate.
    pub success_rate: f64,
    /// False fixes (> 3 reference pixels).
    pub false_fixes: usize,
    /// Position error p95 of the fixes, m (NaN: no fix).
    pub pos_err_p95_m: f64,
    /// Seconds for the point (SAR, InSAR, tile, campaign).
    pub seconds: f64,
}

/// `trade.json`.
#[derive(Debug, Clone, Serialize)]
pub struct TradeReport {
    /// Frames per campaign.
    pub trials: usize,
    /// Campaign seed.
    pub campaign_seed: u64,
    /// Terrain seed.
    pub terrain_seed: u64,
    /// Side of every scene, m.
    pub size_m: f64,
    /// Diffuse surface backscatter at normal incidence, dB (null: none).
    pub diffuse_db: Option<f64>,
    /// Prior of the campaigns (null: none).
    pub prior: Option<PriorSpec>,
    /// Navigator budget.
    pub budget: String,
    /// Every point.
    pub points: Vec<TradePoint>,
    /// Wall time, s.
    pub seconds: f64,
}

/// Run `ground-sim trade`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let t0 = Instant::now();
    if a.trials == 0 {
        bail!("--trials must be ≥ 1");
    }
    if a.diffuse_db.is_nan() || a.diffuse_db > 0.0 {
        bail!("--diffuse-db must be ≤ 0 dB (or -inf for none)");
    }
    if a.nesz_db.iter().any(|v| v.is_nan()) || a.baseline_m.iter().any(|b| !(*b > 0.0)) {
        bail!("--nesz-db must be numbers (or -inf) and --baseline-m positive");
    }
    if a.nesz_db.is_empty() || a.baseline_m.is_empty() || a.looks.is_empty() || a.passes.is_empty()
    {
        bail!("--nesz-db, --baseline-m, --looks and --passes each need at least one value");
    }
    if let Some(p) = a
        .passes
        .iter()
        .find(|&&p| !(1..=ground_sim::insar::pipeline::MAX_PASSES).contains(&p))
    {
        bail!(
            "--passes must be 1–{}, got {p}",
            ground_sim::insar::pipeline::MAX_PASSES
        );
    }
    if !(a.size_m >= 1000.0 && a.size_m <= 20_000.0) {
        bail!("--size-m must be in [1000, 20000] m");
    }
    let all = default_scenes(a.terrain_seed, a.size_m, None);
    let mut scenes = Vec::new();
    for n in &a.scenes {
        match all.iter().find(|s| &s.name == n) {
            Some(s) => scenes.push(s.clone()),
            None => {
                let names: Vec<&str> = all.iter().map(|s| s.name.as_str()).collect();
                bail!(
                    "no scene named {n:?}; synthetic suite scenes: {}",
                    names.join(", ")
                );
            }
        }
    }
    let prior = (a.prior_sigma_m > 0.0).then_some(PriorSpec {
        sigma_m: a.prior_sigma_m,
        heading_sigma_deg: 2.0,
        scale_sigma: 0.02,
    });
    let n_points =
        scenes.len() * a.nesz_db.len() * a.baseline_m.len() * a.looks.len() * a.passes.len();
    let pb = super::progress(n_points as u64, "trade");
    let mut report = TradeReport {
        trials: a.trials,
        campaign_seed: a.campaign_seed,
        terrain_seed: a.terrain_seed,
        size_m: a.size_m,
        diffuse_db: a.diffuse_db.is_finite().then_some(a.diffuse_db),
        prior,
        budget: a.budget.budget.label().to_string(),
        points: Vec::new(),
        seconds: 0.0,
    };
    let points = scenes.iter().flat_map(|scene| {
        a.looks.iter().flat_map(move |&looks| {
            a.passes.iter().flat_map(move |&passes| {
                a.baseline_m.iter().flat_map(move |&baseline_m| {
                    a.nesz_db
                        .iter()
                        .map(move |&nesz| (scene, looks, passes, baseline_m, nesz))
                })
            })
        })
    });
    for (scene, looks, passes, baseline_m, nesz) in points {
        let t = Instant::now();
        let radar = SarConfig {
            baseline_m,
            noise_equivalent_sigma0_db: nesz,
            diffuse_sigma0_db: a.diffuse_db,
            polarisations: vec![Polarisation::HH],
            ..SarConfig::default()
        };
        let spec = SuiteSpec {
            trials: a.trials,
            seed: a.campaign_seed,
            pixel_range_m: [9.0, 11.0],
            sensor: Default::default(),
            kinds: vec![TileKind::Insar],
            priors: vec![prior],
            reference_pixel_m: 20.0,
            radar,
            polarisation: Polarisation::HH,
            looks,
            passes,
            long_baseline_m: 0.0,
            long_filter_sigma_px: None,
            dem_filter: Default::default(),
            fill_tile_holes: ground_sim::insar::InsarConfig::default().fill_tile_holes,
            navmap: NavmapThresholds::default(),
            rehearsal: None,
            rehearse_on_truth: false,
            budget: a.budget.budget,
        };
        let tag = format!(
            "{}-{}{}-b{baseline_m}-{}",
            scene.name,
            looks.name(),
            if passes > 1 {
                format!("-x{passes}")
            } else {
                String::new()
            },
            if nesz.is_finite() {
                format!("nesz{nesz}")
            } else {
                "quiet".to_string()
            }
        );
        let dir = a.out.join(&tag);
        let hidden = indicatif::ProgressBar::hidden();
        let (sr, rows) = run_scene(scene, &spec, &dir, &hidden)?;
        let row = rows.first().context("the point ran no campaign")?;
        let p = TradePoint {
            scene: scene.name.clone(),
            nesz_db: nesz.is_finite().then_some(nesz),
            baseline_m,
            looks,
            passes,
            crlb_height_m: sr.insar_crlb_height_m.unwrap_or(f64::NAN),
            height_rmse_m: sr.insar_height_rmse_m.unwrap_or(f64::NAN),
            slope_rmse_deg: sr.insar_slope_rmse_deg.unwrap_or(f64::NAN),
            valid_fraction: sr.insar_valid_frac.unwrap_or(f64::NAN),
            tile_features: row.tile_features,
            tile_features_on_truth: row
                .tile_features_on_truth
                .context("a trade point's tile is an InSAR tile, which counts its ground")?,
            success_rate: row.summary.success_rate,
            false_fixes: row.summary.false_fixes,
            pos_err_p95_m: row.summary.pos_err_p95_m,
            seconds: t.elapsed().as_secs_f64(),
        };
        let line = format!(
            "{tag:<34} height {:.2} m (CRLB {:.2}), slope {:.2}°, {} features ({} ground), TRN {:.1} %, {} false",
            p.height_rmse_m,
            p.crlb_height_m,
            p.slope_rmse_deg,
            p.tile_features,
            p.tile_features_on_truth,
            100.0 * p.success_rate,
            p.false_fixes
        );
        pb.suspend(|| println!("{line}"));
        pb.inc(1);
        report.points.push(p);
    }
    pb.finish_and_clear();
    report.seconds = t0.elapsed().as_secs_f64();
    let table = table_markdown(&report);
    println!("\n{table}");
    super::write_json(&a.out.join("trade.json"), &report)?;
    std::fs::write(a.out.join("trade.md"), &table)?;
    picture(&report).render().save(a.out.join("trade.png"))?;
    println!(
        "trade: {} points in {:.0} s\njson {}\ntable {}\npicture {}",
        report.points.len(),
        report.seconds,
        a.out.join("trade.json").display(),
        a.out.join("trade.md").display(),
        a.out.join("trade.png").display()
    );
    Ok(())
}

fn design_label(p: &TradePoint, many_scenes: bool) -> String {
    let looks = match p.looks {
        LookDirections::One => "1 look",
        LookDirections::Both => "2 looks",
    };
    let looks = if p.passes > 1 {
        format!("{looks} × {} passes", p.passes)
    } else {
        looks.to_string()
    };
    if many_scenes {
        format!("{} {} m {looks}", p.scene, p.baseline_m)
    } else {
        format!("{} m {looks}", p.baseline_m)
    }
}

/// The table: one row per point.
pub fn table_markdown(r: &TradeReport) -> String {
    let mut s = format!(
        "{} frames per campaign ({}), campaign seed {}, terrain seed {}, {}navigator budget {}.\n\n",
        r.trials,
        if r.prior.is_some() {
            "with a prior"
        } else {
            "no prior"
        },
        r.campaign_seed,
        r.terrain_seed,
        r.diffuse_db
            .map_or(String::new(), |d| format!("diffuse surface term {d} dB, ")),
        r.budget
    );
    s += "| scene | looks | passes | baseline | NESZ | CRLB | height RMSE (/CRLB) | slope RMSE | valid | tile feat. (ground) | TRN success | false | p95 |\n";
    s += "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for p in &r.points {
        s += &format!(
            "| {} | {} | {} | {} m | {} | {:.2} m | {:.2} m ({:.2}) | {:.2}° | {:.1} % | {} ({}) | {:.1} % | {} | {} |\n",
            p.scene,
            p.looks.name(),
            p.passes,
            p.baseline_m,
            p.nesz_db.map_or("none".to_string(), |v| format!("{v} dB")),
            p.crlb_height_m,
            p.height_rmse_m,
            p.height_rmse_m / p.crlb_height_m,
            p.slope_rmse_deg,
            100.0 * p.valid_fraction,
            p.tile_features,
            p.tile_features_on_truth,
            100.0 * p.success_rate,
            p.false_fixes,
            if p.pos_err_p95_m.is_finite() {
                format!("{:.1} m", p.pos_err_p95_m)
            } else {
                "–".to_string()
            }
        );
    }
    s
}

/// TRN success against NESZ, one curve per design (scene × baseline × looks). Points without
/// thermal noise are drawn 5 dB below the lowest noisy point.
pub fn picture(r: &TradeReport) -> Plot {
    let lowest = r
        .points
        .iter()
        .filter_map(|p| p.nesz_db)
        .fold(f64::INFINITY, f64::min);
    let quiet_x = if lowest.is_finite() {
        lowest - 5.0
    } else {
        -40.0
    };
    let many = r
        .points
        .iter()
        .any(|p| r.points.first().is_some_and(|q| q.scene != p.scene));
    let mut labels: Vec<String> = Vec::new();
    for p in &r.points {
        let l = design_label(p, many);
        if !labels.contains(&l) {
            labels.push(l);
        }
    }
    let series = labels
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let mut pts: Vec<(f64, f64)> = r
                .points
                .iter()
                .filter(|p| &design_label(p, many) == l)
                .map(|p| (p.nesz_db.unwrap_or(quiet_x), 100.0 * p.success_rate))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            Series {
                label: l.clone(),
                colour: PALETTE[i % PALETTE.len()],
                points: pts,
                style: Style::Line,
            }
        })
        .collect();
    Plot {
        width: 1000,
        height: 560,
        title: if lowest.is_finite() {
            format!("TRN success vs NESZ (no noise at {quiet_x} dB)")
        } else {
            "TRN success vs NESZ".to_string()
        },
        x_label: "NESZ, dB".into(),
        y_label: "TRN success, %".into(),
        series,
        equal_axes: false,
    }
}
