//! Complex multilooking, coherence, equivalent number of looks and the Cramér–Rao height bound.
//!
//! The paper averages with an 8×8 window moved by 4 pixels (5 m lines × 2.19 m gates in, one
//! output per 20 m × 8.77 m slant ≈ 20 m × 20 m on the ground). Averaging is complex — the phase
//! is taken of `Σ A1·conj(A2)·e^{−iφ_flat}` — and the coherence uses the same window:
//! `γ = |Σ A1·A2*| / sqrt(Σ|A1|²·Σ|A2|²)`.
//!
//! Output pixel `(k, m)` averages SLC lines `step·k … step·k + size − 1` and gates
//! `step·m … step·m + size − 1`; its centre is at line `step·k + (size − 1)/2` and gate
//! `step·m + (size − 1)/2` of the SLC.

use rayon::prelude::*;

use crate::sar::{C32, C64};

/// Multilook window: `size × size` SLC pixels, moved by `step`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct LookWindow {
    /// Window side, SLC pixels (paper: 8).
    pub size: usize,
    /// Step between windows, SLC pixels (paper: 4).
    pub step: usize,
}

impl Default for LookWindow {
    fn default() -> Self {
        Self { size: 8, step: 4 }
    }
}

impl LookWindow {
    /// Outputs along an axis of `n` SLC pixels (0 when `n < size`).
    pub fn outputs(self, n: usize) -> usize {
        if n < self.size || self.step == 0 {
            0
        } else {
            (n - self.size) / self.step + 1
        }
    }
    /// SLC coordinate of the centre of output `k` along an axis.
    pub fn centre(self, k: usize) -> f64 {
        (self.step * k) as f64 + 0.5 * (self.size as f64 - 1.0)
    }
}

/// Window sums of one interferogram.
#[derive(Debug, Clone)]
pub struct Looks {
    /// Output lines (azimuth).
    pub lines: usize,
    /// Output columns (range).
    pub gates: usize,
    /// `Σ A1·conj(A2)·e^{−iφ_flat}` per output, row-major.
    pub cross: Vec<C64>,
    /// `Σ A1·conj(A2)` (flat phase kept) per output.
    pub cross_raw: Vec<C64>,
    /// `Σ |A1|²` per output.
    pub power1: Vec<f64>,
    /// `Σ |A2|²` per output.
    pub power2: Vec<f64>,
    /// Where in the window the phase was measured: the `|A1·A2|`-weighted centroid of the
    /// window's samples relative to its centre, `(Δline, Δgate)` in SLC samples. For phases
    /// that vary little across the window, `arg Σ A1·A2*` is the phase at this point, not at
    /// the centre: speckle moves it by ≈ 1–2 samples, a height error of slope × that distance.
    pub centroid: Vec<(f64, f64)>,
}

