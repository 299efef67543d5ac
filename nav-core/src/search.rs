//! Prior-aided area search: when the feature path finds no fix but the flyer knows roughly where
//! it is (a [`Prior`] from its filter), correlate the frame's slope image against the tile's
//! slope raster over the prior's window and hand the best alignment to the dense refinement
//! ([`crate::refine`]), which confirms or refuses it.
//!
//! Why: on gentle terrain or a noisy reference, a 16-keypoint budget finds too few repeatable
//! blobs, yet the slope field itself still has texture that a frame-wide correlation locks onto.
//! With a prior of tens of metres and a few degrees the search space is small: a few hundred
//! positions, a handful of headings and scales.
//!
//! Method, two levels on regular sample grids of the frame (slope is rotation-invariant, so
//! only the sampling pattern turns with the heading):
//! 1. coarse: [`COARSE_GRID`]² samples, positions every [`COARSE_STEP_PX`] tile
//!    pixels over ±3σ of the prior (at most [`MAX_OFFSETS`] per axis), headings and scales over
//!    ±3σ in steps that move the outermost sample by about one step (at most [`MAX_HEADINGS`]
//!    and [`MAX_SCALES`]); the [`MAX_CANDIDATES`] best peaks at least
//!    [`SearchConfig::exclusion_px`] apart are kept;
//! 2. the best peak climbs uphill in 1 px steps on the coarse grid;
//! 3. fine: [`FINE_GRID`]² samples around it and around every other peak (±1 px, half steps in
//!    heading and scale); a winner below [`SearchConfig::min_fine_ncc`] there ends the search
//!    (nothing matches); the other peaks climb on the fine grid, and those that settle on a
//!    maximum of their own within [`CLIMB_STEPS`], clear of the winner, and with a valley
//!    between them and the winner (the fine correlation dips by more than
//!    [`SearchConfig::min_margin`] somewhere on the path, [`MAX_VALLEY_STEPS`] points at most),
//!    are runners: the winner must beat every runner by [`SearchConfig::min_margin`];
//! 4. the best fine candidate starts the Gauss–Newton refinement. The fix stands only if the
//!    refinement converges to a correlation of at least [`SearchConfig::confirm_min_ncc`] and
//!    the best peak stands clear of every other ([`SearchConfig::min_margin`]): a second, nearly as good
//!    alignment beyond a valley means the terrain is ambiguous, and no fix is safer. A ridge
//!    without a valley (a frame along a crater rim) is one peak: the refinement settles where on
//!    it the frame lies, with a covariance that says how well, or refuses it as singular.
//!
//! Bounds: level 1 reads at most `MAX_OFFSETS² · MAX_HEADINGS · MAX_SCALES · COARSE_GRID²`
//! raster pixels, the winner's climb `CLIMB_STEPS · 8 · COARSE_GRID²`, the fine level
//! `MAX_CANDIDATES · 81 · FINE_GRID²` (3 headings × 3 scales × 9 positions a peak) and the runners' climbs
//! `(MAX_CANDIDATES − 1) · CLIMB_STEPS · 8 · FINE_GRID²`, the valley paths
//! `(MAX_CANDIDATES − 1) · (MAX_VALLEY_STEPS − 1) · FINE_GRID²`; the sample lists live on
//! the stack (≈ 3 KiB). Arithmetic is `f32` per sample in a fixed order, sums per candidate, so
//! host and target agree bit for bit.

use crate::frame::{SLOPE_MAX_RAW, SlopeImage, SlopePx, slope_is_valid};
use crate::msac::Affine;
use crate::navigator::Prior;
use crate::tile::SlopeRaster;

/// Samples per side of the coarse grid.
pub const COARSE_GRID: usize = 7;
/// Samples per side of the fine grid.
pub const FINE_GRID: usize = 12;
/// Coarse positions per axis at most (the window is clipped to this many steps).
pub const MAX_OFFSETS: usize = 9;
/// Coarse position step, tile pixels. The tile's slope is smoothed over about two tile pixels,
/// so a correlation peak is a few pixels wide and a 2 px lattice cannot miss it; an integer
/// step lets every position reuse the sample pattern's rounded raster offsets.
pub const COARSE_STEP_PX: i32 = 2;
/// Coarse headings at most.
pub const MAX_HEADINGS: usize = 5;
/// Coarse scales at most.
pub const MAX_SCALES: usize = 3;
/// Peaks kept from the coarse level.
pub const MAX_CANDIDATES: usize = 3;

/// Largest prior scale the search accepts, tile pixels per (binned) frame pixel.
pub const MAX_PRIOR_SCALE: f32 = 100.0;
/// Largest prior centre coordinate the search accepts, tile pixels.
pub const MAX_PRIOR_COORD_PX: f32 = 1.0e7;

