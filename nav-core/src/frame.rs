//! Frame types over caller-owned buffers, validated once at construction.
//!
//! Axis convention for every image in Umbra: row-major storage, `x` is the column (increasing to
//! the right), `y` is the row (increasing downwards), and the centre of pixel `(col, row)` sits at
//! the coordinates `(x, y) = (col, row)`. So the first pixel's centre is `(0, 0)`, not `(0.5, 0.5)`.

use core::fmt;
use fixed::types::U7F9;

/// One slope pixel: unsigned fixed point with 9 fractional bits, in **degrees**.
///
/// Resolution 1/512° ≈ 0.00195°; valid values are 0..=90° (raw 0..=[`SLOPE_MAX_RAW`]). Any raw
/// value above [`SLOPE_MAX_RAW`] means "no data" ([`SLOPE_NODATA`] is the canonical one). Why fixed
/// point: box sums over an integer integral image are then exact and bit-identical on every target,
/// and cost integer adds only (see `docs/bounds.md`).
pub type SlopePx = U7F9;

/// Raw value of 90°, the largest valid slope.
pub const SLOPE_MAX_RAW: u16 = 90 * 512;

/// Canonical "no data" slope pixel (raw `0xFFFF`, which is not a valid slope).
pub const SLOPE_NODATA: SlopePx = SlopePx::from_bits(u16::MAX);

/// Degrees per raw slope unit.
pub const SLOPE_LSB_DEG: f32 = 1.0 / 512.0;

/// Largest accepted frame side, in pixels. Keypoint coordinates are `f32`; at 16384 px their
/// resolution is still 1/1024 px. The integral image is exact for any frame size (see
/// [`crate::integral`]).
pub const MAX_FRAME_SIDE: usize = 16_384;

/// Whether a slope pixel carries data.
#[inline]
pub fn slope_is_valid(px: SlopePx) -> bool {
    px.to_bits() <= SLOPE_MAX_RAW
}

/// Quantise a slope in degrees to a [`SlopePx`] (round to nearest; clamped to 0..=90°; NaN → no data).
#[inline]
pub fn slope_from_deg(deg: f32) -> SlopePx {
    if deg.is_nan() {
        return SLOPE_NODATA;
    }
    let raw = deg * 512.0 + 0.5;
    let raw = if raw <= 0.0 {
        0
    } else if raw >= SLOPE_MAX_RAW as f32 {
        SLOPE_MAX_RAW
    } else {
        raw as u16
    };
    SlopePx::from_bits(raw)
}

/// Slope in degrees of a valid pixel, or `None` for no data.
#[inline]
pub fn slope_to_deg(px: SlopePx) -> Option<f32> {
    slope_is_valid(px).then(|| px.to_bits() as f32 * SLOPE_LSB_DEG)
}

/// Why a frame was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// Width or height is zero.
    Empty,
    /// `width × height` differs from the buffer length.
    SizeMismatch {
        /// `width × height`.
        expected: usize,
        /// Buffer length given.
        got: usize,
    },
    /// A side exceeds [`MAX_FRAME_SIDE`] or a caller-given capacity.
    TooLarge {
        /// Pixels needed (or side length, for a side limit).
        needed: usize,
        /// Capacity available.
        capacity: usize,
    },
    /// Pixel size is zero, negative or not finite.
    BadPixelSize,
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Empty => write!(f, "frame has zero width or height"),
            Self::SizeMismatch { expected, got } => {
                write!(
                    f,
                    "frame buffer holds {got} pixels, width x height needs {expected}"
                )
            }
            Self::TooLarge { needed, capacity } => {
                write!(f, "frame needs {needed} but capacity is {capacity}")
            }
            Self::BadPixelSize => write!(f, "pixel size must be finite and > 0 m"),
        }
    }
}

impl core::error::Error for FrameError {}

fn check_dims(width: usize, height: usize, len: usize) -> Result<(), FrameError> {
    if width == 0 || height == 0 {
        return Err(FrameError::Empty);
    }
    let side = width.max(height);
    if side > MAX_FRAME_SIDE {
        return Err(FrameError::TooLarge {
            needed: side,
            capacity: MAX_FRAME_SIDE,
        });
    }
    // Cannot overflow: both sides are ≤ 2^14.
    let expected = width * height;
    if expected != len {
        return Err(FrameError::SizeMismatch { expected, got: len });
    }
    Ok(())
}

fn check_pixel(pixel_m: f32) -> Result<(), FrameError> {
    if pixel_m.is_finite() && pixel_m > 0.0 {
        Ok(())
    } else {
        Err(FrameError::BadPixelSize)
    }
}

/// A DEM patch: heights in metres on a square grid, borrowed from the caller.
///
/// Non-finite heights and heights equal to the optional nodata value are masked.
#[derive(Debug, Clone, Copy)]
pub struct DemPatch<'a> {
    heights_m: &'a [f32],
    width: usize,
    height: usize,
    pixel_m: f32,
    nodata_m: Option<f32>,
}

