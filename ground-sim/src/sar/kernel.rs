//! Tabulated Kaiser-windowed sincs: a 16-tap one to interpolate in range during RCMC and
//! coregistration, and a shorter 8-tap one ([`DepositKernel`]) to place a facet at its exact
//! fractional delay in the fast echo method.
//!
//! Both uses see signals oversampled by `fs/B = 2`: the useful band is `|f| ≤ fs/4`. The
//! interpolator (sinc cut at `fs/2`, Kaiser β = 10 over 16 taps, main-lobe half-width ≈
//! 0.21·fs) is flat to ≈ −74 dB up to 0.29·fs and rejects its images beyond 0.71·fs; the
//! deposit kernel is exact to −55 dB in the band, which is all of a deposit that survives the
//! chirp and the matched filter. Both are far below the −40 dB the SLC comparison needs.

/// Taps of the interpolation kernel (samples it spans).
pub const KERNEL_TAPS: usize = 16;
/// Fractional delays tabulated per sample; weights between them are linearly interpolated
/// (error ≈ π²/(8·512²) ≈ 5·10⁻⁶ of a tap, −100 dB).
pub const KERNEL_PHASES: usize = 512;
/// Kaiser window shape parameter.
const KAISER_BETA: f64 = 10.0;
/// Index offset of tap 0 relative to `floor(u)`.
const LEAD: i64 = KERNEL_TAPS as i64 / 2 - 1;

/// Weights of a windowed sinc tabulated at [`KERNEL_PHASES`] + 1 fractional delays.
#[derive(Debug, Clone)]
pub struct SincKernel {
    table: Vec<[f32; KERNEL_TAPS]>,
}

impl Default for SincKernel {
    fn default() -> Self {
        Self::new()
    }
}

/// Modified Bessel function of the first kind, order 0 (power series; converges fast for the
/// small arguments used here).
fn bessel_i0(x: f64) -> f64 {
    let q = 0.25 * x * x;
    let (mut term, mut sum) = (1.0_f64, 1.0_f64);
    for k in 1..64 {
        term *= q / (k * k) as f64;
        sum += term;
        if term < 1e-17 * sum {
            break;
        }
    }
    sum
}

/// The continuous kernel at distance `d` samples.
pub fn kernel_value(d: f64) -> f64 {
    kaiser_sinc(d, KERNEL_TAPS, KAISER_BETA)
}

/// A sinc cut at `fs/2` under a Kaiser window of shape `beta` spanning `taps` samples, at
/// distance `d` samples.
fn kaiser_sinc(d: f64, taps: usize, beta: f64) -> f64 {
    let half = taps as f64 / 2.0;
    let t = d / half;
    if t.abs() > 1.0 {
        return 0.0;
    }
    let sinc = if d.abs() < 1e-12 {
        1.0
    } else {
        (std::f64::consts::PI * d).sin() / (std::f64::consts::PI * d)
    };
    sinc * bessel_i0(beta * (1.0 - t * t).sqrt()) / bessel_i0(beta)
}

/// Taps of the shorter kernel that places a facet's echo at its fractional delay
/// ([`DepositKernel`]). Only the chirp band `|f| ≤ fs/4` of a deposit survives the chirp
/// convolution and the range matched filter, so the kernel need only be exact there: 8 taps at
/// Kaiser β = 6 rebuild a tone anywhere in that band at any fractional delay to better than
/// −52 dB (−55.6 dB computed; test below), and focused SLCs match the time-domain oracle to
/// −68 dB (`sar::tests`), far inside the −40 dB the comparison asks. The 16-tap interpolator
/// is kept for RCMC and coregistration, where the signal is resampled, not synthesised. The
/// echo simulation deposits every facet into every pulse that sees it (≈ 10¹⁰ times for a
/// 16 km map), so its cost is proportional to this.
pub const DEPOSIT_TAPS: usize = 8;
/// Kaiser shape of the deposit kernel (the β with the least worst-case in-band error at 8
/// taps, by a scan of 3–12).
const DEPOSIT_BETA: f64 = 6.0;
/// Index offset of the deposit kernel's tap 0 relative to `floor(u)`.
pub const DEPOSIT_LEAD: i64 = DEPOSIT_TAPS as i64 / 2 - 1;

