//! Quality-guided phase unwrapping (region growing ordered by coherence).
//!
//! The flat-removed phase wraps once the scene's heights span more than one height of
//! ambiguity (≈ 733 m per 2π for the paper's radar). Starting from the most coherent pixel, the
//! unwrapped region grows into its most coherent 4-neighbour first, adding the wrapped phase
//! difference to the neighbour it was reached from. Noisy or masked pixels (quality below
//! `min_quality`) are reached last, so errors there cannot propagate into good areas that have
//! another path. Disconnected islands start again from their own best pixel.
//!
//! The result is defined up to one global multiple of 2π; [`unwrap_quality_guided`] picks the
//! multiple that puts the mean unwrapped phase of the good pixels in `(−π, π]`, i.e. the scene's
//! mean height nearest the datum (the SAR simulation puts its datum at the DEM's mean height; a
//! real processor would use a coarse prior DEM here).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::geometry::wrap_rad;

#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    quality: f32,
    idx: usize,
    from: usize,
}
impl Eq for Entry {}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        self.quality
            .total_cmp(&o.quality)
            // Deterministic ties: lower index first.
            .then_with(|| o.idx.cmp(&self.idx))
    }
}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// Result of unwrapping.
#[derive(Debug, Clone)]
pub struct Unwrapped {
    /// Unwrapped phase per pixel, rad.
    pub phase_rad: Vec<f64>,
    /// Good pixels (quality ≥ `min_quality`) whose unwrapped phase differs from the wrapped one
    /// by a non-zero multiple of 2π.
    pub pixels_changed: usize,
    /// Global multiple of 2π removed so the mean of the good pixels lies in `(−π, π]`.
    pub global_cycles: i64,
    /// Separate regions grown (1 for a connected scene).
    pub regions: usize,
}

/// Unwrap `wrapped` (`width × height`, rad) guided by `quality` (e.g. coherence, same shape).
/// Pixels with `quality < min_quality` are unwrapped last and excluded from the global offset.
pub fn unwrap_quality_guided(
    wrapped: &[f64],
    quality: &[f32],
    width: usize,
    height: usize,
    min_quality: f32,
) -> Unwrapped {
    let n = width * height;
    let mut out = vec![f64::NAN; n];
    let mut done = vec![false; n];
    // Good pixels first (by quality), then the rest, as seeds for each region.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| quality[b].total_cmp(&quality[a]).then(a.cmp(&b)));
    let mut heap = BinaryHeap::new();
    let mut regions = 0;
    let key = |i: usize| -> f32 {
        let q = quality[i];
        if q.is_finite() { q } else { f32::NEG_INFINITY }
    };
    for &seed in &order {
        if done[seed] {
            continue;
        }
        regions += 1;
        done[seed] = true;
        out[seed] = wrapped[seed];
        let push = |heap: &mut BinaryHeap<Entry>, done: &[bool], i: usize| {
            let (r, c) = (i / width, i % width);
            let mut nb = [usize::MAX; 4];
            if c > 0 {
                nb[0] = i - 1;
            }
            if c + 1 < width {
                nb[1] = i + 1;
            }
            if r > 0 {
                nb[2] = i - width;
            }
            if r + 1 < height {
                nb[3] = i + width;
            }
            for j in nb {
                if j != usize::MAX && !done[j] {
                    heap.push(Entry {
                        quality: key(j),
                        idx: j,
                        from: i,
                    });
                }
            }
        };
        push(&mut heap, &done, seed);
        while let Some(e) = heap.pop() {
            if done[e.idx] {
                continue;
            }
            done[e.idx] = true;
            out[e.idx] = out[e.from] + wrap_rad(wrapped[e.idx] - wrapped[e.from]);
            push(&mut heap, &done, e.idx);
        }
    }
    let good: Vec<f64> = (0..n)
        .filter(|&i| quality[i] >= min_quality)
        .map(|i| out[i])
        .collect();
    let mean = if good.is_empty() {
        0.0
    } else {
        good.iter().sum::<f64>() / good.len() as f64
    };
    let cycles = (mean / std::f64::consts::TAU).round();
    let shift = cycles * std::f64::consts::TAU;
    let mut changed = 0;
    for ((u, &w), &q) in out.iter_mut().zip(wrapped).zip(quality) {
        *u -= shift;
        if q >= min_quality && (*u - w).abs() > 1.0 {
            changed += 1;
        }
    }
    Unwrapped {
        phase_rad: out,
        pixels_changed: changed,
        global_cycles: cycles as i64,
        regions,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_steep_ramp_with_noise_and_bad_pixels() {
        let (w, h) = (60, 50);
        // Phase spans ~7 cycles across the image; deterministic "noise" ±0.4 rad.
        let truth: Vec<f64> = (0..w * h)
            .map(|i| {
                let (r, c) = ((i / w) as f64, (i % w) as f64);
                0.6 * c + 0.2 * r - 18.0 + 0.4 * ((i as f64) * 12.9898).sin()
            })
            .collect();
        let wrapped: Vec<f64> = truth.iter().map(|&p| wrap_rad(p)).collect();
        let mut q = vec![0.9f32; w * h];
        // A band of garbage pixels the unwrapper must go around.
        let mut wr = wrapped.clone();
        for r in 10..40 {
            q[r * w + 30] = 0.05;
            wr[r * w + 30] = ((r * 7) as f64).sin() * 3.0;
        }
        let u = unwrap_quality_guided(&wr, &q, w, h, 0.3);
        let mean_t: f64 = truth.iter().sum::<f64>() / truth.len() as f64;
        let shift = (mean_t / std::f64::consts::TAU).round() * std::f64::consts::TAU;
        for i in 0..w * h {
            if q[i] < 0.3 {
                continue;
            }
            assert!(
                (u.phase_rad[i] - (truth[i] - shift)).abs() < 1e-9,
                "pixel {i}"
            );
        }
        assert!(u.pixels_changed > 0);
        assert_eq!(u.regions, 1);
    }

    #[test]
    fn a_residual_within_one_cycle_is_left_alone() {
        let (w, h) = (20, 10);
        let wrapped: Vec<f64> = (0..w * h).map(|i| 0.1 * (i as f64).sin()).collect();
        let q = vec![0.8f32; w * h];
        let u = unwrap_quality_guided(&wrapped, &q, w, h, 0.3);
        assert_eq!(u.pixels_changed, 0);
        assert_eq!(u.global_cycles, 0);
        assert!(
            u.phase_rad
                .iter()
                .zip(&wrapped)
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
    }
}