impl<'a> DemPatch<'a> {
    /// Validate a row-major height buffer of `width × height` samples, `pixel_m` metres apart.
    pub fn new_checked(
        heights_m: &'a [f32],
        width: usize,
        height: usize,
        pixel_m: f32,
    ) -> Result<Self, FrameError> {
        check_dims(width, height, heights_m.len())?;
        check_pixel(pixel_m)?;
        Ok(Self {
            heights_m,
            width,
            height,
            pixel_m,
            nodata_m: None,
        })
    }

    /// Also mask samples equal to `nodata_m` (metres), as GeoTIFF nodata values are.
    pub fn with_nodata(mut self, nodata_m: f32) -> Self {
        self.nodata_m = Some(nodata_m);
        self
    }

    /// Width in pixels (columns).
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels (rows).
    pub fn height(&self) -> usize {
        self.height
    }
    /// Ground sample distance in metres per pixel.
    pub fn pixel_m(&self) -> f32 {
        self.pixel_m
    }
    /// The nodata value set by [`Self::with_nodata`], metres.
    pub fn nodata_m(&self) -> Option<f32> {
        self.nodata_m
    }
    /// The raw height buffer (metres), row-major.
    pub fn heights_m(&self) -> &'a [f32] {
        self.heights_m
    }

    /// Height in metres at `(col, row)`, or `None` outside the patch or where masked.
    #[inline]
    pub fn height_at(&self, col: usize, row: usize) -> Option<f32> {
        if col >= self.width {
            return None;
        }
        let h = *self.heights_m.get(row * self.width + col)?;
        if !h.is_finite() || self.nodata_m == Some(h) {
            None
        } else {
            Some(h)
        }
    }
}

/// A slope image in fixed-point degrees ([`SlopePx`]), borrowed from the caller.
#[derive(Debug, Clone, Copy)]
pub struct SlopeImage<'a> {
    px: &'a [SlopePx],
    width: usize,
    height: usize,
    pixel_m: f32,
}

impl<'a> SlopeImage<'a> {
    /// Validate a row-major slope buffer. Raw values above [`SLOPE_MAX_RAW`] count as no data.
    pub fn new_checked(
        px: &'a [SlopePx],
        width: usize,
        height: usize,
        pixel_m: f32,
    ) -> Result<Self, FrameError> {
        check_dims(width, height, px.len())?;
        check_pixel(pixel_m)?;
        Ok(Self {
            px,
            width,
            height,
            pixel_m,
        })
    }

    /// Width in pixels (columns).
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels (rows).
    pub fn height(&self) -> usize {
        self.height
    }
    /// Ground sample distance in metres per pixel.
    pub fn pixel_m(&self) -> f32 {
        self.pixel_m
    }
    /// The pixels, row-major.
    pub fn pixels(&self) -> &'a [SlopePx] {
        self.px
    }
    /// Pixel at `(col, row)`; [`SLOPE_NODATA`] outside the image.
    #[inline]
    pub fn get(&self, col: usize, row: usize) -> SlopePx {
        if col >= self.width {
            return SLOPE_NODATA;
        }
        self.px
            .get(row * self.width + col)
            .copied()
            .unwrap_or(SLOPE_NODATA)
    }
}

/// Caller-owned storage for one slope frame of at most `MAX_PX` pixels.
///
/// Lives wherever the caller puts it (a `static`, a stack frame, a box); nothing is allocated.
/// Memory: `2 × MAX_PX` bytes plus a few words.
pub struct SlopeBuffer<const MAX_PX: usize> {
    px: [SlopePx; MAX_PX],
    width: usize,
    height: usize,
    pixel_m: f32,
    nodata_sums: u32,
}

impl<const MAX_PX: usize> Default for SlopeBuffer<MAX_PX> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX_PX: usize> SlopeBuffer<MAX_PX> {
    /// An empty buffer (all pixels no data).
    pub const fn new() -> Self {
        Self {
            px: [SLOPE_NODATA; MAX_PX],
            width: 0,
            height: 0,
            pixel_m: 0.0,
            nodata_sums: 0,
        }
    }

    /// Compute the slope of `dem` into this buffer (see [`crate::slope::slope_into`]).
    pub fn compute_from(&mut self, dem: &DemPatch<'_>) -> Result<SlopeImage<'_>, FrameError> {
        let img = crate::slope::slope_into(dem, &mut self.px)?;
        self.width = img.width();
        self.height = img.height();
        self.pixel_m = img.pixel_m();
        self.nodata_sums = 0;
        Ok(img)
    }

    /// [`Self::compute_from`] with isolated dropouts filled (see
    /// [`crate::slope::slope_into_with`]).
    pub fn compute_from_filled(
        &mut self,
        dem: &DemPatch<'_>,
    ) -> Result<SlopeImage<'_>, FrameError> {
        let img = crate::slope::slope_into_with(dem, &mut self.px, true)?;
        self.width = img.width();
        self.height = img.height();
        self.pixel_m = img.pixel_m();
        self.nodata_sums = 0;
        Ok(img)
    }

