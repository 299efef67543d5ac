//! The filter of the geocoded DEM, and what it does to the height bound.
//!
//! The multilooked heights carry pixel-scale noise that the slope operator amplifies, so the
//! chain smooths the geocoded DEM once. Two kernels:
//!
//! - [`DemFilterKind::Gaussian`] (the default): the Gaussian-weighted mean. It raises a
//!   crater's floor and lowers its rim by `σ²/2 · ∇²h`.
//! - [`DemFilterKind::Quadratic`] (session 25, `--dem-filter quadratic`): a local quadratic
//!   fit under Gaussian weights (a 2-D Savitzky–Golay filter), the fitted value at the cell.
//!   It reproduces any quadratic surface exactly, so it leaves no curvature bias. At 2 px it
//!   gives lower height and slope RMSEs than the 1 px mean on every scene of the terrain suite
//!   at both seeds; the tiles made from it do not navigate better (heading p95 worse on the
//!   gentle scenes), so it is not the default (docs/insar.md, "A filter without curvature
//!   bias").
//!
//! Both keep a NaN cell NaN and use only the finite cells of their footprint. Units: output
//! pixels of the geocoded grid (rows azimuth, columns range).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::looks::multilook_noise_correlation;
use crate::dem::stats::CellCounts;

/// Which kernel smooths the geocoded DEM.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum DemFilterKind {
    /// Local quadratic fit under Gaussian weights of σ `sigma_px`, footprint radius
    /// [`quadratic_radius_px`]: no curvature bias.
    Quadratic,
    /// Gaussian-weighted mean of σ `sigma_px`, footprint cut at 3σ: biased by `σ²/2 · ∇²h`.
    /// The chain's default.
    #[default]
    Gaussian,
}

impl DemFilterKind {
    /// The σ, output pixels, the chain uses for this kernel unless told otherwise: 2 px for
    /// the quadratic fit (the widest of 1.5, 2 and 2.5 px whose height and slope RMSEs beat the
    /// 1 px mean's on every scene of the terrain suite), 1 px for the mean (docs/insar.md, "A
    /// filter without curvature bias").
    pub fn default_sigma_px(self) -> f64 {
        match self {
            Self::Quadratic => 2.0,
            Self::Gaussian => 1.0,
        }
    }
}

/// The DEM filter: kernel and width. `sigma_px` ≤ 0 means no filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemFilter {
    /// Kernel.
    pub kind: DemFilterKind,
    /// σ of the Gaussian weights, output pixels.
    pub sigma_px: f64,
}

/// Footprint radius, pixels, of the quadratic fit of weight σ `sigma_px`: `ceil(2.5σ)` (5 at
/// 2 px); the weights beyond are below 4.4 % of the centre's.
pub fn quadratic_radius_px(sigma_px: f64) -> usize {
    (2.5 * sigma_px).ceil().max(1.0) as usize
}

/// Largest white-noise variance gain `Σ k²` a quadratic or plane fit may have before the
/// filter falls back to a lower order (0.3: 55 % of the σ). At 2 px the quadratic keeps 0.056
/// inside the map, 0.16 at a straight edge and 0.54 at a corner, where the plane (0.27)
/// takes over; the mean would keep 0.064 there but shifts a slope's height by its lopsided
/// footprint.
pub const MAX_FIT_WHITE_GAIN: f64 = 0.3;

/// Largest filter σ accepted, pixels: a wider one is a mistake, not a filter, and the bound's
/// per-cell factors cost `O(footprint²)` cells per cell by a hole or an edge.
pub const MAX_SIGMA_PX: f64 = 10.0;

/// Smallest non-zero filter σ accepted, pixels (below, the weights underflow to nothing).
pub const MIN_SIGMA_PX: f64 = 0.1;

impl DemFilter {
    /// Whether it filters at all: σ within [`MIN_SIGMA_PX`]–[`MAX_SIGMA_PX`] (`InsarConfig::validate`
    /// refuses other non-zero values; a library caller passing one gets no filter).
    fn active(&self) -> bool {
        (MIN_SIGMA_PX..=MAX_SIGMA_PX).contains(&self.sigma_px)
    }

