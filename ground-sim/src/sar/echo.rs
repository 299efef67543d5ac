//! Raw chirp echoes (eqs 11–13), fast method and time-domain oracle, plus thermal noise.
//!
//! Echo of pulse `n` (platform at `x_n`), fast-time sample `k` (delay `t_k`):
//!
//! `h(t_k, x_n) = Σ_m S_m · Π[(t_k − 2R_m/c)/(τ/2)] · Π[(x_n − x_m)/(L_s/2)]
//!                · exp(−i4πR_m/λ + iπK_r(t_k − 2R_m/c)²)`, `R_m = |A(x_n) − P_m|`.
//!
//! * [`EchoSimulator::simulate_time_domain`] evaluates this sum directly (the test oracle:
//!   `O(pulses × scatterers × chirp samples)`).
//! * [`EchoSimulator::simulate_fast`] deposits `S_m·exp(−i4πR_m/λ)` for each scatterer with the
//!   windowed-sinc kernel at its exact fractional delay (a band-limited delta, accurate over the
//!   chirp band `|f| ≤ fs/4`), then convolves every pulse with the sampled chirp by one
//!   FFT–multiply–IFFT: `O(pulses × (scatterers × DEPOSIT_TAPS + N log N))`
//!   ([`DEPOSIT_TAPS`] = 8). Both agree inside the chirp band, the only part the range matched
//!   filter keeps.
//!
//! Stop-and-hop: the platform does not move during a pulse's flight. The azimuth envelope uses
//! each scatterer's own footprint `L_s = λR/L_A` so every scatterer spans the same Doppler band
//! `2v/L_A`.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use indicatif::ProgressBar;
use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};

use super::config::{Derived, Polarisation, SarConfig};
use super::geometry::{Antenna, EchoWindow, PulseGrid, fft_friendly_len};
use super::kernel::{DEPOSIT_LEAD, DEPOSIT_TAPS, DepositKernel, KERNEL_TAPS, cos_sin_turns_f32};
use super::scattering::complex_gaussian;
use super::scene::Scatterers;
use super::{C32, C64, MAX_POLARISATIONS, SarError, SarResult};

/// Pulses simulated together in the fast echo method. Each scatterer's data is read once per
/// block instead of once per pulse, and successive deposits alternate between the block's
/// pulse buffers: neighbouring scatterers fall on overlapping samples, and depositing them
/// one after the other into one buffer would make each wait for the previous one's stores.
const PULSE_BLOCK: usize = 4;

/// Which build of the echo deposit loop runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Isa {
    /// The best the CPU has (AVX2 where present).
    Detect,
    /// The baseline build (SSE2 on x86-64).
    #[cfg_attr(
        not(test),
        allow(dead_code, reason = "the tests compare the two builds")
    )]
    Baseline,
}

/// Refuse scatterers with a non-finite along-track position: the pulses find the scatterers
/// they see by a binary search on `x`, which would pass such a scatterer over (or, for a NaN,
/// lose the order the search needs) without counting it anywhere.
fn check_along_track(sc: &Scatterers) -> SarResult<()> {
    let bad = sc.x_m.iter().filter(|x| !x.is_finite()).count();
    if bad > 0 {
        return Err(SarError::Bound(format!(
            "{bad} scatterers have a non-finite along-track position"
        )));
    }
    Ok(())
}

/// One block of pulses for the deposit loop.
struct PulseBlock<'a> {
    sc: &'a Scatterers,
    /// The scatterers' per-pass geometry.
    track: &'a TrackGeometry,
    /// Along-track positions of the block's pulses, m (at most [`PULSE_BLOCK`]).
    xp: &'a [f64],
    /// Scatterers any pulse of the block may see (indices into `sc`).
    range: std::ops::Range<usize>,
    /// Samples from one channel's accumulation buffer to the next ([`deposit_stride`]).
    pol_stride: usize,
}

