//! Fast-Hessian keypoint detector over the integral image (Bay et al., SURF).
//!
//! Filter side for octave `o` (0-based) and layer `l` (0-based) is `3·(2^(o+1)·(l+1) + 1)`:
//! 9, 15, 21, 27 in the first octave, 15, 27, 39, 51 in the second, the layer step doubling per
//! octave. Responses are sampled every `2^o` pixels (step 1 in the first octave). Each lobe of
//! side `side/3` is odd, so every box is placed symmetrically about the sample pixel: no
//! half-pixel drift at any scale.
//!
//! Responses are computed a grid row at a time into a ring of three rows per layer, and
//! non-maximum suppression runs one row behind: memory is `MAX_LAYERS × 3 × width` floats instead
//! of a full response pyramid. Layers that can hold no keypoint themselves (an octave's first
//! and last) are not swept: their responses are computed on demand for the candidates whose
//! maximum test reaches them (at most [`MAX_LAZY_RESPONSES`] a run), with the same values.

use crate::frame::{FrameError, SlopeImage, slope_is_valid};
use crate::integral::Integral;
use core::cmp::Ordering;
use core::fmt;

/// Most octaves a configuration may ask for.
pub const MAX_OCTAVES: usize = 4;
/// Most layers per octave a configuration may ask for (at least 3 are needed for a 3×3×3 maximum).
pub const MAX_LAYERS: usize = 5;
/// Number of response rows kept per layer (the 3×3×3 neighbourhood spans three rows).
pub const RING_ROWS: usize = 3;
/// Keypoint scale σ (pixels) per pixel of filter side, calibrated: a Gaussian blob of standard
/// deviation σ gives its strongest response at the (interpolated) filter side `L` with
/// `σ = SIGMA_PER_SIDE·L + SIGMA_OFFSET_PX`. Measured on 19 blobs, σ = 2.4…12 px (residuals within
/// ±2.6 %). Bay's nominal "9×9 ≈ σ 1.2" (0.133 per pixel of side) underestimates blob scale by
/// about 30 % with area-normalised box responses, so `scale_px` here means blob σ.
pub const SIGMA_PER_SIDE: f32 = 0.205;
/// Offset of the side → σ calibration, pixels (see [`SIGMA_PER_SIDE`]).
pub const SIGMA_OFFSET_PX: f32 = -0.25;
/// Weight of the Dxy term in the determinant: `det = Dxx·Dyy − (0.9·Dxy)²`.
pub const DXY_WEIGHT_SQ: f32 = 0.81;

/// Filter side in pixels for `octave` and `layer` (both 0-based).
pub const fn filter_side(octave: usize, layer: usize) -> usize {
    3 * ((1 << (octave + 1)) * (layer + 1) + 1)
}

/// Sampling step in pixels of `octave` (0-based).
pub const fn sample_step(octave: usize) -> usize {
    1 << octave
}

/// Detector settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DetectorConfig {
    /// Number of octaves, 1..=[`MAX_OCTAVES`].
    pub octaves: u8,
    /// Layers per octave, 3..=[`MAX_LAYERS`].
    pub layers: u8,
    /// Minimum determinant-of-Hessian response, in (degrees of slope)², normalised by filter area.
    pub threshold: f32,
    /// Keypoints with a smaller scale σ (pixels) are discarded before the budget is filled. A frame
    /// finer than its reference (scale 0.5: 10 m vs 20 m pixels) sets this to the reference's
    /// smallest scale in frame pixels, so the budget is not spent on detail the reference cannot
    /// show. 0 keeps everything.
    pub min_scale_px: f32,
    /// Most lazy-layer responses one run computes ([`MAX_LAZY_RESPONSES`] for flight frames,
    /// set by [`crate::Navigator::frame_surf_config`] under a work budget; `u32::MAX`, the
    /// default, for reference tiles built on the ground).
    pub max_lazy_responses: u32,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            octaves: 3,
            layers: 4,
            threshold: 0.1,
            min_scale_px: 0.0,
            max_lazy_responses: u32::MAX,
        }
    }
}

/// A configuration the detector refuses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// `octaves` outside 1..=[`MAX_OCTAVES`].
    Octaves,
    /// `layers` outside 3..=[`MAX_LAYERS`].
    Layers,
    /// `threshold` negative or not finite.
    Threshold,
    /// `min_scale_px` negative or not finite.
    MinScale,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Octaves => write!(f, "octaves must be 1..={MAX_OCTAVES}"),
            Self::Layers => write!(f, "layers must be 3..={MAX_LAYERS}"),
            Self::Threshold => write!(f, "threshold must be finite and >= 0"),
            Self::MinScale => write!(f, "min_scale_px must be finite and >= 0"),
        }
    }
}

impl core::error::Error for ConfigError {}