    fn radius(&self) -> usize {
        match self.kind {
            DemFilterKind::Quadratic => quadratic_radius_px(self.sigma_px),
            DemFilterKind::Gaussian => (3.0 * self.sigma_px).ceil() as usize,
        }
    }

    /// 1-D Gaussian weights over `-r..=r`.
    fn gauss_1d(&self) -> Vec<f64> {
        let r = self.radius() as f64;
        (0..=2 * self.radius())
            .map(|i| {
                let d = i as f64 - r;
                (-d * d / (2.0 * self.sigma_px * self.sigma_px)).exp()
            })
            .collect()
    }

    /// Gaussian-equivalent σ, metres at `pixel_m`, the filter adds to the heights' signal: the
    /// square root of its kernel's second moment per axis. The mean adds its σ; the quadratic
    /// fit adds none (its kernel's second moment is zero, which is what reproducing quadratics
    /// means), unless it is so narrow that it falls back to a plane or the mean
    /// ([`MAX_FIT_WHITE_GAIN`]; below about 0.8 px), whose moment it then reports.
    pub fn signal_sigma_m(&self, pixel_m: f64) -> f64 {
        if !self.active() {
            return 0.0;
        }
        match self.kind {
            DemFilterKind::Gaussian => self.sigma_px * pixel_m,
            DemFilterKind::Quadratic => {
                let k = self.full_kernel();
                let side = 2 * self.radius() + 1;
                let r = self.radius() as f64;
                let moment: f64 = k
                    .iter()
                    .enumerate()
                    .map(|(i, w)| w * ((i % side) as f64 - r).powi(2))
                    .sum();
                // Round-off of an exact zero is not a blur.
                if moment > 1e-9 {
                    moment.sqrt() * pixel_m
                } else {
                    0.0
                }
            }
        }
    }

    /// The footprint's valid cells with their Gaussian weights `g(dy)·g(dx)`, unnormalised, as
    /// `(dy, dx, weight)` (offsets `0..=2r` from the footprint's corner).
    fn footprint_cells(&self, valid: impl Fn(usize, usize) -> bool) -> Vec<(usize, usize, f64)> {
        let g = self.gauss_1d();
        let mut cells = Vec::with_capacity(g.len() * g.len());
        for (dy, gy) in g.iter().enumerate() {
            for (dx, gx) in g.iter().enumerate() {
                if valid(dy, dx) {
                    cells.push((dy, dx, gy * gx));
                }
            }
        }
        cells
    }

    /// The filter's normalised weights at a cell whose footprint cells are valid where
    /// `valid(dy, dx)` (offsets `0..=2r` from the footprint's corner), as `(dy, dx, weight)`;
    /// weights sum to 1. `None` without a valid cell.
    ///
    /// The quadratic fit falls back to a plane, then to the mean, where the valid cells cannot
    /// pin a quadratic (fewer than six, or in a line) or where its weights would keep more
    /// than 55 % of the white noise's σ (`Σ k² >` [`MAX_FIT_WHITE_GAIN`]: an extrapolation, at
    /// a corner or a hole's edge, that would make the cell noisier, not smoother).
    fn weights(&self, valid: impl Fn(usize, usize) -> bool) -> Option<Vec<(usize, usize, f64)>> {
        let r = self.radius() as f64;
        let cells = self.footprint_cells(valid);
        let total: f64 = cells.iter().map(|c| c.2).sum();
        if cells.is_empty() || total <= 0.0 {
            return None;
        }
        let mean = || cells.iter().map(|&(y, x, w)| (y, x, w / total)).collect();
        if self.kind == DemFilterKind::Gaussian {
            return Some(mean());
        }
        for terms in [6, 3] {
            let basis = |dy: usize, dx: usize| -> [f64; 6] {
                let (y, x) = (dy as f64 - r, dx as f64 - r);
                [1.0, x, y, x * x, x * y, y * y]
            };
            let mut m = [[0.0f64; 6]; 6];
            for &(dy, dx, w) in &cells {
                let b = basis(dy, dx);
                for i in 0..terms {
                    for j in 0..terms {
                        m[i][j] += w * b[i] * b[j];
                    }
                }
            }
            let mut e0 = [0.0f64; 6];
            e0[0] = 1.0;
            let Some(a) = solve(&mut m, &mut e0, terms) else {
                continue;
            };
            let k: Vec<(usize, usize, f64)> = cells
                .iter()
                .map(|&(dy, dx, w)| {
                    let b = basis(dy, dx);
                    (dy, dx, w * (0..terms).map(|i| a[i] * b[i]).sum::<f64>())
                })
                .collect();
            let gain: f64 = k.iter().map(|c| c.2 * c.2).sum();
            if gain.is_finite() && gain <= MAX_FIT_WHITE_GAIN {
                return Some(k);
            }
        }
        Some(mean())
    }