/// Search settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SearchConfig {
    /// Run the search when the feature path gives no fix and a prior is given.
    pub enabled: bool,
    /// Search only when the prior's heading σ is at most this, radians: beyond it the heading
    /// steps would not cover ±3σ within [`MAX_HEADINGS`].
    pub max_heading_sigma_rad: f32,
    /// Largest displacement of the outermost coarse sample between neighbouring headings or
    /// scales, tile pixels (sets those steps).
    pub angle_step_px: f32,
    /// Coarse peaks closer than this to a better one are the same peak, tile pixels.
    pub exclusion_px: f32,
    /// The best fine correlation must exceed every other peak's by this much.
    pub min_margin: f32,
    /// Fewest valid coarse samples (of [`COARSE_GRID`]²) for a candidate to count.
    pub min_valid_fraction: f32,
    /// The best coarse correlation must reach this for the search to go on (a frame that
    /// correlates with nothing in the window stops here, before the costlier levels).
    pub min_coarse_ncc: f32,
    /// The winner's correlation (NCC, −1 to 1) on the fine grid must reach this, or the search
    /// ends without a hit. Only the coarse top's fine peak is tested: a window whose top is not
    /// the match gives no fix, as it did before as "two peaks alike".
    pub min_fine_ncc: f32,
    /// The refinement that confirms a hit must converge to at least this correlation (NCC of
    /// frame and reference slope over the refinement's samples; the refinement's own
    /// `min_ncc` applies too).
    ///
    /// Why not the feature path's `verify_min_ncc` (0.7): that gate stands in for a consensus
    /// of too few inliers, which lost in space can be a coincidence anywhere on the tile, and
    /// was set on truth-built tiles, where true alignments read 0.90–0.95. A hit is confined to
    /// the prior's window and has passed its own tests (a clear fine peak, a margin over every
    /// runner beyond a valley, the prior gate after), and where the reference's noise is as
    /// strong as the terrain's texture (an InSAR map of smooth plains) the true alignment
    /// itself correlates below 0.7: at seed 2, 35 of 300 plains frames were right (error ≤ 7 m,
    /// within their 3σ) at NCC 0.61–0.70 and were refused. Wrong alignments refined from
    /// wrong starts read ≤ 0.153 (`dense_check_does_not_confirm_wrong_starts`). 0.5 is the
    /// fine level's and the refinement's own floor, not a value swept on a campaign.
    pub confirm_min_ncc: f32,
    /// Sample budget of the refinement that confirms a hit (the feature path's refinement uses
    /// [`crate::refine::RefineConfig::max_samples`]); smaller because the search has already
    /// spent part of the frame's instruction budget.
    pub refine_max_samples: u32,
    /// Gauss–Newton iterations of that refinement at most (a hit starts within about a pixel
    /// and a degree; with the step control, InSAR fresh-floor hits took 3–15 updates, 18 of 296
    /// more than 10).
    pub refine_max_iterations: u8,
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            max_heading_sigma_rad: 0.15,
            angle_step_px: 2.5,
            exclusion_px: 3.0,
            min_margin: 0.1,
            min_valid_fraction: 0.7,
            min_coarse_ncc: 0.3,
            min_fine_ncc: 0.5,
            confirm_min_ncc: 0.5,
            refine_max_samples: 800,
            refine_max_iterations: 16,
        }
    }
}

/// Why the search gave no starting point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SearchError {
    /// Switched off, or no prior was given.
    Disabled,
    /// The tile carries no slope raster.
    NoRaster,
    /// The prior's heading σ exceeds [`SearchConfig::max_heading_sigma_rad`], or a prior value
    /// is not finite or out of range (scale not in (0, [`MAX_PRIOR_SCALE`]], centre beyond
    /// [`MAX_PRIOR_COORD_PX`]).
    PriorTooWide,
    /// Too few valid frame samples, or a textureless frame.
    FlatFrame,
    /// No candidate with enough valid reference samples under it.
    NoCandidate,
    /// Nothing in the window correlates with the frame ([`SearchConfig::min_coarse_ncc`] on the
    /// coarse grid, [`SearchConfig::min_fine_ncc`] on the fine one).
    NoMatch,
    /// Another peak correlates nearly as well as the best ([`SearchConfig::min_margin`]).
    Ambiguous,
    /// Not run: the frame's work budget ([`crate::NavConfig::work_budget`]) had no room for
    /// the whole lattice and a hit's refinement.
    OverBudget,
}

impl core::fmt::Display for SearchError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Disabled => "disabled",
            Self::NoRaster => "tile has no slope raster",
            Self::PriorTooWide => "prior too wide",
            Self::FlatFrame => "frame too flat or too sparse",
            Self::NoCandidate => "too little valid reference under the prior window",
            Self::NoMatch => "nothing in the window correlates",
            Self::Ambiguous => "two peaks alike",
            Self::OverBudget => "no room left in the frame's work budget",
        })
    }
}

/// What the search found: the best alignment and how clearly it won.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SearchHit {
    /// Frame pixels (unbinned) → tile pixels, a similarity.
    pub affine: Affine,
    /// Normalised cross-correlation of the winner on the fine grid.
    pub ncc: f32,
    /// The winner's correlation on the coarse grid (after climbing to its 1 px peak).
    pub coarse_ncc: f32,
    /// The best fine correlation at the other peaks that settle on a maximum of their own beyond
    /// a valley (−1 when there was none; a maximum on the winner's own ridge is not counted):
    /// at most `ncc − min_margin`.
    pub runner_up_ncc: f32,
    /// Coarse candidates evaluated.
    pub coarse_cells: u32,
}

/// One frame sample: offset from the frame centre in binned frame pixels, and its slope.
#[derive(Clone, Copy, Default)]
struct Sample {
    u: f32,
    v: f32,
    f: f32,
}

/// Sums of one candidate.
#[derive(Clone, Copy, Default)]
struct Corr {
    n: u32,
    sf: f32,
    st: f32,
    sff: f32,
    stt: f32,
    sft: f32,
}

impl Corr {
    #[inline]
    fn add(&mut self, f: f32, t: f32) {
        self.n += 1;
        self.sf += f;
        self.st += t;
        self.sff += f * f;
        self.stt += t * t;
        self.sft += f * t;
    }
    fn ncc(&self) -> f32 {
        let n = self.n as f32;
        if n < 3.0 {
            return -1.0;
        }
        let vf = self.sff - self.sf * self.sf / n;
        let vt = self.stt - self.st * self.st / n;
        let c = self.sft - self.sf * self.st / n;
        if vf > 0.0 && vt > 0.0 {
            c / libm::sqrtf(vf * vt)
        } else {
            -1.0
        }
    }
}

