//! Power spectra of gridded fields: a 2-D FFT and the periodogram summed over octave rings of
//! spatial frequency. The rehearsal's error model (`evaluation::rehearsal`) draws with these
//! spectra, and the two-look fusion (`insar::pipeline::fuse_looks`) measures the map's error
//! spectrum with them.

use rayon::prelude::*;
use rustfft::num_complex::Complex64;

/// In-place 2-D FFT of a row-major `w × h` grid (the inverse unnormalised, as rustfft's).
pub fn fft2(data: &mut [Complex64], w: usize, h: usize, inverse: bool) {
    let mut planner = rustfft::FftPlanner::<f64>::new();
    let (row, col) = if inverse {
        (planner.plan_fft_inverse(w), planner.plan_fft_inverse(h))
    } else {
        (planner.plan_fft_forward(w), planner.plan_fft_forward(h))
    };
    data.par_chunks_mut(w).for_each(|r| row.process(r));
    let mut t = vec![Complex64::new(0.0, 0.0); w * h];
    t.par_chunks_mut(h).enumerate().for_each(|(x, c)| {
        for (y, v) in c.iter_mut().enumerate() {
            *v = data[y * w + x];
        }
    });
    t.par_chunks_mut(h).for_each(|c| col.process(c));
    data.par_chunks_mut(w).enumerate().for_each(|(y, r)| {
        for (x, v) in r.iter_mut().enumerate() {
            *v = t[x * h + y];
        }
    });
}

/// Spatial frequency of coefficient `i` of a `w × h` FFT grid, cycles per pixel (0 to √0.5).
pub fn frequency(i: usize, w: usize, h: usize) -> f64 {
    let freq = |k: usize, len: usize| -> f64 {
        let (k, len) = (k as f64, len as f64);
        if k < len / 2.0 {
            k / len
        } else {
            (k - len) / len
        }
    };
    freq(i % w, w).hypot(freq(i / w, h))
}

/// Lower edges of the octave bands [`band_powers`] sums over, cycles per pixel: below 1/32
/// (wavelengths over 32 cells), then one octave each up to 1/2 and beyond (the grid's
/// corners). On a 20 m map the bands are > 640 m, 320–640, 160–320, 80–160, 40–80 and
/// < 40 m: the second to fifth hold the scales of a tile's features.
pub const BAND_EDGES: [f64; 6] = [0.0, 1.0 / 32.0, 1.0 / 16.0, 1.0 / 8.0, 1.0 / 4.0, 1.0 / 2.0];

/// The octave band of [`BAND_EDGES`] a frequency (cycles per pixel) falls in.
pub fn band_of(f: f64) -> usize {
    BAND_EDGES.iter().rposition(|&e| f >= e).unwrap_or(0)
}

/// Periodogram of the real `w × h` field `z` summed over each octave band of
/// [`BAND_EDGES`] (the DC term left out), per cell of the grid: over all bands it sums to the
/// field's mean square less its squared mean. Non-finite cells count as 0.
pub fn band_powers(z: &[f64], w: usize, h: usize) -> [f64; BAND_EDGES.len()] {
    let n = w * h;
    let mut c: Vec<Complex64> = z
        .iter()
        .map(|&v| Complex64::new(if v.is_finite() { v } else { 0.0 }, 0.0))
        .collect();
    let mut out = [0.0; BAND_EDGES.len()];
    if n == 0 || c.len() != n {
        return out;
    }
    fft2(&mut c, w, h, false);
    let norm = (n as f64).powi(2);
    for (i, v) in c.iter().enumerate().skip(1) {
        out[band_of(frequency(i, w, h))] += v.norm_sqr() / norm;
    }
    out
}

/// Coefficients of a `w × h` FFT grid in each octave band of [`BAND_EDGES`] (the DC term left
/// out).
pub fn band_counts(w: usize, h: usize) -> [usize; BAND_EDGES.len()] {
    let mut out = [0; BAND_EDGES.len()];
    for i in 1..w * h {
        out[band_of(frequency(i, w, h))] += 1;
    }
    out
}

