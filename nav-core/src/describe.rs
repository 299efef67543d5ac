//! Orientation and 64-d descriptor from Haar wavelet responses on the integral image.
//!
//! Haar wavelets here are symmetric about the sample pixel: `dx` is the box of `k` columns right
//! of the pixel minus the `k` columns left of it, over `2k + 1` rows (and transposed for `dy`).
//! Samples whose wavelet would leave the image contribute nothing.

use crate::detector::Keypoint;
use crate::integral::Integral;
use core::f32::consts::{FRAC_PI_3, PI};

/// Descriptor length: 4 × 4 sub-regions × (Σdx, Σdy, Σ|dx|, Σ|dy|).
pub const DESCRIPTOR_LEN: usize = 64;

/// A unit-length SURF descriptor (or all zeros where the window held no gradient at all).
pub type Descriptor = [f32; DESCRIPTOR_LEN];

/// Descriptor sample spacing in units of keypoint σ.
pub const DESC_SPACING_PER_SIGMA: f32 = 0.85;

/// Orientation Haar wavelet half-width in units of σ (full side ≈ 2× this).
pub const ORIENT_HAAR_HALF_PER_SIGMA: f32 = 2.0;

/// Orientation samples: offsets (i, j) in units of σ with i² + j² < 36 (radius 6σ).
pub const ORIENT_SAMPLES: usize = 109;
/// Step of the sliding orientation window's start angle, radians.
pub const ORIENT_WINDOW_STEP_RAD: f32 = 0.15;
/// Number of window positions over a full turn (⌈2π / 0.15⌉).
pub const ORIENT_WINDOWS: usize = 42;

const TWO_PI: f32 = 2.0 * PI;

/// Gaussian weights, computed once per extraction run (they depend only on sample indices).
pub(crate) struct Weights {
    orient: [(i8, i8, f32); ORIENT_SAMPLES],
    desc: [f32; 400],
}

impl Weights {
    pub(crate) fn new() -> Self {
        let mut orient = [(0i8, 0i8, 0.0f32); ORIENT_SAMPLES];
        let mut n = 0;
        for j in -6i8..=6 {
            for i in -6i8..=6 {
                let r2 = (i as i32 * i as i32 + j as i32 * j as i32) as f32;
                if r2 < 36.0
                    && let Some(slot) = orient.get_mut(n)
                {
                    // σ_w = 2σ → exp(−r²/(2·2²)) with r in units of σ.
                    *slot = (i, j, libm::expf(-r2 / 8.0));
                    n += 1;
                }
            }
        }
        let mut desc = [0.0f32; 400];
        for (k, wgt) in desc.iter_mut().enumerate() {
            let (u, v) = ((k % 20) as f32 - 9.5, (k / 20) as f32 - 9.5);
            // σ_w = 3.3σ centred on the keypoint.
            *wgt = libm::expf(-(u * u + v * v) / (2.0 * 3.3 * 3.3));
        }
        Self { orient, desc }
    }
}

/// `floor(v + 0.5)` as an integer: exactly `libm::floorf(v + 0.5) as isize`, with the common
/// case (|v + 0.5| < 2²³, where every `f32` converts to `i32` exactly) done by truncation instead
/// of the library call.
#[inline(always)]
fn round_i(v: f32) -> isize {
    let s = v + 0.5;
    if libm::fabsf(s) < 8_388_608.0 {
        let t = s as i32;
        (if (t as f32) > s { t - 1 } else { t }) as isize
    } else {
        libm::floorf(s) as isize
    }
}

/// Largest Haar half-width whose box sums and their difference are exact in `i32`:
/// `k·(2k + 1)·46 080 < 2³¹`.
const HAAR_I32_MAX_K: isize = 152;
const _: () = assert!(
    (HAAR_I32_MAX_K * (2 * HAAR_I32_MAX_K + 1)) as u64 * crate::frame::SLOPE_MAX_RAW as u64
        <= i32::MAX as u64
);

