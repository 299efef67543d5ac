//! Onboard slope from a DEM patch: Horn's 3×3 gradient, in degrees.
//!
//! The same function serves the ground segment (reference tile) and the flight segment
//! (real-time frames), so both sides quantise slope identically.

use crate::frame::{DemPatch, FrameError, SLOPE_NODATA, SlopeImage, SlopePx, slope_from_deg};

/// Degrees per radian.
const DEG_PER_RAD: f32 = 180.0 / core::f32::consts::PI;

/// Compute the slope of every DEM pixel into `out[..width × height]` and return it as an image.
///
/// Horn (1981): with the 3×3 neighbourhood `a b c / d e f / g h i`,
/// `∂z/∂x = ((c + 2f + i) − (a + 2d + g)) / (8·pixel)`,
/// `∂z/∂y = ((g + 2h + i) − (a + 2b + c)) / (8·pixel)`, slope = atan(|∇z|).
/// Border pixels and pixels with any masked (nodata or non-finite) neighbour are
/// [`SLOPE_NODATA`], so missing heights can never create slope edges.
///
/// Errors: `out` shorter than the frame gives [`FrameError::TooLarge`].
pub fn slope_into<'b>(
    dem: &DemPatch<'_>,
    out: &'b mut [SlopePx],
) -> Result<SlopeImage<'b>, FrameError> {
    slope_into_with(dem, out, false)
}

/// Fewest valid neighbours (of 8) for a missing height to be filled by their mean.
pub const FILL_MIN_NEIGHBOURS: usize = 5;

/// [`slope_into`], optionally filling isolated dropouts first: a missing height with at least
/// [`FILL_MIN_NEIGHBOURS`] valid 8-neighbours takes their mean, so a sensor's scattered lost
/// returns do not blank out 3 × 3 blocks of slope (and every feature footprint that touches
/// one). Larger holes stay masked. The reference tile is built without filling.
pub fn slope_into_with<'b>(
    dem: &DemPatch<'_>,
    out: &'b mut [SlopePx],
    fill_isolated: bool,
) -> Result<SlopeImage<'b>, FrameError> {
    let (w, h) = (dem.width(), dem.height());
    let at = |c: usize, r: usize| dem.height_at(c, r);
    if fill_isolated {
        slope_grid(w, h, dem.pixel_m(), |c, r| filled(&at, w, h, c, r), out)
    } else {
        slope_grid(w, h, dem.pixel_m(), at, out)
    }
}

/// Largest binning factor [`slope_into_binned`] accepts.
pub const MAX_BIN: usize = 8;

/// Slope of the DEM after averaging `k × k` blocks of heights (a block with fewer than half its
/// heights valid is no data), into `out[..(w/k) × (h/k)]`; pixel size `k × pixel_m`. Lets the
/// flyer bring a frame finer than the reference to the reference's ground sample distance
/// before SURF, so both images' slopes come from the same scale of terrain, at a quarter of the
/// pixels for k = 2. Isolated missing blocks are filled as in [`slope_into_with`] when asked.
pub fn slope_into_binned<'b>(
    dem: &DemPatch<'_>,
    k: usize,
    out: &'b mut [SlopePx],
    fill_isolated: bool,
) -> Result<SlopeImage<'b>, FrameError> {
    if k == 0 || k > MAX_BIN {
        return Err(FrameError::TooLarge {
            needed: k,
            capacity: MAX_BIN,
        });
    }
    let (w, h) = (dem.width() / k, dem.height() / k);
    if w == 0 || h == 0 {
        return Err(FrameError::Empty);
    }
    let half = (k * k).div_ceil(2);
    let block = |c: usize, r: usize| {
        let (mut sum, mut n) = (0.0f32, 0usize);
        for j in 0..k {
            for i in 0..k {
                if let Some(z) = dem.height_at(c * k + i, r * k + j) {
                    sum += z;
                    n += 1;
                }
            }
        }
        (n >= half).then(|| sum / n as f32)
    };
    let pixel_m = dem.pixel_m() * k as f32;
    if fill_isolated {
        slope_grid(w, h, pixel_m, |c, r| filled(&block, w, h, c, r), out)
    } else {
        slope_grid(w, h, pixel_m, block, out)
    }
}

