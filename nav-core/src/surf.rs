//! SURF extraction: integral image → fast-Hessian keypoints → orientation → descriptor, with a
//! bounded, deterministic keypoint budget.

use crate::describe::{self, Descriptor, Weights};
use crate::detector::{self, ConfigError, DetectStats, DetectorConfig, Keypoint};
use crate::frame::{FrameError, SlopeImage};
use crate::integral::{Integral, integral_len};
use core::cmp::Ordering;
use core::fmt;
use heapless::binary_heap::{BinaryHeap, Min};

/// SURF settings.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SurfConfig {
    /// Fast-Hessian settings.
    pub detector: DetectorConfig,
    /// Skip orientation assignment (U-SURF): every keypoint gets orientation 0. Only for frames
    /// whose heading relative to the reference is already known to a few degrees.
    pub upright: bool,
}

/// Why extraction failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SurfError {
    /// The frame does not fit the workspace (or is malformed).
    Frame(FrameError),
    /// The configuration is out of range.
    Config(ConfigError),
}

impl fmt::Display for SurfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Frame(e) => write!(f, "SURF frame: {e}"),
            Self::Config(e) => write!(f, "SURF config: {e}"),
        }
    }
}

impl core::error::Error for SurfError {}

impl From<FrameError> for SurfError {
    fn from(e: FrameError) -> Self {
        Self::Frame(e)
    }
}
impl From<ConfigError> for SurfError {
    fn from(e: ConfigError) -> Self {
        Self::Config(e)
    }
}

/// One feature: keypoint plus descriptor.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Feature {
    /// Where and how large.
    pub keypoint: Keypoint,
    /// What it looks like.
    pub descriptor: Descriptor,
}

/// Result of one extraction: at most `N` features, strongest first.
#[derive(Debug, Clone)]
pub struct Features<const N: usize> {
    features: heapless::Vec<Feature, N>,
    /// Accepted keypoints not kept because the budget `N` was full (the weakest go).
    pub dropped: u32,
    /// Detector counters.
    pub stats: DetectStats,
}

impl<const N: usize> Default for Features<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Features<N> {
    /// Empty set.
    pub const fn new() -> Self {
        Self {
            features: heapless::Vec::new(),
            dropped: 0,
            stats: DetectStats {
                candidates: 0,
                maxima: 0,
                rejected_nodata: 0,
                rejected_refine: 0,
                rejected_scale: 0,
                lazy_responses: 0,
                lazy_refused: 0,
            },
        }
    }
    /// Empty the set (no features, counters zero), in place.
    pub fn clear(&mut self) {
        self.features.clear();
        self.dropped = 0;
        self.stats = DetectStats::default();
    }
    /// The features, strongest first (see [`Keypoint::rank_cmp`]).
    pub fn as_slice(&self) -> &[Feature] {
        &self.features
    }
    /// Number of features.
    pub fn len(&self) -> usize {
        self.features.len()
    }
    /// No features.
    pub fn is_empty(&self) -> bool {
        self.features.is_empty()
    }
    /// Memory of this set in bytes.
    pub const fn footprint_bytes() -> usize {
        core::mem::size_of::<Self>()
    }
    /// Express keypoints found on a `k × k`-binned image in the unbinned image's pixels: a binned
    /// pixel `c` covers pixels `k·c … k·c + k − 1`, so its centre is at `k·c + (k − 1)/2`.
    pub fn unbin(&mut self, k: usize) {
        let kf = k as f32;
        let off = (kf - 1.0) * 0.5;
        for f in self.features.iter_mut() {
            f.keypoint.x_px = f.keypoint.x_px * kf + off;
            f.keypoint.y_px = f.keypoint.y_px * kf + off;
            f.keypoint.scale_px *= kf;
        }
    }
}