    /// The full-footprint kernel, row-major `side × side`, summing to 1.
    fn full_kernel(&self) -> Vec<f64> {
        let side = 2 * self.radius() + 1;
        let mut k = vec![0.0; side * side];
        if let Some(ws) = self.weights(|_, _| true) {
            for (dy, dx, w) in ws {
                k[dy * side + dx] = w;
            }
        }
        k
    }
}

/// Gauss–Jordan solve of the leading `n × n` block of `m` against `rhs`, partial pivoting; `None`
/// when a pivot falls below 1e-9 of the largest diagonal (the cells do not pin the fit).
fn solve(m: &mut [[f64; 6]; 6], rhs: &mut [f64; 6], n: usize) -> Option<[f64; 6]> {
    let scale = (0..n).map(|i| m[i][i].abs()).fold(0.0, f64::max);
    if !(scale > 0.0) {
        return None;
    }
    for col in 0..n {
        let p = (col..n).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[p][col].abs() < 1e-9 * scale {
            return None;
        }
        m.swap(col, p);
        rhs.swap(col, p);
        let pivot_row = m[col];
        let pivot_rhs = rhs[col];
        for (row, (mr, r)) in m.iter_mut().zip(rhs.iter_mut()).enumerate().take(n) {
            if row != col {
                let f = mr[col] / pivot_row[col];
                for (a, b) in mr[col..n].iter_mut().zip(&pivot_row[col..n]) {
                    *a -= f * b;
                }
                *r -= f * pivot_rhs;
            }
        }
    }
    let mut out = [0.0; 6];
    for i in 0..n {
        out[i] = rhs[i] / m[i][i];
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// Filter the finite cells of a `w × h` grid (row-major); NaN stays NaN. Cells whose footprint
/// is whole use one kernel; the others (by holes or the edge) their own weights.
pub fn filter_dem(z: &[f64], w: usize, h: usize, filter: DemFilter) -> Vec<f64> {
    if !filter.active() || z.len() < w * h {
        return z.to_vec();
    }
    if filter.kind == DemFilterKind::Gaussian {
        return gaussian_filter(z, w, h, filter.sigma_px);
    }
    let r = filter.radius();
    let side = 2 * r + 1;
    let kernel = filter.full_kernel();
    let finite: Vec<bool> = z.iter().map(|v| v.is_finite()).collect();
    let feet = Footprints::new(&finite, w, h, r);
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            if !finite[i] {
                return f64::NAN;
            }
            let (y, x) = (i / w, i % w);
            let at = |dy: usize, dx: usize| feet.index(y, x, dy, dx);
            if feet.whole(y, x) {
                let mut s = 0.0;
                for dy in 0..side {
                    let row = (y + dy - r) * w + x - r;
                    for dx in 0..side {
                        s += kernel[dy * side + dx] * z[row + dx];
                    }
                }
                return s;
            }
            match filter.weights(|dy, dx| at(dy, dx).is_some_and(|j| finite[j])) {
                Some(ws) => ws
                    .iter()
                    .map(|&(dy, dx, k)| at(dy, dx).map_or(0.0, |j| k * z[j]))
                    .sum(),
                None => z[i],
            }
        })
        .collect()
}