/// Haar responses (dx, dy) at pixel `(x, y)` with half-width `k`, or `None` if the wavelet leaves
/// the image. Raw slope units; callers only use ratios and directions.
#[inline(always)]
fn haar(ii: &Integral<'_>, x: isize, y: isize, k: isize) -> Option<(f32, f32)> {
    if x - k < 0 || y - k < 0 || x + k >= ii.width() as isize || y + k >= ii.height() as isize {
        return None;
    }
    let (right, left, down, up) = if x - k > 0 && y - k > 0 {
        haar_boxes_interior(ii.data(), ii.width(), x as usize, y as usize, k as usize)
    } else {
        let span = 2 * k + 1;
        (
            ii.box_sum_inside(x + 1, y - k, k, span),
            ii.box_sum_inside(x - k, y - k, k, span),
            ii.box_sum_inside(x - k, y + 1, span, k),
            ii.box_sum_inside(x - k, y - k, span, k),
        )
    };
    if k <= HAAR_I32_MAX_K {
        // Each sum is below 2³¹, so the wrapping difference read as i32 is the true one (and
        // i32 → f32 rounds the same value as i64 → f32 did).
        Some((
            right.wrapping_sub(left) as i32 as f32,
            down.wrapping_sub(up) as i32 as f32,
        ))
    } else {
        Some((
            (right as i64 - left as i64) as f32,
            (down as i64 - up as i64) as f32,
        ))
    }
}

/// The four Haar boxes (right, left, down, up) at `(x, y)` with half-width `k`, when every
/// corner is inside the integral (`x − k − 1 ≥ 0`, `y − k − 1 ≥ 0`): the twelve distinct corner
/// values are read once from four rows. Same sums as four `box_sum_inside` calls.
#[inline(always)]
fn haar_boxes_interior(
    data: &[u32],
    w: usize,
    x: usize,
    y: usize,
    k: usize,
) -> (u32, u32, u32, u32) {
    let row = |r: usize| {
        let base = r * w;
        move |c: usize| data.get(base + c).copied().unwrap_or(0)
    };
    let (bot, top, mid, above) = (row(y + k), row(y - k - 1), row(y), row(y - 1));
    let (cr, cx, cl, cf) = (x + k, x, x - 1, x - k - 1);
    let (b_r, b_x, b_l, b_f) = (bot(cr), bot(cx), bot(cl), bot(cf));
    let (t_r, t_x, t_l, t_f) = (top(cr), top(cx), top(cl), top(cf));
    let box4 = |a: u32, b: u32, c: u32, d: u32| a.wrapping_sub(b).wrapping_sub(c).wrapping_add(d);
    let right = box4(b_r, b_x, t_r, t_x);
    let left = box4(b_l, b_f, t_l, t_f);
    let down = box4(b_r, b_f, mid(cr), mid(cf));
    let up = box4(above(cr), above(cf), t_r, t_f);
    (right, left, down, up)
}

/// Dominant orientation (radians, [0, 2π)) from Gaussian-weighted Haar responses within 6σ and a
/// sliding 60° window. Every window's sums start from zero; angles are wrapped into [0, 2π) before
/// windowing and the result is `atan2(Σdy, Σdx)` of the best window.
#[inline(never)] // like `Kernel::row_any`: a stable instruction count whoever calls `extract`
pub(crate) fn orientation(ii: &Integral<'_>, kp: &Keypoint, w: &Weights) -> f32 {
    let s = kp.scale_px;
    let k = round_i(ORIENT_HAAR_HALF_PER_SIGMA * s).max(1);
    let mut samples = [(0.0f32, 0.0f32, 0.0f32); ORIENT_SAMPLES];
    let mut n = 0usize;
    for &(i, j, g) in &w.orient {
        let x = round_i(kp.x_px + i as f32 * s);
        let y = round_i(kp.y_px + j as f32 * s);
        if let Some((dx, dy)) = haar(ii, x, y, k)
            && let Some(slot) = samples.get_mut(n)
        {
            let (wx, wy) = (g * dx, g * dy);
            let mut ang = libm::atan2f(wy, wx);
            if ang < 0.0 {
                ang += TWO_PI;
            }
            *slot = (ang, wx, wy);
            n += 1;
        }
    }
    let samples = samples.get(..n).unwrap_or(&[]);
    let (best, best_x, best_y) = best_window(samples);
    if best == 0.0 {
        return 0.0;
    }
    let mut ori = libm::atan2f(best_y, best_x);
    if ori < 0.0 {
        ori += TWO_PI;
    }
    if ori >= TWO_PI { 0.0 } else { ori }
}