/// Draw a standard normal variate (Box–Muller; one per call keeps the stream simple).
pub(crate) fn normal(rng: &mut impl rand::RngExt) -> f64 {
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A `w × h` field of Gaussian noise with unit variance whose power spectrum is that of white
/// noise blurred by a Gaussian of σ `blur_px` pixels, `exp(−(2π·blur·f)²)` (periodic across the
/// grid's edges); white for `blur_px` 0. Reproducible from `seed`.
pub fn correlated_noise(w: usize, h: usize, blur_px: f64, seed: u64) -> Vec<f64> {
    use rand::SeedableRng;
    let n = w * h;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut c: Vec<Complex64> = (0..n)
        .map(|_| Complex64::new(normal(&mut rng), 0.0))
        .collect();
    if n == 0 {
        return Vec::new();
    }
    fft2(&mut c, w, h, false);
    for (i, v) in c.iter_mut().enumerate() {
        let a = std::f64::consts::TAU * blur_px.max(0.0) * frequency(i, w, h);
        *v *= (-0.5 * a * a).exp();
    }
    fft2(&mut c, w, h, true);
    let out: Vec<f64> = c.iter().map(|v| v.re).collect();
    let sd = (out.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    if sd > 0.0 {
        out.into_iter().map(|v| v / sd).collect()
    } else {
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_powers_sum_to_the_variance_and_find_a_wave_in_its_octave() {
        let (w, h) = (64, 48);
        // A wave of 8 cells along x (1/8 cycle per pixel: the fourth band) plus a constant.
        let z: Vec<f64> = (0..w * h)
            .map(|i| 3.0 + 2.0 * (std::f64::consts::TAU * (i % w) as f64 / 8.0).sin())
            .collect();
        let p = band_powers(&z, w, h);
        let total: f64 = p.iter().sum();
        // A sine of amplitude 2 has variance 2.
        assert!((total - 2.0).abs() < 1e-9, "{p:?}");
        assert!((p[3] - 2.0).abs() < 1e-9, "{p:?}");
        assert_eq!(band_of(0.0), 0);
        assert_eq!(band_of(0.03), 0);
        assert_eq!(band_of(1.0 / 32.0), 1);
        assert_eq!(band_of(0.7), 5);
        // Every coefficient but DC in one band; the coarsest of a 200² grid holds ≈ π·6.25².
        let c = band_counts(200, 200);
        assert_eq!(c.iter().sum::<usize>(), 200 * 200 - 1);
        assert!((100..140).contains(&c[0]), "{c:?}");
    }

    #[test]
    fn correlated_noise_has_unit_variance_and_the_blurs_correlation() {
        let (w, h) = (128, 128);
        let u = correlated_noise(w, h, 1.12, 7);
        let var = u.iter().map(|v| v * v).sum::<f64>() / u.len() as f64;
        assert!((var - 1.0).abs() < 1e-9);
        // Neighbour correlation of Gaussian-blurred white noise: exp(−1/(4σ²)) = 0.82.
        let lag: f64 = (0..h)
            .flat_map(|r| (0..w - 1).map(move |c| (r, c)))
            .map(|(r, c)| u[r * w + c] * u[r * w + c + 1])
            .sum::<f64>()
            / (h * (w - 1)) as f64;
        assert!((lag - 0.819).abs() < 0.03, "{lag}");
        assert_eq!(correlated_noise(w, h, 1.12, 7), u);
        // White: the power spread over the bands by their area (band 4 holds 59 % of the
        // square of frequencies, the corners beyond 1/2 cycle 21 %, band 0 0.3 %).
        let white = correlated_noise(w, h, 0.0, 3);
        let p = band_powers(&white, w, h);
        assert!(
            (p[4] - 0.589).abs() < 0.03 && (p[5] - 0.215).abs() < 0.02,
            "{p:?}"
        );
        assert!(p[0] < 0.01, "{p:?}");
    }
}
