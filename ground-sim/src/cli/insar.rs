//! `ground-sim insar`: DEM → (SAR simulation or given SLCs) → InSAR DEM, slope, mask, reference
//! tile, pictures and `report.json`, all in one folder that `trn` and `eval` take as `--tile`.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use anyhow::Context;
use ground_sim::dem::read_geotiff;
use ground_sim::insar::pipeline::{
    DemFilterKind, LookDirections, process_simulated, process_slcs, run_from_dem_looks,
};
use ground_sim::insar::products::{InsarReport, RunContext, SarSummary, write_outputs};
use ground_sim::insar::{InsarConfig, blocks, label};
use ground_sim::sar::cli::RadarArgs;
use ground_sim::sar::pipeline::{SimOptions, simulate_with};
use ground_sim::sar::{Polarisation, SarConfig, SarDem, Slc};

/// Arguments of `ground-sim insar`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// The scene DEM (GeoTIFF, north-up): what the radar sees, the grid of the product and the
    /// truth it is compared with. Rows = azimuth (flight direction), columns = ground range.
    #[arg(long)]
    pub dem: PathBuf,
    /// Output folder (a reference folder: tile.bin, slope.tif, reference-dem.tif, …).
    #[arg(long)]
    pub out: PathBuf,
    /// Take the SLCs from this `ground-sim sar --out` folder (simulated from the same DEM)
    /// instead of simulating: `slc_a1_<pol>.bin`, `slc_a2_<pol>.bin`.
    #[arg(long)]
    pub slc_dir: Option<PathBuf>,
    /// Output pixel, m (paper: 20).
    #[arg(long, default_value_t = InsarConfig::default().pixel_m)]
    pub pixel_m: f64,
    /// Coherence below which heights are dropped.
    #[arg(long, default_value_t = InsarConfig::default().min_coherence)]
    pub min_coherence: f64,
    /// Filter of the geocoded DEM: `gaussian` (the weighted mean) or `quadratic` (a local
    /// quadratic fit under Gaussian weights: no curvature bias, height and slope RMSE lower on
    /// every suite scene, but tiles not yet better for TRN; docs/insar.md).
    #[arg(long, value_enum, default_value_t = InsarConfig::default().dem_filter)]
    pub dem_filter: DemFilterKind,
    /// Detect the tile's features on the DEM as it is, holes and all (the default fills the
    /// small holes first, as `tile --fill-holes`; the tile's slope raster keeps them missing
    /// either way; docs/insar.md, "The parallax of the height error, and holes in the tile").
    #[arg(long)]
    pub keep_tile_holes: bool,
    /// σ of the DEM filter's Gaussian weights, output pixels (0 = no filter). Default: the
    /// kernel's (2 for `quadratic`, 1 for `gaussian`).
    #[arg(long)]
    pub dem_filter_sigma_px: Option<f64>,
    /// Passes of the speckle-centroid correction (each halves the remaining shift; 0 = the
    /// paper's chain, heights at the window centres).
    #[arg(long, default_value_t = InsarConfig::default().recentre_passes)]
    pub recentre_passes: usize,
    /// Mask dark cells (window power this many dB below the scene median) as shadow; `inf`
    /// masks by geometry and coherence only.
    #[arg(long, allow_hyphen_values = true, default_value_t = InsarConfig::default().shadow_below_median_db)]
    pub shadow_below_median_db: f64,
    /// Use the flat-removed phase wrapped (no unwrapping).
    #[arg(long)]
    pub no_unwrap: bool,
    /// Cell of the coarse prior DEM that picks the unwrapped phase's whole cycles, m (the
    /// `--dem` averaged over such cells, standing for LOLA's global topography; 0 = none, the
    /// unwrapper's datum rule alone). It never enters a height.
    #[arg(long, default_value_t = InsarConfig::default().prior_dem_cell_m)]
    pub prior_dem_cell_m: f64,
    /// Passes of one track stacked per look, 1–16: their interferograms are summed before the
    /// phase and coherence are taken (independent receiver noise, the same ground; each pass
    /// adds its SAR time). Not with `--slc-dir`.
    #[arg(long, default_value_t = 1)]
    pub passes: usize,
    /// A second, longer baseline, m (0 = none, the radar's own pair alone): its
    /// interferogram's heights replace the radar's own where they agree and are better (its
    /// cycles chosen against the short map; the same ground seen through its own receivers;
    /// its SAR time added; docs/insar.md, "A second, longer baseline"). Default: the radar
    /// preset's (`mission` 128 m, `paper` none), none where it would not be longer than the
    /// radar's own baseline or with `--slc-dir` (which holds one pair).
    #[arg(long)]
    pub long_baseline_m: Option<f64>,
    /// σ of the long pair's DEM filter (the Gaussian mean), output pixels (0 = none; default:
    /// the short pair's). 0.5 makes a better DEM of gentle cratered ground and tiles that
    /// navigate worse (docs/insar.md, "The error at the chain's own resolution, and the long
    /// pair's filter"). Only with `--long-baseline-m` and the Gaussian mean.
    #[arg(long)]
    pub long_filter_sigma_px: Option<f64>,
    /// Radar parameters (the first `--pol` is the InSAR channel, default HH). The default is
    /// the mission design with thermal noise at NESZ −25 dB; `--radar paper` gives the paper's
    /// noise-free model, `--no-noise` removes the thermal noise only.
    #[command(flatten)]
    pub radar: RadarArgs,
    /// Look directions: `one` (east, as the paper) or `both` (a second, west-looking pass over
    /// the same scene, fused cell by cell by validity and CRLB; twice the SAR time). Default:
    /// the radar preset's (`mission` both, `paper` one); one with `--slc-dir`.
    #[arg(long, value_enum)]
    pub looks: Option<LookDirections>,
    /// Hide progress bars.
    #[arg(long)]
    pub no_progress: bool,
    /// Largest core block side, output cells: a map wider or taller than this is made in
    /// overlapping blocks (each simulated and processed alone, memory bounded by the block,
    /// then mosaicked); 0 = always one piece.
    #[arg(long, default_value_t = blocks::DEFAULT_BLOCK_CELLS)]
    pub block_cells: usize,
    /// Margin added to each side of a block, output cells.
    #[arg(long, default_value_t = blocks::DEFAULT_OVERLAP_CELLS)]
    pub block_overlap_cells: usize,
    /// Make only block I of N (0-based, e.g. a Slurm array task) into OUT/blocks/ and stop;
    /// N must be the map's block count. `--mosaic` then joins them.
    #[arg(long, value_name = "I/N", conflicts_with = "mosaic")]
    pub block: Option<ground_sim::evaluation::shard::Shard>,
    /// Join the blocks already in OUT/blocks/ (made with the same DEM and flags) into the map
    /// products, without simulating anything.
    #[arg(long)]
    pub mosaic: bool,
    /// Print how the map would be cut (`blocks N rows R cols C`; N = 1 when it fits one
    /// piece) and stop: what a job-array script needs to know.
    #[arg(long, conflicts_with_all = ["mosaic", "block"])]
    pub plan_blocks: bool,
}

