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
    let (w, h) = (dem.width(), dem.height());
    let n = w * h;
    let capacity = out.len();
    let out = out.get_mut(..n).ok_or(FrameError::TooLarge {
        needed: n,
        capacity,
    })?;
    let inv8 = 1.0 / (8.0 * dem.pixel_m());
    for row in 0..h {
        for col in 0..w {
            let v = if row == 0 || col == 0 || row + 1 >= h || col + 1 >= w {
                SLOPE_NODATA
            } else {
                horn(dem, col, row, inv8).map_or(SLOPE_NODATA, slope_from_deg)
            };
            if let Some(o) = out.get_mut(row * w + col) {
                *o = v;
            }
        }
    }
    SlopeImage::new_checked(out, w, h, dem.pixel_m())
}

/// Horn slope in degrees at an interior pixel; `None` if any of the 9 heights is masked.
#[inline]
fn horn(dem: &DemPatch<'_>, col: usize, row: usize, inv8: f32) -> Option<f32> {
    let z = |dc: usize, dr: usize| dem.height_at(col + dc - 1, row + dr - 1);
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
