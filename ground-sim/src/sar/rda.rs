//! Range-Doppler algorithm: range compression → azimuth FFT → RCMC → azimuth compression →
//! azimuth IFFT, one [`Slc`] per channel.
//!
//! * Range: matched filter in the range-frequency domain, `W_r(f)·exp(+iπf²/K_r + iπ/4)` (the
//!   conjugate of the chirp's stationary-phase spectrum) with `W_r` a Hamming window over
//!   `|f| ≤ B/2` (zero outside).
//! * Azimuth: the FFT over pulses gives the range-Doppler domain (zero Doppler centroid: the
//!   antennas look broadside). A target at closest range `R0` sits at range `R0/D(f)` with
//!   `D(f) = sqrt(1 − (λf/2v)²)`; RCMC resamples every Doppler row at `R0/D` with the
//!   windowed-sinc kernel. Its spectrum is `exp(−i4πR0·D/λ)·exp(−iπ/4)·PRF/sqrt(K_a)` (stationary
//!   phase); the filter `W_a(f)·exp(+i4πR0(D − 1)/λ)·exp(+iπ/4)` removes everything but the
//!   carrier, so the focused peak keeps the phase `−4πR0/λ` exactly. `W_a` is a Hamming window
//!   over the Doppler band `|f| ≤ v/L_A`.
//!
//! Gains are normalised so that a point scatterer of amplitude `S` focuses to a peak of `S`
//! (times the carrier); the resolution area of eq 16 is then the PSF's energy area
//! `∫|h|² dA` ([`Slc::resolution_area_m2`]).

use std::sync::Arc;

use indicatif::ProgressBar;
use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};

use super::config::{Derived, SarConfig};
use super::echo::{RawEcho, sampled_chirp};
use super::geometry::{AcquisitionPlan, EchoWindow, PulseGrid, SlcCrop, fft_friendly_len};
use super::kernel::{KERNEL_TAPS, SincKernel};
use super::slc::Slc;
use super::{C32, C64, SarError, SarResult};

/// Generalised Hamming weight at normalised position `q ∈ [−1/2, 1/2]` of the band.
fn hamming(alpha: f64, q: f64) -> f64 {
    alpha + (1.0 - alpha) * (2.0 * std::f64::consts::PI * q).cos()
}

/// Signed frequency of DFT bin `k` of an `n`-point transform at sample rate `rate`.
fn bin_freq(k: usize, n: usize, rate: f64) -> f64 {
    let ks = if k < n.div_ceil(2) {
        k as f64
    } else {
        k as f64 - n as f64
    };
    ks * rate / n as f64
}

/// Focusing plans and filters for one acquisition (both antennas share them).
pub struct RdaProcessor {
    window: EchoWindow,
    pulses: PulseGrid,
    crop: SlcCrop,
    wavelength_m: f64,
    velocity_m_s: f64,
    prf_hz: f64,
    hamming_alpha: f64,
    doppler_half_band_hz: f64,
    range_len: usize,
    /// Range matched filter including the 1/N of the inverse FFT.
    range_filter: Vec<C32>,
    az_len: usize,
    /// Azimuth Hamming weights per Doppler bin, divided by N_a (inverse FFT) and by
    /// `(1/N_a)·Σ W` (the peak gain without the `PRF/sqrt(K_a)` factor).
    az_weight: Vec<f64>,
    range_fwd: Arc<dyn Fft<f32>>,
    range_inv: Arc<dyn Fft<f32>>,
    az_fwd: Arc<dyn Fft<f32>>,
    az_inv: Arc<dyn Fft<f32>>,
    kernel: SincKernel,
    /// Output noise power per unit raw-noise power (range × azimuth at the scene centre).
    noise_gain: f64,
    /// `∫|h_r|² dr` of the normalised range PSF, slant m.
    range_energy_width_m: f64,
    /// `∫|h_a|² dx` of the normalised azimuth PSF, m.
    azimuth_energy_width_m: f64,
}

impl std::fmt::Debug for RdaProcessor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RdaProcessor")
            .field("range_len", &self.range_len)
            .field("az_len", &self.az_len)
            .field("crop", &self.crop)
            .finish()
    }
}

