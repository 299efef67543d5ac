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

#[inline(always)]
fn round_i(v: f32) -> isize {
    libm::floorf(v + 0.5) as isize
}

/// Haar responses (dx, dy) at pixel `(x, y)` with half-width `k`, or `None` if the wavelet leaves
/// the image. Raw slope units; callers only use ratios and directions.
#[inline(always)]
fn haar(ii: &Integral<'_>, x: isize, y: isize, k: isize) -> Option<(f32, f32)> {
    if x - k < 0 || y - k < 0 || x + k >= ii.width() as isize || y + k >= ii.height() as isize {
        return None;
    }
    let span = 2 * k + 1;
    let right = ii.box_sum_inside(x + 1, y - k, k, span) as i64;
    let left = ii.box_sum_inside(x - k, y - k, k, span) as i64;
    let down = ii.box_sum_inside(x - k, y + 1, span, k) as i64;
    let up = ii.box_sum_inside(x - k, y - k, span, k) as i64;
    Some(((right - left) as f32, (down - up) as f32))
}

/// Dominant orientation (radians, [0, 2π)) from Gaussian-weighted Haar responses within 6σ and a
/// sliding 60° window. Every window's sums start from zero; angles are wrapped into [0, 2π) before
/// windowing and the result is `atan2(Σdy, Σdx)` of the best window.
pub(crate) fn orientation(ii: &Integral<'_>, kp: &Keypoint, w: &Weights) -> f32 {
    let s = kp.scale_px;
    let k = round_i(2.0 * s).max(1);
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
    if best == 0.0 {
        return 0.0;
    }
    let mut ori = libm::atan2f(best_y, best_x);
    if ori < 0.0 {
        ori += TWO_PI;
    }
    if ori >= TWO_PI { 0.0 } else { ori }
}

/// The 64-d descriptor: a 20σ square rotated to the keypoint's orientation, 4 × 4 sub-regions of
/// 5 × 5 samples spaced σ apart, Haar half-width round(σ), responses rotated into the keypoint
/// frame and Gaussian-weighted (σ_w = 3.3σ), normalised to unit length.
pub(crate) fn descriptor(ii: &Integral<'_>, kp: &Keypoint, w: &Weights) -> Descriptor {
    let s = kp.scale_px;
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
                cell[0] += rx;
                cell[1] += ry;
                cell[2] += rx.abs();
                cell[3] += ry.abs();
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