/// Horn's slope over a `w × h` grid of heights given by `z(col, row)` (`None` = no data).
fn slope_grid<'b>(
    w: usize,
    h: usize,
    pixel_m: f32,
    z: impl Fn(usize, usize) -> Option<f32>,
    out: &'b mut [SlopePx],
) -> Result<SlopeImage<'b>, FrameError> {
    let n = w * h;
    let capacity = out.len();
    let out = out.get_mut(..n).ok_or(FrameError::TooLarge {
        needed: n,
        capacity,
    })?;
    if !(pixel_m.is_finite() && pixel_m > 0.0) {
        return Err(FrameError::BadPixelSize);
    }
    let inv8 = 1.0 / (8.0 * pixel_m);
    for row in 0..h {
        for col in 0..w {
            let v = if row == 0 || col == 0 || row + 1 >= h || col + 1 >= w {
                SLOPE_NODATA
            } else {
                horn(&z, col, row, inv8).map_or(SLOPE_NODATA, slope_from_deg)
            };
            if let Some(o) = out.get_mut(row * w + col) {
                *o = v;
            }
        }
    }
    SlopeImage::new_checked(out, w, h, pixel_m)
}

/// Height at `(col, row)` from `z`, or the mean of its valid 8-neighbours when it is missing and
/// at least [`FILL_MIN_NEIGHBOURS`] of them are valid (in a fixed order, so deterministic).
fn filled(
    z: &impl Fn(usize, usize) -> Option<f32>,
    w: usize,
    h: usize,
    col: usize,
    row: usize,
) -> Option<f32> {
    if let Some(v) = z(col, row) {
        return Some(v);
    }
    let (mut sum, mut n) = (0.0f32, 0usize);
    for dr in 0..3usize {
        for dc in 0..3usize {
            let (c, r) = (col + dc, row + dr);
            if (dc, dr) == (1, 1) || c == 0 || r == 0 || c > w || r > h {
                continue;
            }
            if let Some(v) = z(c - 1, r - 1) {
                sum += v;
                n += 1;
            }
        }
    }
    (n >= FILL_MIN_NEIGHBOURS).then(|| sum / n as f32)
}