impl RdaProcessor {
    /// Build plans, filters and gains for an acquisition plan.
    pub fn new(cfg: &SarConfig, derived: &Derived, plan: &AcquisitionPlan) -> SarResult<Self> {
        let window = plan.window;
        let pulses = plan.pulses;
        let crop = plan.crop;
        if crop.first_line + crop.lines > pulses.count
            || crop.first_gate + crop.gates > window.samples
        {
            return Err(SarError::Shape("SLC crop outside the echo".into()));
        }
        let range_len = fft_friendly_len(window.samples);
        let az_len = fft_friendly_len(pulses.count);
        let mut planner = FftPlanner::<f32>::new();
        let range_fwd = planner.plan_fft_forward(range_len);
        let range_inv = planner.plan_fft_inverse(range_len);
        let az_fwd = planner.plan_fft_forward(az_len);
        let az_inv = planner.plan_fft_inverse(az_len);

        // Range filter from the exact DFT of the same sampled chirp the echoes use.
        let mut p = sampled_chirp(derived, cfg, range_len);
        range_fwd.process(&mut p);
        let b = derived.bandwidth_hz;
        let fs = derived.sampling_rate_hz;
        let alpha = cfg.hamming_alpha;
        let w_r: Vec<f64> = (0..range_len)
            .map(|k| {
                let f = bin_freq(k, range_len, fs);
                if f.abs() <= 0.5 * b {
                    hamming(alpha, f / b)
                } else {
                    0.0
                }
            })
            .collect();
        // Phase-only reference from the chirp's stationary-phase spectrum,
        // conj(P(f)) ≈ exp(+iπf²/K_r + iπ/4): the output spectrum is W·|P| rather than W·|P|², so
        // the Fresnel ripple of the rectangular chirp enters once (ISLR −34.6 dB instead of
        // −33.4 dB at τ = 10 µs; ideal Hamming: −35.2 dB). The complex gain G_r normalises the
        // peak to exactly 1 (magnitude and phase), so the carrier phase is untouched.
        let nr = range_len as f64;
        let kr = derived.chirp_rate_hz_s;
        let reference: Vec<C64> = (0..range_len)
            .map(|k| {
                let f = bin_freq(k, range_len, fs);
                C64::from_polar(
                    w_r[k],
                    std::f64::consts::PI * f * f / kr + std::f64::consts::FRAC_PI_4,
                )
            })
            .collect();
        let g_r: C64 = reference
            .iter()
            .zip(&p)
            .map(|(h, pk)| h * C64::new(f64::from(pk.re), f64::from(pk.im)))
            .sum::<C64>()
            / nr;
        if g_r.norm().is_nan() || g_r.norm() <= 0.0 {
            return Err(SarError::Config("chirp has no energy in band".into()));
        }
        let range_filter: Vec<C32> = reference
            .iter()
            .map(|h| {
                let v = h / (g_r * nr);
                C32::new(v.re as f32, v.im as f32)
            })
            .collect();
        let p2: Vec<f64> = p.iter().map(|v| f64::from(v.norm_sqr())).collect();
        // Range noise gain N·Σ|H|² and PSF energy dr·N·Σ|H·P|².
        let range_noise = nr
            * range_filter
                .iter()
                .map(|h| f64::from(h.norm_sqr()))
                .sum::<f64>();
        let range_energy_width_m = window.spacing_m
            * nr
            * range_filter
                .iter()
                .zip(&p2)
                .map(|(h, q)| f64::from(h.norm_sqr()) * q)
                .sum::<f64>();

        let prf = derived.prf_hz;
        let half_band = 0.5 * derived.doppler_bandwidth_hz;
        let na = az_len as f64;
        let w_a: Vec<f64> = (0..az_len)
            .map(|k| {
                let f = bin_freq(k, az_len, prf);
                if f.abs() <= half_band {
                    hamming(alpha, f / (2.0 * half_band))
                } else {
                    0.0
                }
            })
            .collect();
        let mean_w = w_a.iter().sum::<f64>() / na;
        let az_weight: Vec<f64> = w_a.iter().map(|w| w / (na * mean_w)).collect();
        // Peak gain at range R: (PRF/sqrt(Ka))·mean_w, removed per gate in `focus`. With that
        // division, |H'|² = az_weight²·Ka/PRF², so the noise gain N_a·Σ|H'|² depends on Ka
        // (evaluated at the centre) while the PSF energy does not.
        let ka_c = derived.azimuth_fm_rate_hz_s;
        let az_sum_w2 = az_weight.iter().map(|w| w * w).sum::<f64>();
        let az_noise = na * az_sum_w2 * ka_c / (prf * prf);
        let azimuth_energy_width_m = derived.azimuth_spacing_m * na * az_sum_w2;
        Ok(Self {
            window,
            pulses,
            crop,
            wavelength_m: derived.wavelength_m,
            velocity_m_s: cfg.velocity_m_s,
            prf_hz: prf,
            hamming_alpha: alpha,
            doppler_half_band_hz: half_band,
            range_len,
            range_filter,
            az_len,
            az_weight,
            range_fwd,
            range_inv,
            az_fwd,
            az_inv,
            kernel: SincKernel::new(),
            noise_gain: range_noise * az_noise,
            range_energy_width_m,
            azimuth_energy_width_m,
        })
    }