impl DetectorConfig {
    /// Check the ranges.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.octaves == 0 || self.octaves as usize > MAX_OCTAVES {
            return Err(ConfigError::Octaves);
        }
        if self.layers < 3 || self.layers as usize > MAX_LAYERS {
            return Err(ConfigError::Layers);
        }
        if !(self.threshold.is_finite() && self.threshold >= 0.0) {
            return Err(ConfigError::Threshold);
        }
        if !(self.min_scale_px.is_finite() && self.min_scale_px >= 0.0) {
            return Err(ConfigError::MinScale);
        }
        Ok(())
    }
}

/// A detected interest point, in frame pixel coordinates (pixel centres at integers).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Keypoint {
    /// Column coordinate, pixels.
    pub x_px: f32,
    /// Row coordinate, pixels.
    pub y_px: f32,
    /// Scale σ in pixels: the standard deviation of the Gaussian blob this keypoint responds to
    /// most (see [`SIGMA_PER_SIDE`]).
    pub scale_px: f32,
    /// Orientation in radians in [0, 2π), measured from the +x (column) axis towards +y (rows,
    /// downwards). 0 for the upright variant.
    pub orientation_rad: f32,
    /// Determinant-of-Hessian response at the refined point, (degrees of slope)².
    pub response: f32,
    /// Sign of the Laplacian (Dxx + Dyy ≥ 0): a dark blob on bright ground is `true`.
    pub laplacian_positive: bool,
}

impl Keypoint {
    /// Total order used to keep the strongest keypoints: response, then scale, then position
    /// (smaller row, then smaller column, ranks higher).
    pub fn rank_cmp(&self, other: &Self) -> Ordering {
        self.response
            .total_cmp(&other.response)
            .then(self.scale_px.total_cmp(&other.scale_px))
            .then(other.y_px.total_cmp(&self.y_px))
            .then(other.x_px.total_cmp(&self.x_px))
    }
}

/// The three box-filter responses at one pixel, exact integers in raw slope units.
///
/// `i32` with wrapping arithmetic is exact: every box sum is exact in `u32` (see
/// [`crate::integral`]), and each response's true value is below 2³¹ in magnitude — the largest,
/// `Dyy`/`Dxx` of the biggest filter a configuration allows (octave 4, layer 5: side 243, lobes of
/// 81 × 161 px), is at most 2 · 81 · 161 · 46 080 ≈ 1.2·10⁹ — so the result modulo 2³² read as
/// `i32` is the true value. (`i32` → `f32` is one instruction on a Cortex-M4F; `i64` → `f32` is a
/// library call, which made up a sixth of a frame's instructions.)
#[derive(Debug, Clone, Copy)]
struct BoxResponses {
    dxx: i32,
    dyy: i32,
    dxy: i32,
}

// The exactness argument above, for the largest filter any configuration can ask for.
const _: () = {
    let side = filter_side(MAX_OCTAVES - 1, MAX_LAYERS - 1) as u64;
    let lobe = side / 3;
    let wide = 2 * lobe - 1;
    assert!(2 * lobe * wide * crate::frame::SLOPE_MAX_RAW as u64 <= i32::MAX as u64);
    assert!(side * wide <= crate::integral::MAX_EXACT_BOX_PX);
};

/// The eight boxes of the three responses for one filter side, as `(x, y, w, h)` relative to the
/// sample pixel: Dyy whole and middle, Dxx whole and middle, Dxy's four lobes (+, +, −, −).
fn boxes(side: isize) -> [(isize, isize, isize, isize); 8] {
    let lobe = side / 3;
    let half = (side - 1) / 2;
    let wide = 2 * lobe - 1;
    [
        (-(lobe - 1), -half, wide, side),
        (-(lobe - 1), -(lobe - 1) / 2, wide, lobe),
        (-half, -(lobe - 1), side, wide),
        (-(lobe - 1) / 2, -(lobe - 1), lobe, wide),
        (-lobe, -lobe, lobe, lobe),
        (1, 1, lobe, lobe),
        (1, -lobe, lobe, lobe),
        (-lobe, 1, lobe, lobe),
    ]
}

#[inline(always)]
fn combine(b: [u32; 8]) -> BoxResponses {
    // Second derivatives: the whole three-lobe box minus three times its middle lobe gives the
    // (+1, −2, +1) pattern with two box sums instead of three.
    let [y1, y2, x1, x2, p1, p2, m1, m2] = b;
    BoxResponses {
        dyy: y1.wrapping_sub(y2.wrapping_mul(3)) as i32,
        dxx: x1.wrapping_sub(x2.wrapping_mul(3)) as i32,
        dxy: p1.wrapping_add(p2).wrapping_sub(m1).wrapping_sub(m2) as i32,
    }
}

#[inline(always)]
fn box_responses(ii: &Integral<'_>, x: isize, y: isize, side: isize) -> BoxResponses {
    let b = boxes(side).map(|(bx, by, bw, bh)| ii.box_sum_inside(x + bx, y + by, bw, bh));
    combine(b)
}