/// A candidate pose: tile position of the frame centre, heading, scale (tile px per binned px).
#[derive(Clone, Copy, Default)]
struct Cand {
    x: f32,
    y: f32,
    heading: f32,
    scale: f32,
    ncc: f32,
}

/// Nearest integer (half up) of `x`, −1 for anything below −0.5 or not finite: a plain
/// float-to-int conversion, one instruction on the target.
#[inline]
fn round_i32(x: f32) -> i32 {
    let y = x + 0.5;
    if y >= 0.0 { y as i32 } else { -1 }
}

/// Raw slope (1/512°) of raster pixel `(col, row)`; `None` outside or without data. Raw units
/// suffice: the correlation is invariant to the scale of either side.
#[inline]
fn raw(r: &SlopeRaster<'_>, col: i32, row: i32) -> Option<f32> {
    if col < 0 || row < 0 {
        return None;
    }
    let p: SlopePx = r.get(col as usize, row as usize);
    slope_is_valid(p).then(|| p.to_bits() as f32)
}

/// Fill `out` with a `grid × grid` lattice of valid frame samples over the frame's inner 90 %;
/// returns how many were valid.
fn frame_samples<const S: usize>(
    img: &SlopeImage<'_>,
    grid: usize,
    out: &mut [Sample; S],
) -> usize {
    let (w, h) = (img.width(), img.height());
    let (uc, vc) = ((w as f32 - 1.0) * 0.5, (h as f32 - 1.0) * 0.5);
    let mut n = 0usize;
    let grid = grid.max(2);
    for j in 0..grid {
        let v =
            libm::roundf(0.05 * h as f32 + (0.9 * h as f32 - 1.0) * j as f32 / (grid - 1) as f32);
        for i in 0..grid {
            let u = libm::roundf(
                0.05 * w as f32 + (0.9 * w as f32 - 1.0) * i as f32 / (grid - 1) as f32,
            );
            let p = img.get(u as usize, v as usize);
            if !slope_is_valid(p) {
                continue;
            }
            if let Some(slot) = out.get_mut(n) {
                *slot = Sample {
                    u: u - uc,
                    v: v - vc,
                    f: p.to_bits() as f32,
                };
                n += 1;
            }
        }
    }
    n
}

/// Correlation of `samples` with the raster under candidate `c`.
/// [`correlate`], counting the samples read into `reads`.
fn correlate_counted(samples: &[Sample], r: &SlopeRaster<'_>, c: &Cand, reads: &mut u32) -> Corr {
    *reads = reads.saturating_add(samples.len() as u32);
    correlate(samples, r, c)
}

fn correlate(samples: &[Sample], r: &SlopeRaster<'_>, c: &Cand) -> Corr {
    let (sn, cs) = (libm::sinf(c.heading), libm::cosf(c.heading));
    let (a, b) = (c.scale * cs, c.scale * sn);
    let mut k = Corr::default();
    for s in samples {
        let x = round_i32(a * s.u - b * s.v + c.x);
        let y = round_i32(b * s.u + a * s.v + c.y);
        if let Some(t) = raw(r, x, y) {
            k.add(s.f, t);
        }
    }
    k
}

/// Steps `−n..=n` of size `step` covering ±`half` (n ≤ (max − 1)/2).
fn steps(half: f32, step: f32, max: usize) -> (i32, f32) {
    if !(half > 0.0 && step > 0.0) {
        return (0, step.max(0.0));
    }
    let n = libm::ceilf(half / step).clamp(0.0, ((max.max(1) - 1) / 2) as f32) as i32;
    (n, step)
}

/// What a search ran, whatever its result (what the navigator charges the frame's work budget).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SearchWork {
    /// Coarse lattice cells correlated.
    pub coarse_cells: u32,
    /// Of those, cells whose sample pattern reached past the raster's edge (read with 2-D
    /// bounds checks, about twice the work of an inner cell).
    pub edge_cells: u32,
    /// The fine level ran (the winner's coarse climb and fine lattice).
    pub fine: bool,
    /// Runners searched on the fine level (each: its fine lattice, climb and valley path).
    pub runners: u8,
    /// Frame samples correlated after the coarse lattice (the winner's coarse climb, the fine
    /// lattices, climbs and valley paths): what the fine level's work varies with.
    pub fine_reads: u32,
}

/// Search the prior's window for the frame `img` (binned by `bin` from the frame's pixel grid)
/// in `raster`. The prior's scale is tile pixels per unbinned frame pixel.
pub fn search(
    img: &SlopeImage<'_>,
    bin: usize,
    raster: &SlopeRaster<'_>,
    prior: &Prior,
    cfg: &SearchConfig,
) -> Result<SearchHit, SearchError> {
    search_metered(img, bin, raster, prior, cfg, &mut SearchWork::default())
}