/// The radar configuration of an InSAR run: `RadarArgs` resolved as for `sar` (thermal noise
/// as the preset says: on at −25 dB for the default mission design), but only the InSAR
/// channel (first `--pol`, default HH).
pub fn radar_config(r: &RadarArgs) -> anyhow::Result<(ground_sim::sar::SarConfig, Polarisation)> {
    let mut sar = r.resolve()?;
    let pol = r.pol.first().copied().unwrap_or(Polarisation::HH);
    sar.polarisations = vec![pol];
    Ok((sar, pol))
}

/// The look directions a command flies: `--looks` when given, else the radar preset's
/// ([`LookDirections::of_preset`]).
pub fn looks_or_preset(looks: Option<LookDirections>, r: &RadarArgs) -> LookDirections {
    looks.unwrap_or_else(|| LookDirections::of_preset(r.preset()))
}

/// The second baseline a command's InSAR maps fuse in, m (0 = none): `given` when given, else
/// the radar preset's ([`ground_sim::sar::RadarPreset::long_baseline_m`]) where it is longer than `sar`'s own
/// baseline (a radar given a longer boom by hand flies that boom alone, and is told so).
pub fn long_baseline_or_preset(given: Option<f64>, r: &RadarArgs, sar: &SarConfig) -> f64 {
    if let Some(b) = given {
        return b;
    }
    let b = r.preset().long_baseline_m();
    if b > 0.0 && b <= sar.baseline_m {
        eprintln!(
            "note: the {} radar's second {b} m baseline is not longer than this radar's {} m: \
             its maps use the {} m pair alone (--long-baseline-m sets one)",
            r.preset().name(),
            sar.baseline_m,
            sar.baseline_m
        );
        return 0.0;
    }
    b
}

impl Args {
    /// This run's second baseline, m: `--long-baseline-m`, else none when `--slc-dir` brings
    /// one pair's SLCs, else the radar preset's ([`long_baseline_or_preset`]).
    pub fn long_baseline_m(&self, sar: &SarConfig) -> f64 {
        match (self.long_baseline_m, &self.slc_dir) {
            (Some(b), _) => b,
            (None, Some(_)) => 0.0,
            (None, None) => long_baseline_or_preset(None, &self.radar, sar),
        }
    }