/// Length (complex samples) of each channel's accumulation buffer in the fast echo method:
/// at least `nfft`, and `≡ 32 (mod 512)` so that the buffers of the pulses and channels start
/// 256 bytes apart modulo 4 KiB. A CPU guesses whether a load depends on an earlier store from
/// the low 12 address bits; buffers a multiple of 4 KiB apart (FFT-friendly lengths often are)
/// would make each deposit wait on the previous one's stores into another buffer. A guard,
/// not a measured gain: on the one layout tried (4 lanes per pulse, before the pulse blocks)
/// its effect did not stand out of this machine's ±10 % run-to-run noise.
fn deposit_stride(nfft: usize) -> usize {
    nfft + (32 + 512 - nfft % 512) % 512
}

/// Raw (unfocused) echoes of one antenna for every simulated polarisation.
///
/// Layout: `data[(pulse·npol + pol)·samples + k]`, `npol = polarisations.len()`.
#[derive(Debug, Clone)]
pub struct RawEcho {
    /// Antenna that transmitted and received.
    pub antenna: Antenna,
    /// Channels, in data order.
    pub polarisations: Vec<Polarisation>,
    /// Fast-time sampling.
    pub window: EchoWindow,
    /// Pulse positions.
    pub pulses: PulseGrid,
    /// Samples, see type docs.
    pub data: Vec<C32>,
}

impl RawEcho {
    /// Samples of pulse `n`, channel index `p`.
    pub fn row(&self, p: usize, n: usize) -> &[C32] {
        let ns = self.window.samples;
        let off = (n * self.polarisations.len() + p) * ns;
        &self.data[off..off + ns]
    }
}

/// Chirp, kernel and FFT plans shared by every pulse.
pub struct EchoSimulator {
    window: EchoWindow,
    pulses: PulseGrid,
    wavelength_m: f64,
    sampling_rate_hz: f64,
    chirp_rate_hz_s: f64,
    pulse_width_s: f64,
    fft_len: usize,
    /// DFT of the sampled chirp centred on index 0, pre-scaled by 1/N for the inverse FFT.
    chirp_spectrum: Vec<C32>,
    fwd: Arc<dyn Fft<f32>>,
    inv: Arc<dyn Fft<f32>>,
    kernel: DepositKernel,
}

impl std::fmt::Debug for EchoSimulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EchoSimulator")
            .field("window", &self.window)
            .field("pulses", &self.pulses)
            .field("fft_len", &self.fft_len)
            .finish()
    }
}

/// The transmitted baseband chirp `exp(iπK_r t²)` sampled at `t = m/fs` for `|t| ≤ τ/2`, placed
/// circularly (negative `m` wrap to the end) in a buffer of length `len`.
pub fn sampled_chirp(derived: &Derived, cfg: &SarConfig, len: usize) -> Vec<C32> {
    let fs = derived.sampling_rate_hz;
    let kr = derived.chirp_rate_hz_s;
    let half = (0.5 * cfg.pulse_width_s * fs).floor() as i64;
    let mut out = vec![C32::new(0.0, 0.0); len];
    for m in -half..=half {
        let t = m as f64 / fs;
        let (s, c) = (std::f64::consts::PI * kr * t * t).sin_cos();
        out[m.rem_euclid(len as i64) as usize] = C32::new(c as f32, s as f32);
    }
    out
}

/// Carrier `exp(−i4πR/λ)` computed from the fractional part of `2R/λ` in f64 so the phase keeps
/// full precision at 10⁵ m ranges.
#[inline]
pub fn carrier(range_m: f64, wavelength_m: f64) -> C64 {
    let cycles = 2.0 * range_m / wavelength_m;
    let frac = cycles - cycles.floor();
    let (s, c) = (-2.0 * std::f64::consts::PI * frac).sin_cos();
    C64::new(c, s)
}