/// Integral-image offsets of the 32 box corners of one filter side, for pixels whose every
/// corner lies inside the image (no clipping): box sum = `I[A] − I[B] − I[C] + I[D]`.
struct Kernel {
    /// Per box: offsets of A (bottom-right), B (left of bottom-left), C (above top-right),
    /// D (above-left of top-left), relative to the sample pixel's index.
    corners: [[isize; 4]; 8],
    /// Normalisation by the filter area and the slope LSB.
    inv: f32,
}

impl Kernel {
    fn new(side: usize, width: usize) -> Self {
        let w = width as isize;
        let at = |dx: isize, dy: isize| dy * w + dx;
        let corners = boxes(side as isize).map(|(bx, by, bw, bh)| {
            let (x0, y0, x1, y1) = (bx - 1, by - 1, bx + bw - 1, by + bh - 1);
            [at(x1, y1), at(x0, y1), at(x1, y0), at(x0, y0)]
        });
        Self {
            corners,
            inv: 1.0 / ((side * side) as f32 * 512.0),
        }
    }

    /// Determinant response at the pixel with integral index `idx` (same value as [`hessian`]).
    #[inline(always)]
    fn response(&self, data: &[u32], idx: usize) -> f32 {
        let get = |off: isize| {
            data.get((idx as isize + off) as usize)
                .copied()
                .unwrap_or(0)
        };
        let b = self.corners.map(|[a, b, c, d]| {
            get(a)
                .wrapping_sub(get(b))
                .wrapping_sub(get(c))
                .wrapping_add(get(d))
        });
        let r = combine(b);
        let dxx = r.dxx as f32 * self.inv;
        let dyy = r.dyy as f32 * self.inv;
        let dxy = r.dxy as f32 * self.inv;
        dxx * dyy - DXY_WEIGHT_SQ * dxy * dxy
    }
}

/// Outputs per block of [`Kernel::row`] (stack: 8 × 32 × 4 B = 1 KiB).
const ROW_BLOCK: usize = 32;

impl Kernel {
    /// Responses at `out.len()` consecutive grid positions of one row, `STEP` pixels apart,
    /// starting at the pixel with integral index `idx0` (every corner inside the image). Each box
    /// sum runs down four strided corner sequences at once, so the loads need no per-element
    /// bounds checks; the arithmetic per position is exactly [`Kernel::response`]'s. Returns how
    /// many leading positions were written (fewer only if a corner sequence would run past the
    /// integral's end; the caller finishes those with [`Kernel::response`]).
    fn row<const STEP: usize>(&self, data: &[u32], idx0: usize, out: &mut [f32]) -> usize {
        let mut done = 0;
        // Position-major: the eight box sums of one position are contiguous. Every entry a block
        // reads is written first in that block.
        let mut sums = [[0u32; 8]; ROW_BLOCK];
        while done < out.len() {
            let len = (out.len() - done).min(ROW_BLOCK);
            let first = idx0 + done * STEP;
            for (bi, corners) in self.corners.iter().enumerate() {
                let seq = |off: isize| {
                    let start = (first as isize + off) as usize;
                    data.get(start..start + len * STEP)
                        .map(|s| s.as_chunks::<STEP>().0)
                };
                let (Some(a), Some(b), Some(c), Some(d)) = (
                    seq(corners[0]),
                    seq(corners[1]),
                    seq(corners[2]),
                    seq(corners[3]),
                ) else {
                    return done;
                };
                for ((((o, a), b), c), d) in sums.iter_mut().zip(a).zip(b).zip(c).zip(d) {
                    if let Some(slot) = o.get_mut(bi) {
                        *slot = a[0]
                            .wrapping_sub(b[0])
                            .wrapping_sub(c[0])
                            .wrapping_add(d[0]);
                    }
                }
            }
            let Some(dst) = out.get_mut(done..done + len) else {
                return done;
            };
            for (o, b) in dst.iter_mut().zip(&sums) {
                let r = combine(*b);
                let dxx = r.dxx as f32 * self.inv;
                let dyy = r.dyy as f32 * self.inv;
                let dxy = r.dxy as f32 * self.inv;
                *o = dxx * dyy - DXY_WEIGHT_SQ * dxy * dxy;
            }
            done += len;
        }
        done
    }

    /// [`Kernel::row`] for the octave's sampling step.
    ///
    /// Never inlined: compiled on its own the response loop keeps its registers; inlined into
    /// `extract` (which it was once `extract` had a second caller, the keyframe capture) the
    /// firmware's worst TRN frame cost 1.2 M instructions more (HIL profile, session 12).
    #[inline(never)]
    fn row_any(&self, step: usize, data: &[u32], idx0: usize, out: &mut [f32]) -> usize {
        match step {
            1 => self.row::<1>(data, idx0, out),
            2 => self.row::<2>(data, idx0, out),
            4 => self.row::<4>(data, idx0, out),
            8 => self.row::<8>(data, idx0, out),
            _ => 0,
        }
    }
}

