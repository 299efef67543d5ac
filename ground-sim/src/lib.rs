//! # ground-sim — Umbra's ground segment
//!
//! Terrain in and out, SAR/InSAR simulation, the reference tile builder and closed-loop
//! evaluation of nav-core. Everything runs on the host with `std`.
//!
//! The modules follow the data flow, terrain to pictures:
//! - [`dem`]: georeferenced DEMs (heights in metres, NaN = nodata), single-band GeoTIFF read and
//!   write with GeoKeys kept verbatim, bilinear/bicubic resampling, cropping by map coordinates;
//!   [`dem::stats`]: slope through nav-core's flight code path, DEM statistics (the `info`
//!   JSON), closed depressions and the main crater's depth/diameter.
//! - [`terrain`]: built-in synthetic lunar scenes from crater morphometry, a Neukum/equilibrium
//!   crater SFD, diffusive degradation and fractal roughness; deterministic per seed. Models and
//!   sources: `docs/terrain.md`.
//! - [`sar`]: dual-antenna SAR echoes over a DEM and Range-Doppler focusing (paper section II).
//! - [`insar`]: DEM from the interferogram (coregistration, flat phase, eq 17, multilook,
//!   unwrapping, geometric correction, mask), accuracy against the truth, the reference folder.
//! - [`reference`]: reference folders and, in [`reference::tile`], tiles (SURF by nav-core).
//! - [`flyer`]: synthetic flyer frames and the flight code as the ground runs it.
//! - [`evaluation`]: scoring against the truth: single frames, registration, campaigns,
//!   closed-loop descents, the terrain suite and the navigability map.
//! - [`pictures`]: PNG hillshade, elevation and slope maps, match pictures and line plots.
//!
//! Conventions: pixel `(col, row)` has its centre at `(col, row)`; map frames are metres, x east,
//! y north; geotransforms are GDAL's (pixel corners).
//!
//! Bounds: grids up to [`terrain::MAX_SIDE_PX`] px a side (nav-core's frame limit); fractal
//! fields up to [`terrain::roughness::MAX_FFT_SIDE`] px, tiled beyond; pictures decimated above
//! [`pictures::render::MAX_PICTURE_SIDE`] px.

pub mod dem;
pub mod evaluation;
pub mod flyer;
pub mod insar;
pub mod pictures;
pub mod reference;
pub mod sar;
pub mod terrain;

use std::path::Path;

use anyhow::Context;

/// Create the parent folder of an output file.
pub fn ensure_parent(path: &Path) -> anyhow::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    Ok(())
}

/// Write `value` as pretty JSON to `path`, creating parent folders.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> anyhow::Result<()> {
    ensure_parent(path)?;
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))
}