    /// This run's look directions: `--looks`, else one pass when `--slc-dir` brings one pass's
    /// SLCs, else the radar preset's.
    pub fn looks(&self) -> LookDirections {
        match (self.looks, &self.slc_dir) {
            (Some(l), _) => l,
            (None, Some(_)) => LookDirections::One,
            (None, None) => looks_or_preset(None, &self.radar),
        }
    }
}

/// What an `insar` run made.
pub enum Outcome {
    /// The map and its report (also written to `OUT/report.json`).
    Map(Box<InsarReport>),
    /// One block of a map in blocks (`--block I/N`), written to `OUT/blocks/`.
    Block(Box<blocks::BlockRecord>),
}

/// Run the chain as `args` says.
pub fn run_chain(a: &Args) -> anyhow::Result<Outcome> {
    let (sar, pol) = radar_config(&a.radar)?;
    let cfg = InsarConfig {
        pixel_m: a.pixel_m,
        min_coherence: a.min_coherence,
        unwrap: !a.no_unwrap,
        dem_filter: a.dem_filter,
        fill_tile_holes: !a.keep_tile_holes,
        dem_filter_sigma_px: a
            .dem_filter_sigma_px
            .unwrap_or_else(|| a.dem_filter.default_sigma_px()),
        recentre_passes: a.recentre_passes,
        shadow_below_median_db: a.shadow_below_median_db,
        prior_dem_cell_m: a.prior_dem_cell_m,
        passes: a.passes,
        long_baseline_m: a.long_baseline_m(&sar),
        long_filter_sigma_px: a.long_filter_sigma_px,
        ..InsarConfig::default()
    }
    .with_radar(&sar);
    // Bad parameters are refused before any simulation.
    cfg.validate()?;
    ground_sim::insar::pipeline::check_long_baseline(&sar, &cfg)?;
    let truth = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let mut ctx = RunContext {
        input_dem: Some(a.dem.clone()),
        ..RunContext::default()
    };
    let layout = blocks::layout_for(&truth, cfg.pixel_m, a.block_cells, a.block_overlap_cells)?;
    if let Some(layout) = layout {
        anyhow::ensure!(
            a.slc_dir.is_none(),
            "--slc-dir holds one pass of the whole scene; a map in blocks simulates its blocks \
             itself (give --block-cells 0 to process those SLCs in one piece)"
        );
        let job = blocks::BlockJob {
            truth: &truth,
            sar: &sar,
            pol,
            cfg: &cfg,
            layout,
            out: &a.out,
            progress: !a.no_progress,
            looks: a.looks(),
        };
        return run_blocks(a, &job, ctx);
    }
    anyhow::ensure!(
        a.block.is_none() && !a.mosaic,
        "this map fits one block of {} cells (--block-cells): nothing to split or join",
        a.block_cells
    );
    let (truth, product) = match &a.slc_dir {
        Some(_) if a.looks() == LookDirections::Both => {
            anyhow::bail!(
                "--looks both simulates both passes itself; --slc-dir holds one pass (drop one of them)"
            )
        }
        Some(_) if cfg.passes > 1 => {
            anyhow::bail!(
                "--passes {} simulates its passes itself; --slc-dir holds one pass (drop one of them)",
                cfg.passes
            )
        }
        Some(_) if cfg.long_baseline_m > 0.0 => {
            anyhow::bail!(
                "--long-baseline-m simulates its second pair itself; --slc-dir holds one pair (drop one of them)"
            )
        }
        None if a.looks() == LookDirections::Both
            || cfg.passes > 1
            || cfg.long_baseline_m > 0.0 =>
        {
            let run = run_from_dem_looks(&truth, &sar, pol, &cfg, !a.no_progress, a.looks())?;
            ctx.filled_nodata = run.filled_nodata;
            ctx.sar = Some(SarSummary::of(&run.pair));
            (run.truth, run.product)
        }
        Some(dir) => {
            let read = |n: u8| -> anyhow::Result<Slc> {
                let p = dir.join(format!("slc_a{n}_{}.bin", pol.tag()));
                let f = File::open(&p).with_context(|| format!("opening {}", p.display()))?;
                Slc::read_from(BufReader::new(f))
                    .with_context(|| format!("reading {}", p.display()))
            };
            let (a1, a2) = (read(1)?, read(2)?);
            process_slcs(&truth, &a1, &a2, &cfg)?
        }
        None => {
            let (sdem, filled) = SarDem::from_dem(&truth)?;
            ctx.filled_nodata = filled;
            let opts = SimOptions {
                progress: !a.no_progress,
                ..SimOptions::default()
            };
            let pair = simulate_with(&sdem, &sar, &opts)?;
            ctx.sar = Some(SarSummary::of(&pair));
            process_simulated(&truth, &pair, pol, &cfg)?
        }
    };
    write_outputs(&a.out, &product, &truth, &ctx).map(|r| Outcome::Map(Box::new(r)))
}