/// [`search`], recording in `work` what it ran.
pub fn search_metered(
    img: &SlopeImage<'_>,
    bin: usize,
    raster: &SlopeRaster<'_>,
    prior: &Prior,
    cfg: &SearchConfig,
    work: &mut SearchWork,
) -> Result<SearchHit, SearchError> {
    if !cfg.enabled {
        return Err(SearchError::Disabled);
    }
    let k = bin.max(1) as f32;
    let scale0 = prior.scale * k;
    // Bounded inputs keep every raster coordinate well inside `i32` (frame sides ≤ 2¹⁴ px).
    if !(prior.heading_sigma_rad.abs() <= cfg.max_heading_sigma_rad
        && scale0 > 0.0
        && scale0 <= MAX_PRIOR_SCALE
        && prior.sigma_px.is_finite()
        && prior
            .center_tile_px
            .iter()
            .all(|v| v.abs() <= MAX_PRIOR_COORD_PX)
        && prior.heading_rad.is_finite()
        && prior.scale_sigma.is_finite())
    {
        return Err(SearchError::PriorTooWide);
    }
    let mut coarse = [Sample::default(); COARSE_GRID * COARSE_GRID];
    let nc = frame_samples(img, COARSE_GRID, &mut coarse);
    let coarse = coarse.get(..nc).unwrap_or(&[]);
    let need = (cfg.min_valid_fraction * (COARSE_GRID * COARSE_GRID) as f32) as u32;
    if (nc as u32) < need.max(8) {
        return Err(SearchError::FlatFrame);
    }
    // Outermost sample radius in tile pixels sets the heading and scale steps.
    let radius = coarse
        .iter()
        .fold(0.0f32, |m, s| m.max(libm::hypotf(s.u, s.v)))
        * scale0;
    if !(radius > 1.0) {
        return Err(SearchError::FlatFrame);
    }
    let dp = COARSE_STEP_PX as f32;
    let (np, _) = steps(3.0 * prior.sigma_px.abs(), dp, MAX_OFFSETS);
    let (nh, dh) = steps(
        3.0 * prior.heading_sigma_rad.abs(),
        cfg.angle_step_px / radius,
        MAX_HEADINGS,
    );
    let (ns, ds) = steps(
        3.0 * prior.scale_sigma.abs() / prior.scale.max(f32::MIN_POSITIVE),
        cfg.angle_step_px / radius,
        MAX_SCALES,
    );
    let mut best = [Cand {
        ncc: -2.0,
        ..Cand::default()
    }; MAX_CANDIDATES];
    let mut cells = 0u32;
    let [px, py] = prior.center_tile_px;
    // Rounded raster offsets of the sample pattern at the window centre; every lattice
    // position shifts them by whole pixels.
    let mut at = [(0i32, 0i32); COARSE_GRID * COARSE_GRID];
    let mut lin = [0i32; COARSE_GRID * COARSE_GRID];
    // Raster sides fit i32: MAX_RASTER_PX is 2²⁸.
    let (wr, hr) = (raster.width() as i32, raster.height() as i32);
    for ih in -nh..=nh {
        let heading = prior.heading_rad + ih as f32 * dh;
        let (sn, cs) = (libm::sinf(heading), libm::cosf(heading));
        for is in -ns..=ns {
            let scale = scale0 * (1.0 + is as f32 * ds);
            let (a, b) = (scale * cs, scale * sn);
            let (mut c0, mut c1, mut r0, mut r1) = (i32::MAX, i32::MIN, i32::MAX, i32::MIN);
            for ((o, l), s) in at.iter_mut().zip(lin.iter_mut()).zip(coarse) {
                *o = (
                    round_i32(a * s.u - b * s.v + px),
                    round_i32(b * s.u + a * s.v + py),
                );
                (c0, c1) = (c0.min(o.0), c1.max(o.0));
                (r0, r1) = (r0.min(o.1), r1.max(o.1));
                *l = o.1.wrapping_mul(wr).wrapping_add(o.0);
            }
            for iy in -np..=np {
                let sy = iy * COARSE_STEP_PX;
                for ix in -np..=np {
                    let sx = ix * COARSE_STEP_PX;
                    cells += 1;
                    let mut k = Corr::default();
                    if c0 + sx >= 0 && c1 + sx < wr && r0 + sy >= 0 && r1 + sy < hr {
                        // The whole pattern lies inside the raster: linear indices, no 2-D
                        // bounds checks.
                        let shift = sy * wr + sx;
                        for (&l, s) in lin.iter().zip(coarse) {
                            let p = raster.raw_index((l + shift) as usize);
                            if p <= SLOPE_MAX_RAW {
                                k.add(s.f, p as f32);
                            }
                        }
                    } else {
                        work.edge_cells = work.edge_cells.saturating_add(1);
                        for (&(oc, or), s) in at.iter().zip(coarse) {
                            if let Some(t) = raw(raster, oc + sx, or + sy) {
                                k.add(s.f, t);
                            }
                        }
                    }
                    if k.n < need.max(8) {
                        continue;
                    }
                    let c = Cand {
                        x: px + sx as f32,
                        y: py + sy as f32,
                        heading,
                        scale,
                        ncc: k.ncc(),
                    };
                    insert(&mut best, c, cfg.exclusion_px);
                }
            }
        }
    }
    work.coarse_cells = cells;
    let coarse_best = best.iter().fold(-2.0f32, |m, c| m.max(c.ncc));
    if coarse_best < -1.0 {
        return Err(SearchError::NoCandidate);
    }
    if coarse_best < cfg.min_coarse_ncc {
        return Err(SearchError::NoMatch);
    }
    let mut order: [usize; MAX_CANDIDATES] = core::array::from_fn(|i| i);
    // Best first (a fixed, total order: ties keep the insertion rank).
    order.sort_unstable_by(|&i, &j| {
        let (a, b): (f32, f32) = (
            best.get(i).map_or(-2.0, |c| c.ncc),
            best.get(j).map_or(-2.0, |c| c.ncc),
        );
        b.total_cmp(&a).then(i.cmp(&j))
    });
    let Some(top) = order.first().and_then(|&i| best.get(i)).copied() else {
        return Err(SearchError::NoCandidate);
    };
    // Every peak climbed uphill in position (1 px steps, at most CLIMB_STEPS) on the coarse
    // samples: a runner-up counts only as a peak of its own, clear of the top's. On smooth slope
    // fields the main peak's shoulders are the best lattice cells outside it, and they are not
    // ambiguity.
    let need = need.max(8);
    work.fine = true;
    let (top, _) = climb(coarse, raster, top, need, &mut work.fine_reads);
    // Fine level around the winner: ±1 px, half steps in heading and scale.
    let mut fine = [Sample::default(); FINE_GRID * FINE_GRID];
    let nf = frame_samples(img, FINE_GRID, &mut fine);
    let fine = fine.get(..nf).unwrap_or(&[]);
    let need_fine = ((cfg.min_valid_fraction * nf as f32) as u32).max(8);
    let winner = fine_peak(
        fine,
        raster,
        top,
        (dh, ds, ns),
        need_fine,
        &mut work.fine_reads,
    );
    if winner.ncc <= -1.0 {
        return Err(SearchError::NoCandidate);
    }
    // The coarse lattice's best of up to 1 215 cells can read 0.3–0.4 on a frame that matches
    // nothing (its 49 samples correlate by chance); the fine lattice judges before the runners
    // and the refinement spend their share of the budget.
    if winner.ncc < cfg.min_fine_ncc {
        return Err(SearchError::NoMatch);
    }
    // The margin is judged on the fine grid (the coarse one is too noisy for it): each runner's
    // best fine correlation within ±1 px of its peak.
    // A runner counts only as a peak of its own: searched like the winner, then climbed in
    // position on the fine grid, it must reach a local maximum within CLIMB_STEPS that stands
    // clear of the winner. On smooth slope fields the main peak's shoulders are the best
    // lattice cells outside it; they climb towards it and are not ambiguity.
    let mut runner = -1.0f32;
    for c in order.iter().skip(1).filter_map(|&i| best.get(i)) {
        if c.ncc <= -1.0 {
            continue;
        }
        work.runners = work.runners.saturating_add(1);
        let start = fine_peak(
            fine,
            raster,
            *c,
            (dh, ds, ns),
            need_fine,
            &mut work.fine_reads,
        );
        let (peak, settled) = climb(fine, raster, start, need_fine, &mut work.fine_reads);
        if settled
            && libm::hypotf(peak.x - winner.x, peak.y - winner.y) > cfg.exclusion_px
            && (peak.ncc <= winner.ncc - cfg.min_margin
                || valley(
                    fine,
                    raster,
                    (&winner, &peak),
                    need_fine,
                    cfg.min_margin,
                    &mut work.fine_reads,
                ))
        {
            runner = runner.max(peak.ncc);
        }
    }
    if runner > winner.ncc - cfg.min_margin {
        return Err(SearchError::Ambiguous);
    }
    let coarse_ncc = top.ncc;
    let top = winner;
    // Centre-anchored similarity in binned pixels → unbinned frame pixels → tile pixels.
    let (w, h) = (img.width() as f32, img.height() as f32);
    let (uc, vc) = ((w - 1.0) * 0.5, (h - 1.0) * 0.5);
    let (sn, cs) = (libm::sinf(top.heading), libm::cosf(top.heading));
    let s = top.scale / k; // tile px per unbinned frame px
    let (a, b) = ((s * cs) as f64, (s * sn) as f64);
    // Unbinned coordinates of the binned image centre: x = k·u + (k − 1)/2.
    let (xc, yc) = (
        (k * uc + 0.5 * (k - 1.0)) as f64,
        (k * vc + 0.5 * (k - 1.0)) as f64,
    );
    let affine = Affine {
        m1: a,
        n1: -b,
        p1: top.x as f64 - a * xc + b * yc,
        m2: b,
        n2: a,
        p2: top.y as f64 - b * xc - a * yc,
    };
    Ok(SearchHit {
        affine,
        ncc: top.ncc,
        coarse_ncc,
        runner_up_ncc: runner,
        coarse_cells: cells,
    })
}