/// What one antenna's pass needs of each scatterer that does not change from pulse to pulse:
/// the zero-Doppler range `R0` and, taken from it once in f64, the fraction of the carrier
/// phase and the echo-window position. Per pulse only `R − R0` is left, small enough (metres)
/// for f32, so the per-pulse geometry runs four scatterers per SSE instruction instead of two.
#[derive(Debug)]
struct TrackGeometry {
    /// `R0 = sqrt((y − y_A)² + (z − z_A)²)`, m (f32: it only enters `R − R0`'s denominator).
    r0_m: Vec<f32>,
    /// Fractional part of `2R0/λ`, turns, in [0, 1).
    phase0_turns: Vec<f32>,
    /// `⌊(R0 − r_first)/Δr⌋ − DEPOSIT_LEAD`, the deposit's first tap at zero squint, samples
    /// (clamped to ±2·10⁹ so that a non-finite position lands far outside the window, where it
    /// is counted).
    gate0: Vec<i32>,
    /// `(R0 − r_first)/Δr − ⌊…⌋`, samples, in [0, 1).
    gate_frac0: Vec<f32>,
    /// Half azimuth footprint, m.
    half_m: Vec<f32>,
}

impl TrackGeometry {
    fn new(sc: &Scatterers, antenna_yz: [f64; 2], window: &EchoWindow, wavelength_m: f64) -> Self {
        let per: Vec<(f32, f32, i32, f32)> = sc
            .y_m
            .par_iter()
            .zip(&sc.z_m)
            .map(|(&y, &z)| {
                let r0 = ((y - antenna_yz[0]).powi(2) + (z - antenna_yz[1]).powi(2)).sqrt();
                let cycles = 2.0 * r0 / wavelength_m;
                let phase = (cycles - cycles.floor()) as f32;
                // The f32 fraction may round up to 1.0: the carrier does not care.
                #[allow(clippy::manual_clamp, reason = "clamp keeps a NaN")]
                let u = ((r0 - window.first_range_m) / window.spacing_m)
                    .max(-2e9)
                    .min(2e9);
                let g = u.floor();
                // |g| ≤ 2·10⁹: fits i32 with the lead and any clamped f32 offset added.
                let gate = (g as i64 - DEPOSIT_LEAD) as i32;
                (r0 as f32, phase, gate, (u - g) as f32)
            })
            .collect();
        Self {
            r0_m: per.iter().map(|p| p.0).collect(),
            phase0_turns: per.iter().map(|p| p.1).collect(),
            gate0: per.iter().map(|p| p.2).collect(),
            gate_frac0: per.iter().map(|p| p.3).collect(),
            half_m: sc.half_footprint_m.iter().map(|&h| h as f32).collect(),
        }
    }
}

impl EchoSimulator {
    /// Plan the FFTs and tabulate the chirp spectrum for a window and pulse grid.
    pub fn new(
        cfg: &SarConfig,
        derived: &Derived,
        window: EchoWindow,
        pulses: PulseGrid,
    ) -> SarResult<Self> {
        let fft_len = fft_friendly_len(window.samples);
        if (derived.chirp_samples as usize) + KERNEL_TAPS >= window.samples {
            return Err(SarError::Bound("echo window shorter than the chirp".into()));
        }
        let mut planner = FftPlanner::<f32>::new();
        let fwd = planner.plan_fft_forward(fft_len);
        let inv = planner.plan_fft_inverse(fft_len);
        let mut chirp_spectrum = sampled_chirp(derived, cfg, fft_len);
        fwd.process(&mut chirp_spectrum);
        let norm = 1.0 / fft_len as f32;
        for v in &mut chirp_spectrum {
            *v *= norm;
        }
        Ok(Self {
            window,
            pulses,
            wavelength_m: derived.wavelength_m,
            sampling_rate_hz: derived.sampling_rate_hz,
            chirp_rate_hz_s: derived.chirp_rate_hz_s,
            pulse_width_s: cfg.pulse_width_s,
            fft_len,
            chirp_spectrum,
            fwd,
            inv,
            kernel: DepositKernel::new(),
        })
    }