/// The sliding 60° window with the largest |Σ(wx, wy)|² over `(angle, wx, wy)` samples (angles
/// in [0, 2π)): `(|Σ|², Σwx, Σwy)`, zeros if every window is empty.
fn best_window(samples: &[(f32, f32, f32)]) -> (f32, f32, f32) {
    // Window sums. Each sample is added to every window that contains it, visiting samples in
    // index order, so each window's sum is formed in exactly the order of the naive
    // window-by-window scan (and is bit-identical to it); only the ~10 candidate windows around
    // the sample's angle are tested, with the same predicate, instead of all 42.
    let mut sums = [(0.0f32, 0.0f32); ORIENT_WINDOWS];
    // Window start angles, each computed exactly as `win as f32 * ORIENT_WINDOW_STEP_RAD`.
    let mut starts = [0.0f32; ORIENT_WINDOWS];
    for (win, s) in starts.iter_mut().enumerate() {
        *s = win as f32 * ORIENT_WINDOW_STEP_RAD;
    }
    for &(ang, wx, wy) in samples {
        // Windows holding `ang` start in (ang − π/3, ang]: at most 7 of them, between
        // ⌊ang/0.15⌋ − 7 and ⌊ang/0.15⌋ (the 0.133 rad gap between the last window and the first
        // shifts the wrapped ones by less than one step); one spare candidate on each side covers
        // rounding.
        let hi = libm::floorf(ang / ORIENT_WINDOW_STEP_RAD) as i32 + 1;
        let lo = hi - 9;
        for j in lo..=hi {
            // j ∈ [−9, 42]: one wrap either way (same as `rem_euclid`, without the division).
            let n = ORIENT_WINDOWS as i32;
            let win = if j < 0 {
                j + n
            } else if j >= n {
                j - n
            } else {
                j
            } as usize;
            let Some(&start) = starts.get(win) else {
                continue;
            };
            let mut d = ang - start;
            if d < 0.0 {
                d += TWO_PI;
            }
            if d < FRAC_PI_3
                && let Some(acc) = sums.get_mut(win)
            {
                acc.0 += wx;
                acc.1 += wy;
            }
        }
    }
    let (mut best, mut best_x, mut best_y) = (0.0f32, 0.0f32, 0.0f32);
    for &(sx, sy) in &sums {
        let m = sx * sx + sy * sy;
        if m > best {
            (best, best_x, best_y) = (m, sx, sy);
        }
    }
    (best, best_x, best_y)
}

