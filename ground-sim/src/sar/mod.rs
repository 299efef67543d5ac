//! # Dual-antenna SAR simulation and Range-Doppler focusing (paper section II)
//!
//! Pipeline, one stage per module:
//!
//! 1. [`geometry`]: the input DEM ([`SarDem`]) and the flat-Moon acquisition geometry
//!    ([`Geometry`]): platform track, the two antennas (baseline `B_L`, tilt `α`), pulse grid and
//!    echo window ([`AcquisitionPlan`]).
//! 2. [`scene`]: two triangles per DEM cell (eq 1) with area, normal, local incidence angle,
//!    polarisation-basis rotation (eqs 2–3), radar shadow and layover flags.
//! 3. [`scattering`]: two-scale reflectivity, Kirchhoff approximation at small local incidence and
//!    small-perturbation method at large (eqs 4–10), one seeded complex Gaussian `w` per facet
//!    shared by both antennas.
//! 4. [`echo`]: raw chirp echoes (eqs 11–13). The fast method deposits every facet into the
//!    range-compressed domain with a windowed-sinc kernel ([`kernel`]) at its exact delay and
//!    carrier phase, then applies the chirp with one FFT–multiply–IFFT per pulse; the direct
//!    time-domain sum of eq 11 is kept as the test oracle.
//! 5. [`rda`]: Range-Doppler algorithm (range matched filter with Hamming, azimuth FFT, RCMC by
//!    sinc interpolation, azimuth compression with Hamming, IFFT) giving one [`Slc`] per
//!    antenna and polarisation, with the `−4πR/λ` carrier phase kept.
//! 6. [`psf`]: point-target analysis (IRW, PSLR, ISLR, peak location, interferometric phase).
//! 7. [`products`]: σ0 image (eq 16), SLC files ([`slc`]), PNG and JSON report.
//!
//! [`pipeline::simulate_insar_pair`] runs stages 1–5 on a DEM and is what the InSAR stage calls.
//!
//! ## Frame and conventions
//!
//! Local flat-Moon Cartesian frame in metres: `x` along track (flight direction, increasing DEM
//! row), `y` ground range (look direction, increasing DEM column), `z` up. The radar looks
//! towards `+y`. SLC rows are azimuth lines (`x`), columns are slant-range gates. Times in
//! seconds, frequencies in hertz, angles in radians unless a name ends in `_deg`.
//!
//! ## Bounds
//!
//! The interpolation kernel has [`kernel::KERNEL_TAPS`] taps tabulated at
//! [`kernel::KERNEL_PHASES`] fractional delays, the echo deposit kernel
//! [`kernel::DEPOSIT_TAPS`] at [`kernel::DEPOSIT_PHASES`]; [`MAX_POLARISATIONS`] polarisations are simulated
//! at once. Memory grows with `pulses × echo samples × polarisations` (8 bytes per complex
//! sample) and with the facet count (about 100 bytes per facet).

pub mod cli;
pub mod config;
pub mod echo;
pub mod geometry;
pub mod kernel;
pub mod pipeline;
pub mod products;
pub mod psf;
pub mod rda;
pub mod scattering;
pub mod scene;
pub mod slc;
#[cfg(test)]
mod tests;

pub use config::{
    Derived, MISSION_BASELINE_M, MISSION_LONG_BASELINE_M, MISSION_NESZ_DB, MOON_DIFFUSE_DB,
    Polarisation, RadarPreset, SarConfig,
};
pub use geometry::{AcquisitionPlan, Antenna, Geometry, SarDem};
pub use pipeline::{InsarPair, simulate_insar_pair};
pub use slc::Slc;

/// Single-precision complex sample used for echoes and images.
pub type C32 = num_complex::Complex<f32>;
/// Double-precision complex value used where phases must stay exact.
pub type C64 = num_complex::Complex<f64>;

/// Speed of light in vacuum, m/s.
pub const SPEED_OF_LIGHT_M_S: f64 = 299_792_458.0;

/// Most polarisations simulated in one run (HH and VV; the cross-pol channels are not formed).
pub const MAX_POLARISATIONS: usize = 2;

/// Errors of the SAR stages. Library code returns these instead of panicking.
#[derive(Debug, thiserror::Error)]
pub enum SarError {
    /// A configuration value is out of its valid range.
    #[error("invalid SAR configuration: {0}")]
    Config(String),
    /// The input DEM is malformed (size, spacing, non-finite heights).
    #[error("invalid DEM: {0}")]
    Dem(String),
    /// The scene geometry is impossible (e.g. terrain above the platform).
    #[error("invalid geometry: {0}")]
    Geometry(String),
    /// A buffer would overflow (a scatterer outside the echo window): reported, never truncated.
    #[error("buffer bound exceeded: {0}")]
    Bound(String),
    /// Two arrays that must agree in shape do not.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// A product file is malformed.
    #[error("bad product file: {0}")]
    Format(String),
    /// Reading or writing a file failed.
    #[error("I/O error: {0}")]
    Io(#[from] std::io::Error),
}

/// Result type of the SAR stages.
pub type SarResult<T> = Result<T, SarError>;