/// Fractional delays the deposit kernel is tabulated at per sample; a deposit takes the
/// nearest (no interpolation between rows: the echo simulation's hottest loop). The delay is
/// then off by at most 1/(2·1024) sample, a shift of ≤ 1.1 mm at the default 2.2 m gates
/// (the carrier phase is untouched: it is computed from the exact range), ≤ 0.044° of phase
/// at the band edge, −62 dB, below the kernel's own −55 dB. 1024 rows of 8 weights fill
/// 32 KiB, a core's L1 data cache, which a finer table would miss on every deposit.
pub const DEPOSIT_PHASES: usize = 1024;

/// One row of the deposit table, on its own 32-byte half cache line.
#[derive(Debug, Clone, Copy)]
#[repr(align(32))]
struct DepositRow([f32; DEPOSIT_TAPS]);

/// The deposit kernel tabulated at [`DEPOSIT_PHASES`] + 1 fractional delays. Rows are handed
/// out paired (`w0 w0 w1 w1 …`): a complex sample's re and im take the same weight, so a
/// deposit into interleaved complex samples is one straight f32 multiply-add over
/// `2·DEPOSIT_TAPS` lanes, which the compiler vectorises.
#[derive(Debug, Clone)]
pub struct DepositKernel {
    rows: Vec<DepositRow>,
}

impl Default for DepositKernel {
    fn default() -> Self {
        Self::new()
    }
}

impl DepositKernel {
    /// Build the table (≈ 32 KiB).
    pub fn new() -> Self {
        let rows = (0..=DEPOSIT_PHASES)
            .map(|p| {
                let f = p as f64 / DEPOSIT_PHASES as f64;
                DepositRow(std::array::from_fn(|j| {
                    kaiser_sinc(
                        j as f64 - DEPOSIT_LEAD as f64 - f,
                        DEPOSIT_TAPS,
                        DEPOSIT_BETA,
                    ) as f32
                }))
            })
            .collect();
        Self { rows }
    }

    /// Where a value at fractional sample position `v` sits relative to sample 0:
    /// `(⌊v⌋, table row)`, the row nearest `(v − ⌊v⌋)·DEPOSIT_PHASES` (0 ..= DEPOSIT_PHASES),
    /// so that `value(v) ≈ Σ_j w[2j]·x[⌊v⌋ − DEPOSIT_LEAD + j]` with `w` from
    /// [`Self::weights`]. `v` is clamped to ±2²¹ first (a NaN to −2²¹, far outside any echo
    /// window, where the caller counts it). Branch-free, so that a loop over many `v`
    /// vectorises; the fraction and its scaling by a power of two round nothing.
    #[inline(always)]
    pub fn position(v: f32) -> (i32, u32) {
        const LIMIT: f32 = 2_097_152.0;
        #[allow(clippy::manual_clamp, reason = "clamp keeps a NaN")]
        let v = v.max(-LIMIT).min(LIMIT);
        let (vf, vi) = floor_fast_f32(v);
        let g = (v - vf) * DEPOSIT_PHASES as f32;
        let (_, gi) = floor_fast_f32(g + 0.5);
        (vi, gi as u32)
    }

    /// Paired weights of a table row from [`Self::position`] (rows past the end are clamped).
    #[inline(always)]
    pub fn weights(&self, row: usize) -> [f32; 2 * DEPOSIT_TAPS] {
        let r = &self.rows[row.min(DEPOSIT_PHASES)].0;
        std::array::from_fn(|q| r[q / 2])
    }
}

impl SincKernel {
    /// Build the table (≈ 33 KiB).
    pub fn new() -> Self {
        let table = (0..=KERNEL_PHASES)
            .map(|p| {
                let f = p as f64 / KERNEL_PHASES as f64;
                let mut row = [0.0_f32; KERNEL_TAPS];
                for (j, w) in row.iter_mut().enumerate() {
                    *w = kernel_value(j as f64 - LEAD as f64 - f) as f32;
                }
                row
            })
            .collect();
        Self { table }
    }

    /// Weights for a value at fractional sample position `u`: `value(u) ≈ Σ_j w[j]·x[first + j]`.
    /// Returns `first` (may be negative or past the end: callers check bounds).
    #[inline(always)]
    pub fn weights(&self, u: f64) -> (i64, [f32; KERNEL_TAPS]) {
        // Truncation is floor for u ≥ 0 (the hot path) and avoids a libm call on baseline x86.
        let k0 = if u >= 0.0 {
            (u as i64) as f64
        } else {
            u.floor()
        };
        let pf = (u - k0) * KERNEL_PHASES as f64;
        let p = (pf as usize).min(KERNEL_PHASES - 1);
        let a = (pf - p as f64) as f32;
        let (r0, r1) = (&self.table[p], &self.table[p + 1]);
        let mut w = [0.0_f32; KERNEL_TAPS];
        for j in 0..KERNEL_TAPS {
            w[j] = r0[j] + a * (r1[j] - r0[j]);
        }
        (k0 as i64 - LEAD, w)
    }
}