    /// Output noise power per unit raw-noise power per sample (at the scene centre).
    pub fn noise_gain(&self) -> f64 {
        self.noise_gain
    }
    /// `∫|h_r|² dr` of the unit-peak range response, slant metres.
    pub fn range_energy_width_m(&self) -> f64 {
        self.range_energy_width_m
    }
    /// `∫|h_a|² dx` of the unit-peak azimuth response, metres.
    pub fn azimuth_energy_width_m(&self) -> f64 {
        self.azimuth_energy_width_m
    }
    /// Hamming coefficient used.
    pub fn hamming_alpha(&self) -> f64 {
        self.hamming_alpha
    }

    /// Range-compress every pulse of channel `p`: returns `az_len × samples` (rows past the
    /// last pulse are zero, ready for the azimuth FFT).
    fn range_compress(&self, raw: &RawEcho, p: usize) -> Vec<C32> {
        let ns = self.window.samples;
        let nr = self.range_len;
        let mut out = vec![C32::new(0.0, 0.0); self.az_len * ns];
        let scratch_len = self
            .range_fwd
            .get_inplace_scratch_len()
            .max(self.range_inv.get_inplace_scratch_len());
        out.par_chunks_mut(ns)
            .take(self.pulses.count)
            .enumerate()
            .for_each_init(
                || {
                    (
                        vec![C32::new(0.0, 0.0); nr],
                        vec![C32::new(0.0, 0.0); scratch_len],
                    )
                },
                |(buf, scratch), (n, row)| {
                    buf[..ns].copy_from_slice(raw.row(p, n));
                    buf[ns..].fill(C32::new(0.0, 0.0));
                    self.range_fwd.process_with_scratch(buf, scratch);
                    for (v, h) in buf.iter_mut().zip(&self.range_filter) {
                        *v *= h;
                    }
                    self.range_inv.process_with_scratch(buf, scratch);
                    row.copy_from_slice(&buf[..ns]);
                },
            );
        out
    }

    /// FFT (forward or inverse) along every row of a `rows × len` matrix.
    fn fft_rows(fft: &Arc<dyn Fft<f32>>, data: &mut [C32], len: usize) {
        let scratch_len = fft.get_inplace_scratch_len();
        data.par_chunks_mut(len).for_each_init(
            || vec![C32::new(0.0, 0.0); scratch_len],
            |scratch, row| fft.process_with_scratch(row, scratch),
        );
    }

