//! Dense refinement of a feature fix: Gauss–Newton alignment of the frame's slope image to the
//! tile's reference slope raster over a grid of frame pixels.
//!
//! Why: the feature fix rests on 10–30 keypoints whose positions scatter by ≈ 0.5 tile pixels
//! (a keypoint is a blob centre, not a corner), so its rotation error is a few tenths of a
//! degree on small frames. Every textured frame pixel carries information; aligning thousands of
//! them brings rotation and position down by an order of magnitude. The feature fix stays the
//! authority on *whether* there is a fix (it starts the refinement, and the refined transform
//! may not stray from it); the refinement only sharpens it.
//!
//! Method: inverse-compositional Gauss–Newton (Baker & Matthews) with a similarity warp (frame
//! pixels → tile pixels: rotation, scale, translation) and a linear photometric model
//! `R ≈ g·F + o` between the frame slope `F` and the reference slope `R` (InSAR slopes are
//! biased by height noise; binning and smoothing change contrast). Frame gradients come from
//! central differences on the frame's own pixel grid, the reference is sampled bilinearly, and
//! residuals are Huber-weighted at twice the previous pass' RMS so dropouts and craters that
//! changed do not pull the fit. Samples keep clear of the frame's border band, where the
//! smoothing kernel was cut and the slope is biased ([`FrameInfo::border_px`]), and the scale
//! takes a prior from the frame's own metric pixel size ([`RefineConfig::frame_scale_sigma`]).
//!
//! Covariance: the sandwich of the estimating equation (see [`Refined::center_cov_tile_px2`]),
//! because the Jacobian comes from the frame, whose noise adds to the Gauss–Newton matrix
//! without adding information (errors in variables); the final pass also sums the reference's
//! gradient for it.
//!
//! Bounds: at most [`MAX_ITERATIONS`] + 1 passes over at most [`RefineConfig::max_samples`]
//! samples; no buffers (every sum is a register or stack scalar). Per-sample arithmetic is `f32`
//! in a fixed order (summed per row, rows summed in `f64`), so host and target agree bit for bit.

use crate::frame::{SLOPE_LSB_DEG, SlopeImage, SlopePx, slope_is_valid};
use crate::msac::Affine;
use crate::pose::similarity;
use crate::tile::SlopeRaster;
use core::fmt;
use nalgebra::{SMatrix, SVector};

/// Hard cap on Gauss–Newton iterations, whatever the configuration says.
pub const MAX_ITERATIONS: u8 = 20;

/// Smallest step length the step control may shrink to (three halvings). Convergence is judged
/// on the applied step, so with the step length at this floor a "converged" refinement's full
/// Gauss–Newton step is below `converge_px / MIN_STEP_LENGTH`; an iteration that still swings
/// there runs out of iterations and is refused (`NotConverged`), as before the step control.
pub const MIN_STEP_LENGTH: f64 = 0.125;

/// What the final (sandwich) pass costs in plain passes: it also reads the reference's
/// gradient and sums the sensitivity matrix, and the covariance follows it (HIL profiles,
/// session 29: 3 passes of 729 samples cost 2.1–2.3 M Cortex-M4 instructions, ≈ 4 plain
/// passes' worth). [`RefineConfig::max_sample_passes`] and the work counted by
/// [`refine_metered`] are in plain-pass samples.
pub const SANDWICH_PASS_WEIGHT: u32 = 2;

/// How much lower than under the feature fix the refined correlation may be. NCC is not the
/// objective (the Huber-weighted photometric residual is), so a better alignment can correlate
/// a hair worse: measured −0.0003 on a frame whose rotation error fell from 0.077° to 0.007°.
pub const NCC_TOLERANCE: f32 = 0.01;

/// Refinement settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RefineConfig {
    /// Run the refinement when the tile carries a slope raster.
    pub enabled: bool,
    /// Gauss–Newton iterations at most (capped at [`MAX_ITERATIONS`]).
    pub max_iterations: u8,
    /// Sample grid budget: the frame is sampled on a regular grid with the smallest stride that
    /// keeps at most this many samples.
    pub max_samples: u32,
    /// Fewest valid samples (frame and reference both valid) for a refinement.
    pub min_samples: u32,
    /// Largest move of any frame corner, tile pixels, from the feature fix to the refined
    /// transform. A feature fix on few inliers can be a few degrees off (corners several pixels
    /// away) and the refinement rescues it; a much larger move means it slid into another
    /// valley of the slope field.
    pub max_shift_px: f32,
    /// Smallest normalised cross-correlation of frame and reference slope under the refined
    /// transform (measured on true alignments: 0.90–0.95 for truth-built tiles).
    pub min_ncc: f32,
    /// Converged when an update moves every frame corner by less than this, tile pixels.
    pub converge_px: f32,
    /// Relative 1σ of the frame's own scale: the ranging sensor grids its DEM frame in metres
    /// (pixel size from its beam geometry and range), so the frame-to-tile scale is known to
    /// about this much before any matching. Used as a prior on the warp's scale when the caller
    /// passes the expected scale ([`FrameInfo::scale`]); 0 leaves the scale free.
    ///
    /// Why: on a bowl or a crater wall the slope grows nearly in proportion to the distance from
    /// the crater's axis, so a scale change about the frame centre looks like a contrast change
    /// (the photometric gain) plus a shift of the whole frame. With the scale free the fit trades
    /// them, and a few percent of scale error became 10–20 m of position error that the
    /// alignment residuals could not show (fresh-crater floor, Shackleton rim; docs/registration.md).
    pub frame_scale_sigma: f32,
    /// Work allowance, samples × passes (the final pass weighs [`SANDWICH_PASS_WEIGHT`]): a
    /// pass starts only if its whole sample grid still fits in what is left of this, else the
    /// refinement stops ([`RefineError::OverBudget`]).
    /// The navigator sets it from the frame's work budget ([`crate::NavConfig::work_budget`]);
    /// `u32::MAX` (the default) leaves the pass count to `max_iterations` alone.
    pub max_sample_passes: u32,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            max_iterations: 20,
            max_samples: 1100,
            min_samples: 300,
            max_shift_px: 12.0,
            min_ncc: 0.5,
            converge_px: 0.03,
            frame_scale_sigma: 0.005,
            max_sample_passes: u32::MAX,
        }
    }
}

/// Why a refinement was not applied (the feature fix then stands as it was).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RefineError {
    /// Switched off in the configuration.
    Disabled,
    /// The tile carries no slope raster.
    NoRaster,
    /// Fewer valid samples than [`RefineConfig::min_samples`].
    TooFewSamples,
    /// The normal equations are singular (a textureless frame).
    Singular,
    /// No convergence within the iteration budget.
    NotConverged,
    /// The refined transform moved a frame corner beyond [`RefineConfig::max_shift_px`].
    MovedTooFar,
    /// The refined alignment correlates worse than the feature fix (by more than
    /// [`NCC_TOLERANCE`]) or less than [`RefineConfig::min_ncc`].
    WorseCorrelation,
    /// Stopped (or not started): its next pass, the final one included, did not fit in
    /// [`RefineConfig::max_sample_passes`] (the frame's work budget).
    OverBudget,
}

impl fmt::Display for RefineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Disabled => "refinement disabled",
            Self::NoRaster => "tile has no slope raster",
            Self::TooFewSamples => "too few valid samples",
            Self::Singular => "frame has too little texture",
            Self::NotConverged => "did not converge",
            Self::MovedTooFar => "moved too far from the feature fix",
            Self::WorseCorrelation => "correlation worse than the feature fix or too low",
            Self::OverBudget => "no room left in the frame's work budget",
        })
    }
}

