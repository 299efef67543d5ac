//! Integer integral image of a slope frame, with exact box sums.
//!
//! Entries are `u32` and accumulate with wrapping arithmetic. A box sum `A − B − C + D` taken with
//! wrapping arithmetic equals the true box sum modulo 2³²; the true sum of any box of `k` pixels is
//! at most `k × SLOPE_MAX_RAW` = `k × 46080`, below 2³² for `k ≤ 93 206` pixels (a 305 × 305 box).
//! The largest box Umbra ever takes is a 195 × 195 fast-Hessian lobe (38 025 pixels), so every box
//! sum is exact for any frame size — the integral "cannot overflow" in the only sense that matters.
//! No-data pixels contribute 0.

use crate::frame::{FrameError, SLOPE_MAX_RAW, SlopeImage};

/// Largest box (in pixels) whose sum is guaranteed exact.
pub const MAX_EXACT_BOX_PX: u64 = (u32::MAX as u64) / (SLOPE_MAX_RAW as u64);

// The largest fast-Hessian lobe (195 × 195, octave 4) must stay within the exact range.
const _: () = assert!(195 * 195 <= MAX_EXACT_BOX_PX);

/// Inclusive-prefix integral image over caller-owned storage:
/// `I(x, y) = Σ_{i ≤ x, j ≤ y} slope_raw(i, j)` (mod 2³²).
#[derive(Debug, Clone, Copy)]
pub struct Integral<'a> {
    data: &'a [u32],
    width: usize,
    height: usize,
}

impl<'a> Integral<'a> {
    /// Build the integral of `img` into `out[..w × h]`.
    pub fn build(img: &SlopeImage<'_>, out: &'a mut [u32]) -> Result<Self, FrameError> {
        let (w, h) = (img.width(), img.height());
        let n = w * h;
        let capacity = out.len();
        let out = out.get_mut(..n).ok_or(FrameError::TooLarge {
            needed: n,
            capacity,
        })?;
        let px = img.pixels();
        // Row by row: running row sum plus the integral row above (same wrapping additions in
        // the same order as the per-pixel definition).
        let mut above_start: Option<usize> = None;
        for row in 0..h {
            let start = row * w;
            let (done, rest) = out.split_at_mut(start);
            let above = above_start.and_then(|a| done.get(a..a + w));
            let (Some(dst), Some(src)) = (rest.get_mut(..w), px.get(start..start + w)) else {
                break;
            };
            let mut run = 0u32;
            match above {
                Some(above) => {
                    for ((o, p), a) in dst.iter_mut().zip(src).zip(above) {
                        let raw = p.to_bits();
                        run = run.wrapping_add(if raw <= SLOPE_MAX_RAW { raw as u32 } else { 0 });
                        *o = a.wrapping_add(run);
                    }
                }
                None => {
                    for (o, p) in dst.iter_mut().zip(src) {
                        let raw = p.to_bits();
                        run = run.wrapping_add(if raw <= SLOPE_MAX_RAW { raw as u32 } else { 0 });
                        *o = run;
                    }
                }
            }
            above_start = Some(start);
        }
        Ok(Self {
            data: out,
            width: w,
            height: h,
        })
    }

    /// The entries, row-major (`width × height`).
    pub(crate) fn data(&self) -> &'a [u32] {
        self.data
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    #[inline(always)]
    fn at(&self, x: isize, y: isize) -> u32 {
        // I(−1, ·) = I(·, −1) = 0; callers pass x < width, y < height.
        if x < 0 || y < 0 {
            return 0;
        }
        self.data
            .get(y as usize * self.width + x as usize)
            .copied()
            .unwrap_or(0)
    }

