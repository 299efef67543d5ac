//! `ground-sim terrain`: generate a synthetic preset DEM.

use std::path::{Path, PathBuf};

use anyhow::Context;
use ground_sim::dem::stats::{DemStats, dem_stats};
use ground_sim::dem::{SampleKind, write_geotiff};
use ground_sim::pictures::render::write_pictures;
use ground_sim::terrain::{Preset, TerrainParams, TerrainReport, Window, generate};

/// Arguments of `ground-sim terrain`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene preset.
    #[arg(long, value_enum)]
    pub preset: Preset,
    /// Window placement in the host crater.
    #[arg(long, value_enum, default_value = "floor")]
    pub window: Window,
    /// PRNG seed (same seed → bit-identical DEM).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Side of the square scene, metres.
    #[arg(long, default_value_t = 4000.0)]
    pub size_m: f64,
    /// Pixel size, metres.
    #[arg(long, default_value_t = 5.0)]
    pub pixel_m: f64,
    /// Output GeoTIFF.
    #[arg(long)]
    pub out: PathBuf,
    /// Sample type of the GeoTIFF.
    #[arg(long, value_enum, default_value = "f32")]
    pub format: SampleKind,
    /// Folder for hillshade.png, elevation.png and slope.png.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Write the generation report and DEM statistics as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What `terrain` produced (also the JSON it writes).
#[derive(Debug, serde::Serialize)]
pub struct TerrainOutput {
    /// The GeoTIFF written.
    pub dem: PathBuf,
    /// Pictures written.
    pub pictures: Vec<PathBuf>,
    /// Generation report (model, crater counts per bin).
    pub report: TerrainReport,
    /// Statistics of the generated DEM.
    pub stats: DemStats,
    /// Wall-clock time of the generation alone, seconds.
    pub generate_s: f64,
}

/// Generate, write and describe one scene.
pub fn make(
    params: &TerrainParams,
    out: &Path,
    format: SampleKind,
    png: Option<&Path>,
) -> anyhow::Result<TerrainOutput> {
    let pb = super::progress(4, "terrain");
    let t0 = std::time::Instant::now();
    let (dem, report) = generate(params, &pb).context("generating terrain")?;
    let generate_s = t0.elapsed().as_secs_f64();
    pb.finish_and_clear();
    super::ensure_parent(out)?;
    write_geotiff(&dem, out, Some(format)).with_context(|| format!("writing {}", out.display()))?;
    let stats = dem_stats(&dem).context("DEM statistics")?;
    let pictures = match png {
        Some(dir) => {
            let pb = super::progress(1, "pictures");
            let p = write_pictures(&dem, dir).context("writing pictures")?;
            pb.finish_and_clear();
            p
        }
        None => Vec::new(),
    };
    Ok(TerrainOutput {
        dem: out.to_path_buf(),
        pictures,
        report,
        stats,
        generate_s,
    })
}

/// Print the crater bins: model expectation vs drawn vs visible.
pub fn print_craters(r: &TerrainReport) {
    println!("  craters centred in the window (model = expected from the SFD):");
    println!(
        "    {:>16} {:>9} {:>7} {:>8}",
        "D bin (m)", "model", "drawn", "fresh"
    );
    for b in &r.crater_bins {
        println!(
            "    {:>16} {:>9.1} {:>7} {:>8}",
            format!("{:.0}-{:.0}", b.d_min_m, b.d_max_m),
            b.model,
            b.drawn,
            b.fresh
        );
    }
}

/// Run `ground-sim terrain`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let params = TerrainParams {
        preset: a.preset,
        window: a.window,
        seed: a.seed,
        size_m: a.size_m,
        pixel_m: a.pixel_m,
    };
    let o = make(&params, &a.out, a.format, a.png.as_deref())?;
    super::print_stats(
        &format!(
            "{:?} ({:?} window, seed {}) -> {} in {:.2} s",
            a.preset,
            a.window,
            a.seed,
            a.out.display(),
            o.generate_s
        ),
        &o.stats,
    );
    print_craters(&o.report);
    for p in &o.pictures {
        println!("  picture {}", p.display());
    }
    if let Some(j) = &a.json {
        super::write_json(j, &o)?;
        println!("  json {}", j.display());
    }
    Ok(())
}
