//! Resampling a DEM to another pixel size (the paper interpolates LOLA's 10 m grid to 5 m).
//!
//! The output grid keeps the input's upper-left corner and covers as much of its extent as a
//! whole number of new pixels does. Output pixel centres are mapped into input pixel-centre
//! coordinates and interpolated. Beyond the outermost input centres (half a pixel of the extent)
//! the grid is extended with Keys' (1981) boundary rule `f(-1) = 3f(0) − 3f(1) + f(2)`, which keeps
//! planes and quadratics exact up to the edge instead of flattening them as edge clamping would.

use rayon::prelude::*;

use super::{Dem, DemError};

/// Interpolation kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
pub enum Interpolation {
    /// Bilinear (2×2 taps): exact for planes.
    Bilinear,
    /// Keys cubic convolution, a = −0.5 (4×4 taps): exact for planes and quadratics.
    Bicubic,
}

/// Padding on each side of the extended grid, in pixels.
const PAD: usize = 2;

/// Resample `dem` to square pixels of `pixel_m` metres. A tap on a nodata sample gives nodata.
pub fn resample_to_pixel(dem: &Dem, pixel_m: f64, method: Interpolation) -> Result<Dem, DemError> {
    let old_px = dem.pixel_m()?;
    if !(pixel_m.is_finite() && pixel_m > 0.0) {
        return Err(DemError::Invalid(format!(
            "pixel size {pixel_m} m must be > 0"
        )));
    }
    let (w, h) = (dem.width(), dem.height());
    if w < 3 || h < 3 {
        return Err(DemError::Invalid(format!(
            "resampling needs at least 3x3 pixels, the DEM has {w}x{h}"
        )));
    }
    let ratio = pixel_m / old_px;
    // A tiny tolerance keeps exact multiples (4000 m / 5 m) from losing their last pixel.
    let nw = ((w as f64 / ratio) + 1e-9).floor() as usize;
    let nh = ((h as f64 / ratio) + 1e-9).floor() as usize;
    if nw == 0 || nh == 0 || nw > 65_535 || nh > 65_535 {
        return Err(DemError::Invalid(format!(
            "resampling {w}x{h} at {old_px} m to {pixel_m} m gives a {nw}x{nh} grid"
        )));
    }
    let padded = Padded::new(dem);
    let taps_x: Vec<Taps> = (0..nw).map(|i| taps(i, ratio, method)).collect();
    let taps_y: Vec<Taps> = (0..nh).map(|i| taps(i, ratio, method)).collect();
    let mut out = vec![0.0f32; nw * nh];
    out.par_chunks_mut(nw)
        .zip(taps_y.par_iter())
        .for_each(|(row, ty)| {
            for (o, tx) in row.iter_mut().zip(&taps_x) {
                *o = padded.interpolate(tx, ty);
            }
        });
    let mut geo = dem.geo.clone();
    geo.transform.0[1] = pixel_m;
    geo.transform.0[5] = -pixel_m;
    let mut res = Dem::new(nw, nh, out, geo)?;
    res.nodata = dem.nodata;
    res.sample = dem.sample;
    Ok(res)
}

/// Up to four taps: first padded index and weights.
#[derive(Debug, Clone, Copy)]
struct Taps {
    first: usize,
    w: [f64; 4],
    n: usize,
}

fn taps(i: usize, ratio: f64, method: Interpolation) -> Taps {
    // Centre of output pixel i in input pixel-centre coordinates, then shifted into the padding.
    let u = (i as f64 + 0.5) * ratio - 0.5 + PAD as f64;
    let base = u.floor();
    let t = u - base;
    let b = base as usize;
    match method {
        Interpolation::Bilinear => Taps {
            first: b,
            w: [1.0 - t, t, 0.0, 0.0],
            n: 2,
        },
        Interpolation::Bicubic => Taps {
            first: b - 1,
            w: [keys(1.0 + t), keys(t), keys(1.0 - t), keys(2.0 - t)],
            n: 4,
        },
    }
}

/// Keys' cubic convolution kernel with a = −0.5.
fn keys(s: f64) -> f64 {
    let s = s.abs();
    if s <= 1.0 {
        (1.5 * s - 2.5) * s * s + 1.0
    } else if s < 2.0 {
        ((-0.5 * s + 2.5) * s - 4.0) * s + 2.0
    } else {
        0.0
    }
}

/// The DEM extended by [`PAD`] pixels on each side (f64, Keys boundary rule).
struct Padded {
    w: usize,
    z: Vec<f64>,
}