fn run_blocks(
    a: &Args,
    job: &blocks::BlockJob<'_>,
    mut ctx: RunContext,
) -> anyhow::Result<Outcome> {
    let n = job.layout.count();
    if let Some(b) = a.block {
        anyhow::ensure!(
            b.count == n,
            "--block {}/{}: this map is cut into {n} blocks ({}×{} of ≤ {} cells), so N must be {n}",
            b.index,
            b.count,
            job.layout.rows,
            job.layout.cols,
            job.layout.block_cells
        );
        let r = blocks::run_block(job, b.index)?;
        return Ok(Outcome::Block(Box::new(r)));
    }
    if !a.mosaic {
        let pb = if a.no_progress {
            indicatif::ProgressBar::hidden()
        } else {
            super::progress(n as u64, "blocks")
        };
        for i in 0..n {
            blocks::run_block(job, i)?;
            pb.inc(1);
        }
        pb.finish_and_clear();
    }
    let m = blocks::mosaic(job)?;
    ctx.sar = Some(m.sar.clone());
    ctx.filled_nodata = m.filled_nodata;
    ctx.blocks = Some(m.report);
    write_outputs(&a.out, &m.product, &m.truth, &ctx).map(|r| Outcome::Map(Box::new(r)))
}

/// Print the report's headline figures.
pub fn print_report(r: &InsarReport, out: &Path) {
    let a = &r.accuracy;
    println!(
        "grid       {}x{} px at {} m -> {}",
        r.grid[0],
        r.grid[1],
        r.grid[2],
        out.display()
    );
    println!(
        "height     RMSE {:.2} m, bias {:+.2} m, std {:.2} m, |err| p95 {:.2} m ({} px)",
        a.height_rmse_m, a.height_bias_m, a.height_std_m, a.height_abs_p95_m, a.compared_pixels
    );
    println!(
        "CRLB       {:.2} m (RMSE/CRLB {:.2}); coherence {:.3} (all radar px {:.3}); looks {:.1}",
        a.crlb_height_m,
        a.rmse_over_crlb,
        a.coherence_mean,
        r.coherence_mean_radar,
        r.effective_looks
    );
    println!(
        "slope      RMSE {:.2}°, bias {:+.2}°",
        a.slope_rmse_deg, a.slope_bias_deg
    );
    println!(
        "matched    vs the truth through the look window: height RMSE {:.2} m, slope RMSE {:.2}°; \
         and the DEM filter: {:.2} m (over the CRLB {:.2})",
        a.height_rmse_window_matched_m,
        a.slope_rmse_window_matched_deg,
        a.height_rmse_resolution_matched_m,
        a.rmse_over_crlb_resolution_matched
    );
    let m = &r.mask;
    println!(
        "valid      {:.2} %; masked: {} {:.2} %, {} {:.2} %, {} {:.2} %, {} {:.2} %",
        100.0 * a.valid_fraction,
        label::name(label::LAYOVER),
        100.0 * m.layover,
        label::name(label::SHADOW),
        100.0 * m.shadow,
        label::name(label::LOW_COHERENCE),
        100.0 * m.low_coherence,
        label::name(label::OUTSIDE),
        100.0 * m.outside
    );
    println!(
        "eq 20      truth layover {:.3} %, shadow {:.3} %; of those masked {:.1} %",
        100.0 * a.eq20_layover_fraction,
        100.0 * a.eq20_shadow_fraction,
        100.0 * a.eq20_masked_fraction
    );
    println!(
        "geometry   truth ray-traced layover {:.3} %, shadow {:.3} %; masked beyond it (> {} px) {:.3} %",
        100.0 * a.geometric_layover_fraction,
        100.0 * a.geometric_shadow_fraction,
        ground_sim::insar::accuracy::GEOMETRY_MATCH_PX,
        100.0 * a.masked_outside_geometry_fraction
    );
    let c = &r.coregistration;
    if let Some(chk) = &c.check {
        println!(
            "coreg      offset {:+.3}..{:+.3} gate; residual by coherence {:+.3} gate; coherence {:.3} (none: {:.3})",
            c.offset_near_gates,
            c.offset_far_gates,
            chk.residual_gates,
            chk.coherence_at_prediction,
            chk.coherence_without_coregistration
        );
    }
    let u = &r.unwrap;
    println!(
        "unwrap     phase span {:.2} rad = {:.0} m of height (ambiguity {:.0} m); {} px changed",
        u.phase_span_rad, u.height_span_m, u.ambiguity_height_m, u.pixels_changed
    );
    if let Some(b) = &r.blocks {
        let l = &b.layout;
        println!(
            "blocks     {}x{} blocks of <= {} cells (+{} each side); seams: {} cells compared, \
             difference RMS {:.2} m, max {:.2} m, {} whole-cycle ({} map cells dropped)",
            l.rows,
            l.cols,
            l.block_cells,
            l.overlap_cells,
            b.overlap_cells_compared,
            b.overlap_height_diff_rms_m,
            b.overlap_height_diff_max_m,
            b.overlap_cycle_disagreements,
            b.cells_dropped_for_cycles
        );
        println!(
            "           height RMSE in the blend zones {:.2} m ({} cells), elsewhere {:.2} m ({} cells); peak RSS {}",
            b.height_rmse_blend_zone_m,
            b.valid_cells[0],
            b.height_rmse_elsewhere_m,
            b.valid_cells[1],
            b.peak_rss_mib
                .map(|m| format!("{m:.0} MiB"))
                .unwrap_or_else(|| "unknown".into())
        );
    }
    println!(
        "tile       {} features ({} of them on a truth-built tile's: ground, not noise){}; InSAR {:.2} s{}",
        r.tile_features,
        r.tile_features_on_truth,
        if r.tile.holes.filled_cells > 0 {
            format!(
                ", detected with {} of the map's {} missing cells filled",
                r.tile.holes.filled_cells, r.tile.holes.missing_cells
            )
        } else {
            String::new()
        },
        r.insar_s,
        r.sar
            .as_ref()
            .map(|s| format!(", SAR {:.1} s", s.timings.total_s))
            .unwrap_or_default()
    );
}