    /// Squared cross-track distance of every scatterer from an antenna's track.
    fn rho2(sc: &Scatterers, antenna_yz: [f64; 2]) -> Vec<f64> {
        sc.y_m
            .par_iter()
            .zip(&sc.z_m)
            .map(|(&y, &z)| (y - antenna_yz[0]).powi(2) + (z - antenna_yz[1]).powi(2))
            .collect()
    }

    /// Index range of scatterers that may be inside pulse `n`'s footprint.
    fn footprint(&self, sc: &Scatterers, half_max: f64, n: usize) -> (usize, usize, f64) {
        let xp = self.pulses.x(n);
        let lo = sc.x_m.partition_point(|&x| x < xp - half_max);
        let hi = sc.x_m.partition_point(|&x| x <= xp + half_max);
        (lo, hi, xp)
    }

    fn empty(&self, sc: &Scatterers, antenna: Antenna) -> RawEcho {
        RawEcho {
            antenna,
            polarisations: sc.polarisations.clone(),
            window: self.window,
            pulses: self.pulses,
            data: vec![
                C32::new(0.0, 0.0);
                self.pulses.count * self.window.samples * sc.polarisations.len()
            ],
        }
    }

    /// Fast exact-equivalent echoes (see module docs). `antenna_yz` is the antenna track's
    /// `(y, z)`, m. Errors if a scatterer's kernel would fall outside the window.
    pub fn simulate_fast(
        &self,
        sc: &Scatterers,
        antenna: Antenna,
        antenna_yz: [f64; 2],
        progress: &ProgressBar,
    ) -> SarResult<RawEcho> {
        self.simulate_fast_with(sc, antenna, antenna_yz, progress, Isa::Detect)
    }

    /// [`Self::simulate_fast`] with the instruction set chosen (tests compare the two).
    pub(crate) fn simulate_fast_with(
        &self,
        sc: &Scatterers,
        antenna: Antenna,
        antenna_yz: [f64; 2],
        progress: &ProgressBar,
        isa: Isa,
    ) -> SarResult<RawEcho> {
        let npol = sc.polarisations.len();
        if npol == 0 || npol > MAX_POLARISATIONS {
            return Err(SarError::Config("scatterers carry no polarisation".into()));
        }
        check_along_track(sc)?;
        let mut raw = self.empty(sc, antenna);
        let ns = self.window.samples;
        let nfft = self.fft_len;
        let track = TrackGeometry::new(sc, antenna_yz, &self.window, self.wavelength_m);
        let pol_stride = deposit_stride(nfft);
        let half_max = sc.max_half_footprint_m();
        let outside = AtomicUsize::new(0);
        let scratch_len = self
            .fwd
            .get_inplace_scratch_len()
            .max(self.inv.get_inplace_scratch_len());
        raw.data
            .par_chunks_mut(PULSE_BLOCK * npol * ns)
            .enumerate()
            .for_each_init(
                || {
                    (
                        vec![C32::new(0.0, 0.0); PULSE_BLOCK * npol * pol_stride],
                        vec![C32::new(0.0, 0.0); scratch_len],
                    )
                },
                |(buf, scratch), (b, rows)| {
                    buf.fill(C32::new(0.0, 0.0));
                    let n0 = b * PULSE_BLOCK;
                    let count = rows.len() / (npol * ns);
                    let (lo, _, _) = self.footprint(sc, half_max, n0);
                    let (_, hi, _) = self.footprint(sc, half_max, n0 + count - 1);
                    let xp: [f64; PULSE_BLOCK] =
                        std::array::from_fn(|j| self.pulses.x(n0 + j.min(count - 1)));
                    let block = PulseBlock {
                        sc,
                        track: &track,
                        xp: &xp[..count],
                        range: lo..hi,
                        pol_stride,
                    };
                    let missed = self.deposit_pulses(&block, buf, isa);
                    if missed > 0 {
                        outside.fetch_add(missed, Ordering::Relaxed);
                    }
                    for (j, row) in rows.chunks_exact_mut(npol * ns).enumerate() {
                        for p in 0..npol {
                            let at = (j * npol + p) * pol_stride;
                            let v = &mut buf[at..at + nfft];
                            self.fwd.process_with_scratch(v, scratch);
                            for (v, &h) in v.iter_mut().zip(&self.chirp_spectrum) {
                                *v *= h;
                            }
                            self.inv.process_with_scratch(v, scratch);
                            row[p * ns..(p + 1) * ns].copy_from_slice(&v[..ns]);
                        }
                        progress.inc(1);
                    }
                },
            );
        let missed = outside.into_inner();
        if missed > 0 {
            return Err(SarError::Bound(format!(
                "{missed} scatterer-pulse pairs fell outside the echo window"
            )));
        }
        Ok(raw)
    }