    /// Sum of raw slope values in the box with top-left pixel `(x, y)` and size `w × h`, clipped to
    /// the image (the part outside counts as 0). Exact for boxes up to [`MAX_EXACT_BOX_PX`].
    #[inline]
    pub fn box_sum(&self, x: isize, y: isize, w: isize, h: isize) -> u32 {
        let x0 = x.max(0) - 1;
        let y0 = y.max(0) - 1;
        let x1 = (x + w - 1).min(self.width as isize - 1);
        let y1 = (y + h - 1).min(self.height as isize - 1);
        if x1 <= x0 || y1 <= y0 {
            return 0;
        }
        self.at(x1, y1)
            .wrapping_sub(self.at(x0, y1))
            .wrapping_sub(self.at(x1, y0))
            .wrapping_add(self.at(x0, y0))
    }

    /// [`Self::box_sum`] for a box the caller knows lies inside the image (no clipping work).
    #[inline(always)]
    pub(crate) fn box_sum_inside(&self, x: isize, y: isize, w: isize, h: isize) -> u32 {
        let (x0, y0, x1, y1) = (x - 1, y - 1, x + w - 1, y + h - 1);
        self.at(x1, y1)
            .wrapping_sub(self.at(x0, y1))
            .wrapping_sub(self.at(x1, y0))
            .wrapping_add(self.at(x0, y0))
    }
}

/// Scratch length (in `u32`) that [`Integral::build`] needs for a `width × height` frame.
pub const fn integral_len(width: usize, height: usize) -> usize {
    width * height
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{SLOPE_NODATA, SlopePx};

    /// Deterministic pseudo-random raw slopes including the maximum and no-data values.
    fn image(w: usize, h: usize, seed: u32) -> [SlopePx; 37 * 29] {
        let mut s = seed;
        let mut px = [SLOPE_NODATA; 37 * 29];
        for p in px.iter_mut().take(w * h) {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            *p = match s % 11 {
                0 => SLOPE_NODATA,
                1 => SlopePx::from_bits(SLOPE_MAX_RAW),
                _ => SlopePx::from_bits((s >> 8) as u16 % (SLOPE_MAX_RAW + 1)),
            };
        }
        px
    }

    #[test]
    fn box_sums_equal_direct_summation_exactly() {
        let (w, h) = (37usize, 29usize);
        for seed in 1..4u32 {
            let px = image(w, h, seed * 7919);
            let img = SlopeImage::new_checked(&px[..w * h], w, h, 10.0).unwrap();
            let mut buf = [0u32; 37 * 29];
            let ii = Integral::build(&img, &mut buf).unwrap();
            for y in -3..(h as isize + 2) {
                for x in -3..(w as isize + 2) {
                    for (bw, bh) in [(1, 1), (3, 5), (9, 9), (40, 2), (2, 31)] {
                        let mut direct = 0u64;
                        for yy in y.max(0)..(y + bh).min(h as isize) {
                            for xx in x.max(0)..(x + bw).min(w as isize) {
                                let raw = px[yy as usize * w + xx as usize].to_bits();
                                if raw <= SLOPE_MAX_RAW {
                                    direct += raw as u64;
                                }
                            }
                        }
                        assert_eq!(
                            ii.box_sum(x, y, bw, bh) as u64,
                            direct,
                            "box {x},{y},{bw}x{bh}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn box_sums_stay_exact_when_the_integral_wraps() {
        // 800 × 800 pixels at 90°: the full-frame integral is 2.9e10, wrapping u32 six times.
        use std::vec;
        const W: usize = 800;
        let px = vec![SlopePx::from_bits(SLOPE_MAX_RAW); W * W];
        let img = SlopeImage::new_checked(&px, W, W, 5.0).unwrap();
        let mut buf = vec![0u32; W * W];
        let ii = Integral::build(&img, &mut buf).unwrap();
        let full = SLOPE_MAX_RAW as u64;
        assert_eq!(ii.box_sum(600, 600, 195, 195) as u64, 195 * 195 * full);
        assert_eq!(ii.box_sum(700, 10, 99, 51) as u64, 99 * 51 * full);
    }
}
