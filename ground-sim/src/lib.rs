//! # ground-sim — Umbra's ground segment
//!
//! Terrain in and out, SAR/InSAR simulation, the reference tile builder and closed-loop
//! evaluation of nav-core. Everything runs on the host with `std`.
//!
//! Modules so far:
//! - [`dem`]: georeferenced DEMs (heights in metres, NaN = nodata), single-band GeoTIFF read and
//!   write with GeoKeys kept verbatim, bilinear/bicubic resampling, cropping by map coordinates.
//! - [`terrain`]: built-in synthetic lunar scenes (`shackleton`, `shoemaker`) from crater
//!   morphometry, a Neukum/equilibrium crater SFD, diffusive degradation and fractal roughness;
//!   deterministic per seed. Models and sources: `docs/terrain.md`.
//! - [`analysis`]: slope through nav-core's flight code path, DEM statistics (the `info` JSON),
//!   closed depressions and the main crater's depth/diameter.
//! - [`render`]: PNG hillshade, elevation and slope pictures with labelled colour bars.
//! - [`sar`]: dual-antenna SAR echoes over a DEM and Range-Doppler focusing (paper section II).
//! - [`insar`]: DEM from the interferogram (coregistration, flat phase, eq 17, multilook,
//!   unwrapping, geometric correction, mask), accuracy against the truth, the reference folder.
//! - [`tile`], [`reference`]: reference tiles (SURF by nav-core) and reference folders.
//! - [`frames`], [`onboard`], [`trn`], [`register`]: synthetic flyer frames, the flight code as
//!   the ground runs it, and scoring against the truth.
//!
//! Conventions: pixel `(col, row)` has its centre at `(col, row)`; map frames are metres, x east,
//! y north; geotransforms are GDAL's (pixel corners).
//!
//! Bounds: grids up to [`terrain::MAX_SIDE_PX`] px a side (nav-core's frame limit); fractal
//! fields up to [`terrain::roughness::MAX_FFT_SIDE`] px, tiled beyond; pictures decimated above
//! [`render::MAX_PICTURE_SIDE`] px.

pub mod analysis;
pub mod dem;
pub mod descent;
pub mod frames;
pub mod insar;
pub mod matchplot;
pub mod onboard;
pub mod plot;
pub mod reference;
pub mod register;
pub mod render;
pub mod sar;
pub mod terrain;
pub mod tile;
pub mod trn;