/// The filter's footprints on a grid: which cells' footprints are whole (inside the grid, on
/// valid cells only), and where a footprint offset lands.
struct Footprints {
    counts: CellCounts,
    w: usize,
    h: usize,
    r: usize,
}

impl Footprints {
    fn new(valid: &[bool], w: usize, h: usize, r: usize) -> Self {
        let counts = CellCounts::new(w, h, |i| valid.get(i).copied().unwrap_or(false));
        Self { counts, w, h, r }
    }

    /// Whether the footprint of `(y, x)` lies inside the grid on valid cells only.
    fn whole(&self, y: usize, x: usize) -> bool {
        let (r, w, h) = (self.r, self.w, self.h);
        if y < r || x < r || y + r >= h || x + r >= w {
            return false;
        }
        let side = 2 * r + 1;
        self.counts.count(y - r, x - r, y + r + 1, x + r + 1) == side * side
    }

    /// Grid index of the footprint offset `(dy, dx)` (`0..=2r`) of cell `(y, x)`, if inside.
    fn index(&self, y: usize, x: usize, dy: usize, dx: usize) -> Option<usize> {
        let yy = (y + dy).checked_sub(self.r)?;
        let xx = (x + dx).checked_sub(self.r)?;
        (yy < self.h && xx < self.w).then_some(yy * self.w + xx)
    }
}

/// The multilook noise model the bound's filter factor needs: `size`-sample windows moved
/// `step` samples per radar pixel, `lag_per_px[axis]` radar pixels per output pixel (azimuth
/// first, then range), each axis's `oversampling`, focusing window Hamming `alpha`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LookNoise {
    /// Window side, samples.
    pub size: usize,
    /// Window step, samples.
    pub step: usize,
    /// Radar pixels per output pixel, azimuth then range.
    pub lag_per_px: [f64; 2],
    /// Sampling over the processed bandwidth, azimuth then range.
    pub oversampling: [f64; 2],
    /// Hamming coefficient of the focusing windows.
    pub alpha: f64,
}

impl LookNoise {
    /// Correlation of neighbouring multilooked heights per axis at lags `0..=n` output pixels;
    /// `None` for unusable lags.
    fn rho(&self, n: usize) -> Option<[Vec<f64>; 2]> {
        if !self.lag_per_px.iter().all(|l| l.is_finite() && *l >= 0.0) {
            return None;
        }
        Some([0, 1].map(|axis| {
            (0..=n)
                .map(|d| {
                    multilook_noise_correlation(
                        self.size,
                        self.step,
                        d as f64 * self.lag_per_px[axis],
                        self.oversampling[axis],
                        self.alpha,
                    )
                })
                .collect()
        }))
    }
}

/// Covariance of two filtered cells with weights `a` and `b` (`(dy, dx, weight)`, offsets in
/// one frame) under the noise correlation `rho`, in units of the unfiltered variance.
fn filtered_covariance(
    a: &[(usize, usize, f64)],
    b: &[(usize, usize, f64)],
    rho: &[Vec<f64>; 2],
) -> f64 {
    let look = |v: &Vec<f64>, d: usize| v.get(d).copied().unwrap_or(0.0);
    let mut var = 0.0;
    for &(ya, xa, ka) in a {
        for &(yb, xb, kb) in b {
            let dy = ya.abs_diff(yb);
            let dx = xa.abs_diff(xb);
            var += ka * kb * look(&rho[0], dy) * look(&rho[1], dx);
        }
    }
    var
}

