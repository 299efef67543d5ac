//! `ground-sim demo`: the whole ground chain end to end into one folder.
//!
//! terrain (`shackleton` preset) → SAR echoes and focusing (both antennas, HH) → InSAR DEM,
//! slope, mask and reference tile → one TRN check (a synthetic 10 m frame from the truth DEM
//! against the InSAR tile), then a summary table. Products:
//!
//! - `OUT/dem.tif`, `OUT/{hillshade,elevation,slope}.png`, `OUT/info.json` — the truth terrain;
//! - `OUT/sar/` — SLCs, σ0 pictures, SAR `report.json`;
//! - `OUT/insar/` — the reference folder (`tile.bin`, `slope.tif`, `reference-dem.tif`,
//!   `tile.json`) plus coherence/mask GeoTIFFs, Fig. 5/6 pictures and InSAR `report.json`;
//! - `OUT/trn.json`, `OUT/trn.png` — the TRN check (the paper's Fig. 7);
//! - `OUT/demo.json` — this summary.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, anyhow};
use ground_sim::dem::SampleKind;
use ground_sim::evaluation::trn::{TrnScore, check_frame};
use ground_sim::flyer::frames::{FramePose, SensorModel};
use ground_sim::flyer::onboard::Budget;
use ground_sim::insar::InsarConfig;
use ground_sim::insar::pipeline::{
    ChainRun, LookDirections, fly_long_pair, fuse_looks, mirrored_dem, process_simulated,
    run_from_dem, west_pass_seed,
};
use ground_sim::insar::products::{InsarReport, RunContext, SarSummary, write_outputs};
use ground_sim::reference::load;
use ground_sim::sar::RadarPreset;
use ground_sim::sar::SarConfig;
use ground_sim::sar::SarDem;
use ground_sim::sar::cli::RadarArgs;
use ground_sim::sar::pipeline::{SimOptions, simulate_with};
use ground_sim::sar::products::write_products;
use ground_sim::terrain::{Preset, TerrainParams};
use nav_core::Tile;

/// Arguments of `ground-sim demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Terrain seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write the summary JSON here (default: OUT/demo.json).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Heading of the TRN frame: its +x axis, clockwise from east, degrees.
    #[arg(long, default_value_t = 0.0)]
    pub heading_deg: f64,
    /// Radar design (default `mission`: 32 m baseline with a second 128 m pair, NESZ −25 dB,
    /// the Moon's diffuse echo, both looks; `paper`: the paper's noise-free model, 8 m, one look).
    #[arg(long, value_enum)]
    pub radar: Option<RadarPreset>,
    /// Thermal noise of the radar, NESZ in dB (default: the design's, −25 dB for `mission`).
    #[arg(long, allow_hyphen_values = true, conflicts_with = "no_noise")]
    pub nesz_db: Option<f64>,
    /// No thermal noise (only the noise: `--radar paper` for the paper's whole model).
    #[arg(long)]
    pub no_noise: bool,
    /// Diffuse surface backscatter at normal incidence, dB (default: the design's, −17 dB for
    /// `mission`, none for `paper`; docs/insar.md, "Walls under noise").
    #[arg(long, allow_hyphen_values = true)]
    pub diffuse_db: Option<f64>,
    /// Look directions: `one` (east, as the paper) or `both` (a second, west-looking pass
    /// fused in; twice the SAR time). Default: the design's (`mission` both, `paper` one).
    #[arg(long, value_enum)]
    pub looks: Option<LookDirections>,
    /// A second, longer baseline, m (0 = none; `insar --long-baseline-m`; its SAR time added).
    /// Default: the design's (`mission` 128 m, `paper` none).
    #[arg(long)]
    pub long_baseline_m: Option<f64>,
    /// Hide progress bars.
    #[arg(long)]
    pub no_progress: bool,
}