/// The 64-d descriptor: a 20σ square rotated to the keypoint's orientation, 4 × 4 sub-regions of
/// 5 × 5 samples spaced σ apart, Haar half-width round(σ), responses rotated into the keypoint
/// frame and Gaussian-weighted (σ_w = 3.3σ), normalised to unit length.
#[inline(never)] // see `orientation`
pub(crate) fn descriptor(ii: &Integral<'_>, kp: &Keypoint, w: &Weights) -> Descriptor {
    let s = kp.scale_px * DESC_SPACING_PER_SIGMA;
    let k = round_i(s).max(1);
    let (si, co) = (
        libm::sinf(kp.orientation_rad),
        libm::cosf(kp.orientation_rad),
    );
    let mut d = [0.0f32; DESCRIPTOR_LEN];
    for j in 0..20usize {
        for i in 0..20usize {
            let (u, v) = ((i as f32 - 9.5) * s, (j as f32 - 9.5) * s);
            let x = round_i(kp.x_px + co * u - si * v);
            let y = round_i(kp.y_px + si * u + co * v);
            let Some((gx, gy)) = haar(ii, x, y, k) else {
                continue;
            };
            let g = w.desc.get(j * 20 + i).copied().unwrap_or(0.0);
            let rx = g * (co * gx + si * gy);
            let ry = g * (co * gy - si * gx);
            let base = ((j / 5) * 4 + i / 5) * 4;
            if let Some(cell) = d.get_mut(base..base + 4) {
                for (slot, v) in cell.iter_mut().zip([rx, ry, rx.abs(), ry.abs()]) {
                    *slot += v;
                }
            }
        }
    }
    let norm2: f32 = d.iter().map(|v| v * v).sum();
    if norm2 > 0.0 {
        let inv = 1.0 / libm::sqrtf(norm2);
        for v in &mut d {
            *v *= inv;
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The obvious version: every window scans every sample.
    fn best_window_naive(samples: &[(f32, f32, f32)]) -> (f32, f32, f32) {
        let (mut best, mut best_x, mut best_y) = (0.0f32, 0.0f32, 0.0f32);
        for win in 0..ORIENT_WINDOWS {
            let start = win as f32 * ORIENT_WINDOW_STEP_RAD;
            let (mut sx, mut sy) = (0.0f32, 0.0f32);
            for &(ang, wx, wy) in samples {
                let mut d = ang - start;
                if d < 0.0 {
                    d += TWO_PI;
                }
                if d < FRAC_PI_3 {
                    sx += wx;
                    sy += wy;
                }
            }
            let m = sx * sx + sy * sy;
            if m > best {
                (best, best_x, best_y) = (m, sx, sy);
            }
        }
        (best, best_x, best_y)
    }

    #[test]
    fn windowed_orientation_sums_are_bit_identical_to_the_naive_scan() {
        let mut state = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        // Angles on and next to every window boundary, plus random ones.
        let mut special = std::vec::Vec::new();
        for w in 0..ORIENT_WINDOWS {
            let s = w as f32 * ORIENT_WINDOW_STEP_RAD;
            for a in [s, s + FRAC_PI_3, s - 1e-6, s + 1e-6, s + FRAC_PI_3 - 1e-6] {
                let a = if a < 0.0 { a + TWO_PI } else { a };
                if a < TWO_PI {
                    special.push(a);
                }
            }
        }
        special.extend([
            0.0,
            TWO_PI - 1e-6,
            f32::from_bits(TWO_PI.to_bits() - 1),
            6.15,
            5.25,
        ]);
        for round in 0..400 {
            let n = 1 + round % ORIENT_SAMPLES;
            let samples: std::vec::Vec<(f32, f32, f32)> = (0..n)
                .map(|k| {
                    let ang = if round % 3 == 0 {
                        special[(k * 7 + round) % special.len()]
                    } else {
                        next() * TWO_PI * 0.9999999
                    };
                    (ang, next() - 0.5, next() - 0.5)
                })
                .collect();
            let (a, b) = (best_window(&samples), best_window_naive(&samples));
            assert_eq!(
                (a.0.to_bits(), a.1.to_bits(), a.2.to_bits()),
                (b.0.to_bits(), b.1.to_bits(), b.2.to_bits()),
                "round {round}"
            );
        }
    }

    #[test]
    fn fast_round_equals_floorf() {
        for v in [
            -3.5f32,
            -2.5,
            -0.5,
            -0.49999997,
            0.0,
            0.49999997,
            0.5,
            1.5,
            2.4999998,
            1e7,
            -1e7,
            8_388_607.5,
            3e9,
            -3e9,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            assert_eq!(round_i(v), libm::floorf(v + 0.5) as isize, "{v}");
        }
        let mut x = -1000.0f32;
        while x < 1000.0 {
            assert_eq!(round_i(x), libm::floorf(x + 0.5) as isize, "{x}");
            x += 0.0137;
        }
    }
}