/// Determinant response and Laplacian sign at `(x, y)` for a filter of `side` pixels.
/// The caller guarantees the filter lies inside the image.
#[inline(always)]
fn hessian(ii: &Integral<'_>, x: isize, y: isize, side: isize) -> (f32, bool) {
    let r = box_responses(ii, x, y, side);
    // Normalise by the filter area and the slope LSB so responses are in degrees of slope,
    // comparable across scales.
    let inv = 1.0 / ((side * side) as f32 * 512.0);
    let dxx = r.dxx as f32 * inv;
    let dyy = r.dyy as f32 * inv;
    let dxy = r.dxy as f32 * inv;
    (
        dxx * dyy - DXY_WEIGHT_SQ * dxy * dxy,
        r.dxx as i64 + r.dyy as i64 >= 0,
    )
}

/// Largest keypoint scale σ (pixels) that a maximum in `layer` of `octave` can refine to: the
/// sub-scale step is at most half-way (in log side) towards the next layer. Slightly generous
/// (0.1 %) so that `f32` rounding in [`refine`] can never exceed it.
fn max_refined_sigma(octave: usize, layer: usize) -> f32 {
    let s0 = filter_side(octave, layer) as f32;
    let s1 = filter_side(octave, layer + 1) as f32;
    SIGMA_PER_SIDE * libm::sqrtf(s0 * s1) * 1.001 + SIGMA_OFFSET_PX
}

/// Length of the response ring (in `f32`) the detector needs for a frame `width` pixels wide.
pub const fn ring_len(width: usize) -> usize {
    MAX_LAYERS * RING_ROWS * width
}

/// Counters from one detection run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DetectStats {
    /// Responses above the threshold in the layers searched, inside the filters' reach, each
    /// tested for a strict 3×3×3 maximum (the detector's terrain-dependent work: steep or rough
    /// ground has many more than gentle ground).
    pub candidates: u32,
    /// Strict 3×3×3 maxima above the threshold, in the layers that can reach `min_scale_px`
    /// (layers that cannot are not searched at all).
    pub maxima: u32,
    /// Maxima refused because the filter footprint touched no-data pixels.
    pub rejected_nodata: u32,
    /// Maxima refused by sub-pixel refinement (offset > 0.5 or singular Hessian).
    pub rejected_refine: u32,
    /// Keypoints below `min_scale_px`.
    pub rejected_scale: u32,
    /// Responses of the lazy layers computed for candidates' maximum tests (at most
    /// [`DetectorConfig::max_lazy_responses`]).
    pub lazy_responses: u32,
    /// Lazy responses a candidate needed after [`DetectorConfig::max_lazy_responses`] were
    /// spent: each ended that candidate's test as "not a maximum" (0 on every frame of the HIL
    /// sets; the cap keeps detection's work inside what [`crate::cost`] charges on any input).
    pub lazy_refused: u32,
}

/// Most responses of the lazy layers one detection run of a flight frame computes on demand
/// ([`DetectorConfig::max_lazy_responses`]; reference tiles, built on the ground without a
/// work budget, are not capped). Past it a candidate that needs one more is taken as no
/// maximum and counted in [`DetectStats::lazy_refused`].
/// Detection's charge in [`crate::cost`] (3.95 M for a 100 × 100 binned frame) exceeds the
/// sweep of a featureless frame (3.06 M) by ≈ 0.89 M; a lazy response costs ≈ 360 Cortex-M4
/// instructions with its test (QEMU, session 41: `stress-max_keypoints`, 788 of them, 0.28 M),
/// so 2 000 (0.72 M) keep the lazy layers inside that margin on any input and detection is
/// bounded by construction. The most any of the 385 frames of seven HIL sets needed is 804.
pub const MAX_LAZY_RESPONSES: u32 = 2_000;

/// Run the detector, handing every accepted keypoint to `sink` (in a deterministic order).
pub(crate) fn detect(
    img: &SlopeImage<'_>,
    ii: &Integral<'_>,
    cfg: &DetectorConfig,
    ring: &mut [f32],
    sink: impl FnMut(Keypoint),
) -> Result<DetectStats, FrameError> {
    detect_swept(img, ii, cfg, ring, sink, false)
}