/// One line of the demo summary table.
#[derive(Debug, serde::Serialize)]
pub struct DemoStep {
    /// Step name.
    pub step: String,
    /// Main figure(s) of the step.
    pub result: String,
    /// Files written.
    pub files: Vec<PathBuf>,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// The demo's JSON: steps and the full outputs of each.
#[derive(Debug, serde::Serialize)]
pub struct DemoSummary {
    /// Steps run, in order.
    pub steps: Vec<DemoStep>,
    /// Whole run, wall-clock seconds.
    pub total_s: f64,
    /// The terrain step's full output.
    pub terrain: super::terrain::TerrainOutput,
    /// Radar simulation summary.
    pub sar: SarSummary,
    /// The InSAR report (also `OUT/insar/report.json`).
    pub insar: InsarReport,
    /// The TRN check (also `OUT/trn.json`).
    pub trn: TrnScore,
}

/// Run every stage into `out`.
pub fn run_demo(a: &Args) -> anyhow::Result<DemoSummary> {
    let out = &a.out;
    let t_all = Instant::now();
    let mut steps = Vec::new();

    // 1. Terrain.
    let t0 = Instant::now();
    let mut params = TerrainParams::new(Preset::Shackleton);
    params.seed = a.seed;
    let dem_path = out.join("dem.tif");
    let terrain = super::terrain::make(&params, &dem_path, SampleKind::F32, Some(out))?;
    let s = &terrain.stats;
    let mut files = vec![dem_path.clone()];
    files.extend(terrain.pictures.iter().cloned());
    steps.push(DemoStep {
        step: "terrain (shackleton, floor)".into(),
        result: format!(
            "{}x{} @ {} m, {:.0}..{:.0} m, slope<30 {:.2} %, <35 {:.2} %",
            s.width,
            s.height,
            s.pixel_m,
            s.elev_min_m,
            s.elev_max_m,
            100.0 * s.slope_lt30_frac,
            100.0 * s.slope_lt35_frac
        ),
        files,
        seconds: t0.elapsed().as_secs_f64(),
    });

    // 2. SAR: both antennas, HH, Range-Doppler focusing.
    let t0 = Instant::now();
    let truth = ground_sim::dem::read_geotiff(&dem_path)?;
    let radar = RadarArgs {
        radar: a.radar,
        nesz_db: a.nesz_db,
        no_noise: a.no_noise,
        diffuse_db: a.diffuse_db,
        ..RadarArgs::default()
    };
    let looks = super::insar::looks_or_preset(a.looks, &radar);
    let (sar_cfg, pol) = super::insar::radar_config(&radar)?;
    let (sdem, filled) = SarDem::from_dem(&truth)?;
    let opts = SimOptions {
        progress: !a.no_progress,
        ..SimOptions::default()
    };
    let pair = simulate_with(&sdem, &sar_cfg, &opts)?;
    let sar_dir = out.join("sar");
    let sar_report = write_products(&pair, [sdem.width, sdem.height], sdem.pixel_m, &sar_dir)?;
    let slc = &pair.slcs[0];
    steps.push(DemoStep {
        step: format!("SAR (A1+A2, HH, RDA; radar {})", radar.preset().name()),
        result: format!(
            "baseline {} m, {} facets, SLC {}x{}, NESZ {}, diffuse {}, echoes {:.1} s",
            sar_cfg.baseline_m,
            pair.stats.facets,
            slc.lines,
            slc.gates,
            if sar_cfg.noise_sigma0_linear().is_some() {
                format!("{} dB", sar_cfg.noise_equivalent_sigma0_db)
            } else {
                "none".into()
            },
            if sar_cfg.diffuse_sigma0_db.is_finite() {
                format!("{} dB", sar_cfg.diffuse_sigma0_db)
            } else {
                "none".into()
            },
            pair.timings.echoes_s
        ),
        files: vec![sar_dir.clone(), sar_report],
        seconds: t0.elapsed().as_secs_f64(),
    });

    // 3. InSAR and the reference folder.
    let t0 = Instant::now();
    let cfg = InsarConfig {
        long_baseline_m: super::insar::long_baseline_or_preset(a.long_baseline_m, &radar, &sar_cfg),
        ..InsarConfig::default()
    }
    .with_radar(&sar_cfg);
    cfg.validate()?;
    // The west-looking pass (the same radar over the mirrored scene, its own noise, as
    // `run_from_dem_looks` draws it) flies beside the east look's processing and second pair:
    // each is parallel inside, but not everywhere, and together they keep both cores busy.
    // Its progress bars stay off, so the east look's draw alone.
    let west_look = || -> anyhow::Result<Option<ChainRun>> {
        if looks != LookDirections::Both {
            return Ok(None);
        }
        let west_sar = SarConfig {
            seed: west_pass_seed(sar_cfg.seed),
            ..sar_cfg.clone()
        };
        run_from_dem(&mirrored_dem(&truth)?, &west_sar, pol, &cfg, false).map(Some)
    };
    let east_look = || -> anyhow::Result<_> {
        let (truth_grid, mut product) = process_simulated(&truth, &pair, pol, &cfg)?;
        // The east look's second pair (as `run_from_dem` flies it); the west look's comes
        // with its `run_from_dem`.
        let long = fly_long_pair(
            &sdem,
            &sar_cfg,
            pol,
            &cfg,
            !a.no_progress,
            &truth_grid.grid,
            &mut product,
        )?;
        Ok((truth_grid, product, long))
    };
    let (east, west) = rayon::join(east_look, west_look);
    let (truth_grid, mut product, long) = east?;
    let mut sar_summary = SarSummary::of(&pair);
    if let Some(long) = long {
        sar_summary.timings += &long;
    }
    if let Some(west) = west? {
        fuse_looks(&mut product, &west.product)?;
        // The report's SAR time is both passes' (as `insar` reports it).
        sar_summary.timings += &west.pair.timings;
    }
    let insar_dir = out.join("insar");
    let ctx = RunContext {
        sar: Some(sar_summary),
        input_dem: Some(dem_path.clone()),
        filled_nodata: filled,
        blocks: None,
    };
    let insar = write_outputs(&insar_dir, &product, &truth_grid, &ctx)?;
    let acc = &insar.accuracy;
    steps.push(DemoStep {
        step: match (looks, cfg.long_baseline_m > 0.0) {
            (LookDirections::One, false) => "InSAR DEM (20 m)".into(),
            (LookDirections::One, true) => format!(
                "InSAR DEM (20 m, + {} m pair; its SAR incl.)",
                cfg.long_baseline_m
            ),
            (LookDirections::Both, false) => {
                "InSAR DEM (20 m, both looks; west pass's SAR incl.)".into()
            }
            (LookDirections::Both, true) => format!(
                "InSAR DEM (20 m, both looks, + {} m pairs; their SAR incl.)",
                cfg.long_baseline_m
            ),
        },
        result: format!(
            "height RMSE {:.2} m (CRLB {:.2} m), slope RMSE {:.2}°, valid {:.1} %, coherence {:.3}",
            acc.height_rmse_m,
            acc.crlb_height_m,
            acc.slope_rmse_deg,
            100.0 * acc.valid_fraction,
            acc.coherence_mean
        ),
        files: vec![insar_dir.join("report.json")],
        seconds: t0.elapsed().as_secs_f64() - insar.products_s,
    });
    steps.push(DemoStep {
        step: "reference tile".into(),
        result: format!(
            "{}x{} px at {} m, {} SURF features, {} bytes",
            insar.tile.width_px,
            insar.tile.height_px,
            insar.tile.pixel_m,
            insar.tile_features,
            insar.tile.tile_bytes
        ),
        files: vec![insar_dir.join(ground_sim::reference::TILE_FILE)],
        seconds: insar.products_s,
    });

    // 4. One TRN check: a 10 m frame from the truth at the tile centre.
    let t0 = Instant::now();
    let trn = trn_check(&insar_dir, &truth, a.heading_deg, out)?;
    steps.push(DemoStep {
        step: format!("TRN check (10 m frame, {}°)", a.heading_deg),
        result: match (trn.rotation_deg, trn.pos_err_m) {
            (Some(r), Some(p)) => format!(
                "fix: {} matches, {} inliers, rotation {:.2}° (error {:+.2}°), scale {:.3}, \
                 position error {:.1} m, registration mean/max {:.2}/{:.2} px",
                trn.matches,
                trn.inliers,
                r,
                trn.heading_err_deg.unwrap_or(f64::NAN),
                trn.scale.unwrap_or(f64::NAN),
                p,
                trn.pos_err_mean_px.unwrap_or(f64::NAN),
                trn.pos_err_max_px.unwrap_or(f64::NAN)
            ),
            _ => format!(
                "no fix ({}): {} matches, {} inliers",
                trn.no_fix_reason.as_deref().unwrap_or("?"),
                trn.matches,
                trn.inliers
            ),
        },
        files: vec![out.join("trn.json"), out.join("trn.png")],
        seconds: t0.elapsed().as_secs_f64(),
    });

    Ok(DemoSummary {
        steps,
        total_s: t_all.elapsed().as_secs_f64(),
        terrain,
        sar: SarSummary::of(&pair),
        insar,
        trn,
    })
}

/// A synthetic 10 m frame (200 × 200 px, default sensor noise) from `truth` at the centre of
/// the tile in `tile_dir`, located by the onboard chain and scored; writes `trn.json` and the
/// match picture `trn.png` into `out`.
fn trn_check(
    tile_dir: &Path,
    truth: &ground_sim::dem::Dem,
    heading_deg: f64,
    out: &Path,
) -> anyhow::Result<TrnScore> {
    let reference = load(tile_dir)?;
    let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
    let h = tile.header();
    let (cx, cy) = h.pixel_to_geo(
        (h.width_px as f64 - 1.0) / 2.0,
        (h.height_px as f64 - 1.0) / 2.0,
    );
    let pose = FramePose {
        x_m: cx,
        y_m: cy,
        heading_rad: heading_deg.to_radians(),
        pixel_m: 10.0,
    };
    let sensor = SensorModel::default();
    let check = check_frame(truth, &tile, &pose, &sensor, 1, Budget::Flight)?;
    let s = check.score.clone();
    super::write_json(&out.join("trn.json"), &s)?;
    if let Some(ref_slope) = &reference.slope {
        let img = check.picture(ref_slope);
        let p = out.join("trn.png");
        img.save(&p)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(s)
}

/// Run `ground-sim demo`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let summary = run_demo(a)?;
    let json = a.json.clone().unwrap_or_else(|| a.out.join("demo.json"));
    super::write_json(&json, &summary)?;
    super::write_json(&a.out.join("info.json"), &summary.terrain.stats)?;
    println!("{:<32} {:>7}  result", "step", "time");
    for s in &summary.steps {
        println!("{:<32} {:>6.2}s  {}", s.step, s.seconds, s.result);
        for f in &s.files {
            println!("{:<32} {:>7}  -> {}", "", "", f.display());
        }
    }
    println!("{:<32} {:>6.2}s", "total", summary.total_s);
    super::terrain::print_craters(&summary.terrain.report);
    println!("summary json: {}", json.display());
    Ok(())
}