/// A refined transform.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Refined {
    /// Frame pixels → tile pixels, a similarity.
    pub affine: Affine,
    /// Gauss–Newton updates made.
    pub iterations: u8,
    /// Valid samples in the final pass.
    pub samples: u32,
    /// Normalised cross-correlation of frame and reference slope under the feature fix.
    pub ncc_before: f32,
    /// The same under the refined transform.
    pub ncc_after: f32,
    /// RMS of the photometric residual `R − (g·F + o)` in the final pass, degrees of slope.
    pub residual_rms_deg: f32,
    /// Largest move of a frame corner from the feature fix, tile pixels.
    pub shift_px: f32,
    /// Covariance of the frame centre, tile pixels² (row-major 2 × 2): the sandwich
    /// σ²·A⁻¹·H·A⁻ᵀ of the final pass, H the Gauss–Newton matrix from the frame's gradients, A
    /// the same sums with the reference's gradients on one side (the frame's noise inflates H
    /// but not A), both with the scale prior's information when there is one
    /// ([`FrameInfo::scale`]); σ² inflated for residuals correlated between neighbouring
    /// samples (see [`Refined::correlation`]). It describes the alignment noise only, not
    /// errors of the reference itself (an InSAR DEM's errors shift the whole frame alike): the
    /// fix adds the tile's `reference_sigma_m` to it
    /// ([`crate::pose::with_reference_error`]; measured in `docs/registration.md`, Covariance).
    pub center_cov_tile_px2: [[f64; 2]; 2],
    /// Standard deviation of the rotation, radians (same model).
    pub rotation_sigma_rad: f64,
    /// Standard deviation of the scale, tile pixels per frame pixel (same model).
    pub scale_sigma: f64,
    /// Correlation ρ of the residuals of neighbouring samples along a row (clamped to 0–0.9);
    /// the covariances are inflated by (1 + ρ)/(1 − ρ), the variance factor of a mean of
    /// first-order correlated samples.
    pub correlation: f32,
}

/// What the caller knows about the frame beyond its slope image.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameInfo {
    /// The scale the frame's own pixel size implies, tile pixels per unbinned frame pixel
    /// (frame metres per pixel / tile metres per pixel); with a positive
    /// [`RefineConfig::frame_scale_sigma`] a prior on the warp's log-scale, weighted against the
    /// residual variance so the covariances include it. `None` leaves the scale to the slopes.
    pub scale: Option<f64>,
    /// Slope-image pixels at each border to leave out: those whose smoothing kernel was cut by
    /// the border ([`crate::slope::smoothing_radius`] + 1 for a smoothed image, 0 otherwise).
    /// Their slope is biased in proportion to the terrain's slope, the same way on every
    /// frame, where the reference (smoothed in the interior of a large map) has no such bias:
    /// on steep ground that band pulled the fit by 10–20 m (docs/registration.md).
    pub border_px: usize,
}

/// Similarity warp in centred frame coordinates: `X = M·(u − c) + t`, tile pixels.
#[derive(Clone, Copy)]
struct Warp {
    m: [[f64; 2]; 2],
    t: [f64; 2],
}

impl Warp {
    fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        (
            self.m[0][0] * x + self.m[0][1] * y + self.t[0],
            self.m[1][0] * x + self.m[1][1] * y + self.t[1],
        )
    }
}

/// What a pass holds fixed: the photometric model `R ≈ gain·F + offset` (degrees), the Huber
/// threshold (degrees) and whether to sum the sensitivity matrix ([`Pass::a`]).
#[derive(Clone, Copy)]
struct PassModel {
    gain: f32,
    offset: f32,
    huber: f32,
    sandwich: bool,
}

/// Sums of one pass.
#[derive(Default)]
struct Pass {
    /// Upper triangle of the normal matrix, row by row.
    h: [f64; 21],
    b: [f64; 6],
    n: u32,
    sf: f64,
    sr: f64,
    sff: f64,
    srr: f64,
    sfr: f64,
    see: f64,
    /// Σ e·e' over horizontally neighbouring valid samples.
    slag: f64,
    /// Σ e·e' over vertically neighbouring valid samples (the first [`LAG_ROW`] of a row).
    svlag: f64,
    /// Σ e·e''' over valid samples three apart along a row, with the two between them valid
    /// (final pass only: the correlation's shape, [`Pass::sigma2`]).
    slag3: f64,
    /// Σ e·e''' over valid samples three rows apart, with the two between them valid (final
    /// pass only; the first [`LAG_ROW`] of a row).
    svlag3: f64,
    /// Pairs summed (final pass only): lag 1 and lag 3 along rows, lag 1 and lag 3 down
    /// columns. A run of L valid samples holds L − 1 pairs at lag 1 but L − 3 at lag 3, so the
    /// decay's shape compares per-pair means, not sums over the same Σe².
    pairs: [u32; 4],
    /// Rows 0–5, columns 0–3 of the sensitivity matrix `A = Σ w·s_F·s_Rᵀ` (row-major 6 × 4),
    /// filled only in the final pass ([`pass`]'s `sandwich`); its columns 4–5 equal the
    /// normal matrix's.
    a: [f64; 24],
}

/// Most lags [`lag_factor`] sums where the decay is faster than first order.
const LAG_TERMS: u16 = 64;

/// Terms of [`lag_factor`]'s sum below this are left out (with the rest of the sum: the terms
/// fall monotonically).
const LAG_TERM_FLOOR: f32 = 1e-6;

/// Variance factor of a sum of samples along one axis whose correlation at lag k is
/// ρ₁^(kᵖ): 1 + 2·Σₖ ρ₁^(kᵖ). The decay's shape p comes from the measured lag-3
/// correlation, ρ₃ = ρ₁^(3ᵖ), held between 1 and 2:
///
/// - p = 1, first order ρ₁ᵏ: the slowest decay assumed, (1 + ρ₁)/(1 − ρ₁) in closed form,
///   the model used before the shape was measured;
/// - p = 2, Gaussian ρ₁^(k²): residuals of two Gaussian-smoothed slope images whose
///   difference is itself smooth.
///
/// A first-order model on residuals that decay like the blur overstated their variance about
/// twofold per axis over InSAR maps (docs/registration.md, "What an InSAR fix's σ covers").
/// Lag 3 rather than 2, because a slower tail behind a fast start (the InSAR plains) shows
/// there first. The sum runs in `f32`: the Cortex-M4F does `f32` arithmetic in hardware and
/// `f64` in software, and `f64` transcendentals cost up to 7 M instructions a frame here (HIL,
/// session 35). At most [`LAG_TERMS`] terms.
fn lag_factor(rho1: f64, rho3: f64) -> f64 {
    if !(rho1 > 0.0 && rho1 < 1.0) {
        return 1.0;
    }
    let cube = rho1 * rho1 * rho1;
    if !rho3.is_finite() || rho3 >= cube {
        return (1.0 + rho1) / (1.0 - rho1);
    }
    let ln_rho = libm::logf(rho1 as f32);
    let p = if rho3 <= cube * cube * cube {
        2.0
    } else {
        // ln ρ₃ / ln ρ₁ = 3ᵖ lies in (3, 9) here.
        libm::logf(libm::logf(rho3 as f32) / ln_rho) / libm::logf(3.0)
    };
    let mut f = 1.0f32;
    let mut k = 1u16;
    while k <= LAG_TERMS {
        let term = libm::expf(ln_rho * libm::powf(k as f32, p));
        if !(term >= LAG_TERM_FLOOR) {
            break;
        }
        f += 2.0 * term;
        k += 1;
    }
    f as f64
}

/// Samples per row whose residuals are kept for the vertical lag correlation (a row of the
/// default 1 100-sample grid on a square frame has 34).
pub const LAG_ROW: usize = 128;

/// Index of `(i, j)`, `i ≤ j`, in a row-by-row upper triangle of a 6 × 6 matrix.
fn tri(i: usize, j: usize) -> usize {
    let (i, j) = (i.min(j), i.max(j));
    i * 6 - i * i.saturating_sub(1) / 2 + (j - i)
}