/// 1.5·2⁵²: for `|x| < 2⁵¹`, `x + MAGIC` has a unit last place, so the FPU rounds `x` to an
/// integer in the default mode and that integer sits in the low mantissa bits (two's
/// complement), readable without a float-to-int conversion.
const MAGIC: f64 = 6_755_399_441_055_744.0;

/// `floor(x)` for `|x| < 2⁵¹`, as a float and as an integer, with no libm call, branch or
/// saturating conversion, so loops over arrays of it vectorise.
#[inline(always)]
pub fn floor_fast(x: f64) -> (f64, i64) {
    let shifted = x + MAGIC;
    let n = shifted - MAGIC;
    // Rounded up: step down one (a select, not a branch).
    let up = n > x;
    let f = if up { n - 1.0 } else { n };
    let i = (shifted.to_bits() as i64).wrapping_sub(MAGIC.to_bits() as i64) - i64::from(up);
    (f, i)
}

/// 1.5·2²³, the f32 counterpart of [`MAGIC`] (for `|x| < 2²²`).
const MAGIC_F32: f32 = 12_582_912.0;

/// `floor(x)` for `|x| < 2²²` in f32, as a float and as an integer, branch-free like
/// [`floor_fast`].
#[inline(always)]
pub fn floor_fast_f32(x: f32) -> (f32, i32) {
    let shifted = x + MAGIC_F32;
    let n = shifted - MAGIC_F32;
    let up = n > x;
    let f = if up { n - 1.0 } else { n };
    let i = (shifted.to_bits() as i32).wrapping_sub(MAGIC_F32.to_bits() as i32) - i32::from(up);
    (f, i)
}