    /// Slope of `dem` binned `k × k` and smoothed by a Gaussian of `sigma_px` binned pixels
    /// (see [`crate::slope::slope_into_binned_smoothed`]; binned rows at most `CAP` wide).
    pub fn compute_binned_smoothed<const CAP: usize>(
        &mut self,
        dem: &DemPatch<'_>,
        k: usize,
        sigma_px: f32,
        fill: bool,
    ) -> Result<SlopeImage<'_>, FrameError> {
        let (img, sums) = crate::slope::slope_into_binned_smoothed_counted::<CAP>(
            dem,
            k,
            sigma_px,
            &mut self.px,
            fill,
        )?;
        self.width = img.width();
        self.height = img.height();
        self.pixel_m = img.pixel_m();
        self.nodata_sums = sums;
        Ok(img)
    }

    /// How many column sums of the last [`Self::compute_binned_smoothed`]'s smoothing held a
    /// missing height and were summed again term by term (a count, see
    /// [`crate::slope::slope_into_binned_smoothed_counted`]; 0 after any other computation).
    pub fn nodata_sums(&self) -> u32 {
        self.nodata_sums
    }

    /// Slope of `dem` binned `k × k` (see [`crate::slope::slope_into_binned`]).
    pub fn compute_binned(
        &mut self,
        dem: &DemPatch<'_>,
        k: usize,
        fill: bool,
    ) -> Result<SlopeImage<'_>, FrameError> {
        let img = crate::slope::slope_into_binned(dem, k, &mut self.px, fill)?;
        self.width = img.width();
        self.height = img.height();
        self.pixel_m = img.pixel_m();
        self.nodata_sums = 0;
        Ok(img)
    }

    /// Block-average `img` by `k × k` (mean of the valid raw values of each block; a block with
    /// fewer than half valid is no data) into this buffer; pixel size `k × img.pixel_m()`.
    pub fn bin_from(
        &mut self,
        img: &SlopeImage<'_>,
        k: usize,
    ) -> Result<SlopeImage<'_>, FrameError> {
        if k == 0 || k > crate::slope::MAX_BIN {
            return Err(FrameError::TooLarge {
                needed: k,
                capacity: crate::slope::MAX_BIN,
            });
        }
        let (w, h) = (img.width() / k, img.height() / k);
        if w == 0 || h == 0 {
            return Err(FrameError::Empty);
        }
        let n = w * h;
        let out = self.px.get_mut(..n).ok_or(FrameError::TooLarge {
            needed: n,
            capacity: MAX_PX,
        })?;
        let half = (k * k).div_ceil(2) as u32;
        for r in 0..h {
            for c in 0..w {
                let (mut sum, mut cnt) = (0u32, 0u32);
                for j in 0..k {
                    for i in 0..k {
                        let p = img.get(c * k + i, r * k + j);
                        if slope_is_valid(p) {
                            sum += p.to_bits() as u32;
                            cnt += 1;
                        }
                    }
                }
                let v = if cnt >= half {
                    // Rounded integer mean: exact and identical on every target.
                    SlopePx::from_bits(((sum + cnt / 2) / cnt) as u16)
                } else {
                    SLOPE_NODATA
                };
                if let Some(o) = out.get_mut(r * w + c) {
                    *o = v;
                }
            }
        }
        self.width = w;
        self.height = h;
        self.pixel_m = img.pixel_m() * k as f32;
        self.nodata_sums = 0;
        self.image()
    }

    /// The last computed image.
    pub fn image(&self) -> Result<SlopeImage<'_>, FrameError> {
        let n = self.width * self.height;
        let px = self.px.get(..n).ok_or(FrameError::TooLarge {
            needed: n,
            capacity: MAX_PX,
        })?;
        SlopeImage::new_checked(px, self.width, self.height, self.pixel_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantisation_round_trips_within_half_lsb() {
        for i in 0..=9000 {
            let deg = i as f32 * 0.01;
            let back = slope_to_deg(slope_from_deg(deg)).unwrap_or(f32::NAN);
            assert!(
                (back - deg).abs() <= 0.5 * SLOPE_LSB_DEG + 1e-6,
                "{deg} -> {back}"
            );
        }
        assert!(!slope_is_valid(slope_from_deg(f32::NAN)));
        assert_eq!(slope_from_deg(-3.0).to_bits(), 0);
        assert_eq!(slope_from_deg(1e9).to_bits(), SLOPE_MAX_RAW);
    }

    #[test]
    fn construction_is_validated() {
        let h = [0.0f32; 12];
        assert!(DemPatch::new_checked(&h, 4, 3, 10.0).is_ok());
        assert_eq!(
            DemPatch::new_checked(&h, 5, 3, 10.0).err(),
            Some(FrameError::SizeMismatch {
                expected: 15,
                got: 12
            })
        );
        assert_eq!(
            DemPatch::new_checked(&h, 0, 3, 10.0).err(),
            Some(FrameError::Empty)
        );
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                DemPatch::new_checked(&h, 4, 3, bad).err(),
                Some(FrameError::BadPixelSize)
            );
        }
        let s = [SLOPE_NODATA; 6];
        assert!(SlopeImage::new_checked(&s, 3, 2, 20.0).is_ok());
        assert!(SlopeImage::new_checked(&s, 2, 2, 20.0).is_err());
    }
}