impl Looks {
    /// Coherence magnitude per output, 0 where both powers are 0.
    pub fn coherence(&self) -> Vec<f32> {
        self.cross
            .iter()
            .zip(self.power1.iter().zip(&self.power2))
            .map(|(c, (&p1, &p2))| {
                let d = (p1 * p2).sqrt();
                if d > 0.0 {
                    (c.norm() / d).min(1.0) as f32
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Add another pass's sums over the same windows (stacking passes of one track: the cross
    /// products and powers add, so the coherence and phase are those of all samples together).
    /// The centroid becomes the two passes' mean weighted by their window power (an
    /// approximation of the `|A1·A2|` weights each centroid was taken with). Returns `false`,
    /// leaving `self` as it was, when the shapes differ.
    #[must_use]
    pub fn add_pass(&mut self, o: &Looks) -> bool {
        if (o.lines, o.gates, o.cross.len()) != (self.lines, self.gates, self.cross.len()) {
            return false;
        }
        for i in 0..self.cross.len() {
            let (wa, wb) = (self.power1[i] + self.power2[i], o.power1[i] + o.power2[i]);
            if wa + wb > 0.0 {
                let (a, b) = (self.centroid[i], o.centroid[i]);
                self.centroid[i] = (
                    (a.0 * wa + b.0 * wb) / (wa + wb),
                    (a.1 * wa + b.1 * wb) / (wa + wb),
                );
            }
            self.cross[i] += o.cross[i];
            self.cross_raw[i] += o.cross_raw[i];
            self.power1[i] += o.power1[i];
            self.power2[i] += o.power2[i];
        }
        true
    }
}

/// Complex multilook of `a1·conj(a2)` (both `lines × gates`, row-major, already coregistered)
/// with the flat phase `flat_rad[gate]` removed before averaging.
pub fn multilook(
    a1: &[C32],
    a2: &[C32],
    lines: usize,
    gates: usize,
    flat_rad: &[f64],
    w: LookWindow,
) -> Looks {
    let (lo, go) = (w.outputs(lines), w.outputs(gates));
    let deramp: Vec<C64> = flat_rad
        .iter()
        .map(|&p| C64::new(p.cos(), -p.sin()))
        .collect();
    // Per SLC line: range-window sums at every output gate; then sum `size` lines.
    let half = 0.5 * (w.size as f64 - 1.0);
    let row_sums = |i: usize| -> Vec<Sums> {
        let (r1, r2) = (
            &a1[i * gates..(i + 1) * gates],
            &a2[i * gates..(i + 1) * gates],
        );
        (0..go)
            .map(|m| {
                let mut acc = Sums::default();
                for (o, j) in (w.step * m..w.step * m + w.size).enumerate() {
                    let (x, y) = (r1[j], r2[j]);
                    let p = C64::new(f64::from(x.re), f64::from(x.im))
                        * C64::new(f64::from(y.re), -f64::from(y.im));
                    acc.cross += p * deramp[j];
                    acc.raw += p;
                    acc.p1 += f64::from(x.norm_sqr());
                    acc.p2 += f64::from(y.norm_sqr());
                    let a = p.norm();
                    acc.w += a;
                    acc.wg += a * (o as f64 - half);
                }
                acc
            })
            .collect()
    };
    let rows: Vec<Vec<Sums>> = (0..lines).into_par_iter().map(row_sums).collect();
    let n = lo * go;
    let mut out = Looks {
        lines: lo,
        gates: go,
        cross: vec![C64::new(0.0, 0.0); n],
        cross_raw: vec![C64::new(0.0, 0.0); n],
        power1: vec![0.0; n],
        power2: vec![0.0; n],
        centroid: vec![(0.0, 0.0); n],
    };
    let mut weight = vec![(0.0f64, 0.0f64, 0.0f64); n];
    for k in 0..lo {
        for (l, row) in rows[w.step * k..w.step * k + w.size].iter().enumerate() {
            let dl = l as f64 - half;
            for (m, s) in row.iter().enumerate() {
                let o = k * go + m;
                out.cross[o] += s.cross;
                out.cross_raw[o] += s.raw;
                out.power1[o] += s.p1;
                out.power2[o] += s.p2;
                weight[o].0 += s.w;
                weight[o].1 += s.w * dl;
                weight[o].2 += s.wg;
            }
        }
    }
    for (c, &(sw, sl, sg)) in out.centroid.iter_mut().zip(&weight) {
        if sw > 0.0 {
            *c = (sl / sw, sg / sw);
        }
    }
    out
}

/// One SLC line's sums over a range window.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    cross: C64,
    raw: C64,
    p1: f64,
    p2: f64,
    /// `Σ |A1·A2|` and `Σ |A1·A2|·(gate − window centre)`.
    w: f64,
    wg: f64,
}

/// Normalised autocorrelation magnitude of the speckle of an SLC whose spectrum is the
/// Hamming window `α + (1 − α)·cos(2πu)`, `|u| ≤ 1/2` of the processed band, sampled
/// `oversampling` times faster than that band, at a lag of `d` samples (the Fourier transform
/// of the power spectrum `W²`; 1 at `d` = 0).
pub fn speckle_correlation(d: f64, oversampling: f64, alpha: f64) -> f64 {
    const STEPS: usize = 4096;
    let (mut re, mut im, mut norm) = (0.0f64, 0.0f64, 0.0f64);
    for s in 0..STEPS {
        let u = (s as f64 + 0.5) / STEPS as f64 - 0.5;
        let w = alpha + (1.0 - alpha) * (std::f64::consts::TAU * u).cos();
        let ph = std::f64::consts::TAU * u * d / oversampling;
        re += w * w * ph.cos();
        im += w * w * ph.sin();
        norm += w * w;
    }
    re.hypot(im) / norm
}

/// Equivalent number of independent looks of a `size`-sample average along one axis of an SLC
/// ([`speckle_correlation`] `ρ`): `N = size² / Σ_{k,l} |ρ(k − l)|²`.
pub fn equivalent_looks_1d(size: usize, oversampling: f64, alpha: f64) -> f64 {
    (size * size) as f64 / window_overlap(size, 0.0, oversampling, alpha)
}

/// `Σ_{k,l} |ρ(k − l − shift)|²` over two `size`-sample windows `shift` samples apart.
fn window_overlap(size: usize, shift: f64, oversampling: f64, alpha: f64) -> f64 {
    let mut sum = 0.0;
    for k in 0..size {
        for l in 0..size {
            sum += speckle_correlation(k as f64 - l as f64 - shift, oversampling, alpha).powi(2);
        }
    }
    sum
}

/// Correlation of the interferometric phase noise of two multilooked pixels `lag` output
/// pixels apart along one axis (a fraction of a pixel allowed), for a window of `size` SLC
/// samples moved `step` samples per output pixel: the two windows' sums share the speckle of
/// overlapping and neighbouring samples, `Σ|ρ(k − l − lag·step)|² / Σ|ρ(k − l)|²`
/// ([`speckle_correlation`]; the phase noise of a high-coherence pixel is linear in those
/// sums). 1 at lag 0; for the default 8-sample window, step 4, 2× oversampling: 0.58 at one
/// pixel, 0.08 at two.
pub fn multilook_noise_correlation(
    size: usize,
    step: usize,
    lag: f64,
    oversampling: f64,
    alpha: f64,
) -> f64 {
    let den = window_overlap(size, 0.0, oversampling, alpha);
    if den > 0.0 {
        window_overlap(size, lag * step as f64, oversampling, alpha) / den
    } else {
        0.0
    }
}

/// Cramér–Rao bound of the interferometric phase from `looks` independent looks at coherence
/// `gamma`: `σ_φ = sqrt((1 − γ²)/(2·N·γ²))`, rad (Rodriguez & Martin 1992). Infinite at γ = 0.
pub fn phase_crlb_rad(gamma: f64, looks: f64) -> f64 {
    if !(gamma > 0.0 && looks > 0.0) {
        return f64::INFINITY;
    }
    let g2 = (gamma * gamma).min(1.0);
    ((1.0 - g2) / (2.0 * looks * g2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uncorrelated_samples_give_one_look_each() {
        // Rectangular spectrum sampled at its Nyquist rate: ρ(d) = sinc(d) = δ(d).
        assert!((equivalent_looks_1d(8, 1.0, 1.0) - 8.0).abs() < 1e-3);
        // Oversampling correlates neighbours, fewer looks than samples, at least size/over/…
        let n = equivalent_looks_1d(8, 2.0, 0.54);
        assert!(n > 2.5 && n < 5.0, "{n}");
    }

    #[test]
    fn stacked_passes_sum_like_one_longer_window() {
        let (lines, gates) = (13, 17);
        let w = LookWindow::default();
        let mk = |k: f32| -> Vec<C32> {
            (0..lines * gates)
                .map(|i| C32::new((i as f32 * k).sin(), (i as f32 * 0.3 * k).cos()))
                .collect()
        };
        let flat: Vec<f64> = (0..gates).map(|j| 0.1 * j as f64).collect();
        let (p1, p2, q1, q2) = (mk(0.37), mk(0.21), mk(0.53), mk(0.11));
        let a = multilook(&p1, &p2, lines, gates, &flat, w);
        let b = multilook(&q1, &q2, lines, gates, &flat, w);
        let mut s = a.clone();
        assert!(s.add_pass(&b));
        for i in 0..s.cross.len() {
            assert!((s.cross[i] - (a.cross[i] + b.cross[i])).norm() < 1e-9);
            assert!((s.power1[i] - (a.power1[i] + b.power1[i])).abs() < 1e-9);
            assert!((s.power2[i] - (a.power2[i] + b.power2[i])).abs() < 1e-9);
            let (wa, wb) = (a.power1[i] + a.power2[i], b.power1[i] + b.power2[i]);
            let c = (a.centroid[i].0 * wa + b.centroid[i].0 * wb) / (wa + wb);
            assert!((s.centroid[i].0 - c).abs() < 1e-9);
        }
        // A pass on another grid is refused and changes nothing.
        let other = multilook(&p1[..8 * gates], &p2[..8 * gates], 8, gates, &flat, w);
        assert_ne!(other.lines, s.lines);
        let before = s.cross.clone();
        assert!(!s.add_pass(&other));
        assert_eq!(s.cross, before);
    }

    #[test]
    fn neighbouring_looks_share_their_overlap() {
        let r = |lag: f64| multilook_noise_correlation(8, 4, lag, 2.0, 0.54);
        assert!((r(0.0) - 1.0).abs() < 1e-12);
        assert!((r(1.0) - 0.579).abs() < 0.005, "{}", r(1.0));
        assert!((r(2.0) - 0.079).abs() < 0.005, "{}", r(2.0));
        assert!(r(0.5) < 1.0 && r(0.5) > r(1.0));
        // Uncorrelated samples, windows that do not overlap: nothing shared.
        assert!(multilook_noise_correlation(4, 4, 1.0, 1.0, 1.0) < 1e-3);
        // Half-overlapping windows of uncorrelated samples share half.
        assert!((multilook_noise_correlation(8, 4, 1.0, 1.0, 1.0) - 0.5).abs() < 1e-3);
    }

    #[test]
    fn crlb_limits() {
        assert!(phase_crlb_rad(1.0, 10.0) == 0.0);
        assert!(phase_crlb_rad(0.0, 10.0).is_infinite());
        let s = phase_crlb_rad(0.9, 20.0);
        assert!((s - ((1.0 - 0.81) / (40.0 * 0.81f64)).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn multilook_matches_a_direct_sum_and_its_geometry() {
        let (lines, gates) = (13, 17);
        let w = LookWindow::default();
        let a1: Vec<C32> = (0..lines * gates)
            .map(|i| C32::new((i as f32 * 0.37).sin(), (i as f32 * 0.11).cos()))
            .collect();
        let a2: Vec<C32> = (0..lines * gates)
            .map(|i| C32::new((i as f32 * 0.21).cos(), (i as f32 * 0.53).sin()))
            .collect();
        let flat: Vec<f64> = (0..gates).map(|j| 0.3 * j as f64).collect();
        let l = multilook(&a1, &a2, lines, gates, &flat, w);
        assert_eq!((l.lines, l.gates), (2, 3));
        assert_eq!(w.centre(1), 7.5);
        let (k, m) = (1, 2);
        let mut want = C64::new(0.0, 0.0);
        for i in 4 * k..4 * k + 8 {
            for j in 4 * m..4 * m + 8 {
                let x = a1[i * gates + j];
                let y = a2[i * gates + j];
                let p = C64::new(f64::from(x.re), f64::from(x.im))
                    * C64::new(f64::from(y.re), -f64::from(y.im));
                want += p * C64::new(0.0, -flat[j]).exp();
            }
        }
        assert!((l.cross[k * 3 + m] - want).norm() < 1e-9);
        // Identical images are fully coherent.
        let l2 = multilook(&a1, &a1, lines, gates, &vec![0.0; gates], w);
        assert!(l2.coherence().iter().all(|&c| (c - 1.0).abs() < 1e-6));
    }
}