/// [`detect`], with `sweep_all` sweeping every layer row by row as before session 41 (the
/// tests' reference for the lazy layers).
fn detect_swept(
    img: &SlopeImage<'_>,
    ii: &Integral<'_>,
    cfg: &DetectorConfig,
    ring: &mut [f32],
    mut sink: impl FnMut(Keypoint),
    sweep_all: bool,
) -> Result<DetectStats, FrameError> {
    let (w, h) = (img.width(), img.height());
    let needed = ring_len(w);
    if ring.len() < needed {
        return Err(FrameError::TooLarge {
            needed,
            capacity: ring.len(),
        });
    }
    let has_nodata = img.pixels().iter().any(|p| !slope_is_valid(*p));
    let nodata_map = if has_nodata {
        NodataMap::build(img)
    } else {
        None
    };
    let mut stats = DetectStats::default();
    let (mut lazy_done, mut lazy_refused) = (0u32, 0u32);
    let layers = cfg.layers as usize;
    let data = ii.data();
    for octave in 0..cfg.octaves as usize {
        // Layers whose maxima can reach `min_scale_px` ("live"), and the layers their 3×3×3
        // neighbourhoods read. Maxima of the other layers would all be refused by the scale test,
        // so their responses are never computed: same keypoints, less work (a 10 m frame against
        // a 20 m tile skips the whole first octave).
        let live = |layer: usize| {
            layer >= 1
                && layer + 1 < layers
                && !(max_refined_sigma(octave, layer) < cfg.min_scale_px)
        };
        if !(1..layers.saturating_sub(1)).any(live) {
            continue;
        }
        let needed =
            |layer: usize| live(layer) || live(layer + 1) || (layer > 0 && live(layer - 1));
        // A layer read only as a live layer's neighbour ("lazy": the octave's first and last,
        // with the default four layers) is not swept row by row: a response of it is computed
        // when a candidate that is already the largest of its own layer's 3 × 3 (and of its
        // other neighbour layer, when that one is swept) needs it, and kept in the ring for the
        // next candidate.
        // Most candidates fail before, so half the octave's responses are never computed; the
        // ones that are get exactly the value the sweep would have given (same keypoints).
        let lazy = |layer: usize| !sweep_all && needed(layer) && !live(layer);
        let step = sample_step(octave);
        let kernels: [Kernel; MAX_LAYERS] =
            core::array::from_fn(|layer| Kernel::new(filter_side(octave, layer), w));
        let (gw, gh) = (w.div_ceil(step), h.div_ceil(step));
        let idx =
            |layer: usize, gy: usize, gx: usize| (layer * RING_ROWS + gy % RING_ROWS) * gw + gx;
        for gy in 0..gh {
            let y = gy * step;
            for layer in 0..layers {
                if !needed(layer) {
                    continue;
                }
                let side = filter_side(octave, layer);
                let half = (side - 1) / 2;
                let Some(kernel) = kernels.get(layer) else {
                    continue;
                };
                let row_start = idx(layer, gy, 0);
                let Some(row) = ring.get_mut(row_start..row_start + gw) else {
                    continue;
                };
                if lazy(layer) {
                    row.fill(NOT_YET);
                    continue;
                }
                let rows_inside = y >= half && y + half < h;
                // Grid columns whose filter lies inside the image: x ≥ half, x + half < w.
                let gx_lo = half.div_ceil(step).min(gw);
                let gx_hi = if w > half {
                    (w - half - 1) / step + 1
                } else {
                    0
                }
                .min(gw);
                if !rows_inside || gx_lo >= gx_hi {
                    row.fill(0.0);
                    continue;
                }
                // Outside the filter's reach the response is 0.
                if let Some(edge) = row.get_mut(..gx_lo) {
                    edge.fill(0.0);
                }
                if let Some(edge) = row.get_mut(gx_hi..) {
                    edge.fill(0.0);
                }
                // The first column may sit exactly on the filter's edge (x = half): its corners
                // reach column −1, so it takes the clipping path.
                let mut gx = gx_lo;
                if gx * step == half || y == half {
                    if y == half {
                        for (g, slot) in row.iter_mut().enumerate().take(gx_hi).skip(gx_lo) {
                            *slot = hessian(ii, (g * step) as isize, y as isize, side as isize).0;
                        }
                        continue;
                    }
                    if let Some(slot) = row.get_mut(gx) {
                        *slot = hessian(ii, (gx * step) as isize, y as isize, side as isize).0;
                    }
                    gx += 1;
                }
                if let Some(seg) = row.get_mut(gx..gx_hi) {
                    let done = kernel.row_any(step, data, y * w + gx * step, seg);
                    for (k, slot) in seg.iter_mut().enumerate().skip(done) {
                        *slot = kernel.response(data, y * w + (gx + k) * step);
                    }
                }
            }
            if gy < 2 {
                continue;
            }
            let cy = gy - 1;
            let row_start = |layer: usize, gy: usize| idx(layer, gy, 0);
            for layer in 1..layers - 1 {
                if !live(layer) {
                    continue;
                }
                // The largest filter of the neighbourhood must fit one step beyond the centre.
                let reach = (filter_side(octave, layer + 1) - 1) / 2 + step;
                let y = cy * step;
                if y < reach || y + reach >= h {
                    continue;
                }
                // The 3 × 3 × 3 neighbourhood's nine ring rows, found once per centre row (the
                // same layer's first: a candidate that is no maximum most often has a larger
                // neighbour there; a lazy layer's last, its responses being dear).
                let order = if lazy(layer - 1) {
                    [layer, layer + 1, layer - 1]
                } else {
                    [layer, layer - 1, layer + 1]
                };
                let rows = order.map(|l| [cy - 1, cy, cy + 1].map(|yy| row_start(l, yy)));
                for gx in 1..gw.saturating_sub(1) {
                    let x = gx * step;
                    if x < reach || x + reach >= w {
                        continue;
                    }
                    let v = ring.get(idx(layer, cy, gx)).copied().unwrap_or(0.0);
                    if v.is_nan() || v <= cfg.threshold {
                        continue;
                    }
                    stats.candidates = stats.candidates.saturating_add(1);
                    let fill = |li: usize, yi: usize, xx: usize| {
                        if lazy_done >= cfg.max_lazy_responses {
                            // Larger than any response: the candidate is no maximum.
                            lazy_refused = lazy_refused.saturating_add(1);
                            return f32::INFINITY;
                        }
                        lazy_done += 1;
                        let l = order.get(li).copied().unwrap_or(layer);
                        let side = filter_side(octave, l);
                        let at = (xx * step, (cy + yi - 1) * step);
                        kernels
                            .get(l)
                            .map_or(0.0, |k| on_demand(ii, k, (w, h), side, at))
                    };
                    if !strict_max(ring, &rows, gx, v, fill) {
                        continue;
                    }
                    stats.maxima += 1;
                    let touches = match &nodata_map {
                        Some(map) => map.touches(img, x, y, reach),
                        None => has_nodata && touches_nodata(img, x, y, reach),
                    };
                    if touches {
                        stats.rejected_nodata += 1;
                        continue;
                    }
                    let at = |layer: usize, gy: usize, gx: usize| {
                        ring.get(idx(layer, gy, gx)).copied().unwrap_or(0.0)
                    };
                    match refine(&at, ii, octave, layer, cy, gx) {
                        Some(kp) if kp.scale_px >= cfg.min_scale_px => sink(kp),
                        Some(_) => stats.rejected_scale += 1,
                        None => stats.rejected_refine += 1,
                    }
                }
            }
        }
    }
    stats.lazy_responses = lazy_done;
    stats.lazy_refused = lazy_refused;
    Ok(stats)
}

