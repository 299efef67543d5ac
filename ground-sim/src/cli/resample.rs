//! `ground-sim resample`: change the pixel size of a DEM and/or crop it by map coordinates.

use std::path::PathBuf;

use anyhow::{Context, bail};
use ground_sim::dem::stats::dem_stats;
use ground_sim::dem::{Interpolation, read_geotiff, resample_to_pixel, write_geotiff};

/// Arguments of `ground-sim resample`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input GeoTIFF DEM.
    #[arg(long)]
    pub dem: PathBuf,
    /// Output GeoTIFF (same sample type, GeoKeys and nodata as the input).
    #[arg(long)]
    pub out: PathBuf,
    /// New pixel size in metres (default: keep).
    #[arg(long)]
    pub pixel_m: Option<f64>,
    /// Interpolation kernel.
    #[arg(long, value_enum, default_value = "bicubic")]
    pub method: Interpolation,
    /// Crop first to pixels centred in this map rectangle: XMIN,YMIN,XMAX,YMAX (metres).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub crop: Option<Vec<f64>>,
    /// Write statistics of the output as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Run `ground-sim resample`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let mut dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    if let Some(c) = &a.crop {
        let [x0, y0, x1, y1] = c.as_slice() else {
            bail!("--crop needs XMIN,YMIN,XMAX,YMAX");
        };
        dem = dem.crop_geo(*x0, *y0, *x1, *y1).context("cropping")?;
    }
    if let Some(px) = a.pixel_m {
        dem = resample_to_pixel(&dem, px, a.method).context("resampling")?;
    }
    super::ensure_parent(&a.out)?;
    write_geotiff(&dem, &a.out, None).with_context(|| format!("writing {}", a.out.display()))?;
    let stats = dem_stats(&dem)?;
    super::print_stats(
        &format!("{} -> {}", a.dem.display(), a.out.display()),
        &stats,
    );
    if let Some(j) = &a.json {
        super::write_json(j, &stats)?;
    }
    Ok(())
}