/// `(cos 2πt, sin 2πt)` in f32 for a phase `t` in turns, `|t| < 2²⁰`: the quadrant
/// reduction (exact in f32) and Taylor polynomials on `[−π/4, π/4]` (error < 4·10⁻⁷, tested
/// against libm). The echo deposit passes its carrier's turns relative to a whole number of
/// turns taken in f64 per scatterer, so the few tens of turns left fit f32. No libm call and
/// no branch: it runs in a vectorised loop.
#[inline(always)]
pub fn cos_sin_turns_f32(t: f32) -> (f32, f32) {
    let x4 = 4.0 * t;
    let shifted = x4 + MAGIC_F32;
    let q = shifted - MAGIC_F32;
    let r = (x4 - q) * std::f32::consts::FRAC_PI_2;
    let r2 = r * r;
    let s = r * (1.0 + r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0))));
    let c = 1.0 + r2 * (-0.5 + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0))));
    // Quadrant q mod 4 from the mantissa bits: 0 → (c, s), 1 → (−s, c), 2 → (−c, −s),
    // 3 → (s, −c). Selected and negated with bit operations: the quadrant is random from one
    // facet to the next, and a branch on it mispredicts three times in four.
    let qb = shifted.to_bits();
    let swap = (qb & 1).wrapping_neg();
    let (cb, sb) = (c.to_bits(), s.to_bits());
    let cos_b = (cb & !swap) | (sb & swap);
    let sin_b = (sb & !swap) | (cb & swap);
    let neg_cos = (qb.wrapping_add(1) & 2) << 30;
    let neg_sin = (qb & 2) << 30;
    (
        f32::from_bits(cos_b ^ neg_cos),
        f32::from_bits(sin_b ^ neg_sin),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Worst error over fractional delays of a complex tone at `f` cycles/sample rebuilt
    /// from its samples with `weights` (first tap, weight of tap j).
    fn tone_error(f: f64, weights: impl Fn(f64) -> (i64, Vec<f32>)) -> f64 {
        let x: Vec<(f64, f64)> = (0..96)
            .map(|n| {
                let ph = 2.0 * std::f64::consts::PI * f * n as f64;
                (ph.cos(), ph.sin())
            })
            .collect();
        let mut worst = 0.0_f64;
        for step in 0..64 {
            let u = 40.0 + step as f64 / 64.0 + 0.003;
            let (first, w) = weights(u);
            let (mut re, mut im) = (0.0, 0.0);
            for (j, &wj) in w.iter().enumerate() {
                let s = x[(first + j as i64) as usize];
                re += f64::from(wj) * s.0;
                im += f64::from(wj) * s.1;
            }
            let ph = 2.0 * std::f64::consts::PI * f * u;
            worst = worst.max(((re - ph.cos()).powi(2) + (im - ph.sin()).powi(2)).sqrt());
        }
        worst
    }

    #[test]
    fn deposit_kernel_is_exact_to_minus_52_db_across_the_chirp_band() {
        let k = DepositKernel::new();
        for i in 0..=10 {
            let f = 0.025 * i as f64; // 0 … fs/4
            let e = tone_error(f, |u| {
                let (first, row) = DepositKernel::position(u as f32);
                let w = k.weights(row as usize);
                (
                    i64::from(first) - DEPOSIT_LEAD,
                    w.iter().step_by(2).copied().collect(),
                )
            });
            let db = 20.0 * e.log10();
            assert!(db < -52.0, "tone at {f} cycles/sample: {db:.1} dB");
        }
        // Paired: both lanes of a sample carry the same weight.
        let (_, row) = DepositKernel::position(12.345);
        let w = k.weights(row as usize);
        assert!(w.chunks_exact(2).all(|p| p[0].to_bits() == p[1].to_bits()));
        // The branch-free table position is the plain one: ⌊v⌋ and the nearest row of the
        // fractional part, ⌊g + ½⌋ in f32 (a fraction rounding up to the next whole sample
        // takes the last row, which is the next sample's row 0 shifted by one).
        for i in 0..4000 {
            let v = -3.0 + i as f32 * 0.618_034 + 1e-4 * (i % 7) as f32;
            let k0 = v.floor();
            let row = ((v - k0) * DEPOSIT_PHASES as f32 + 0.5).floor() as u32;
            assert_eq!(DepositKernel::position(v), (k0 as i32, row), "v = {v}");
        }
        assert!(DepositKernel::position(f32::NAN).0 <= -2_000_000);
        // The last row (a whole sample of delay) is row 0 shifted by one tap.
        let (first, last) = (k.weights(0), k.weights(DEPOSIT_PHASES));
        for j in 1..DEPOSIT_TAPS {
            assert!((last[2 * j] - first[2 * j - 2]).abs() < 1e-6, "tap {j}");
        }
    }

    #[test]
    fn f32_carrier_matches_libm() {
        let mut worst = 0.0f64;
        for i in 0..200_000u64 {
            let t = ((i as f64) * 4.656_612_873e-3 + if i % 2 == 0 { 1.3e2 } else { -3.1 }) as f32;
            let (c, s) = cos_sin_turns_f32(t);
            let t = f64::from(t);
            let frac = t - t.floor();
            let (s0, c0) = (2.0 * std::f64::consts::PI * frac).sin_cos();
            worst = worst
                .max((f64::from(c) - c0).abs())
                .max((f64::from(s) - s0).abs());
        }
        assert!(worst < 4e-7, "{worst}");
    }

    #[test]
    fn floor_fast_is_floor() {
        for &x in &[
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e9 + 0.25,
            -1e9 - 0.75,
            3.0,
        ] {
            let (f, i) = floor_fast(x);
            assert_eq!(f, x.floor(), "{x}");
            assert_eq!(i, x.floor() as i64, "{x}");
        }
        for i in 0..100_000 {
            let x = (i as f32 - 50_000.0) * 0.173_21 + 1e-3 * (i % 3) as f32;
            let (f, n) = floor_fast_f32(x);
            assert_eq!(f, x.floor(), "{x}");
            assert_eq!(n, x.floor() as i32, "{x}");
        }
    }

    #[test]
    fn interpolates_a_band_limited_tone() {
        // A complex tone at 0.2 cycles/sample (inside the fs/4 band) shifted by arbitrary
        // fractions must be reproduced to better than −70 dB.
        let k = SincKernel::new();
        let f = 0.2;
        let x: Vec<(f64, f64)> = (0..64)
            .map(|n| {
                let ph = 2.0 * std::f64::consts::PI * f * n as f64;
                (ph.cos(), ph.sin())
            })
            .collect();
        for &u in &[30.0, 30.123, 30.5, 30.999, 31.77] {
            let (first, w) = k.weights(u);
            let (mut re, mut im) = (0.0, 0.0);
            for j in 0..KERNEL_TAPS {
                let s = x[(first + j as i64) as usize];
                re += f64::from(w[j]) * s.0;
                im += f64::from(w[j]) * s.1;
            }
            let ph = 2.0 * std::f64::consts::PI * f * u;
            let err = ((re - ph.cos()).powi(2) + (im - ph.sin()).powi(2)).sqrt();
            assert!(err < 3e-4, "u = {u}: error {err}");
        }
    }
}