/// The best fine-grid correlation within ±1 px and half a coarse step in heading and scale of
/// `c` (`steps` = heading step, scale step, scale step count).
fn fine_peak(
    fine: &[Sample],
    r: &SlopeRaster<'_>,
    c: Cand,
    (dh, ds, ns): (f32, f32, i32),
    need: u32,
    reads: &mut u32,
) -> Cand {
    let mut best = Cand { ncc: -2.0, ..c };
    for dh_i in -1..=1 {
        for ds_i in -1..=1 {
            if ns == 0 && ds_i != 0 {
                continue;
            }
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let mut t = Cand {
                        x: c.x + dx as f32,
                        y: c.y + dy as f32,
                        heading: c.heading + 0.5 * dh_i as f32 * dh,
                        scale: c.scale * (1.0 + 0.5 * ds_i as f32 * ds),
                        ncc: 0.0,
                    };
                    let k = correlate_counted(fine, r, &t, reads);
                    if k.n < need {
                        continue;
                    }
                    t.ncc = k.ncc();
                    if t.ncc > best.ncc {
                        best = t;
                    }
                }
            }
        }
    }
    best
}

/// Segments at most of the path between the winner and a runner that [`valley`] correlates at
/// their `MAX_VALLEY_STEPS − 1` inner points: 1 px apart up to 16 px, the coarse window's width
/// (`(MAX_OFFSETS − 1) · COARSE_STEP_PX`); after their climbs (3 coarse and 1 fine steps for the
/// winner, 1 fine and 3 climbing steps for a runner) the two can be 24 px apart per axis, ≈ 34 px,
/// sampled then every ≈ 2.1 px.
pub const MAX_VALLEY_STEPS: usize = 16;
const _: () = assert!(MAX_VALLEY_STEPS >= 2);