/// Factor by which the DEM filter shrinks the standard deviation of multilook height noise at
/// a cell whose footprint is whole: `sqrt(Σ_ab k_a k_b ρ_az ρ_rg)` over the kernel's weights
/// `k` (summing to 1) and the noise correlation of the cells ([`multilook_noise_correlation`]).
/// White noise would keep `sqrt(Σ k²)`; the overlap of the looks keeps more. For the default
/// chain (8-sample windows, step 4, 2× oversampling, radar pixels of the 20 m grid) it is 0.50
/// for the quadratic fit at 2 px and 0.553 for the mean at 1 px. 1 without a filter or with
/// unusable lags.
pub fn dem_filter_noise_factor(filter: DemFilter, noise: LookNoise) -> f64 {
    if !filter.active() {
        return 1.0;
    }
    let r = filter.radius();
    let Some(rho) = noise.rho(2 * r + 1) else {
        return 1.0;
    };
    let f = if filter.kind == DemFilterKind::Gaussian {
        // Separable: per axis, in the order the chain has always summed it (the default
        // products stay bit-identical).
        let g = filter.gauss_1d();
        let total: f64 = g.iter().sum();
        let mut factor = 1.0;
        for rho in &rho {
            let mut var = 0.0;
            for (i, a) in g.iter().enumerate() {
                for (j, b) in g.iter().enumerate() {
                    var += a * b * rho[i.abs_diff(j)];
                }
            }
            factor *= var.max(0.0).sqrt() / total;
        }
        factor
    } else {
        let Some(k) = filter.weights(|_, _| true) else {
            return 1.0;
        };
        filtered_covariance(&k, &k, &rho).max(0.0).sqrt()
    };
    if f.is_finite() { f } else { 1.0 }
}

/// Correlation of the filtered height noise between a cell and its neighbour one output pixel
/// away, azimuth and range (whole footprints). The rehearsal's error model takes its
/// correlation length from it ([`error_blur_m`]).
pub fn filtered_neighbour_correlation(filter: DemFilter, noise: LookNoise) -> [f64; 2] {
    let r = if filter.active() { filter.radius() } else { 0 };
    let Some(rho) = noise.rho(2 * r + 2) else {
        return [0.0; 2];
    };
    // No filter: each cell alone.
    let k = filter
        .active()
        .then(|| filter.weights(|_, _| true))
        .flatten()
        .unwrap_or_else(|| vec![(0, 0, 1.0)]);
    let v0 = filtered_covariance(&k, &k, &rho);
    // The neighbour's weights are the same kernel one cell further along the axis.
    let shifted = |axis: usize| -> f64 {
        let moved: Vec<(usize, usize, f64)> = k
            .iter()
            .map(|&(y, x, w)| {
                if axis == 0 {
                    (y + 1, x, w)
                } else {
                    (y, x + 1, w)
                }
            })
            .collect();
        filtered_covariance(&k, &moved, &rho) / v0
    };
    let c = [shifted(0), shifted(1)];
    c.map(|v| {
        if v.is_finite() {
            v.clamp(0.0, 1.0)
        } else {
            0.0
        }
    })
}

/// σ, metres, of the Gaussian blur whose white-noise field has the filtered noise's neighbour
/// correlation at one output pixel of `pixel_m` (mean of the two axes): `p / (2 sqrt(−ln ρ))`,
/// since such a field correlates as `exp(−d² / 4σ²)`. 0 for uncorrelated noise, or when it
/// cannot be told (ρ ≥ 1). The default chain (1 px mean): ρ ≈ 0.84 → 23.7 m; with the 2 px
/// quadratic fit ρ ≈ 0.90 → 30.4 m. The suite's InSAR height errors, which also hold the
/// chain's error on relief (less correlated, and not in the bound), show 0.81–0.83 at 20 m on
/// the plains and lola under the mean and 0.82–0.84 under the quadratic fit.
pub fn error_blur_m(filter: DemFilter, noise: LookNoise, pixel_m: f64) -> f64 {
    let [a, b] = filtered_neighbour_correlation(filter, noise);
    let rho = 0.5 * (a + b);
    // Below 0.01 the noise is white for the rehearsal's purpose (a blur under 0.35 px).
    if !(rho > 0.01 && rho < 1.0 && pixel_m > 0.0) {
        return 0.0;
    }
    pixel_m / (2.0 * (-rho.ln()).sqrt())
}