/// Horn slope in degrees at an interior pixel; `None` if any of the 9 heights is masked.
#[inline]
fn horn(
    z: &impl Fn(usize, usize) -> Option<f32>,
    col: usize,
    row: usize,
    inv8: f32,
) -> Option<f32> {
    let z = |dc: usize, dr: usize| z(col + dc - 1, row + dr - 1);
    let (a, b, c) = (z(0, 0)?, z(1, 0)?, z(2, 0)?);
    let (d, f) = (z(0, 1)?, z(2, 1)?);
    let (g, hh, i) = (z(0, 2)?, z(1, 2)?, z(2, 2)?);
    // Centre height is not used by Horn's operator but a masked centre must still mask the pixel.
    z(1, 1)?;
    let dzdx = ((c + 2.0 * f + i) - (a + 2.0 * d + g)) * inv8;
    let dzdy = ((g + 2.0 * hh + i) - (a + 2.0 * b + c)) * inv8;
    let grad = libm::sqrtf(dzdx * dzdx + dzdy * dzdy);
    let deg = libm::atanf(grad) * DEG_PER_RAD;
    // Overflowing gradients (huge heights) give +inf → atan = 90°, still a valid slope; NaN masks.
    Some(deg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{SLOPE_LSB_DEG, slope_is_valid, slope_to_deg};

    fn plane(w: usize, h: usize, px: f32, gx: f32, gy: f32) -> [f32; 64] {
        let mut z = [0.0f32; 64];
        for r in 0..h {
            for c in 0..w {
                z[r * w + c] = gx * c as f32 * px + gy * r as f32 * px + 100.0;
            }
        }
        z
    }

    #[test]
    fn tilted_plane_gives_its_slope() {
        let (gx, gy) = (0.3f32, -0.4f32); // |∇z| = 0.5
        let z = plane(8, 8, 10.0, gx, gy);
        let dem = DemPatch::new_checked(&z, 8, 8, 10.0).unwrap();
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into(&dem, &mut out).unwrap();
        let expect = libm::atanf(0.5) * DEG_PER_RAD;
        for r in 1..7 {
            for c in 1..7 {
                let got = slope_to_deg(img.get(c, r)).unwrap();
                assert!((got - expect).abs() <= SLOPE_LSB_DEG, "{got} vs {expect}");
            }
        }
        // Borders are masked.
        assert!(!slope_is_valid(img.get(0, 3)));
        assert!(!slope_is_valid(img.get(7, 7)));
    }

    #[test]
    fn nodata_masks_its_neighbourhood() {
        let mut z = plane(8, 8, 5.0, 0.1, 0.0);
        z[3 * 8 + 3] = f32::NAN;
        z[5 * 8 + 6] = -9999.0;
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0)
            .unwrap()
            .with_nodata(-9999.0);
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into(&dem, &mut out).unwrap();
        for r in 1..7usize {
            for c in 1..7usize {
                let near_nan = r.abs_diff(3) <= 1 && c.abs_diff(3) <= 1;
                let near_nodata = r.abs_diff(5) <= 1 && c.abs_diff(6) <= 1;
                assert_eq!(slope_is_valid(img.get(c, r)), !(near_nan || near_nodata));
            }
        }
    }

    #[test]
    fn isolated_dropouts_are_filled_when_asked() {
        let mut z = plane(8, 8, 5.0, 0.1, 0.2);
        z[3 * 8 + 3] = f32::NAN;
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into_with(&dem, &mut out, true).unwrap();
        // The plane's slope everywhere inside, the hole filled by its neighbours' mean (exact on
        // a plane).
        let expect = libm::atanf(libm::sqrtf(0.01 + 0.04)) * DEG_PER_RAD;
        for r in 1..7 {
            for c in 1..7 {
                let got = slope_to_deg(img.get(c, r)).unwrap();
                assert!(
                    (got - expect).abs() <= 2.0 * SLOPE_LSB_DEG,
                    "{got} vs {expect}"
                );
            }
        }
        // A 3 × 3 hole is too large: its centre stays masked.
        let mut z = plane(8, 8, 5.0, 0.1, 0.2);
        for r in 2..5 {
            for c in 2..5 {
                z[r * 8 + c] = f32::NAN;
            }
        }
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let img = slope_into_with(&dem, &mut out, true).unwrap();
        assert!(!slope_is_valid(img.get(3, 3)));
    }

    #[test]
    fn binning_averages_blocks_and_keeps_the_slope_of_a_plane() {
        let z = plane(8, 8, 5.0, 0.3, -0.4);
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into_binned(&dem, 2, &mut out, false).unwrap();
        assert_eq!((img.width(), img.height(), img.pixel_m()), (4, 4, 10.0));
        let expect = libm::atanf(0.5) * DEG_PER_RAD;
        for r in 1..3 {
            for c in 1..3 {
                assert!((slope_to_deg(img.get(c, r)).unwrap() - expect).abs() <= SLOPE_LSB_DEG);
            }
        }
        assert!(slope_into_binned(&dem, 0, &mut out, false).is_err());
        assert!(slope_into_binned(&dem, 9, &mut out, false).is_err());
    }

    #[test]
    fn output_too_small_is_an_error() {
        let z = [0.0f32; 64];
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let mut out = [SLOPE_NODATA; 10];
        assert!(matches!(
            slope_into(&dem, &mut out),
            Err(FrameError::TooLarge {
                needed: 64,
                capacity: 10
            })
        ));
    }
}
