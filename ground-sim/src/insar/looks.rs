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

/// Factor on a cell's height bound from the parallax of its error, ≥ 1:
/// `max(1, √(1 + 2kρ + k²a²))` with `k = −s·cot θ` (`s` the ground's rise per metre away from
/// the radar, `θ` the look angle), `ρ` the correlation of the cell's height noise with that of
/// the mean height that placed it and `a²` that mean's variance over the cell's. Why: the chain
/// places each height on the ground with a mean height, whose error moves it across the slope
/// (`δy = δh̄·cot θ`), so the geocoded cell reads `δh − s·δy`. Facing the radar (`k < 0`) the
/// formula falls below 1; no reduction is credited there, as foreshortening's own error, which
/// the bound does not hold, is larger (docs/insar.md, "The parallax of the height error, and
/// holes in the tile").
pub fn parallax_bound_factor(k: f64, rho: f64, a2: f64) -> f64 {
    let v = 1.0 + 2.0 * k * rho + k * k * a2;
    if v.is_finite() {
        v.max(1.0).sqrt()
    } else {
        1.0
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

/// Phase CRLB of `passes` stacked passes of one track that share their speckle, rad.
///
/// `gamma` is the stack's coherence (all passes' sums together) and `thermal` the receiver
/// noise's share of it (the coherence of two passes of one antenna is `SNR/(1 + SNR)`, and the
/// interferometric pair's thermal coherence is the geometric mean of its two antennas', see
/// [`passes_thermal_coherence`]). Only the thermal part of the phase variance averages over
/// the passes; what the surface decorrelates (the coherence `gamma/thermal`) is the same in
/// every pass, because the passes see the same speckle. So the variance is that of the surface
/// part at `looks_per_pass` looks plus the rest of the one-pass variance divided by `passes`.
/// With one pass it is [`phase_crlb_rad`] at `looks_per_pass`. With several passes and no
/// thermal estimate (`thermal` ≤ 0 or not finite: a window without echo in some pass) nothing
/// is credited to stacking: one pass's bound.
///
/// Valid for passes that fly the same orbit, as simulated here: a real repeat pass also loses
/// pass-to-pass coherence to its own baseline and to time, which this estimate would count as
/// receiver noise, and the bound would be optimistic.
///
/// Why: counting all passes as looks claimed 0.50 m of height noise for a 4-pass InSAR map of
/// smooth plains whose error was 0.72 m (RMSE/CRLB 1.44 against 1.13 for one pass), and the
/// navigation filter, which takes the map's noise from that bound, trusted its fixes too much.
pub fn stacked_phase_crlb_rad(gamma: f64, thermal: f64, looks_per_pass: f64, passes: usize) -> f64 {
    if passes <= 1 {
        return phase_crlb_rad(gamma, looks_per_pass);
    }
    if !(thermal > 0.0 && thermal.is_finite()) {
        return phase_crlb_rad(gamma, looks_per_pass);
    }
    let n = passes as f64;
    let one = phase_crlb_rad(gamma, looks_per_pass);
    let surface = phase_crlb_rad((gamma / thermal.min(1.0)).min(1.0), looks_per_pass);
    if !(one.is_finite() && surface.is_finite()) {
        return one;
    }
    let (v1, vs) = (one * one, surface * surface);
    (vs + (v1 - vs).max(0.0) / n).sqrt()
}

/// Thermal coherence of a stack's interferometric pair per output window, from the passes
/// themselves: consecutive passes of one antenna share the ground and its speckle and differ
/// by receiver noise only, so their coherence is `SNR/(1 + SNR)` of that antenna. The pair's is
/// the geometric mean of the two antennas' (`1/sqrt((1 + 1/SNR₁)(1 + 1/SNR₂))`). `passes1` and
/// `passes2` hold each pass's SLC of antenna 1 and 2 on their own (uncoregistered, same track)
/// grids. `None` with fewer than two passes or when the shapes differ.
pub fn passes_thermal_coherence(
    passes1: &[&[C32]],
    passes2: &[&[C32]],
    lines: usize,
    gates: usize,
    w: LookWindow,
) -> Option<Vec<f32>> {
    if passes1.len() < 2 || passes1.len() != passes2.len() {
        return None;
    }
    let zero = vec![0.0f64; gates];
    let antenna = |p: &[&[C32]]| -> Option<Vec<f32>> {
        let mut acc: Option<Looks> = None;
        for pair in p.windows(2) {
            let (a, b) = (pair.first()?, pair.get(1)?);
            if a.len() != lines * gates || b.len() != lines * gates {
                return None;
            }
            let l = multilook(a, b, lines, gates, &zero, w);
            match acc.as_mut() {
                None => acc = Some(l),
                Some(s) => {
                    if !s.add_pass(&l) {
                        return None;
                    }
                }
            }
        }
        acc.map(|l| l.coherence())
    };
    let (r1, r2) = (antenna(passes1)?, antenna(passes2)?);
    Some(
        r1.iter()
            .zip(&r2)
            .map(|(a, b)| (a.max(0.0) * b.max(0.0)).sqrt())
            .collect(),
    )
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
    fn parallax_scales_bounds_on_slopes_facing_away_only() {
        // The default window's correlations: 0.518 and 0.371 (docs/insar.md).
        assert_eq!(parallax_bound_factor(0.0, 0.518, 0.371), 1.0);
        // 33° facing away at 26°: k = tan 33° · cot 26° = 1.33.
        let k = 33f64.to_radians().tan() / 26f64.to_radians().tan();
        let away = parallax_bound_factor(k, 0.518, 0.371);
        assert!((away - 1.74).abs() < 0.02, "{away}");
        assert_eq!(parallax_bound_factor(-k, 0.518, 0.371), 1.0);
        assert_eq!(parallax_bound_factor(f64::NAN, 0.518, 0.371), 1.0);
        // Grows with the slope.
        assert!(parallax_bound_factor(0.5, 0.518, 0.371) < away);
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

    #[test]
    fn stacked_crlb_averages_only_the_thermal_part() {
        let (l, g) = (6.5, 0.9);
        // One pass: the plain bound.
        assert_eq!(stacked_phase_crlb_rad(g, 0.95, l, 1), phase_crlb_rad(g, l));
        // Several passes but no thermal estimate: nothing credited to stacking.
        assert_eq!(stacked_phase_crlb_rad(g, 0.0, l, 4), phase_crlb_rad(g, l));
        assert_eq!(
            stacked_phase_crlb_rad(g, f64::NAN, l, 4),
            phase_crlb_rad(g, l)
        );
        // All of the decorrelation thermal: the passes are independent looks.
        let all_thermal = stacked_phase_crlb_rad(g, g, l, 4);
        assert!((all_thermal - phase_crlb_rad(g, 4.0 * l)).abs() < 1e-12);
        // None of it thermal: stacking the same speckle gains nothing.
        let none_thermal = stacked_phase_crlb_rad(g, 1.0, l, 4);
        assert!((none_thermal - phase_crlb_rad(g, l)).abs() < 1e-12);
        // In between, between the two, and more passes never hurt.
        let half = stacked_phase_crlb_rad(g, g.sqrt(), l, 4);
        assert!(half > all_thermal && half < none_thermal, "{half}");
        assert!(stacked_phase_crlb_rad(g, g.sqrt(), l, 16) < half);
        assert!(stacked_phase_crlb_rad(0.0, 0.5, l, 4).is_infinite());
    }

    #[test]
    fn passes_of_one_antenna_measure_its_snr() {
        use rand::{RngExt, SeedableRng};
        // A shared speckled signal of power 1 plus independent noise per pass: antenna 1 at
        // SNR 9 (thermal coherence 0.9), antenna 2 at SNR 0.25 (0.2). The pair's is their
        // geometric mean, 0.42; an arithmetic mean would read 0.55.
        let (lines, gates, passes) = (64, 64, 3);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let mut gauss = |s: f64| -> C32 {
            let (u1, u2): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
            let r = (-2.0 * u1.ln()).sqrt() * s * std::f64::consts::FRAC_1_SQRT_2;
            let t = std::f64::consts::TAU * u2;
            C32::new((r * t.cos()) as f32, (r * t.sin()) as f32)
        };
        let x: Vec<C32> = (0..lines * gates).map(|_| gauss(1.0)).collect();
        let mut pass = |sn: f64| -> Vec<C32> { x.iter().map(|&v| v + gauss(sn)).collect() };
        let p1: Vec<Vec<C32>> = (0..passes).map(|_| pass(1.0 / 3.0)).collect();
        let p2: Vec<Vec<C32>> = (0..passes).map(|_| pass(2.0)).collect();
        let r1: Vec<&[C32]> = p1.iter().map(Vec::as_slice).collect();
        let r2: Vec<&[C32]> = p2.iter().map(Vec::as_slice).collect();
        let w = LookWindow { size: 16, step: 16 };
        let t = passes_thermal_coherence(&r1, &r2, lines, gates, w).unwrap();
        let mean = t.iter().map(|&v| f64::from(v)).sum::<f64>() / t.len() as f64;
        let expect = (0.9f64 * 0.2).sqrt();
        assert!((mean - expect).abs() < 0.03, "{mean} vs {expect}");
        // One pass has no partner to compare with.
        assert!(passes_thermal_coherence(&r1[..1], &r2[..1], lines, gates, w).is_none());
    }
}