/// Whether the fine correlation dips by more than `depth` below the lower of `a` and `b` somewhere
/// on the straight path between them (position, heading and scale interpolated, points about
/// 1 px apart, at most [`MAX_VALLEY_STEPS`]). Two alignments are two peaks only with a valley
/// between them: where a frame lies along a crater rim, its correlation with the slope raster
/// is a ridge, whose sampling ripple makes local maxima a few pixels apart that are one peak,
/// and the refinement, not a tie-break on a 144-sample lattice, settles where on it the frame
/// lies (its covariance says how well: a straight ridge leaves it singular, and no fix).
/// A point with too few valid samples (a hole in the reference, the map's edge) counts as a
/// dip: what lies between the two peaks is unknown, and calling them one peak would err
/// towards a fix.
fn valley(
    fine: &[Sample],
    r: &SlopeRaster<'_>,
    (a, b): (&Cand, &Cand),
    need: u32,
    depth: f32,
    reads: &mut u32,
) -> bool {
    let floor = a.ncc.min(b.ncc) - depth;
    let d = libm::hypotf(b.x - a.x, b.y - a.y);
    let n = (libm::ceilf(d) as usize).clamp(2, MAX_VALLEY_STEPS);
    (1..n).any(|i| {
        let f = i as f32 / n as f32;
        let c = Cand {
            x: a.x + f * (b.x - a.x),
            y: a.y + f * (b.y - a.y),
            heading: a.heading + f * (b.heading - a.heading),
            scale: a.scale + f * (b.scale - a.scale),
            ncc: 0.0,
        };
        let k = correlate_counted(fine, r, &c, reads);
        k.n < need || k.ncc() < floor
    })
}

/// Uphill steps at most when checking whether a runner-up is a peak of its own.
pub const CLIMB_STEPS: usize = 3;

/// Climb from `c` to the best 8-neighbour (1 px) until none is better or the step budget ends;
/// the flag says whether it settled on a local maximum.
fn climb(
    samples: &[Sample],
    r: &SlopeRaster<'_>,
    mut c: Cand,
    need: u32,
    reads: &mut u32,
) -> (Cand, bool) {
    for _ in 0..CLIMB_STEPS {
        let mut next = c;
        for dy in -1..=1 {
            for dx in -1..=1 {
                if dx == 0 && dy == 0 {
                    continue;
                }
                let mut t = Cand {
                    x: c.x + dx as f32,
                    y: c.y + dy as f32,
                    ..c
                };
                let k = correlate_counted(samples, r, &t, reads);
                if k.n < need {
                    continue;
                }
                t.ncc = k.ncc();
                if t.ncc > next.ncc {
                    next = t;
                }
            }
        }
        if next.ncc <= c.ncc {
            return (c, true);
        }
        c = next;
    }
    (c, false)
}

