//! `ground-sim demo`: everything that exists so far, end to end, into one folder.
//!
//! Today: the `shackleton` preset terrain, its GeoTIFF, pictures and statistics. Later stages
//! (SAR, InSAR, reference tile, TRN) append their own step functions to [`run_demo`].

use std::path::{Path, PathBuf};

use ground_sim::dem::SampleKind;
use ground_sim::terrain::{Preset, TerrainParams};

/// Arguments of `ground-sim demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// PRNG seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write the summary JSON here (default: OUT/demo.json).
    #[arg(long)]
    pub json: Option<PathBuf>,
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
    /// The terrain step's full output.
    pub terrain: super::terrain::TerrainOutput,
}

/// Run every available stage into `out`.
pub fn run_demo(out: &Path, seed: u64) -> anyhow::Result<DemoSummary> {
    let mut steps = Vec::new();
    let t0 = std::time::Instant::now();
    let mut params = TerrainParams::new(Preset::Shackleton);
    params.seed = seed;
    let dem_path = out.join("dem.tif");
    let terrain = super::terrain::make(&params, &dem_path, SampleKind::F32, Some(out))?;
    let s = &terrain.stats;
    let mut files = vec![dem_path];
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
    // Later issues: SAR echoes, RDA focusing, InSAR DEM, reference tile, TRN fixes.
    Ok(DemoSummary { steps, terrain })
}

/// Run `ground-sim demo`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let summary = run_demo(&a.out, a.seed)?;
    let json = a.json.clone().unwrap_or_else(|| a.out.join("demo.json"));
    super::write_json(&json, &summary)?;
    super::write_json(&a.out.join("info.json"), &summary.terrain.stats)?;
    println!("{:<30} {:>7}  result", "step", "time");
    for s in &summary.steps {
        println!("{:<30} {:>6.2}s  {}", s.step, s.seconds, s.result);
        for f in &s.files {
            println!("{:<30} {:>7}  -> {}", "", "", f.display());
        }
    }
    super::terrain::print_craters(&summary.terrain.report);
    println!("summary json: {}", json.display());
    Ok(())
}
