//! Fractal (self-affine) roughness by spectral synthesis.
//!
//! A Gaussian random field whose power spectrum falls as `(k² + k0²)^-(H+1)` (the 2-D spectrum of
//! a self-affine surface with Hurst exponent H, rolled off below the wavenumber `k0 = 1/λ0` so
//! that long wavelengths do not tilt a 4 km window by hundreds of metres). White complex Gaussian
//! coefficients are shaped by that amplitude and inverse-transformed (rustfft); the real part is
//! the field (Saupe 1988, "Algorithms for random fractals"). The field is then scaled so that its
//! RMS height difference at one pixel equals `ν(L) = ν0 (L / 5 m)^H` — the RMS deviation model of
//! Rosenburg et al. (2011, JGR 116, E02001) for LOLA topography.
//!
//! Determinism: the coefficients are drawn sequentially from a seeded PCG stream; each FFT row is
//! an independent computation, so the result does not depend on the number of threads.

use rand::SeedableRng;
use rayon::prelude::*;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;

use super::sfd::std_normal;

/// Largest FFT side in pixels; bigger grids tile the (periodic) field. 4096² complex f64 is 256 MiB.
pub const MAX_FFT_SIDE: usize = 4096;

/// Roughness parameters.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct Roughness {
    /// Hurst exponent H (0 < H < 1); lunar highlands ≈ 0.9–0.95 at metre-to-km baselines.
    pub hurst: f64,
    /// RMS height difference at a 5 m baseline, metres.
    pub nu5_m: f64,
    /// Roll-off wavelength λ0 in metres (spectrum flattens above it).
    pub rolloff_m: f64,
}

/// A `w × h` roughness field (metres, zero mean) for pixels of `pixel_m` metres.
pub fn fractal_field(w: usize, h: usize, pixel_m: f64, r: &Roughness, seed: u64) -> Vec<f32> {
    let side = w.max(h).next_power_of_two().clamp(8, MAX_FFT_SIDE);
    let n = side;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let k0 = 1.0 / r.rolloff_m.max(pixel_m);
    let df = 1.0 / (n as f64 * pixel_m); // cycles per metre per frequency index
    let freq = |i: usize| -> f64 {
        let i = i as f64;
        if i < n as f64 / 2.0 {
            i * df
        } else {
            (i - n as f64) * df
        }
    };
    let expo = -(r.hurst + 1.0) / 2.0;
    let mut spec: Vec<Complex64> = Vec::with_capacity(n * n);
    for ky in 0..n {
        let fy = freq(ky);
        for kx in 0..n {
            let fx = freq(kx);
            let k2 = fx * fx + fy * fy;
            let a = if kx == 0 && ky == 0 {
                0.0
            } else {
                (k2 + k0 * k0).powf(expo)
            };
            let re = std_normal(&mut rng);
            let im = std_normal(&mut rng);
            spec.push(Complex64::new(re * a, im * a));
        }
    }
    let mut planner = FftPlanner::<f64>::new();
    let fft = planner.plan_fft_inverse(n);
    let fft_rows = |buf: &mut [Complex64]| {
        buf.par_chunks_mut(n).for_each(|row| fft.process(row));
    };
    fft_rows(&mut spec);
    let mut t = transpose(&spec, n);
    fft_rows(&mut t);
    // `t` is transposed: element (x, y) of the field sits at t[x·n + y].
    let mut out = vec![0.0f32; w * h];
    for (row, o) in out.chunks_mut(w).enumerate() {
        for (col, v) in o.iter_mut().enumerate() {
            *v = t[(col % n) * n + (row % n)].re as f32;
        }
    }
    // Scale to the target RMS height difference at one pixel.
    let target = r.nu5_m * (pixel_m / 5.0).powf(r.hurst);
    let nu = rms_lag1(&out, w, h);
    let s = if nu > 0.0 { (target / nu) as f32 } else { 0.0 };
    let mean = out.iter().map(|&v| f64::from(v)).sum::<f64>() / out.len() as f64;
    for v in &mut out {
        *v = (*v - mean as f32) * s;
    }
    out
}

fn transpose(a: &[Complex64], n: usize) -> Vec<Complex64> {
    let mut t = vec![Complex64::new(0.0, 0.0); n * n];
    t.par_chunks_mut(n).enumerate().for_each(|(x, col)| {
        for (y, v) in col.iter_mut().enumerate() {
            *v = a[y * n + x];
        }
    });
    t
}

/// RMS of height differences between horizontal and vertical neighbours.
pub fn rms_lag1(z: &[f32], w: usize, h: usize) -> f64 {
    let mut acc = 0.0f64;
    let mut cnt = 0usize;
    for r in 0..h {
        for c in 0..w {
            let v = f64::from(z[r * w + c]);
            if c + 1 < w {
                let d = f64::from(z[r * w + c + 1]) - v;
                if d.is_finite() {
                    acc += d * d;
                    cnt += 1;
                }
            }
            if r + 1 < h {
                let d = f64::from(z[(r + 1) * w + c]) - v;
                if d.is_finite() {
                    acc += d * d;
                    cnt += 1;
                }
            }
        }
    }
    if cnt == 0 {
        0.0
    } else {
        (acc / cnt as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_has_requested_roughness_and_scaling() {
        let r = Roughness {
            hurst: 0.9,
            nu5_m: 0.4,
            rolloff_m: 1e6,
        };
        let z = fractal_field(256, 256, 5.0, &r, 3);
        assert!((rms_lag1(&z, 256, 256) - 0.4).abs() < 1e-3);
        // RMS deviation at 8 px should be about 8^H times the 1 px value.
        let mut acc = 0.0;
        let mut n = 0;
        for row in 0..256 {
            for c in 0..248 {
                let d = f64::from(z[row * 256 + c + 8] - z[row * 256 + c]);
                acc += d * d;
                n += 1;
            }
        }
        let ratio = (acc / n as f64).sqrt() / 0.4;
        assert!((4.0..9.0).contains(&ratio), "nu(8)/nu(1) = {ratio}");
        assert_eq!(z, fractal_field(256, 256, 5.0, &r, 3));
        assert_ne!(z, fractal_field(256, 256, 5.0, &r, 4));
    }
}