/// Keep the best `MAX_CANDIDATES` peaks at least `excl` apart: a better candidate near a kept
/// one replaces it, a worse one is dropped.
fn insert(best: &mut [Cand; MAX_CANDIDATES], c: Cand, excl: f32) {
    let e2 = excl * excl;
    if let Some(near) = best.iter_mut().find(|b| {
        b.ncc > -2.0 && {
            let (dx, dy) = (b.x - c.x, b.y - c.y);
            dx * dx + dy * dy <= e2
        }
    }) {
        if c.ncc > near.ncc {
            *near = c;
        } else {
            return;
        }
    } else if let Some(worst) = best
        .iter_mut()
        .min_by(|a, b| a.ncc.total_cmp(&b.ncc))
        .filter(|w| c.ncc > w.ncc)
    {
        *worst = c;
    } else {
        return;
    }
    // A replaced peak may now sit near another kept one: keep the better of such pairs.
    for i in 0..MAX_CANDIDATES {
        for j in (i + 1)..MAX_CANDIDATES {
            let (Some(a), Some(b)) = (best.get(i).copied(), best.get(j).copied()) else {
                continue;
            };
            if a.ncc > -2.0 && b.ncc > -2.0 {
                let (dx, dy) = (a.x - b.x, a.y - b.y);
                if dx * dx + dy * dy <= e2 {
                    let drop = if a.ncc >= b.ncc { j } else { i };
                    if let Some(d) = best.get_mut(drop) {
                        d.ncc = -2.0;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{SLOPE_NODATA, slope_from_deg};
    use crate::tile::{Tile, TileHeader, tile_len_with_raster, write_tile_with_raster};
    use std::vec;
    use std::vec::Vec;

    const W: usize = 160;
    const F: usize = 80;

    /// Textured slope field, degrees, at tile pixel `(x, y)`: no period inside the tile.
    fn field(x: f64, y: f64) -> f64 {
        20.0 + 6.0 * libm::sin(0.21 * x + 0.4) * libm::cos(0.17 * y - 0.3)
            + 4.0 * libm::sin(0.093 * x - 0.131 * y)
            + 3.0 * libm::cos(0.31 * y + 0.05 * x)
            + 2.5 * libm::sin(0.047 * x + 0.061 * y + 1.0)
    }

    /// Stripes: the same along a whole direction, so every shift along it correlates alike.
    fn stripes(x: f64, _y: f64) -> f64 {
        20.0 + 8.0 * libm::sin(0.23 * x)
    }

    /// Alike bumps on a 7 px square lattice: distinct peaks with valleys between them.
    fn lattice(x: f64, y: f64) -> f64 {
        let k = core::f64::consts::TAU / 7.0;
        20.0 + 6.0 * libm::sin(k * x) + 6.0 * libm::sin(k * y)
    }

    fn tile_bytes(f: fn(f64, f64) -> f64) -> Vec<u8> {
        let raster: Vec<_> = (0..W * W)
            .map(|i| slope_from_deg(f((i % W) as f64, (i / W) as f64) as f32))
            .collect();
        let header = TileHeader {
            width_px: W as u32,
            height_px: W as u32,
            origin_x_m: 0.0,
            origin_y_m: 0.0,
            pixel_x_m: 20.0,
            pixel_y_m: -20.0,
            projection: "test",
            feature_count: 0,
            octaves: 3,
            layers: 4,
            threshold: 1.0,
            min_scale_px: 0.0,
            upright: false,
            smoothing_m: 0.0,
            reference_sigma_m: [0.0; 2],
            height_noise_m: 0.0,
        };
        let mut buf = vec![0u8; tile_len_with_raster(512, 0, W * W)];
        let n = write_tile_with_raster(&header, &[], Some(&raster), &mut buf).unwrap();
        buf.truncate(n);
        buf
    }

    fn similarity_at(deg: f32, s: f32, tx: f32, ty: f32) -> Affine {
        let (sn, cs) = (libm::sinf(deg.to_radians()), libm::cosf(deg.to_radians()));
        Affine {
            m1: (s * cs) as f64,
            n1: (-s * sn) as f64,
            p1: tx as f64,
            m2: (s * sn) as f64,
            n2: (s * cs) as f64,
            p2: ty as f64,
        }
    }

    /// The similarity of rotation `deg` and scale `s` that puts the frame centre at `(x, y)`.
    fn centred(deg: f32, s: f32, x: f32, y: f32) -> Affine {
        let a = similarity_at(deg, s, 0.0, 0.0);
        let (cx, cy) = centre(&a);
        similarity_at(deg, s, x - cx, y - cy)
    }

    fn frame(truth: &Affine, f: fn(f64, f64) -> f64) -> Vec<SlopePx> {
        (0..F * F)
            .map(|i| {
                let (x, y) = truth.apply((i % F) as f64, (i / F) as f64);
                slope_from_deg(f(x, y) as f32)
            })
            .collect()
    }

    fn centre(a: &Affine) -> (f32, f32) {
        let c = (F as f64 - 1.0) * 0.5;
        let (x, y) = a.apply(c, c);
        (x as f32, y as f32)
    }

    fn prior_near(truth: &Affine, dx: f32, dy: f32, dh_deg: f32) -> Prior {
        let (x, y) = centre(truth);
        let sim = crate::pose::similarity(truth);
        Prior {
            center_tile_px: [x + dx, y + dy],
            sigma_px: 3.0,
            heading_rad: sim.rotation_rad as f32 + dh_deg.to_radians(),
            heading_sigma_rad: 2f32.to_radians(),
            scale: sim.scale as f32,
            scale_sigma: 0.02 * sim.scale as f32,
        }
    }

    #[test]
    fn finds_the_frame_inside_the_prior_window() {
        let bytes = tile_bytes(field);
        let tile = Tile::parse(&bytes).unwrap();
        let raster = tile.slope_raster().unwrap();
        for (deg, dx, dy, dh) in [
            (30.0, 4.0, -3.0, 2.0),
            (200.0, -7.0, 5.0, -3.5),
            (-75.0, 0.5, 8.0, 0.0),
        ] {
            let truth = centred(deg, 0.9, 80.0, 78.0);
            let px = frame(&truth, field);
            let img = SlopeImage::new_checked(&px, F, F, 18.0).unwrap();
            let prior = prior_near(&truth, dx, dy, dh);
            let hit = search(&img, 1, raster, &prior, &SearchConfig::default()).unwrap();
            let (a, b) = (centre(&hit.affine), centre(&truth));
            assert!(
                libm::hypotf(a.0 - b.0, a.1 - b.1) < 1.5,
                "{deg}°: {a:?} vs {b:?}, {hit:?}"
            );
            assert!(
                hit.ncc > 0.9 && hit.runner_up_ncc < hit.ncc - 0.1,
                "{hit:?}"
            );
            // The refinement takes it from there to the truth.
            let r = crate::refine::refine(
                &img,
                1,
                raster,
                &hit.affine,
                &crate::refine::FrameInfo::default(),
                &crate::refine::RefineConfig::default(),
            )
            .unwrap();
            let c = centre(&r.affine);
            assert!(libm::hypotf(c.0 - b.0, c.1 - b.1) < 0.05, "{r:?}");
        }
    }

    #[test]
    fn binned_frames_map_back_to_frame_pixels() {
        let bytes = tile_bytes(field);
        let tile = Tile::parse(&bytes).unwrap();
        // The image is the frame binned by 2: image column u is frame x = 2u + 0.5.
        let binned = similarity_at(15.0, 0.9, 50.0, 45.0);
        let px = frame(&binned, field);
        let img = SlopeImage::new_checked(&px, F, F, 18.0).unwrap();
        let sim = crate::pose::similarity(&binned);
        let (cx, cy) = centre(&binned);
        let prior = Prior {
            center_tile_px: [cx + 2.0, cy - 1.0],
            sigma_px: 3.0,
            heading_rad: sim.rotation_rad as f32,
            heading_sigma_rad: 0.03,
            scale: 0.45,
            scale_sigma: 0.005,
        };
        let hit = search(&img, 2, raster(&tile), &prior, &SearchConfig::default()).unwrap();
        // Frame pixel (2u + 0.5) must land where image pixel u lands under `binned`.
        for (u, v) in [(0.0, 0.0), (79.0, 79.0), (10.0, 60.0)] {
            let (a, b) = hit.affine.apply(2.0 * u + 0.5, 2.0 * v + 0.5);
            let (c, d) = binned.apply(u, v);
            assert!(libm::hypot(a - c, b - d) < 2.0, "({u}, {v}): {hit:?}");
        }
    }

    fn raster<'a>(t: &'a Tile<'a>) -> &'a SlopeRaster<'a> {
        t.slope_raster().unwrap()
    }

    #[test]
    fn refuses_what_it_cannot_decide() {
        let bytes = tile_bytes(field);
        let tile = Tile::parse(&bytes).unwrap();
        let r = raster(&tile);
        let cfg = SearchConfig::default();
        let truth = similarity_at(30.0, 0.9, 50.0, 45.0);
        let px = frame(&truth, field);
        let img = SlopeImage::new_checked(&px, F, F, 18.0).unwrap();
        let prior = prior_near(&truth, 2.0, 2.0, 1.0);
        let off = SearchConfig {
            enabled: false,
            ..cfg
        };
        assert_eq!(search(&img, 1, r, &prior, &off), Err(SearchError::Disabled));
        // A heading known to ±30° is lost-in-space work, for the feature path.
        let wide = Prior {
            heading_sigma_rad: 0.5,
            ..prior
        };
        assert_eq!(
            search(&img, 1, r, &wide, &cfg),
            Err(SearchError::PriorTooWide)
        );
        for bad in [
            Prior {
                scale: 0.0,
                ..prior
            },
            Prior {
                center_tile_px: [f32::NAN, 3.0],
                ..prior
            },
            Prior {
                sigma_px: f32::INFINITY,
                ..prior
            },
            Prior {
                center_tile_px: [3.0e9, -3.0e9],
                ..prior
            },
            Prior {
                scale: 1.0e6,
                ..prior
            },
        ] {
            assert_eq!(
                search(&img, 1, r, &bad, &cfg),
                Err(SearchError::PriorTooWide)
            );
        }
        // No data in the frame.
        let empty = vec![SLOPE_NODATA; F * F];
        let empty_img = SlopeImage::new_checked(&empty, F, F, 18.0).unwrap();
        assert_eq!(
            search(&empty_img, 1, r, &prior, &cfg),
            Err(SearchError::FlatFrame)
        );
        // A prior far outside the tile.
        let away = Prior {
            center_tile_px: [5000.0, 5000.0],
            ..prior
        };
        assert_eq!(
            search(&img, 1, r, &away, &cfg),
            Err(SearchError::NoCandidate)
        );
        // A lattice of alike bumps 7 px apart: the window holds several peaks with valleys
        // between them.
        let straight = similarity_at(0.0, 0.9, 50.0, 45.0);
        let lbytes = tile_bytes(lattice);
        let ltile = Tile::parse(&lbytes).unwrap();
        let lpx = frame(&straight, lattice);
        let limg = SlopeImage::new_checked(&lpx, F, F, 18.0).unwrap();
        let lprior = prior_near(&straight, 0.0, 0.0, 0.0);
        assert_eq!(
            search(&limg, 1, raster(&ltile), &lprior, &cfg),
            Err(SearchError::Ambiguous)
        );
    }

    /// A frame whose coarse lattice's pixels are the terrain's and every other pixel noise: the
    /// coarse level finds the truth, the fine lattice sees noise, and the search stops there.
    #[test]
    fn the_fine_lattice_has_the_last_word_on_a_match() {
        let bytes = tile_bytes(field);
        let tile = Tile::parse(&bytes).unwrap();
        let truth = centred(20.0, 0.9, 80.0, 78.0);
        let clean = frame(&truth, field);
        let on_coarse = |i: usize| {
            let at = |k: usize| {
                libm::roundf(0.05 * F as f32 + (0.9 * F as f32 - 1.0) * k as f32 / 6.0) as usize
            };
            let hit = |p: usize| (0..COARSE_GRID).any(|k| at(k) == p);
            hit(i % F) && hit(i / F)
        };
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let px: Vec<SlopePx> = (0..F * F)
            .map(|i| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                if on_coarse(i) {
                    clean[i]
                } else {
                    slope_from_deg(5.0 + 30.0 * (state >> 40) as f32 / (1u64 << 24) as f32)
                }
            })
            .collect();
        let img = SlopeImage::new_checked(&px, F, F, 18.0).unwrap();
        let prior = prior_near(&truth, 2.0, -1.0, 0.5);
        assert_eq!(
            search(&img, 1, raster(&tile), &prior, &SearchConfig::default()),
            Err(SearchError::NoMatch)
        );
        // It is the fine lattice's verdict: the coarse level passed.
        let off = SearchConfig {
            min_fine_ncc: -1.0,
            ..SearchConfig::default()
        };
        assert_ne!(
            search(&img, 1, raster(&tile), &prior, &off),
            Err(SearchError::NoMatch)
        );
        // The same frame without the noise is found.
        let img = SlopeImage::new_checked(&clean, F, F, 18.0).unwrap();
        assert!(search(&img, 1, raster(&tile), &prior, &SearchConfig::default()).is_ok());
    }

    /// Stripes along the tile's y axis: every shift along them correlates alike, a ridge without
    /// a valley. The search hands one point of it on, and the refinement refuses it, since
    /// nothing fixes the position along the stripes.
    #[test]
    fn a_ridge_is_left_to_the_refinement() {
        let cfg = SearchConfig::default();
        let sbytes = tile_bytes(stripes);
        let stile = Tile::parse(&sbytes).unwrap();
        let straight = similarity_at(0.0, 0.9, 50.0, 45.0);
        let spx = frame(&straight, stripes);
        let simg = SlopeImage::new_checked(&spx, F, F, 18.0).unwrap();
        let sprior = prior_near(&straight, 0.0, 0.0, 0.0);
        let r = raster(&stile);
        let hit = search(&simg, 1, r, &sprior, &cfg).expect("a point on the ridge");
        let refined = crate::refine::refine(
            &simg,
            1,
            r,
            &hit.affine,
            &crate::refine::FrameInfo::default(),
            &crate::refine::RefineConfig::default(),
        );
        assert_eq!(refined.err(), Some(crate::refine::RefineError::Singular));
    }
}