/// Wrapper giving keypoints the total order used for selection.
#[derive(Clone, Copy)]
struct Ranked(Keypoint);
impl PartialEq for Ranked {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Ranked {}
impl PartialOrd for Ranked {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Ranked {
    fn cmp(&self, o: &Self) -> Ordering {
        self.0.rank_cmp(&o.0)
    }
}

/// Caller-owned scratch for one extraction: the integral image and the detector's response ring.
pub struct Scratch<'a> {
    /// At least [`integral_len`] `u32`.
    pub integral: &'a mut [u32],
    /// At least [`detector::ring_len`] `f32`.
    pub ring: &'a mut [f32],
}

/// Scratch sizes `(integral u32s, ring f32s)` for a `width × height` frame.
pub const fn scratch_len(width: usize, height: usize) -> (usize, usize) {
    (integral_len(width, height), detector::ring_len(width))
}

/// Fixed-capacity workspace for frames of at most `MAX_PX` pixels and `MAX_W` columns.
///
/// Memory: `4·MAX_PX + 4·MAX_LAYERS·3·MAX_W` bytes (see `docs/bounds.md`).
pub struct SurfWorkspace<const MAX_PX: usize, const MAX_W: usize> {
    integral: [u32; MAX_PX],
    ring: [[[f32; MAX_W]; detector::RING_ROWS]; detector::MAX_LAYERS],
}

impl<const MAX_PX: usize, const MAX_W: usize> Default for SurfWorkspace<MAX_PX, MAX_W> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX_PX: usize, const MAX_W: usize> SurfWorkspace<MAX_PX, MAX_W> {
    /// Zeroed workspace (`const`, so it can live in a `static`).
    pub const fn new() -> Self {
        Self {
            integral: [0; MAX_PX],
            ring: [[[0.0; MAX_W]; detector::RING_ROWS]; detector::MAX_LAYERS],
        }
    }
    /// Borrow as slices.
    pub fn scratch(&mut self) -> Scratch<'_> {
        Scratch {
            integral: &mut self.integral,
            ring: self.ring.as_flattened_mut().as_flattened_mut(),
        }
    }
    /// Memory of this workspace in bytes.
    pub const fn footprint_bytes() -> usize {
        core::mem::size_of::<Self>()
    }
}

/// Extract at most `N` SURF features from `img` into `out` (cleared first).
///
/// Frames too small for the smallest filter give an empty result, not an error; frames larger than
/// the scratch give [`SurfError::Frame`]. The same input gives bit-identical output on every
/// target: integer box sums, IEEE `f32` arithmetic in a fixed order, and `libm`'s portable
/// transcendental functions.
pub fn extract<const N: usize>(
    img: &SlopeImage<'_>,
    cfg: &SurfConfig,
    scratch: Scratch<'_>,
    out: &mut Features<N>,
) -> Result<(), SurfError> {
    *out = Features::new();
    cfg.detector.validate()?;
    let ii = Integral::build(img, scratch.integral)?;
    let mut heap: BinaryHeap<Ranked, Min, N> = BinaryHeap::new();
    let mut dropped = 0u32;
    let stats = detector::detect(img, &ii, &cfg.detector, scratch.ring, |kp| {
        let cand = Ranked(kp);
        if let Err(cand) = heap.push(cand) {
            // Full: keep the stronger of the candidate and the current weakest.
            dropped = dropped.saturating_add(1);
            if heap.peek().is_some_and(|weakest| cand > *weakest) {
                heap.pop();
                // Cannot fail: one slot was just freed.
                let _ = heap.push(cand);
            }
        }
    })?;
    let weights = Weights::new();
    let mut ranked = heap.into_vec();
    ranked.sort_unstable_by(|a, b| b.cmp(a));
    for Ranked(mut kp) in ranked {
        if !cfg.upright {
            kp.orientation_rad = describe::orientation(&ii, &kp, &weights);
        }
        let descriptor = describe::descriptor(&ii, &kp, &weights);
        // Cannot fail: at most N keypoints came out of the heap.
        let _ = out.features.push(Feature {
            keypoint: kp,
            descriptor,
        });
    }
    out.dropped = dropped;
    out.stats = stats;
    Ok(())
}
