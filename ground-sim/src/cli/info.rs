//! `ground-sim info`: describe a DEM file.

use std::path::PathBuf;

use anyhow::Context;
use ground_sim::dem::read_geotiff;
use ground_sim::dem::stats::dem_stats;
use ground_sim::pictures::render::write_pictures;

/// Arguments of `ground-sim info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// GeoTIFF DEM to describe.
    #[arg(long)]
    pub dem: PathBuf,
    /// Write the statistics as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also write hillshade/elevation/slope pictures into this folder.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Run `ground-sim info`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let stats = dem_stats(&dem).context("DEM statistics")?;
    super::print_stats(&format!("{}", a.dem.display()), &stats);
    if let Some(dir) = &a.png {
        for p in write_pictures(&dem, dir).context("writing pictures")? {
            println!("  picture {}", p.display());
        }
    }
    if let Some(j) = &a.json {
        super::write_json(j, &stats)?;
        println!("  json {}", j.display());
    }
    Ok(())
}