impl Pass {
    fn normal_matrix(&self) -> SMatrix<f64, 6, 6> {
        SMatrix::from_fn(|i, j| self.h.get(tri(i, j)).copied().unwrap_or(0.0))
    }
    fn rhs(&self) -> SVector<f64, 6> {
        SVector::from_fn(|i, _| self.b.get(i).copied().unwrap_or(0.0))
    }
    fn ncc(&self) -> f32 {
        let n = self.n as f64;
        if n < 2.0 {
            return 0.0;
        }
        let vf = self.sff - self.sf * self.sf / n;
        let vr = self.srr - self.sr * self.sr / n;
        let c = self.sfr - self.sf * self.sr / n;
        if vf > 0.0 && vr > 0.0 {
            (c / libm::sqrt(vf * vr)) as f32
        } else {
            0.0
        }
    }
    fn lag_correlation(&self) -> f32 {
        if self.see > 0.0 {
            ((self.slag / self.see) as f32).clamp(0.0, 0.9)
        } else {
            0.0
        }
    }
    fn vertical_lag_correlation(&self) -> f32 {
        if self.see > 0.0 {
            ((self.svlag / self.see) as f32).clamp(0.0, 0.9)
        } else {
            0.0
        }
    }
    /// Residual variance per sample, degrees², inflated for the residuals' correlation along
    /// both axes of the sample grid (the effective number of independent samples shrinks by
    /// both axes' factors).
    ///
    /// The steps' passes assume the slowest decay, first order ρᵏ (factor (1 + ρ)/(1 − ρ)); the
    /// final pass also measures the correlation three samples apart and sums the decay it
    /// shows ([`lag_factor`]). An axis without a lag-3 pair, or without a positive lag-1 sum,
    /// keeps first order.
    fn sigma2(&self) -> f64 {
        let rho = self.lag_correlation() as f64;
        let rho_v = self.vertical_lag_correlation() as f64;
        let [n1, n3, n1v, n3v] = self.pairs;
        // ρ₃ as ρ₁ times the ratio of the per-pair means at lags 3 and 1; NaN (first order,
        // the conservative end) where that ratio is undefined.
        let lag3 = |rho1: f64, s1: f64, n1: u32, s3: f64, n3: u32| {
            if n1 > 0 && n3 > 0 && s1 > 0.0 {
                rho1 * (s3 / n3 as f64) / (s1 / n1 as f64)
            } else {
                f64::NAN
            }
        };
        let inflate = if n3 > 0 || n3v > 0 {
            lag_factor(rho, lag3(rho, self.slag, n1, self.slag3, n3))
                * lag_factor(rho_v, lag3(rho_v, self.svlag, n1v, self.svlag3, n3v))
        } else {
            // The steps' passes: the same expression, so their fits keep every bit.
            (1.0 + rho) / (1.0 - rho) * (1.0 + rho_v) / (1.0 - rho_v)
        };
        self.see / (self.n as f64 - 6.0).max(1.0) * inflate
    }
    fn rms(&self) -> f32 {
        if self.n == 0 {
            0.0
        } else {
            libm::sqrt(self.see / self.n as f64) as f32
        }
    }
}

#[inline]
fn deg(p: SlopePx) -> Option<f32> {
    slope_is_valid(p).then(|| p.to_bits() as f32 * SLOPE_LSB_DEG)
}

/// The bilinear patch of the reference at tile pixel `(x, y)`: its four corners (degrees; top
/// left, top right, bottom left, bottom right) and the fractional position in it. `None`
/// unless all four are valid.
#[inline]
fn patch(r: &SlopeRaster<'_>, x: f32, y: f32) -> Option<([f32; 4], f32, f32)> {
    if !(x >= 0.0 && y >= 0.0) {
        return None;
    }
    let (x0, y0) = (libm::floorf(x), libm::floorf(y));
    let (c, row) = (x0 as usize, y0 as usize);
    if c + 1 >= r.width() || row + 1 >= r.height() {
        return None;
    }
    let corners = [
        deg(r.get(c, row))?,
        deg(r.get(c + 1, row))?,
        deg(r.get(c, row + 1))?,
        deg(r.get(c + 1, row + 1))?,
    ];
    Some((corners, x - x0, y - y0))
}

/// Value of a [`patch`] at `(fx, fy)`, degrees.
#[inline]
fn patch_value([a, b, c, d]: [f32; 4], fx: f32, fy: f32) -> f32 {
    let top = a + fx * (b - a);
    let bot = c + fx * (d - c);
    top + fy * (bot - top)
}

/// Bilinear reference slope at tile pixel `(x, y)`, degrees; `None` unless all four
/// neighbours are valid.
#[inline]
fn bilinear(r: &SlopeRaster<'_>, x: f32, y: f32) -> Option<f32> {
    let (k, fx, fy) = patch(r, x, y)?;
    Some(patch_value(k, fx, fy))
}

/// [`bilinear`] with the bilinear patch's gradient: `(R, ∂R/∂X, ∂R/∂Y)`, degrees per tile
/// pixel (the value has the same bits as [`bilinear`]'s).
#[inline]
fn bilinear_grad(r: &SlopeRaster<'_>, x: f32, y: f32) -> Option<(f32, f32, f32)> {
    let (k, fx, fy) = patch(r, x, y)?;
    let [a, b, c, d] = k;
    let gx = (b - a) + fy * ((d - c) - (b - a));
    let gy = (c - a) + fx * ((d - b) - (c - a));
    Some((patch_value(k, fx, fy), gx, gy))
}

/// Sample grid stride: the smallest with at most `budget` samples over `w × h` interior pixels.
fn stride(w: usize, h: usize, budget: u32) -> usize {
    let budget = budget.max(1) as usize;
    let mut s = 1usize;
    // Bounded: the count falls below 1 at s = max(w, h).
    while s < w.max(h) && w.div_ceil(s) * h.div_ceil(s) > budget {
        s += 1;
    }
    s
}