impl Padded {
    fn new(dem: &Dem) -> Self {
        let (w0, h0) = (dem.width(), dem.height());
        let (w, h) = (w0 + 2 * PAD, h0 + 2 * PAD);
        let mut z = vec![0.0f64; w * h];
        for r in 0..h0 {
            for c in 0..w0 {
                z[(r + PAD) * w + c + PAD] = f64::from(dem.heights_m()[r * w0 + c]);
            }
        }
        // Extend rows, then columns (the corners come out of the second pass).
        for r in PAD..PAD + h0 {
            let row = &mut z[r * w..(r + 1) * w];
            extend(row, 1, PAD, w0);
        }
        for c in 0..w {
            let mut col: Vec<f64> = (0..h).map(|r| z[r * w + c]).collect();
            extend(&mut col, 1, PAD, h0);
            for (r, v) in col.into_iter().enumerate() {
                z[r * w + c] = v;
            }
        }
        Self { w, z }
    }

    fn interpolate(&self, tx: &Taps, ty: &Taps) -> f32 {
        let mut acc = 0.0;
        for j in 0..ty.n {
            let wy = ty.w[j];
            if wy == 0.0 {
                continue;
            }
            let row = (ty.first + j) * self.w;
            for i in 0..tx.n {
                let wx = tx.w[i];
                if wx == 0.0 {
                    continue;
                }
                let v = self.z.get(row + tx.first + i).copied().unwrap_or(f64::NAN);
                acc += wx * wy * v;
            }
        }
        acc as f32
    }
}

/// Fill `PAD` samples on both ends of `v` (whose data are `v[PAD..PAD + n]`).
fn extend(v: &mut [f64], stride: usize, pad: usize, n: usize) {
    let at = |k: usize| k * stride;
    for k in (0..pad).rev() {
        v[at(k)] = 3.0 * v[at(k + 1)] - 3.0 * v[at(k + 2)] + v[at(k + 3)];
    }
    let end = pad + n;
    for k in end..end + pad {
        v[at(k)] = 3.0 * v[at(k - 1)] - 3.0 * v[at(k - 2)] + v[at(k - 3)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dem::GeoRef;

    fn field(w: usize, h: usize, px: f64, f: impl Fn(f64, f64) -> f64) -> Dem {
        let geo = GeoRef::local(100.0, 900.0, px, "t");
        let mut z = Vec::new();
        for r in 0..h {
            for c in 0..w {
                z.push(f((c as f64 + 0.5) * px, (r as f64 + 0.5) * px) as f32);
            }
        }
        Dem::new(w, h, z, geo).unwrap()
    }

    #[test]
    fn planes_are_reproduced_by_both_kernels() {
        let plane = |x: f64, y: f64| 50.0 + 0.3 * x - 0.7 * y;
        let d = field(40, 30, 10.0, plane);
        for m in [Interpolation::Bilinear, Interpolation::Bicubic] {
            for px in [5.0, 3.0, 20.0, 7.5] {
                let r = resample_to_pixel(&d, px, m).unwrap();
                assert_eq!(r.origin_m(), d.origin_m());
                for row in 0..r.height() {
                    for col in 0..r.width() {
                        let want = plane((col as f64 + 0.5) * px, (row as f64 + 0.5) * px);
                        let got = f64::from(r.get(col, row).unwrap());
                        assert!((got - want).abs() < 1e-3, "{m:?} {px}: {got} vs {want}");
                    }
                }
            }
        }
    }

    #[test]
    fn bicubic_reproduces_quadratics_and_keeps_samples() {
        let quad = |x: f64, y: f64| 0.01 * x * x - 0.02 * x * y + 0.005 * y * y + x;
        let d = field(30, 30, 10.0, quad);
        let r = resample_to_pixel(&d, 5.0, Interpolation::Bicubic).unwrap();
        assert_eq!((r.width(), r.height()), (60, 60));
        for row in 0..60 {
            for col in 0..60 {
                let want = quad((col as f64 + 0.5) * 5.0, (row as f64 + 0.5) * 5.0);
                let got = f64::from(r.get(col, row).unwrap());
                assert!((got - want).abs() < 2e-3, "{got} vs {want}");
            }
        }
        // Same pixel size: identity.
        let same = resample_to_pixel(&d, 10.0, Interpolation::Bicubic).unwrap();
        for (a, b) in same.heights_m().iter().zip(d.heights_m()) {
            assert!((a - b).abs() < 1e-4);
        }
    }

    #[test]
    fn nodata_propagates_and_bad_sizes_fail() {
        let mut d = field(10, 10, 10.0, |x, _| x);
        d.heights_m_mut()[55] = f32::NAN;
        let r = resample_to_pixel(&d, 5.0, Interpolation::Bilinear).unwrap();
        assert!(r.nodata_count() > 0 && r.nodata_count() < 20);
        assert!(resample_to_pixel(&d, 0.0, Interpolation::Bilinear).is_err());
        assert!(resample_to_pixel(&d, f64::NAN, Interpolation::Bilinear).is_err());
    }
}