    /// Deposit every scatterer of `block.range` that each pulse of the block sees into that
    /// pulse's buffers in `buf` (`npol` buffers of `block.pol_stride` samples per pulse, the
    /// first `fft_len` of each used); returns how many fell outside the echo window.
    ///
    /// Per chunk of scatterers, first the geometry of the whole chunk for every pulse (range
    /// increment, table position, carrier) in straight f32 loops the compiler vectorises four
    /// wide, then the kernel deposits, scatterer by scatterer and pulse by pulse: a scatterer's
    /// data is read once for the block of pulses, and consecutive deposits go to different
    /// pulses' buffers, so none waits on the previous one's stores.
    ///
    /// On an x86-64 CPU with AVX2 the same code runs compiled for it (eight lanes instead of
    /// four; found at run time, so one binary serves every machine). No FMA is enabled, so
    /// every operation and its rounding are the baseline's: the echoes are bit-identical
    /// either way (`sar::tests::avx2_echoes_are_the_baseline_bits`).
    fn deposit_pulses(&self, block: &PulseBlock<'_>, buf: &mut [C32], isa: Isa) -> usize {
        #[cfg(target_arch = "x86_64")]
        if isa == Isa::Detect && std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the one requirement of calling a function compiled for AVX2 is a CPU
            // that has it, checked on the line above.
            #[allow(
                unsafe_code,
                reason = "run-time dispatch to the AVX2 build of the loop"
            )]
            return unsafe { self.deposit_pulses_avx2(block, buf) };
        }
        let _ = isa;
        self.deposit_pulses_body(block, buf)
    }

    /// [`Self::deposit_pulses_body`] compiled for AVX2 (without FMA: same roundings).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    fn deposit_pulses_avx2(&self, block: &PulseBlock<'_>, buf: &mut [C32]) -> usize {
        self.deposit_pulses_body(block, buf)
    }

    /// The deposit loop of [`Self::deposit_pulses`], inlined into each instruction-set build.
    #[allow(
        clippy::needless_range_loop,
        reason = "one index walks parallel SoA arrays"
    )]
    #[inline(always)]
    fn deposit_pulses_body(&self, block: &PulseBlock<'_>, buf: &mut [C32]) -> usize {
        let PulseBlock {
            sc,
            track,
            xp,
            pol_stride,
            ..
        } = *block;
        let range = block.range.clone();
        const CHUNK: usize = 64;
        let npol = sc.polarisations.len();
        let ns = self.window.samples;
        let inv_dr = (1.0 / self.window.spacing_m) as f32;
        let two_over_lambda = (2.0 / self.wavelength_m) as f32;
        let flat: &mut [f32] = bytemuck::cast_slice_mut(buf);
        let pulses = xp.len().min(PULSE_BLOCK);
        let mut missed = 0usize;
        let mut first = [[0_i32; CHUNK]; PULSE_BLOCK];
        let mut row = [[0_u32; CHUNK]; PULSE_BLOCK];
        let mut amp = [[[C32::new(0.0, 0.0); MAX_POLARISATIONS]; CHUNK]; PULSE_BLOCK];
        let mut inside = [[false; CHUNK]; PULSE_BLOCK];
        let mut dxs = [0.0_f32; CHUNK];
        let mut start = range.start;
        while start < range.end {
            let end = (start + CHUNK).min(range.end);
            let m = end - start;
            let (xs, halves, amps) = (
                &sc.x_m[start..end],
                &track.half_m[start..end],
                &sc.amplitude[start..end],
            );
            let (r0s, ph0s, g0s, gf0s) = (
                &track.r0_m[start..end],
                &track.phase0_turns[start..end],
                &track.gate0[start..end],
                &track.gate_frac0[start..end],
            );
            for j in 0..pulses {
                // Along-track offsets first: the f64 subtraction runs two (AVX2: four) lanes wide, and on
                // its own it lets the f32 loop below run four.
                for k in 0..m {
                    dxs[k] = (xs[k] - xp[j]) as f32;
                }
                let (inside, first, row, amp) =
                    (&mut inside[j], &mut first[j], &mut row[j], &mut amp[j]);
                // Geometry of the chunk: no branch, no libm, no saturating conversion.
                for k in 0..m {
                    let dx = dxs[k];
                    // Negated so that a NaN reaches the counted window check below.
                    inside[k] = !(dx.abs() > halves[k]);
                    // R − R0 = dx²/(R0 + R), without the cancellation of R − R0: f32 keeps it
                    // to ~10⁻⁷ of itself (metres at most), where R itself needs f64.
                    let dx2 = dx * dx;
                    let r0 = r0s[k];
                    let dr = dx2 / (r0 + (r0 * r0 + dx2).sqrt());
                    let (f, row_k) = DepositKernel::position(gf0s[k] + dr * inv_dr);
                    // Both within ±2.1·10⁹: no overflow.
                    first[k] = g0s[k] + f;
                    row[k] = row_k;
                    // exp(−i4πR/λ) = exp(−i2π·(2R0/λ + 2(R − R0)/λ)), the first term's
                    // fraction taken in f64 once per scatterer.
                    let (c, s) = cos_sin_turns_f32(ph0s[k] + dr * two_over_lambda);
                    let carrier = C32::new(c, -s);
                    amp[k] = std::array::from_fn(|p| amps[k][p] * carrier);
                }
            }
            for k in 0..m {
                for j in 0..pulses {
                    if !inside[j][k] {
                        continue;
                    }
                    let f = first[j][k];
                    if f < 0 || f as usize + DEPOSIT_TAPS > ns {
                        missed += 1;
                        continue;
                    }
                    let w = self.kernel.weights(row[j][k] as usize);
                    for (p, &a) in amp[j][k].iter().enumerate().take(npol) {
                        // Interleaved re/im against paired weights: the same products and
                        // sums as `d += a·w` per complex sample, in vector lanes.
                        let aa: [f32; 2 * DEPOSIT_TAPS] =
                            std::array::from_fn(|q| if q % 2 == 0 { a.re } else { a.im });
                        let at = 2 * ((j * npol + p) * pol_stride + f as usize);
                        // In range: f + DEPOSIT_TAPS ≤ ns ≤ pol_stride was checked above.
                        let dst = &mut flat[at..at + 2 * DEPOSIT_TAPS];
                        for ((d, &wk), &ak) in dst.iter_mut().zip(w.iter()).zip(aa.iter()) {
                            *d += ak * wk;
                        }
                    }
                }
            }
            start = end;
        }
        missed
    }

    /// Direct evaluation of eq 11 (the oracle). Cost grows with the chirp length: keep scenes
    /// small.
    #[allow(
        clippy::needless_range_loop,
        reason = "one index walks parallel SoA arrays"
    )]
    pub fn simulate_time_domain(
        &self,
        sc: &Scatterers,
        antenna: Antenna,
        antenna_yz: [f64; 2],
    ) -> SarResult<RawEcho> {
        let npol = sc.polarisations.len();
        check_along_track(sc)?;
        let mut raw = self.empty(sc, antenna);
        let ns = self.window.samples;
        let rho2 = Self::rho2(sc, antenna_yz);
        let half_max = sc.max_half_footprint_m();
        let fs = self.sampling_rate_hz;
        let half_tau = 0.5 * self.pulse_width_s;
        let kr = self.chirp_rate_hz_s;
        let r0 = self.window.first_range_m;
        let dr = self.window.spacing_m;
        let outside = AtomicUsize::new(0);
        raw.data
            .par_chunks_mut(npol * ns)
            .enumerate()
            .for_each(|(n, row)| {
                let mut acc = vec![C64::new(0.0, 0.0); npol * ns];
                let (lo, hi, xp) = self.footprint(sc, half_max, n);
                for i in lo..hi {
                    let dx = sc.x_m[i] - xp;
                    if dx.abs() > sc.half_footprint_m[i] {
                        continue;
                    }
                    let r = (rho2[i] + dx * dx).sqrt();
                    let car = carrier(r, self.wavelength_m);
                    // Delay of sample k relative to the echo: t_k − 2R/c = (k − u)/fs.
                    let u = (r - r0) / dr;
                    let k_lo = (u - half_tau * fs).ceil();
                    let k_hi = (u + half_tau * fs).floor();
                    if k_lo < 0.0 || k_hi >= ns as f64 {
                        outside.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    let amps: [C64; MAX_POLARISATIONS] = std::array::from_fn(|p| {
                        let a = sc.amplitude[i][p];
                        C64::new(f64::from(a.re), f64::from(a.im)) * car
                    });
                    for k in k_lo as usize..=k_hi as usize {
                        let t = (k as f64 - u) / fs;
                        let (s, c) = (std::f64::consts::PI * kr * t * t).sin_cos();
                        let chirp = C64::new(c, s);
                        for p in 0..npol {
                            acc[p * ns + k] += amps[p] * chirp;
                        }
                    }
                }
                for (o, a) in row.iter_mut().zip(&acc) {
                    *o = C32::new(a.re as f32, a.im as f32);
                }
            });
        let missed = outside.into_inner();
        if missed > 0 {
            return Err(SarError::Bound(format!(
                "{missed} scatterer-pulse pairs fell outside the echo window"
            )));
        }
        Ok(raw)
    }
}

/// Add circular complex white Gaussian noise of power `power_per_sample` (E|n|²) to every raw
/// sample, seeded per antenna and channel (receivers have independent noise).
pub fn add_thermal_noise(raw: &mut RawEcho, power_per_sample: f64, seed: u64) {
    if !(power_per_sample.is_finite() && power_per_sample > 0.0) {
        return;
    }
    let amp = power_per_sample.sqrt();
    let ns = raw.window.samples;
    let npol = raw.polarisations.len();
    let codes: Vec<u64> = raw
        .polarisations
        .iter()
        .map(|p| u64::from(p.code()))
        .collect();
    let stream_base = 1000 + 10 * raw.antenna.index() as u64;
    raw.data
        .par_chunks_mut(ns)
        .enumerate()
        .for_each(|(row_idx, row)| {
            let (pulse, p) = (row_idx / npol, row_idx % npol);
            let stream = stream_base + codes[p];
            for (k, v) in row.iter_mut().enumerate() {
                let g = complex_gaussian(seed, stream, (pulse * ns + k) as u64) * amp;
                *v += C32::new(g.re as f32, g.im as f32);
            }
        });
}