/// Ring entry of a lazy layer whose response has not been computed yet (no response is −∞: box
/// sums are finite).
const NOT_YET: f32 = f32::NEG_INFINITY;

/// Whether `v`, the response at column `gx` of the middle row of `rows[0]`, is larger than all
/// 26 neighbours: `rows` holds the ring offsets of the rows above, at and below the centre, for
/// the centre's layer and its two neighbour layers. A response outside the ring reads 0; one not
/// computed yet ([`NOT_YET`]) is `fill(layer index in rows, row index, column)`, stored in the
/// ring for the next candidate.
#[inline]
fn strict_max(
    ring: &mut [f32],
    rows: &[[usize; 3]; 3],
    gx: usize,
    v: f32,
    mut fill: impl FnMut(usize, usize, usize) -> f32,
) -> bool {
    for (li, layer_rows) in rows.iter().enumerate() {
        for (yi, &start) in layer_rows.iter().enumerate() {
            for xx in gx - 1..=gx + 1 {
                if (li, yi, xx) == (0, 1, gx) {
                    continue;
                }
                let r = match ring.get_mut(start + xx) {
                    Some(slot) if *slot == NOT_YET => {
                        *slot = fill(li, yi, xx);
                        *slot
                    }
                    Some(slot) => *slot,
                    None => 0.0,
                };
                if r >= v {
                    return false;
                }
            }
        }
    }
    true
}

/// Response of a filter of `side` pixels (`kernel` its offsets) at pixel `(x, y)` of a `w × h`
/// image, exactly as the row sweep of [`detect`] computes it: 0 where the filter leaves the
/// image, [`hessian`] where it touches the image's first row or column, [`Kernel::response`]
/// elsewhere.
#[inline(never)]
fn on_demand(
    ii: &Integral<'_>,
    kernel: &Kernel,
    (w, h): (usize, usize),
    side: usize,
    (x, y): (usize, usize),
) -> f32 {
    let half = (side - 1) / 2;
    if x < half || y < half || x + half >= w || y + half >= h {
        return 0.0;
    }
    if x == half || y == half {
        return hessian(ii, x as isize, y as isize, side as isize).0;
    }
    kernel.response(ii.data(), y * w + x)
}

/// Side of the blocks of [`NodataMap`], pixels.
const NODATA_BLOCK: usize = 8;
/// Blocks a [`NodataMap`] can hold (frames up to 724 × 724 pixels); larger frames use the plain
/// scan.
const NODATA_MAP_BLOCKS: usize = 8192;

/// One bit per 8 × 8 block: whether the block holds any no-data pixel. Lets the no-data test of
/// a maximum skip clean blocks and scan only the pixels of dirty ones (same answer as scanning
/// the whole square).
struct NodataMap {
    bits: [u32; NODATA_MAP_BLOCKS / 32],
    bw: usize,
}