/// One pass over the sample grid: stride `st`, samples at least `lo` pixels from every border
/// (their central differences reach `lo − 1`). With `sandwich` it also sums the sensitivity
/// matrix [`Pass::a`] from the reference's own gradient (the final pass' covariance).
fn pass(
    frame: &SlopeImage<'_>,
    raster: &SlopeRaster<'_>,
    warp: &Warp,
    (st, lo): (usize, usize),
    centre: (f32, f32),
    model: &PassModel,
) -> Pass {
    let (w, h) = (frame.width(), frame.height());
    let m = [
        [warp.m[0][0] as f32, warp.m[0][1] as f32],
        [warp.m[1][0] as f32, warp.m[1][1] as f32],
    ];
    let t = [warp.t[0] as f32, warp.t[1] as f32];
    let PassModel {
        gain: g,
        offset: o,
        huber,
        sandwich,
    } = *model;
    let mut out = Pass::default();
    let half = st / 2;
    let mut v = lo + half;
    // Residuals of the previous sample row (NaN = no valid sample there).
    let mut above = [f32::NAN; LAG_ROW];
    // Residuals two and three sample rows up (final pass only; NaN = none, or a row between
    // invalid).
    let mut above2 = [f32::NAN; LAG_ROW];
    let mut above3 = [f32::NAN; LAG_ROW];
    while v + lo < h {
        let mut svlag = 0.0f32;
        let (mut slag3, mut svlag3) = (0.0f32, 0.0f32);
        let mut pairs = [0u32; 4];
        let (mut prev2, mut prev3) = (None::<f32>, None::<f32>);
        let mut col = 0usize;
        let mut hr = [0.0f32; 21];
        let mut br = [0.0f32; 6];
        let mut ar = [0.0f32; 24];
        let (mut sf, mut sr, mut sff, mut srr, mut sfr, mut see) =
            (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
        let (mut slag, mut prev) = (0.0f32, None::<f32>);
        let mut u = lo + half;
        while u + lo < w {
            let sample = (|| {
                let f = deg(frame.get(u, v))?;
                let fx = 0.5 * (deg(frame.get(u + 1, v))? - deg(frame.get(u - 1, v))?);
                let fy = 0.5 * (deg(frame.get(u, v + 1))? - deg(frame.get(u, v - 1))?);
                let (x, y) = (u as f32 - centre.0, v as f32 - centre.1);
                let px = m[0][0] * x + m[0][1] * y + t[0];
                let py = m[1][0] * x + m[1][1] * y + t[1];
                let (r, gx, gy) = if sandwich {
                    bilinear_grad(raster, px, py)?
                } else {
                    (bilinear(raster, px, py)?, 0.0, 0.0)
                };
                Some((f, fx, fy, x, y, r, gx, gy))
            })();
            u += st;
            let slot = above.get_mut(col);
            let slot2 = above2.get_mut(col);
            let slot3 = above3.get_mut(col);
            col += 1;
            let Some((f, fx, fy, x, y, r, gx, gy)) = sample else {
                (prev, prev2, prev3) = (None, None, None);
                for a in [slot, slot2, slot3].into_iter().flatten() {
                    *a = f32::NAN;
                }
                continue;
            };
            let e = r - (g * f + o);
            if sandwich {
                if let (Some(p3), Some(_), Some(_)) = (prev3, prev2, prev) {
                    slag3 += p3 * e;
                    pairs[1] += 1;
                }
                if prev.is_some() {
                    pairs[0] += 1;
                }
                prev3 = prev2;
                prev2 = prev;
            }
            if let Some(p) = prev {
                slag += p * e;
            }
            prev = Some(e);
            if let Some(a) = slot {
                if sandwich && let (Some(a2), Some(a3)) = (slot2, slot3) {
                    // Three rows up only through valid samples between.
                    if a3.is_finite() && a2.is_finite() && a.is_finite() {
                        svlag3 += *a3 * e;
                        pairs[3] += 1;
                    }
                    if a.is_finite() {
                        pairs[2] += 1;
                    }
                    *a3 = *a2;
                    *a2 = *a;
                }
                if a.is_finite() {
                    svlag += *a * e;
                }
                *a = e;
            }
            let ae = libm::fabsf(e);
            let wt = if ae > huber { huber / ae } else { 1.0 };
            let s = [
                g * (fx * x + fy * y),
                g * (fy * x - fx * y),
                g * fx,
                g * fy,
                f,
                1.0,
            ];
            let mut hk = hr.iter_mut();
            for (i, (si, bi)) in s.iter().zip(br.iter_mut()).enumerate() {
                let wsi = wt * si;
                *bi += wsi * e;
                for (sj, hij) in s.iter().skip(i).zip(hk.by_ref()) {
                    *hij += wsi * sj;
                }
            }
            if sandwich {
                // The reference's gradient in frame pixels, Mᵀ·∇R: how the residual really
                // moves with the warp (R is what gets resampled), free of the frame's noise.
                let rx = m[0][0] * gx + m[1][0] * gy;
                let ry = m[0][1] * gx + m[1][1] * gy;
                let s_ref = [rx * x + ry * y, ry * x - rx * y, rx, ry];
                for (si, arow) in s.iter().zip(ar.chunks_exact_mut(4)) {
                    let wsi = wt * si;
                    for (aij, sj) in arow.iter_mut().zip(s_ref) {
                        *aij += wsi * sj;
                    }
                }
            }
            sf += f;
            sr += r;
            sff += f * f;
            srr += r * r;
            sfr += f * r;
            see += e * e;
            out.n += 1;
        }
        for (t, r) in out.b.iter_mut().zip(br) {
            *t += r as f64;
        }
        for (t, r) in out.h.iter_mut().zip(hr) {
            *t += r as f64;
        }
        if sandwich {
            for (t, r) in out.a.iter_mut().zip(ar) {
                *t += r as f64;
            }
        }
        out.sf += sf as f64;
        out.sr += sr as f64;
        out.sff += sff as f64;
        out.srr += srr as f64;
        out.sfr += sfr as f64;
        out.see += see as f64;
        out.slag += slag as f64;
        out.svlag += svlag as f64;
        out.slag3 += slag3 as f64;
        out.svlag3 += svlag3 as f64;
        for (t, c) in out.pairs.iter_mut().zip(pairs) {
            *t += c;
        }
        v += st;
    }
    out
}

/// Refine `initial` (frame pixels → tile pixels) by aligning `frame` to `raster`.
///
/// `frame` is the slope image the features came from, `bin` the binning factor between it and
/// the frame pixel coordinates of `initial` (frame pixel `x = bin·u + (bin − 1)/2` for image
/// column `u`; 1 when unbinned). The result maps frame pixels (unbinned) to tile pixels.
///
/// `info` carries the frame's expected scale and the border band to leave out ([`FrameInfo`]).
pub fn refine(
    frame: &SlopeImage<'_>,
    bin: usize,
    raster: &SlopeRaster<'_>,
    initial: &Affine,
    info: &FrameInfo,
    cfg: &RefineConfig,
) -> Result<Refined, RefineError> {
    refine_metered(frame, bin, raster, initial, info, cfg, &mut 0)
}

/// [`refine`], adding to `work` the valid samples of every pass it ran (samples × passes, the
/// final pass weighing [`SANDWICH_PASS_WEIGHT`], whatever the result: what the navigator
/// charges the frame's work budget).
pub fn refine_metered(
    frame: &SlopeImage<'_>,
    bin: usize,
    raster: &SlopeRaster<'_>,
    initial: &Affine,
    info: &FrameInfo,
    cfg: &RefineConfig,
    work: &mut u32,
) -> Result<Refined, RefineError> {
    if !cfg.enabled {
        return Err(RefineError::Disabled);
    }
    let (w, h) = (frame.width(), frame.height());
    if w < 3 || h < 3 {
        return Err(RefineError::TooFewSamples);
    }
    let k = bin.max(1) as f64;
    let off = (k - 1.0) * 0.5;
    let (uc, vc) = ((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5);
    // Start from the nearest similarity, anchored at the frame centre: the warp family only
    // composes similarities, so any shear of the feature affine would otherwise stay frozen in.
    let sim = similarity(initial);
    let (sn, cs) = (libm::sin(sim.rotation_rad), libm::cos(sim.rotation_rad));
    let sk = sim.scale * k;
    let (cx, cy) = initial.apply(k * uc + off, k * vc + off);
    let start = Warp {
        m: [[sk * cs, -sk * sn], [sk * sn, sk * cs]],
        t: [cx, cy],
    };
    let mut warp = start;
    let corners = [(-uc, -vc), (uc, -vc), (-uc, vc), (uc, vc)];
    let moved = |a: &Warp, b: &Warp| {
        corners.iter().fold(0.0f64, |acc, &(x, y)| {
            let (ax, ay) = a.apply(x, y);
            let (bx, by) = b.apply(x, y);
            acc.max(libm::hypot(ax - bx, ay - by))
        })
    };
    // Central differences need one pixel beyond each sample, outside the biased band (a band
    // wider than the frame leaves no sample: too few samples, below).
    let lo = info.border_px.min(w.max(h)).saturating_add(1);
    let st = stride(
        w.saturating_sub(2 * lo),
        h.saturating_sub(2 * lo),
        cfg.max_samples,
    );
    // Every pass reads at most this grid (an upper bound of its valid samples).
    let grid = u32::try_from(
        w.saturating_sub(2 * lo).div_ceil(st) * h.saturating_sub(2 * lo).div_ceil(st),
    )
    .unwrap_or(u32::MAX);
    let mut allowance = cfg.max_sample_passes;
    // The scale prior as (log of the expected scale, 1σ of the log-scale).
    let sig = cfg.frame_scale_sigma as f64;
    let scale_prior = info
        .scale
        .filter(|s| s.is_finite() && *s > 0.0 && sig.is_finite() && sig > 0.0)
        .map(|s| (libm::log(s), sig));
    // The scale prior's weight in a pass. The warp's scale after an update z is
    // s/|1 + z₀ + i·z₁| ≈ s·(1 − z₀), so the prior is one more residual ln s − ln s̄ − z₀,
    // weighted by the pass' residual variance over the prior's: (weight, residual).
    let prior_term = |p: &Pass, warp: &Warp| {
        let (ln_expected, sig) = scale_prior?;
        let s_now = libm::hypot(warp.m[0][0], warp.m[1][0]) / k;
        let wt = p.sigma2() / (sig * sig);
        (s_now > 0.0 && wt.is_finite()).then(|| (wt, libm::log(s_now) - ln_expected))
    };
    // Normal equations of a pass with the scale prior added.
    let normal = |p: &Pass, warp: &Warp| {
        let (mut hm, mut b) = (p.normal_matrix(), p.rhs());
        if let Some((wt, e)) = prior_term(p, warp) {
            if let Some(h00) = hm.get_mut((0, 0)) {
                *h00 += wt;
            }
            if let Some(b0) = b.get_mut(0) {
                *b0 += wt * e;
            }
        }
        (hm, b)
    };
    let centre = (uc as f32, vc as f32);
    let (mut g, mut o) = (1.0f32, 0.0f32);
    let mut huber = f32::INFINITY;
    let iters = cfg.max_iterations.min(MAX_ITERATIONS);
    let mut ncc_before = 0.0f32;
    let mut converged = false;
    let mut done = 0u8;
    let (mut damp, mut prev_b, mut prev_zb) = (1.0f64, [0.0f64; 6], 0.0f64);
    let last = loop {
        let model = PassModel {
            gain: g,
            offset: o,
            huber,
            sandwich: converged || done >= iters,
        };
        // Out of updates without converging: the final pass could not change the verdict.
        if !converged && done >= iters && done > 0 {
            return Err(RefineError::NotConverged);
        }
        let weight = if model.sandwich {
            SANDWICH_PASS_WEIGHT
        } else {
            1
        };
        let Some(rest) = allowance.checked_sub(grid.saturating_mul(weight)) else {
            return Err(RefineError::OverBudget);
        };
        allowance = rest;
        let p = pass(frame, raster, &warp, (st, lo), centre, &model);
        *work = work.saturating_add(p.n.saturating_mul(weight));
        if p.n < cfg.min_samples.max(8) {
            return Err(RefineError::TooFewSamples);
        }
        if done == 0 {
            ncc_before = p.ncc();
        }
        if converged || done >= iters {
            break p;
        }
        huber = (2.0 * p.rms()).max(1e-3);
        let (hm, b) = normal(&p, &warp);
        let Some(chol) = hm.cholesky() else {
            return Err(RefineError::Singular);
        };
        let z: [f64; 6] = chol.solve(&b).into();
        // A full Gauss–Newton step that turns back on more than half of the last full step
        // (zₖᵀ·b₋₁ < −½·zₖ₋₁ᵀ·b₋₁ in the last pass' metric, b₋₁ = H₋₁·zₖ₋₁) says the iteration
        // oscillates without decaying: where the frame's Jacobian misjudges the curvature of a
        // weak direction, plain Gauss–Newton settles into a two-cycle there and never converges
        // (InSAR fresh-crater floor, docs/registration.md). Halve the step length then, for the
        // rest of the refinement, down to [`MIN_STEP_LENGTH`]. A reversal that decays on its
        // own is left alone: on truth-built tiles the fix is good to 0.01 px, and damping those
        // moved where the 0.03 px test stopped (LOLA scene: mean NEES 1.97 → 2.25–2.38).
        let back: f64 = z.iter().zip(prev_b.iter()).map(|(a, c)| a * c).sum();
        if back < -0.5 * prev_zb {
            damp = (damp * 0.5).max(MIN_STEP_LENGTH);
        }
        prev_zb = z.iter().zip(b.iter()).map(|(a, c)| a * c).sum();
        prev_b = b.into();
        let z = z.map(|v| v * damp);
        let [z0, z1, dx, dy, dg, d_o] = z;
        let (da, db) = (1.0 + z0, z1);
        let det = da * da + db * db;
        if !(det > 1e-6 && z.iter().all(|v| v.is_finite())) {
            return Err(RefineError::Singular);
        }
        // W ← W ∘ W_q⁻¹ with W_q(x) = S·x + d, S = [[da, −db], [db, da]].
        let si = [[da / det, db / det], [-db / det, da / det]];
        let mm = &warp.m;
        let m = [
            [
                mm[0][0] * si[0][0] + mm[0][1] * si[1][0],
                mm[0][0] * si[0][1] + mm[0][1] * si[1][1],
            ],
            [
                mm[1][0] * si[0][0] + mm[1][1] * si[1][0],
                mm[1][0] * si[0][1] + mm[1][1] * si[1][1],
            ],
        ];
        let next = Warp {
            m,
            t: [
                warp.t[0] - (m[0][0] * dx + m[0][1] * dy),
                warp.t[1] - (m[1][0] * dx + m[1][1] * dy),
            ],
        };
        converged = moved(&next, &warp) < cfg.converge_px as f64;
        warp = next;
        g += dg as f32;
        o += d_o as f32;
        done += 1;
    };
    if !converged {
        return Err(RefineError::NotConverged);
    }
    let shift = moved(&warp, &start);
    if !(shift <= cfg.max_shift_px as f64) {
        return Err(RefineError::MovedTooFar);
    }
    let ncc_after = last.ncc();
    if !(ncc_after >= ncc_before - NCC_TOLERANCE && ncc_after >= cfg.min_ncc) {
        return Err(RefineError::WorseCorrelation);
    }
    // Covariance of (da, db, dx, dy, g, o) from the final pass (with the scale prior),
    // inflated for correlation: the sandwich σ²·A⁻¹·H·A⁻ᵀ of the estimating equation
    // Σ w·s_F·e = 0. H (from the frame's gradients) both steers the fit and weighs its noise,
    // but the frame's gradients carry the frame's noise, which adds to H without adding
    // information: σ²·H⁻¹ alone was overconfident by about 1.4× in variance wherever the
    // frame's texture is weak beside its noise (keyframe odometry, plains). A takes the
    // residual's true sensitivity from the reference's gradient instead, whose noise is
    // independent of the frame's (docs/registration.md, Covariance). Huber's weights enter
    // A and H as IRLS weights w (a strict M-estimator would take ψ′, 0 beyond the threshold,
    // in A and w²·e² in the meat): alike for the few samples clipped at 2× the RMS. An A
    // with an exactly zero pivot (possible, where H was positive definite, on a reference
    // without gradient under the frame) refuses the refinement as `Singular`.
    let hm = normal(&last, &warp).0;
    let mut am = SMatrix::<f64, 6, 6>::from_fn(|i, j| {
        if j < 4 {
            last.a.get(i * 4 + j).copied().unwrap_or(f64::NAN)
        } else {
            hm.get((i, j)).copied().unwrap_or(f64::NAN)
        }
    });
    if let (Some((wt, _)), Some(a00)) = (prior_term(&last, &warp), am.get_mut((0, 0))) {
        *a00 += wt;
    }
    let Some(ai) = am.try_inverse() else {
        return Err(RefineError::Singular);
    };
    let inv = ai * hm * ai.transpose();
    if !(0..6).all(|i| inv.get((i, i)).is_some_and(|v| v.is_finite() && *v > 0.0)) {
        return Err(RefineError::Singular);
    }
    let rho = last.lag_correlation() as f64;
    let sigma2 = last.sigma2();
    let cv = |i: usize, j: usize| sigma2 * inv.get((i, j)).copied().unwrap_or(f64::NAN);
    // The centre moves by −M·d: covariance M·Σ_dd·Mᵀ.
    let m = &warp.m;
    let sdd = [[cv(2, 2), cv(2, 3)], [cv(3, 2), cv(3, 3)]];
    let mut cov = [[0.0f64; 2]; 2];
    for (i, row) in cov.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let (mi, mj) = (
                m.get(i).copied().unwrap_or_default(),
                m.get(j).copied().unwrap_or_default(),
            );
            *v = mi[0] * (sdd[0][0] * mj[0] + sdd[0][1] * mj[1])
                + mi[1] * (sdd[1][0] * mj[0] + sdd[1][1] * mj[1]);
        }
    }
    let scale_now = libm::hypot(m[0][0], m[1][0]) / k;
    // Back to unbinned frame pixels: u = (x − off)/k.
    let (m, t) = (warp.m, warp.t);
    let (a, b, c, d) = (m[0][0] / k, m[0][1] / k, m[1][0] / k, m[1][1] / k);
    let (u0, v0) = (uc + off / k, vc + off / k);
    let affine = Affine {
        m1: a,
        n1: b,
        p1: t[0] - m[0][0] * u0 - m[0][1] * v0,
        m2: c,
        n2: d,
        p2: t[1] - m[1][0] * u0 - m[1][1] * v0,
    };
    Ok(Refined {
        affine,
        iterations: done,
        samples: last.n,
        ncc_before,
        ncc_after,
        residual_rms_deg: last.rms(),
        shift_px: shift as f32,
        center_cov_tile_px2: cov,
        rotation_sigma_rad: libm::sqrt(cv(1, 1).max(0.0)),
        scale_sigma: scale_now * libm::sqrt(cv(0, 0).max(0.0)),
        correlation: rho as f32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{SLOPE_NODATA, slope_from_deg};
    use crate::tile::{Tile, TileHeader, tile_len_with_raster, write_tile_with_raster};
    use std::vec;
    use std::vec::Vec;

    const W: usize = 96;

    /// Smooth, textured slope field in degrees at tile pixel `(x, y)`: broad slopes plus
    /// [`fine_texture`].
    fn field(x: f64, y: f64) -> f64 {
        20.0 + 4.0 * libm::sin(0.09 * x - 0.13 * y) + fine_texture(x, y)
    }

    /// The field's fine texture (periods of 20–37 px), degrees.
    fn fine_texture(x: f64, y: f64) -> f64 {
        6.0 * libm::sin(0.21 * x + 0.4) * libm::cos(0.17 * y - 0.3)
            + 3.0 * libm::cos(0.31 * y + 0.05 * x)
    }

    fn tile_bytes(raster: Option<&[SlopePx]>) -> Vec<u8> {
        let header = TileHeader {
            width_px: W as u32,
            height_px: W as u32,
            origin_x_m: 0.0,
            origin_y_m: 0.0,
            pixel_x_m: 20.0,
            pixel_y_m: -20.0,
            projection: "test",
            feature_count: 0,
            octaves: 3,
            layers: 4,
            threshold: 1.0,
            min_scale_px: 0.0,
            upright: false,
            smoothing_m: 0.0,
            reference_sigma_m: [0.0; 2],
            height_noise_m: 0.0,
        };
        let mut buf = vec![0u8; tile_len_with_raster(512, 0, W * W)];
        let n = write_tile_with_raster(&header, &[], raster, &mut buf).unwrap();
        buf.truncate(n);
        buf
    }

    fn reference() -> Vec<SlopePx> {
        (0..W * W)
            .map(|i| slope_from_deg(field((i % W) as f64, (i / W) as f64) as f32))
            .collect()
    }

    /// A 60 × 60 frame seeing the field through `truth` (frame px → tile px).
    fn frame(truth: &Affine) -> Vec<SlopePx> {
        (0..60 * 60)
            .map(|i| {
                let (x, y) = truth.apply((i % 60) as f64, (i / 60) as f64);
                slope_from_deg(field(x, y) as f32)
            })
            .collect()
    }

    fn similarity_at(deg: f64, s: f64, tx: f64, ty: f64) -> Affine {
        let (sn, cs) = (libm::sin(deg.to_radians()), libm::cos(deg.to_radians()));
        Affine {
            m1: s * cs,
            n1: -s * sn,
            p1: tx,
            m2: s * sn,
            n2: s * cs,
            p2: ty,
        }
    }

    /// `got` and `want` put each frame point within `tol_px` tile pixels of each other.
    fn assert_maps_agree(got: &Affine, want: &Affine, pts: &[(f64, f64)], tol_px: f64) {
        for &(x, y) in pts {
            let (a, b) = got.apply(x, y);
            let (c, d) = want.apply(x, y);
            assert!(libm::hypot(a - c, b - d) < tol_px, "({x}, {y}): {got:?}");
        }
    }

    #[test]
    fn recovers_a_perturbed_similarity() {
        let bytes = tile_bytes(Some(&reference()));
        let tile = Tile::parse(&bytes).unwrap();
        let truth = similarity_at(30.0, 0.8, 40.0, 20.0);
        let px = frame(&truth);
        let img = SlopeImage::new_checked(&px, 60, 60, 16.0).unwrap();
        // Start 1.5° and 1 px off, with 1 % scale error.
        let start = similarity_at(31.5, 0.808, 41.0, 19.2);
        let r = refine(
            &img,
            1,
            tile.slope_raster().unwrap(),
            &start,
            &FrameInfo::default(),
            &RefineConfig::default(),
        )
        .unwrap();
        let sim = similarity(&r.affine);
        assert!(
            (sim.rotation_rad.to_degrees() - 30.0).abs() < 0.02,
            "{sim:?}"
        );
        assert!((sim.scale / 0.8 - 1.0).abs() < 1e-3, "{sim:?}");
        assert_maps_agree(
            &r.affine,
            &truth,
            &[(0.0, 0.0), (59.0, 59.0), (30.0, 10.0)],
            0.05,
        );
        assert!(r.ncc_after > r.ncc_before && r.ncc_after > 0.99, "{r:?}");
    }

    /// On a noise-free frame the sensitivity matrix A, built from the reference's gradient,
    /// equals the Gauss–Newton matrix H built from the frame's, entry by entry: signs, the
    /// warp's transpose and the block layout all have to be right for that (a sign or a
    /// transposed M would only rotate the sandwich, which a NEES test cannot see).
    #[test]
    fn the_reference_sensitivity_matches_the_frame_jacobian() {
        let bytes = tile_bytes(Some(&reference()));
        let tile = Tile::parse(&bytes).unwrap();
        let truth = similarity_at(30.0, 0.8, 40.0, 20.0);
        let px = frame(&truth);
        let img = SlopeImage::new_checked(&px, 60, 60, 16.0).unwrap();
        // The warp of `truth` about the frame centre, as `refine` builds it.
        let (sn, cs) = (libm::sin(30f64.to_radians()), libm::cos(30f64.to_radians()));
        let (cx, cy) = truth.apply(29.5, 29.5);
        let warp = Warp {
            m: [[0.8 * cs, -0.8 * sn], [0.8 * sn, 0.8 * cs]],
            t: [cx, cy],
        };
        let model = PassModel {
            gain: 1.0,
            offset: 0.0,
            huber: f32::INFINITY,
            sandwich: true,
        };
        let p = pass(
            &img,
            tile.slope_raster().unwrap(),
            &warp,
            (2, 1),
            (29.5, 29.5),
            &model,
        );
        assert!(p.n > 500, "{}", p.n);
        let h = p.normal_matrix();
        for i in 0..6 {
            for j in 0..4 {
                let (a, hij) = (p.a[i * 4 + j], h[(i, j)]);
                let scale = libm::sqrt(h[(i, i)] * h[(j, j)]);
                assert!(
                    (a - hij).abs() <= 0.02 * scale,
                    "A[{i}][{j}] = {a}, H = {hij} (scale {scale})"
                );
            }
        }
        // Without the flag nothing is summed.
        let off = pass(
            &img,
            tile.slope_raster().unwrap(),
            &warp,
            (2, 1),
            (29.5, 29.5),
            &PassModel {
                sandwich: false,
                ..model
            },
        );
        assert!(off.a.iter().all(|v| *v == 0.0));
        assert_eq!(off.h, p.h);
    }

    /// The shape's two ends and the middle, with the thresholds built as `lag_factor` builds
    /// them (ρ·ρ·ρ, then its cube), since `powi` may round otherwise.
    #[test]
    fn the_lag_factor_spans_first_order_to_gaussian_decay() {
        for rho in [0.1, 0.5, 0.9] {
            let cube = rho * rho * rho;
            let ninth = cube * cube * cube;
            // Lag 3 at ρ³ (or above): first order, (1 + ρ)/(1 − ρ), in closed form.
            let first = (1.0 + rho) / (1.0 - rho);
            assert_eq!(lag_factor(rho, cube), first);
            assert_eq!(lag_factor(rho, rho), first);
            assert_eq!(lag_factor(rho, f64::NAN), first);
            // Lag 3 at ρ⁹ (or below): Gaussian, 1 + 2·Σ ρ^(k²).
            let gauss: f64 = 1.0 + 2.0 * (1..=64).map(|k| rho.powi(k * k)).sum::<f64>();
            assert!((lag_factor(rho, ninth) - gauss).abs() < 1e-5 * gauss);
            assert_eq!(lag_factor(rho, -0.3), lag_factor(rho, ninth));
            // Just above the Gaussian end the computed shape takes over, continuously.
            let near = lag_factor(rho, ninth * 1.01);
            assert!(near >= lag_factor(rho, ninth) && (near - gauss).abs() < 1e-2 * gauss);
            // In between: p = ln 5 / ln 3 for ρ₃ = ρ⁵, against an f64 sum of that shape.
            let p = libm::log(5.0) / libm::log(3.0);
            let want: f64 = 1.0
                + 2.0
                    * (1..=64)
                        .map(|k| libm::pow(rho, libm::pow(k as f64, p)))
                        .sum::<f64>();
            let mid = lag_factor(rho, cube * rho * rho);
            assert!((mid - want).abs() < 1e-4 * want, "{mid} {want}");
            assert!(gauss < mid && mid < first);
        }
        // Uncorrelated (or anticorrelated, clamped to 0 before) residuals: no inflation.
        assert_eq!(lag_factor(0.0, 0.0), 1.0);
        assert_eq!(lag_factor(f64::NAN, 0.5), 1.0);
        // At the 0.9 clamp the Gaussian factor is about a quarter of the first-order one.
        let c = 0.9 * 0.9 * 0.9;
        let r = lag_factor(0.9, c * c * c) / lag_factor(0.9, c);
        assert!(r > 0.25 && r < 0.3, "{r}");
    }

    /// The final pass's lag sums against a brute-force count over the same residuals: a frame
    /// that sees the reference through a pure shift plus a known ripple, one sample masked.
    /// Lag 3 pairs only through valid samples between, both axes; the steps' passes sum none.
    #[test]
    fn the_final_pass_sums_lag_three_through_valid_samples_only() {
        let bytes = tile_bytes(Some(&reference()));
        let tile = Tile::parse(&bytes).unwrap();
        let raster = tile.slope_raster().unwrap();
        let ripple = |u: usize, v: usize| 2.0 * libm::sin(1.7 * u as f64 + 0.9 * v as f64);
        let mut px: Vec<SlopePx> = (0..60 * 60)
            .map(|i| {
                let (u, v) = (i % 60, i / 60);
                slope_from_deg((field(u as f64 + 10.0, v as f64 + 10.0) + ripple(u, v)) as f32)
            })
            .collect();
        // (12, 12) is a sample of the stride-2 grid; no other sample reads it.
        px[12 * 60 + 12] = SLOPE_NODATA;
        let img = SlopeImage::new_checked(&px, 60, 60, 16.0).unwrap();
        let warp = Warp {
            m: [[1.0, 0.0], [0.0, 1.0]],
            t: [39.5, 39.5],
        };
        let model = PassModel {
            gain: 1.0,
            offset: 0.0,
            huber: f32::INFINITY,
            sandwich: true,
        };
        let p = pass(&img, raster, &warp, (2, 1), (29.5, 29.5), &model);
        // The residual at each sample of the grid (u, v = 2, 4, …, 58), None where masked.
        let grid: Vec<Vec<Option<f64>>> = (2..59)
            .step_by(2)
            .map(|v| {
                (2..59)
                    .step_by(2)
                    .map(|u| {
                        (u != 12 || v != 12).then(|| {
                            let r = bilinear(raster, u as f32 + 10.0, v as f32 + 10.0).unwrap();
                            (r - deg(img.get(u, v)).unwrap()) as f64
                        })
                    })
                    .collect()
            })
            .collect();
        let (mut s3, mut sv3, mut pairs) = (0.0, 0.0, [0u32; 4]);
        for (i, row) in grid.iter().enumerate() {
            for (j, e) in row.iter().enumerate() {
                let Some(e) = e else { continue };
                let at = |i: usize, j: usize| grid[i][j];
                if j >= 1 && at(i, j - 1).is_some() {
                    pairs[0] += 1;
                }
                if j >= 3 && (1..=3).all(|d| at(i, j - d).is_some()) {
                    s3 += e * at(i, j - 3).unwrap();
                    pairs[1] += 1;
                }
                if i >= 1 && at(i - 1, j).is_some() {
                    pairs[2] += 1;
                }
                if i >= 3 && (1..=3).all(|d| at(i - d, j).is_some()) {
                    sv3 += e * at(i - 3, j).unwrap();
                    pairs[3] += 1;
                }
            }
        }
        assert_eq!(p.pairs, pairs);
        // 29 samples a row and column (28 lag-1 and 26 lag-3 pairs each), one masked: its row
        // and its column each lose 2 lag-1 and 4 lag-3 pairs.
        assert_eq!(pairs, [29 * 28 - 2, 29 * 26 - 4, 29 * 28 - 2, 29 * 26 - 4]);
        assert!(
            (p.slag3 - s3).abs() <= 1e-4 * s3.abs().max(1.0),
            "{} {s3}",
            p.slag3
        );
        assert!(
            (p.svlag3 - sv3).abs() <= 1e-4 * sv3.abs().max(1.0),
            "{} {sv3}",
            p.svlag3
        );
        assert!(s3 != 0.0 && sv3 != 0.0);
        let off = pass(
            &img,
            raster,
            &warp,
            (2, 1),
            (29.5, 29.5),
            &PassModel {
                sandwich: false,
                ..model
            },
        );
        assert_eq!((off.slag3, off.svlag3, off.pairs), (0.0, 0.0, [0; 4]));
        assert_eq!(off.slag, p.slag);
    }

    /// Over many noisy frames the refined centre scatters as its covariance says. The frame
    /// carries white slope noise of 1° per pixel against gradients of about 1° per pixel, so
    /// its central differences are noisy: σ²·H⁻¹ alone (before the sandwich) scored a mean
    /// NEES of 8.4 here, the sandwich 1.58 (session 20, with the first-order lag factor: a
    /// little conservative, the residuals' lag correlation, clamped at 0 from below, inflated
    /// σ² by ~1.2 on white noise). The noisy H
    /// also shortens every Gauss–Newton step (by H_true/H, 0.4 here), so the default 0.03 px
    /// convergence test stops short of the fixed point and leaves the estimate nearer its
    /// start; the test converges tightly to score the fixed point, whose covariance the
    /// sandwich describes.
    #[test]
    fn the_covariance_covers_a_noisy_frame() {
        let bytes = tile_bytes(Some(&reference()));
        let tile = Tile::parse(&bytes).unwrap();
        let truth = similarity_at(30.0, 0.8, 40.0, 20.0);
        let mut rng = crate::rng::Pcg32::new(20_261_126, 7);
        let mut gauss = || {
            let u1 = (rng.next_u32() as f64 + 1.0) / 4_294_967_297.0;
            let u2 = rng.next_u32() as f64 / 4_294_967_296.0;
            libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(core::f64::consts::TAU * u2)
        };
        let (trials, mut sum) = (300, 0.0);
        let (cx, cy) = truth.apply(29.5, 29.5);
        let start = similarity_at(30.5, 0.8, 40.6, 19.6);
        let cfg = RefineConfig {
            converge_px: 0.002,
            ..RefineConfig::default()
        };
        for _ in 0..trials {
            let px: Vec<SlopePx> = (0..60 * 60)
                .map(|i| {
                    let (x, y) = truth.apply((i % 60) as f64, (i / 60) as f64);
                    slope_from_deg((field(x, y) + gauss()) as f32)
                })
                .collect();
            let img = SlopeImage::new_checked(&px, 60, 60, 16.0).unwrap();
            let r = refine(
                &img,
                1,
                tile.slope_raster().unwrap(),
                &start,
                &FrameInfo::default(),
                &cfg,
            )
            .unwrap();
            let (x, y) = r.affine.apply(29.5, 29.5);
            let (ex, ey) = (x - cx, y - cy);
            let c = r.center_cov_tile_px2;
            let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
            sum += (c[1][1] * ex * ex - 2.0 * c[0][1] * ex * ey + c[0][0] * ey * ey) / det;
        }
        // χ²(2): mean 2, standard error of a 300-trial mean 0.12.
        let nees = sum / trials as f64;
        assert!((1.3..2.6).contains(&nees), "mean NEES {nees}");
    }

    /// Slope of `heights` (`w × h`, 20 m pixels) smoothed by σ = 2 px, as the navigator
    /// smooths frames and the ground smooths tiles.
    fn smoothed_slope(heights: &[f32], w: usize, h: usize) -> Vec<SlopePx> {
        let patch = crate::frame::DemPatch::new_checked(heights, w, h, 20.0).unwrap();
        let mut px = vec![SLOPE_NODATA; w * h];
        crate::slope::slope_into_binned_smoothed::<128>(&patch, 1, 2.0, &mut px, false).unwrap();
        px
    }

    #[test]
    fn the_border_band_of_a_smoothed_frame_is_left_out() {
        // A crater wall: slope growing from 9° to 25° across the frame, with some texture.
        let height = |x: f64, y: f64| {
            0.06 * (x + 5.0) * (x + 5.0) + 4.0 * libm::sin(0.35 * x) * libm::cos(0.3 * y)
        };
        let grid = |w: usize, h: usize, dx: f64, dy: f64| -> Vec<f32> {
            (0..w * h)
                .map(|i| height((i % w) as f64 + dx, (i / w) as f64 + dy) as f32)
                .collect()
        };
        let reference = smoothed_slope(&grid(W, W, 0.0, 0.0), W, W);
        let bytes = tile_bytes(Some(&reference));
        let tile = Tile::parse(&bytes).unwrap();
        // The frame: 64 × 64 of the same ground at the same pixel, offset (15, 14), clear of
        // the reference's own border band.
        let px = smoothed_slope(&grid(64, 64, 15.0, 14.0), 64, 64);
        let img = SlopeImage::new_checked(&px, 64, 64, 20.0).unwrap();
        let truth = similarity_at(0.0, 1.0, 15.0, 14.0);
        let start = similarity_at(0.3, 1.0, 15.4, 13.7);
        let err = |border_px: usize| {
            let info = FrameInfo {
                scale: Some(1.0),
                border_px,
            };
            let r = refine(
                &img,
                1,
                tile.slope_raster().unwrap(),
                &start,
                &info,
                &RefineConfig::default(),
            )
            .unwrap();
            let (a, b) = r.affine.apply(31.5, 31.5);
            let (c, d) = truth.apply(31.5, 31.5);
            libm::hypot(a - c, b - d)
        };
        let border = crate::slope::smoothing_radius(2.0) + 1;
        assert_eq!(border, 7);
        // With the band the centre is pulled off by the cut kernels' bias; without it the
        // fit is exact to the interpolation.
        let (with_band, without) = (err(0), err(border));
        std::println!("centre error: band kept {with_band:.4} px, left out {without:.4} px");
        assert!(without < 0.02, "border left out: centre {without} px off");
        assert!(
            with_band > 5.0 * without && with_band > 0.05,
            "border kept: centre {with_band} px off (left out: {without})"
        );
    }

    /// A frame whose fine slope texture is a third as strong as the reference's (its broad
    /// slopes as strong): its Jacobian underrates the fit's curvature, so a plain
    /// Gauss–Newton step overshoots (the refinement without the step control ends here as
    /// "did not converge", checked by switching the halving off). With it
    /// the refinement must converge inside the budget to a fixed point: started again from
    /// its own answer, it stays there. (The fixed point is a few tenths of a degree off the
    /// truth: the altered texture biases it, which is not what this test is about.)
    #[test]
    fn an_overshooting_jacobian_still_converges() {
        let bytes = tile_bytes(Some(&reference()));
        let tile = Tile::parse(&bytes).unwrap();
        let raster = tile.slope_raster().unwrap();
        let truth = similarity_at(30.0, 0.8, 40.0, 20.0);
        let px: Vec<SlopePx> = (0..60 * 60)
            .map(|i| {
                let (x, y) = truth.apply((i % 60) as f64, (i / 60) as f64);
                slope_from_deg((field(x, y) - 2.0 / 3.0 * fine_texture(x, y)) as f32)
            })
            .collect();
        let img = SlopeImage::new_checked(&px, 60, 60, 16.0).unwrap();
        let start = similarity_at(31.0, 0.8, 40.8, 19.4);
        let cfg = RefineConfig::default();
        let r = refine(&img, 1, raster, &start, &FrameInfo::default(), &cfg).unwrap();
        assert!(r.iterations < 20, "{r:?}");
        assert_maps_agree(
            &r.affine,
            &truth,
            &[(0.0, 0.0), (59.0, 59.0), (30.0, 10.0)],
            1.5,
        );
        let again = refine(&img, 1, raster, &r.affine, &FrameInfo::default(), &cfg).unwrap();
        assert_maps_agree(
            &again.affine,
            &r.affine,
            &[(0.0, 0.0), (59.0, 59.0), (30.0, 10.0)],
            0.05,
        );
    }

    #[test]
    fn the_frame_scale_prior_enters_the_fit() {
        let bytes = tile_bytes(Some(&reference()));
        let tile = Tile::parse(&bytes).unwrap();
        let truth = similarity_at(30.0, 0.8, 40.0, 20.0);
        let px = frame(&truth);
        let img = SlopeImage::new_checked(&px, 60, 60, 16.0).unwrap();
        let start = similarity_at(31.5, 0.808, 41.0, 19.2);
        let run = |scale: f64, sigma: f32| {
            let cfg = RefineConfig {
                frame_scale_sigma: sigma,
                ..RefineConfig::default()
            };
            let info = FrameInfo {
                scale: Some(scale),
                border_px: 0,
            };
            refine(&img, 1, tile.slope_raster().unwrap(), &start, &info, &cfg).unwrap()
        };
        // The right scale with the default σ: the fit stays exact.
        let r = run(0.8, RefineConfig::default().frame_scale_sigma);
        assert!(
            (similarity(&r.affine).scale / 0.8 - 1.0).abs() < 1e-3,
            "{r:?}"
        );
        // A prior 2 % off and 100 times tighter than the data: it wins, and the scale's σ
        // says so; with σ = 0 the slopes alone decide.
        let tight = run(0.816, 1e-4);
        let s = similarity(&tight.affine).scale;
        assert!((s / 0.816 - 1.0).abs() < 2e-3, "scale {s}");
        assert!(tight.scale_sigma < 2e-4, "{tight:?}");
        let free = run(0.816, 0.0);
        assert!(
            (similarity(&free.affine).scale / 0.8 - 1.0).abs() < 1e-3,
            "{free:?}"
        );
        // A prior as tight as the data (same relative σ, right scale): the information adds
        // up, so the scale's σ shrinks by √2 — the prior is weighed against the residual
        // variance, not in raw units.
        let data = free.scale_sigma / 0.8;
        let both = run(0.8, data as f32);
        let ratio = both.scale_sigma / free.scale_sigma;
        assert!(
            (ratio * core::f64::consts::SQRT_2 - 1.0).abs() < 0.05,
            "σ with prior / without: {ratio} (data σ {data})"
        );
    }

    #[test]
    fn binned_frames_map_back_to_frame_pixels() {
        let bytes = tile_bytes(Some(&reference()));
        let tile = Tile::parse(&bytes).unwrap();
        // A 120 px frame binned by 2 into the 60 px image: image column u is frame x = 2u + 0.5.
        let truth_binned = similarity_at(-20.0, 0.9, 50.0, 30.0);
        let px = frame(&truth_binned);
        let img = SlopeImage::new_checked(&px, 60, 60, 18.0).unwrap();
        // The same map on frame pixels: x = 2u + 0.5 → u = (x − 0.5)/2.
        let t = &truth_binned;
        let truth = Affine {
            m1: t.m1 / 2.0,
            n1: t.n1 / 2.0,
            p1: t.p1 - 0.25 * (t.m1 + t.n1),
            m2: t.m2 / 2.0,
            n2: t.n2 / 2.0,
            p2: t.p2 - 0.25 * (t.m2 + t.n2),
        };
        let start = Affine {
            p1: truth.p1 + 0.7,
            ..truth
        };
        let r = refine(
            &img,
            2,
            tile.slope_raster().unwrap(),
            &start,
            &FrameInfo::default(),
            &RefineConfig::default(),
        )
        .unwrap();
        assert_maps_agree(&r.affine, &truth, &[(0.0, 0.0), (119.0, 119.0)], 0.05);
    }

    #[test]
    fn refuses_what_it_cannot_do() {
        let reference = reference();
        let truth = similarity_at(10.0, 0.8, 40.0, 20.0);
        let px = frame(&truth);
        let img = SlopeImage::new_checked(&px, 60, 60, 16.0).unwrap();
        let bytes = tile_bytes(Some(&reference));
        let tile = Tile::parse(&bytes).unwrap();
        let raster = tile.slope_raster().unwrap();
        let cfg = RefineConfig::default();
        // Switched off.
        let off = RefineConfig {
            enabled: false,
            ..cfg
        };
        assert_eq!(
            refine(&img, 1, raster, &truth, &FrameInfo::default(), &off),
            Err(RefineError::Disabled)
        );
        // A flat frame against a flat reference: nothing to align.
        let flat_ref = vec![slope_from_deg(12.0); W * W];
        let flat_bytes = tile_bytes(Some(&flat_ref));
        let flat_tile = Tile::parse(&flat_bytes).unwrap();
        let flat = vec![slope_from_deg(12.0); 60 * 60];
        let flat_img = SlopeImage::new_checked(&flat, 60, 60, 16.0).unwrap();
        assert!(
            refine(
                &flat_img,
                1,
                flat_tile.slope_raster().unwrap(),
                &truth,
                &FrameInfo::default(),
                &cfg
            )
            .is_err()
        );
        // A frame of no data, or a start that puts the frame outside the tile.
        let empty = vec![SLOPE_NODATA; 60 * 60];
        let empty_img = SlopeImage::new_checked(&empty, 60, 60, 16.0).unwrap();
        assert_eq!(
            refine(&empty_img, 1, raster, &truth, &FrameInfo::default(), &cfg),
            Err(RefineError::TooFewSamples)
        );
        let outside = similarity_at(10.0, 0.8, 4000.0, 20.0);
        assert_eq!(
            refine(&img, 1, raster, &outside, &FrameInfo::default(), &cfg),
            Err(RefineError::TooFewSamples)
        );
        // A start far from the truth (a wrong fix) must not be "confirmed": it either fails or
        // is refused for moving too far or correlating too little.
        let wrong = similarity_at(10.0, 0.8, 70.0, 60.0);
        let r = refine(&img, 1, raster, &wrong, &FrameInfo::default(), &cfg);
        if let Ok(r) = r {
            assert_maps_agree(&r.affine, &truth, &[(30.0, 30.0)], 0.1);
        }
        // Degenerate affine starts (zero or non-finite scale) never panic.
        let zero = Affine {
            m1: 0.0,
            n1: 0.0,
            m2: 0.0,
            n2: 0.0,
            ..truth
        };
        assert!(refine(&img, 1, raster, &zero, &FrameInfo::default(), &cfg).is_err());
        let nan = Affine {
            m1: f64::NAN,
            ..truth
        };
        assert!(refine(&img, 1, raster, &nan, &FrameInfo::default(), &cfg).is_err());
    }
}
