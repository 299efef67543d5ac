//! # DEM from the interferogram (paper section III)
//!
//! Two SLCs of one pass (antennas A1, A2 from [`crate::sar`]) become a geocoded 20 m DEM, its
//! slope, coherence and layover/shadow mask, and the reference tile the flyer navigates with.
//! One stage per module:
//!
//! 1. [`geometry`]: baseline and datum of the pair ([`PairGeometry`]); flat-Moon phase; height
//!    from phase with eq 17 at each pixel's own `R1` and `θ1`; closed-form reference inversion.
//! 2. [`coreg`]: sub-pixel range coregistration of A2 onto A1 (geometric offset ≈ +0.26 gate,
//!    16-tap sinc), checked against a coherence search on the data.
//! 3. [`looks`]: interferogram with the flat phase removed, complex 8×8 multilook with step 4
//!    (20 m), coherence on the same window, equivalent looks and the Cramér–Rao phase bound.
//! 4. [`unwrap`]: quality-guided unwrapping (needed only when heights span more than the
//!    ≈ 733 m height of ambiguity; the built-in scenes stay within one cycle).
//! 5. [`geocode`]: each pixel's ground position from `R1` and its height (radar parallax
//!    removed), resampling onto a regular ground grid aligned with the truth DEM, holes as
//!    nodata with a mask code; eq 20 layover/shadow test.
//! 6. [`demfilter`]: the filter of the geocoded DEM (a Gaussian mean by default, or a local
//!    quadratic fit without curvature bias) and what it does to the height bound.
//! 7. [`accuracy`]: comparison with the truth DEM resampled to the same grid.
//! 8. [`pipeline`]: everything above on a pair ([`process_pair`]), or from a DEM with the SAR
//!    simulation inside ([`run_from_dem`]).
//! 9. [`baselines`]: optionally a second, longer baseline whose heights replace the short
//!    pair's where they agree and are better (`--long-baseline-m`).
//! 10. [`products`]: GeoTIFFs, the paper's Fig. 5 and 6 pictures, the reference folder
//!     (tile) and `report.json`.
//!
//! Frames and units: the SAR frame of [`crate::sar`] (metres; `x` along track = DEM rows,
//! `y` ground range = DEM columns, `z` up); phases in radians; heights in metres above the
//! lunar datum of the input DEM. Conventions and measured figures: `docs/insar.md`.

pub mod accuracy;
pub mod baselines;
pub mod blocks;
pub mod coreg;
pub mod cycles;
pub mod demfilter;
pub mod geocode;
pub mod geometry;
pub mod looks;
pub mod pipeline;
pub mod products;
#[cfg(test)]
mod tests;
pub mod unwrap;

pub use accuracy::{Accuracy, compare};
pub use geocode::{GeocodeParams, OutputGrid, label};
pub use geometry::PairGeometry;
pub use looks::LookWindow;
pub use pipeline::{ChainRun, InsarConfig, InsarProduct, TruthOnGrid, process_pair, run_from_dem};

/// Errors of the InSAR stages.
#[derive(Debug, thiserror::Error)]
pub enum InsarError {
    /// The SLC pair (or a configuration value) cannot be processed.
    #[error("invalid InSAR input: {0}")]
    Input(String),
    /// The SAR simulation failed.
    #[error(transparent)]
    Sar(#[from] crate::sar::SarError),
    /// A DEM operation failed.
    #[error(transparent)]
    Dem(#[from] crate::dem::DemError),
}

/// Result type of the InSAR stages.
pub type InsarResult<T> = Result<T, InsarError>;