impl NodataMap {
    fn build(img: &SlopeImage<'_>) -> Option<Self> {
        let (w, h) = (img.width(), img.height());
        let (bw, bh) = (w.div_ceil(NODATA_BLOCK), h.div_ceil(NODATA_BLOCK));
        if bw * bh > NODATA_MAP_BLOCKS {
            return None;
        }
        let mut map = Self {
            bits: [0; NODATA_MAP_BLOCKS / 32],
            bw,
        };
        for (row, px) in img.pixels().chunks_exact(w).enumerate() {
            for (col, p) in px.iter().enumerate() {
                if !slope_is_valid(*p) {
                    let b = (row / NODATA_BLOCK) * bw + col / NODATA_BLOCK;
                    if let Some(word) = map.bits.get_mut(b / 32) {
                        *word |= 1 << (b % 32);
                    }
                }
            }
        }
        Some(map)
    }

    fn dirty(&self, bx: usize, by: usize) -> bool {
        let b = by * self.bw + bx;
        self.bits
            .get(b / 32)
            .is_some_and(|w| w & (1 << (b % 32)) != 0)
    }

    /// [`touches_nodata`] through the block map.
    fn touches(&self, img: &SlopeImage<'_>, x: usize, y: usize, reach: usize) -> bool {
        let w = img.width();
        let px = img.pixels();
        let (x0, x1, y0, y1) = (x - reach, x + reach, y - reach, y + reach);
        for by in y0 / NODATA_BLOCK..=y1 / NODATA_BLOCK {
            for bx in x0 / NODATA_BLOCK..=x1 / NODATA_BLOCK {
                if !self.dirty(bx, by) {
                    continue;
                }
                let cx0 = x0.max(bx * NODATA_BLOCK);
                let cx1 = x1.min(bx * NODATA_BLOCK + NODATA_BLOCK - 1);
                let cy0 = y0.max(by * NODATA_BLOCK);
                let cy1 = y1.min(by * NODATA_BLOCK + NODATA_BLOCK - 1);
                for row in cy0..=cy1 {
                    if let Some(run) = px.get(row * w + cx0..=row * w + cx1)
                        && run.iter().any(|p| !slope_is_valid(*p))
                    {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Whether any pixel within `reach` of `(x, y)` (a square) is no data.
fn touches_nodata(img: &SlopeImage<'_>, x: usize, y: usize, reach: usize) -> bool {
    let w = img.width();
    let px = img.pixels();
    for row in y - reach..=y + reach {
        let start = row * w + x - reach;
        if let Some(run) = px.get(start..=start + 2 * reach)
            && run.iter().any(|p| !slope_is_valid(*p))
        {
            return true;
        }
    }
    false
}

/// Sub-pixel and sub-scale refinement of a 3×3×3 maximum.
///
/// Position: one Newton step x̂ = −H⁻¹∇ on the 3×3 responses of the maximum's layer (grid units);
/// offsets above 0.5 in x or y are rejected. Scale: the vertex of the parabola through the three
/// layers' responses in u = ln(side), because the layers are unevenly spaced in log-scale (9, 15,
/// 21, 27) and the response falls off about symmetrically in log-scale. The vertex of a parabola
/// through a strict maximum always lies within half a layer of it, so the 0.5 rule holds for
/// scale by construction. Position and scale are solved separately on purpose: the joint 3-D step
/// with layer-index spacing couples the scale model's error into position (measured: up to
/// 0.09 px bias on σ = 3.5 px blobs, 0.004 px decoupled).
fn refine(
    at: &impl Fn(usize, usize, usize) -> f32,
    ii: &Integral<'_>,
    octave: usize,
    layer: usize,
    cy: usize,
    gx: usize,
) -> Option<Keypoint> {
    let v = |dl: isize, dy: isize, dx: isize| {
        at(
            (layer as isize + dl) as usize,
            (cy as isize + dy) as usize,
            (gx as isize + dx) as usize,
        )
    };
    let c = v(0, 0, 0);
    let dx = (v(0, 0, 1) - v(0, 0, -1)) * 0.5;
    let dy = (v(0, 1, 0) - v(0, -1, 0)) * 0.5;
    let dxx = v(0, 0, 1) + v(0, 0, -1) - 2.0 * c;
    let dyy = v(0, 1, 0) + v(0, -1, 0) - 2.0 * c;
    let dxy = (v(0, 1, 1) - v(0, 1, -1) - v(0, -1, 1) + v(0, -1, -1)) * 0.25;
    let det = dxx * dyy - dxy * dxy;
    if !det.is_finite() || det.abs() <= f32::MIN_POSITIVE {
        return None;
    }
    let ox = -(dyy * dx - dxy * dy) / det;
    let oy = -(dxx * dy - dxy * dx) / det;
    let within = |o: f32| o.abs() <= 0.5;
    if !(within(ox) && within(oy)) {
        return None;
    }
    let side = filter_side(octave, layer);
    let (um, u0, up) = (
        libm::logf(filter_side(octave, layer - 1) as f32),
        libm::logf(side as f32),
        libm::logf(filter_side(octave, layer + 1) as f32),
    );
    let (vm, vp) = (v(-1, 0, 0), v(1, 0, 0));
    let num = (u0 - um) * (u0 - um) * (c - vp) - (u0 - up) * (u0 - up) * (c - vm);
    let den = (u0 - um) * (c - vp) - (u0 - up) * (c - vm);
    let u_star = if den.abs() > f32::MIN_POSITIVE {
        u0 - 0.5 * num / den
    } else {
        u0
    };
    let os = if u_star >= u0 {
        (u_star - u0) / (up - u0)
    } else {
        (u0 - u_star) / (u0 - um)
    };
    if !within(os) {
        return None;
    }
    let x = gx * sample_step(octave);
    let y = cy * sample_step(octave);
    let (_, lap) = hessian(ii, x as isize, y as isize, side as isize);
    // Response at the refined point, from the quadratic model.
    let response = c + 0.5 * (dx * ox + dy * oy);
    let step = sample_step(octave) as f32;
    Some(Keypoint {
        x_px: (gx as f32 + ox) * step,
        y_px: (cy as f32 + oy) * step,
        scale_px: SIGMA_PER_SIDE * libm::expf(u_star) + SIGMA_OFFSET_PX,
        orientation_rad: 0.0,
        response,
        laplacian_positive: lap,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{SlopePx, slope_from_deg};

    /// Keypoints (all fields' bits) and the shared counters of one run.
    fn run(px: &[SlopePx], w: usize, cfg: &DetectorConfig, sweep_all: bool) -> std::vec::Vec<u32> {
        let h = px.len() / w;
        let img = SlopeImage::new_checked(px, w, h, 20.0).unwrap();
        let mut integral = std::vec![0u32; w * h];
        let ii = Integral::build(&img, &mut integral).unwrap();
        let mut ring = std::vec![0.0f32; ring_len(w)];
        let mut out = std::vec::Vec::new();
        let stats = detect_swept(
            &img,
            &ii,
            cfg,
            &mut ring,
            |k| {
                out.extend([k.x_px, k.y_px, k.scale_px, k.response].map(f32::to_bits));
                out.push(k.laplacian_positive as u32);
            },
            sweep_all,
        )
        .unwrap();
        out.extend([
            stats.candidates,
            stats.maxima,
            stats.rejected_nodata,
            stats.rejected_refine,
            stats.rejected_scale,
        ]);
        out
    }

    #[test]
    fn lazy_layers_give_the_keypoints_of_the_full_sweep() {
        // Smooth random blobs plus noise, with and without a hole, on square and narrow
        // frames; 4 and 5 layers, up to 4 octaves, a raised minimum scale (only some layers
        // live) and a zero threshold (every position a candidate, lazy responses uncapped).
        let mut rng = crate::rng::Pcg32::new(41, 1);
        let mut next = move || (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32;
        let mut compared = 0;
        for (w, h) in [(120usize, 120usize), (200, 64), (40, 150)] {
            let blobs: std::vec::Vec<(f32, f32, f32, f32)> = (0..40)
                .map(|_| {
                    (
                        next() * w as f32,
                        next() * h as f32,
                        1.5 + next() * 8.0,
                        next() * 30.0,
                    )
                })
                .collect();
            let mut px: std::vec::Vec<SlopePx> = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let v: f32 = blobs
                        .iter()
                        .map(|&(bx, by, s, a)| {
                            a * libm::expf(-((x - bx).powi(2) + (y - by).powi(2)) / (2.0 * s * s))
                        })
                        .sum();
                    slope_from_deg((v + next() * 2.0).min(89.0))
                })
                .collect();
            for hole in [false, true] {
                if hole {
                    for r in h / 3..h / 3 + 6 {
                        for c in w / 4..w / 2 {
                            px[r * w + c] = crate::frame::SLOPE_NODATA;
                        }
                    }
                }
                for cfg in [
                    DetectorConfig {
                        threshold: 0.01,
                        ..DetectorConfig::default()
                    },
                    DetectorConfig {
                        threshold: 0.0,
                        layers: 5,
                        octaves: 4,
                        ..DetectorConfig::default()
                    },
                    DetectorConfig {
                        threshold: 0.01,
                        min_scale_px: 4.0,
                        ..DetectorConfig::default()
                    },
                    DetectorConfig {
                        threshold: 0.0,
                        layers: 5,
                        min_scale_px: 6.0,
                        ..DetectorConfig::default()
                    },
                ] {
                    let (lazy, swept) = (run(&px, w, &cfg, false), run(&px, w, &cfg, true));
                    assert_eq!(lazy, swept, "{w}×{h}, hole {hole}, {cfg:?}");
                    compared += (lazy.len() - 5) / 5;
                }
            }
        }
        assert!(compared > 200, "only {compared} keypoints compared");
    }
}