    /// Focus every channel of a raw echo. `antenna_yz` and `reference_height_m` are recorded
    /// in the SLC geometry.
    pub fn focus(
        &self,
        raw: &RawEcho,
        antenna_yz: [f64; 2],
        reference_height_m: f64,
        progress: &ProgressBar,
    ) -> SarResult<Vec<Slc>> {
        if raw.window != self.window || raw.pulses != self.pulses {
            return Err(SarError::Shape(
                "raw echo does not match the focusing plan".into(),
            ));
        }
        let ns = self.window.samples;
        let na = self.az_len;
        let crop = self.crop;
        let gates = crop.gates;
        let dr = self.window.spacing_m;
        let lambda = self.wavelength_m;
        let v = self.velocity_m_s;
        // Per-gate closest range and the 1/(PRF/sqrt(Ka)) peak-gain factor.
        let gate_range: Vec<f64> = (0..gates)
            .map(|j| self.window.first_range_m + (crop.first_gate + j) as f64 * dr)
            .collect();
        let gate_gain: Vec<f64> = gate_range
            .iter()
            .map(|&r| (2.0 * v * v / (lambda * r)).sqrt() / self.prf_hz)
            .collect();
        let mut slcs = Vec::with_capacity(raw.polarisations.len());
        for (p, &pol) in raw.polarisations.iter().enumerate() {
            // 1. Range compression, rows = pulses.
            let rc = self.range_compress(raw, p);
            progress.inc(1);
            // 2. Azimuth FFT along pulses: transpose to gates × pulses.
            let mut cols = vec![C32::new(0.0, 0.0); ns * na];
            transpose::transpose(&rc, &mut cols, ns, na);
            drop(rc);
            Self::fft_rows(&self.az_fwd, &mut cols, na);
            let mut rd = vec![C32::new(0.0, 0.0); na * ns];
            transpose::transpose(&cols, &mut rd, na, ns);
            drop(cols);
            progress.inc(1);
            // 3+4. RCMC and azimuth compression, per Doppler row, over the kept gates only.
            let mut comp = vec![C32::new(0.0, 0.0); na * gates];
            comp.par_chunks_mut(gates)
                .zip(rd.par_chunks(ns))
                .enumerate()
                .for_each(|(k, (out, row))| {
                    let f = bin_freq(k, na, self.prf_hz);
                    let wgt = self.az_weight[k];
                    if wgt == 0.0 || f.abs() > self.doppler_half_band_hz {
                        return;
                    }
                    let d = (1.0 - (lambda * f / (2.0 * v)).powi(2)).sqrt();
                    for (j, o) in out.iter_mut().enumerate() {
                        let r0 = gate_range[j];
                        let u = (crop.first_gate + j) as f64 + r0 * (1.0 / d - 1.0) / dr;
                        let (first, w) = self.kernel.weights(u);
                        let mut acc = C32::new(0.0, 0.0);
                        if first >= 0 && first as usize + KERNEL_TAPS <= ns {
                            let src = &row[first as usize..first as usize + KERNEL_TAPS];
                            for (s, &wj) in src.iter().zip(w.iter()) {
                                acc += *s * wj;
                            }
                        }
                        // exp(+i4πR0(D−1)/λ + iπ/4), phase reduced in f64.
                        let cycles = 2.0 * r0 * (d - 1.0) / lambda + 0.125;
                        let (s, c) =
                            (2.0 * std::f64::consts::PI * (cycles - cycles.round())).sin_cos();
                        let g = wgt * gate_gain[j];
                        *o = acc * C32::new((c * g) as f32, (s * g) as f32);
                    }
                });
            drop(rd);
            progress.inc(1);
            // 5. Azimuth IFFT: transpose to gates × Doppler, IFFT, back to lines × gates.
            let mut cols = vec![C32::new(0.0, 0.0); gates * na];
            transpose::transpose(&comp, &mut cols, gates, na);
            drop(comp);
            Self::fft_rows(&self.az_inv, &mut cols, na);
            let mut img = vec![C32::new(0.0, 0.0); na * gates];
            transpose::transpose(&cols, &mut img, na, gates);
            drop(cols);
            let data =
                img[crop.first_line * gates..(crop.first_line + crop.lines) * gates].to_vec();
            progress.inc(1);
            slcs.push(Slc {
                antenna: raw.antenna,
                polarisation: pol,
                lines: crop.lines,
                gates,
                data,
                first_range_m: gate_range[0],
                range_spacing_m: dr,
                first_azimuth_m: self.pulses.x(crop.first_line),
                azimuth_spacing_m: self.pulses.spacing_m,
                wavelength_m: lambda,
                antenna_yz_m: antenna_yz,
                velocity_m_s: v,
                range_energy_width_m: self.range_energy_width_m,
                azimuth_energy_width_m: self.azimuth_energy_width_m,
                reference_height_m,
            });
        }
        Ok(slcs)
    }
}