/// Run `ground-sim insar`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    if a.plan_blocks {
        let truth = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
        match blocks::layout_for(&truth, a.pixel_m, a.block_cells, a.block_overlap_cells)? {
            Some(l) => println!(
                "blocks {} rows {} cols {} grid {}x{} block_cells {} overlap_cells {}",
                l.count(),
                l.rows,
                l.cols,
                l.grid_width,
                l.grid_height,
                l.block_cells,
                l.overlap_cells
            ),
            None => println!("blocks 1 (one piece)"),
        }
        return Ok(());
    }
    let r = match run_chain(a)? {
        Outcome::Map(r) => r,
        Outcome::Block(r) => {
            let n = r.layout.count();
            println!(
                "block {}/{n} ({}x{} cells) -> {}: valid {:.1} %, SAR {:.1} s, InSAR {:.1} s; \
                 when all {n} are made, join them with the same flags and --mosaic",
                r.block.index,
                r.block.extent.width(),
                r.block.extent.height(),
                blocks::block_dir(&a.out, r.block.index).display(),
                100.0 * r.mask.valid,
                r.sar_timings.total_s,
                r.insar_s
            );
            return Ok(());
        }
    };
    print_report(&r, &a.out);
    if r.tile_features == 0 {
        eprintln!("warning: the reference tile has no features (too small or too noisy a DEM)");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ground_sim::sar::{MISSION_LONG_BASELINE_M, RadarPreset};

    /// The second pair each radar flies by default, and when it gives way.
    #[test]
    fn the_second_baseline_follows_the_preset_unless_told() {
        let of = |radar: Option<RadarPreset>, baseline_m: Option<f64>, given: Option<f64>| {
            let r = RadarArgs {
                radar,
                baseline_m,
                ..RadarArgs::default()
            };
            long_baseline_or_preset(given, &r, &r.resolve().unwrap())
        };
        assert_eq!(of(None, None, None), MISSION_LONG_BASELINE_M);
        assert_eq!(of(Some(RadarPreset::Paper), None, None), 0.0);
        assert_eq!(of(None, None, Some(0.0)), 0.0);
        assert_eq!(of(Some(RadarPreset::Paper), None, Some(64.0)), 64.0);
        // A boom given by hand shorter than the second pair keeps it; one as long flies alone.
        assert_eq!(of(None, Some(64.0), None), MISSION_LONG_BASELINE_M);
        assert_eq!(of(None, Some(200.0), None), 0.0);
    }
}