/// [`dem_filter_noise_factor`] per cell of a `w × h` grid (rows azimuth, columns range) whose
/// `valid` cells the filter averaged: a cell whose footprint is cut by holes or the grid's
/// edge has its own weights ([`filter_dem`]) and mostly keeps more noise (a cell alone keeps
/// all of it). Returns the whole footprint's factor and the per-cell ones (1 everywhere
/// without a filter, and at masked cells).
pub fn dem_filter_noise_factors(
    valid: &[bool],
    w: usize,
    h: usize,
    filter: DemFilter,
    noise: LookNoise,
) -> (f64, Vec<f64>) {
    let n = (w * h).min(valid.len());
    let full = dem_filter_noise_factor(filter, noise);
    if !filter.active() {
        return (1.0, vec![1.0; n]);
    }
    let r = filter.radius();
    let Some(rho) = noise.rho(2 * r + 1) else {
        return (1.0, vec![1.0; n]);
    };
    let feet = Footprints::new(valid, w, h, r);
    let per_cell = (0..n)
        .into_par_iter()
        .map(|i| {
            let (y, x) = (i / w, i % w);
            if feet.whole(y, x) {
                return full;
            }
            if !valid[i] {
                // Masked: the chain never reports a bound there.
                return 1.0;
            }
            let at =
                |dy: usize, dx: usize| feet.index(y, x, dy, dx).is_some_and(|j| j < n && valid[j]);
            let f = if filter.kind == DemFilterKind::Gaussian {
                // Unnormalised weights, the total divided out last: the order the chain has
                // always used (bit-identical default products).
                let cells = filter.footprint_cells(at);
                let total: f64 = cells.iter().map(|c| c.2).sum();
                filtered_covariance(&cells, &cells, &rho).max(0.0).sqrt() / total
            } else {
                let Some(k) = filter.weights(at) else {
                    return 1.0;
                };
                filtered_covariance(&k, &k, &rho).max(0.0).sqrt()
            };
            if f.is_finite() { f } else { 1.0 }
        })
        .collect();
    (full, per_cell)
}

/// Gaussian filter of standard deviation `sigma_px` (kernel cut at 3σ) over the finite values
/// of a `w × h` grid, normalised by the weights that fell on finite values; NaN stays NaN.
pub fn gaussian_filter(z: &[f64], w: usize, h: usize, sigma_px: f64) -> Vec<f64> {
    let r = (3.0 * sigma_px).ceil() as usize;
    let k: Vec<f64> = (0..=2 * r)
        .map(|i| {
            let d = i as f64 - r as f64;
            (-d * d / (2.0 * sigma_px * sigma_px)).exp()
        })
        .collect();
    // Separable: rows, then columns, each carrying (Σ k·z, Σ k) so holes renormalise.
    let pass = |src: &[(f64, f64)], horizontal: bool| -> Vec<(f64, f64)> {
        let mut out = vec![(0.0, 0.0); w * h];
        for y in 0..h {
            for x in 0..w {
                let (mut a, mut b) = (0.0, 0.0);
                for (i, &kk) in k.iter().enumerate() {
                    let d = i as i64 - r as i64;
                    let (xx, yy) = if horizontal {
                        (x as i64 + d, y as i64)
                    } else {
                        (x as i64, y as i64 + d)
                    };
                    if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                        continue;
                    }
                    let (v, wt) = src[yy as usize * w + xx as usize];
                    a += kk * v;
                    b += kk * wt;
                }
                out[y * w + x] = (a, b);
            }
        }
        out
    };
    let init: Vec<(f64, f64)> = z
        .iter()
        .map(|&v| if v.is_finite() { (v, 1.0) } else { (0.0, 0.0) })
        .collect();
    let out = pass(&pass(&init, true), false);
    out.iter()
        .zip(z)
        .map(|(&(a, b), &v)| {
            if v.is_finite() && b > 0.0 {
                a / b
            } else {
                f64::NAN
            }
        })
        .collect()
}
