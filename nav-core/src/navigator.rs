//! One call per frame: DEM patch (or slope image) in, fix or typed no-fix out, against a
//! reference tile, with a caller-owned workspace.

use crate::cost;
use crate::frame::{DemPatch, FrameError, SlopeBuffer, SlopeImage};
use crate::matching::{Match, MatchConfig, MatchStats, match_features};
use crate::msac::{Affine, Correspondence, MsacConfig, msac_counted};
use crate::pose::{Fix, GateConfig, NoFix, make_fix};
use crate::refine::{FrameInfo, RefineConfig, RefineError, Refined, refine_metered};
use crate::search::{SearchConfig, SearchError, SearchHit, search_metered};
use crate::surf::{Features, SurfConfig, SurfError, SurfWorkspace, extract};
use crate::tile::Tile;
use core::fmt;

/// Smallest keypoint scale the detector produces, pixels (σ of layer 15's lower half-step).
const SMALLEST_SCALE_PX: f32 = 2.5;

/// Predicted pose with uncertainty, to restrict matching to the predicted footprint.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Prior {
    /// Predicted frame centre in tile pixels `[x, y]`.
    pub center_tile_px: [f32; 2],
    /// 1σ position uncertainty, tile pixels (isotropic). `f32::INFINITY` says nothing about
    /// the position (no prior gate); NaN refuses every fix the prior would gate.
    pub sigma_px: f32,
    /// Predicted heading (frame +x axis in tile axes), radians.
    pub heading_rad: f32,
    /// 1σ heading uncertainty, radians; ≥ π/4 disables the orientation gate.
    pub heading_sigma_rad: f32,
    /// Predicted scale, tile pixels per frame pixel.
    pub scale: f32,
    /// 1σ scale uncertainty.
    pub scale_sigma: f32,
}

/// Navigator settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NavConfig {
    /// Descriptor matching.
    pub matching: MatchConfig,
    /// Robust estimation.
    pub msac: MsacConfig,
    /// Quality gate.
    pub gate: GateConfig,
    /// A fix farther than this many combined σ from the prior (Mahalanobis length under the
    /// prior's and the fix's position covariances summed) is refused.
    pub prior_gate_sigmas: f32,
    /// When the frame is finer than the tile, ignore frame keypoints smaller than the tile's
    /// smallest scale (in frame pixels) so the keypoint budget goes to matchable detail.
    pub auto_min_scale: bool,
    /// Guided matching after the first consensus: every frame feature is matched to the
    /// best-SSD tile feature within `guided_radius_px` (tile pixels) of where the transform puts
    /// it, with a consistent scale and SSD below `guided_max_ssd`; MSAC then runs again on that
    /// set. The global ratio test rejects many true matches on repetitive crater terrain; near
    /// the predicted position they are unambiguous, and more inliers mean a better fix. 0
    /// disables it.
    pub guided_radius_px: f32,
    /// SSD limit for guided matches.
    pub guided_max_ssd: f32,
    /// Fill isolated height dropouts before computing slope (see
    /// [`crate::slope::slope_into_with`]).
    pub fill_dropouts: bool,
    /// Bin frames (DEM or slope) finer than the tile to about the tile's ground sample distance
    /// (`k = ⌊tile pixel / frame pixel + 0.3⌋` when that is ≥ 2) before slope and SURF: both
    /// slopes then see the same scale of terrain, keypoints land more consistently, and the
    /// frame has k² times fewer pixels to process. Keypoints and the fix stay in frame pixels.
    pub bin_to_tile: bool,
    /// Smooth DEM frames (after binning) by the tile's [`crate::TileHeader::smoothing_m`], so
    /// frame and reference slopes come from terrain at the same resolution. Slope-image frames
    /// cannot be smoothed this way and are used as given.
    pub match_tile_smoothing: bool,
    /// Dense refinement of every fix against the tile's slope raster (when it carries one).
    pub refine: RefineConfig,
    /// Prior-aided area search when the feature path gives no fix ([`crate::search`]).
    pub search: SearchConfig,
    /// With a prior, run the area search first on a DEM frame's slope alone ([`Self::locate_dem`];
    /// the atlas and slope-image paths keep the feature path first), and detect and
    /// match features only when it gives no fix (without searching again). A frame the
    /// search fixes then skips detection, descriptors and matching (≈ 6–10 M Cortex-M4
    /// instructions of a 200 × 200 frame, docs/bounds.md); one it does not pays for the search
    /// before its feature path. Without it, the search runs only after the feature path
    /// failed, and a search fix after a full keypoint budget overran the flyer's 20 M budget
    /// (session 28; with it, on the terrain suite's 36 campaigns with a prior, success the same
    /// or higher, no false fix, docs/registration.md).
    pub search_first: bool,
    /// Work budget of one frame, in [`crate::cost`] units (estimated Cortex-M4 instructions):
    /// before each variable stage (area search, detection, a feature path after a failed
    /// search, matching, MSAC, guided matching, each refinement) the navigator checks that the stage's worst case fits in what is left,
    /// and skips it or caps its samples and passes to fit ([`FrameReport::over_budget`]). A
    /// frame's [`FrameReport::work`] is then at most the larger of this and its slope
    /// ([`crate::cost::fixed_first_stage`]). Default [`crate::cost::FLIGHT_BUDGET`]
    /// (20 M); `u32::MAX` leaves the frame unbounded (a ground-only option).
    pub work_budget: u32,
}

impl Default for NavConfig {
    fn default() -> Self {
        Self {
            matching: MatchConfig::default(),
            msac: MsacConfig::default(),
            gate: GateConfig::default(),
            prior_gate_sigmas: 5.0,
            auto_min_scale: true,
            guided_radius_px: 3.0,
            guided_max_ssd: 1.0,
            fill_dropouts: true,
            bin_to_tile: true,
            match_tile_smoothing: true,
            refine: RefineConfig::default(),
            search: SearchConfig::default(),
            search_first: true,
            work_budget: crate::cost::FLIGHT_BUDGET,
        }
    }
}

/// Work of what an area search ran: its coarse cells and, if it got there, its fine level and
/// runners.
fn search_work(w: &crate::search::SearchWork) -> u32 {
    let coarse = w
        .coarse_cells
        .saturating_mul(cost::SEARCH_PER_COARSE_CELL)
        .saturating_add(w.edge_cells.saturating_mul(cost::SEARCH_PER_EDGE_CELL));
    if w.fine {
        coarse
            .saturating_add(cost::SEARCH_FINE_WINNER)
            .saturating_add(cost::SEARCH_PER_RUNNER.saturating_mul(u32::from(w.runners)))
    } else {
        coarse
    }
}

/// Errors that are not "no fix": the frame or configuration itself is unusable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NavError {
    /// Malformed frame or too large for the workspace.
    Frame(FrameError),
    /// SURF refused the frame or configuration.
    Surf(SurfError),
}

impl fmt::Display for NavError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Frame(e) => write!(f, "frame: {e}"),
            Self::Surf(e) => write!(f, "{e}"),
        }
    }
}
impl core::error::Error for NavError {}
impl From<FrameError> for NavError {
    fn from(e: FrameError) -> Self {
        Self::Frame(e)
    }
}
impl From<SurfError> for NavError {
    fn from(e: SurfError) -> Self {
        Self::Surf(e)
    }
}

/// Everything one frame produced.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameReport {
    /// The fix, or why there is none.
    pub outcome: Result<Fix, NoFix>,
    /// Frame features extracted.
    pub features: u16,
    /// Frame keypoints dropped by the budget.
    pub features_dropped: u32,
    /// Putative matches.
    pub matches: u16,
    /// MSAC inliers (0 if MSAC did not run).
    pub inliers: u16,
    /// MSAC samples drawn.
    pub msac_iterations: u16,
    /// The MSAC affine even when the gate refused it (diagnostics), if MSAC ran.
    pub affine: Option<Affine>,
    /// Matching counters.
    pub match_stats: MatchStats,
    /// Detector counters for the frame.
    pub detect_stats: crate::detector::DetectStats,
    /// Whether SURF ran on the frame: false when the area search, run first
    /// ([`NavConfig::search_first`]), fixed it.
    pub detected: bool,
    /// The area search ran before detection ([`NavConfig::search_first`] with a prior): a frame
    /// still without a fix then went through the feature path after it, whose verdict is the
    /// outcome (and `search` keeps the search's).
    pub search_first: bool,
    /// The dense refinements' work in this frame: valid samples summed over every pass of every
    /// refinement run (a search hit's and a feature fix's), whatever their result, the final
    /// pass of each weighing [`crate::refine::SANDWICH_PASS_WEIGHT`].
    pub refine_sample_passes: u32,
    /// The dense refinement of the fix: `None` when there was no feature fix to refine,
    /// otherwise what it gave or why it was not applied (the fix then stands unrefined, unless
    /// the refinement contradicted it, a thin consensus went unconfirmed or the budget stopped
    /// the refinement: see `outcome`).
    pub refine: Option<Result<Refined, RefineError>>,
    /// The feature consensus alone failed the gate (fewer than [`GateConfig::min_inliers`]
    /// inliers but at least [`GateConfig::min_inliers_verified`], or clustered inliers): the
    /// fix stood only if the refinement confirmed it.
    pub needed_confirmation: bool,
    /// The prior-aided area search: `None` when it did not run (no prior, search disabled, or
    /// on the features-first paths a feature fix), otherwise its best alignment or why it
    /// found none. Its fix, if any,
    /// is the outcome (with [`Fix::area_search`] set).
    pub search: Option<Result<SearchHit, SearchError>>,
    /// What the area search ran in this frame (zero when it did not run).
    pub search_work: crate::search::SearchWork,
    /// Work this frame spent, [`crate::cost`] units (estimated Cortex-M4 instructions, from
    /// what each stage ran: pixels, keypoints, matching pairs, MSAC samples drawn, search
    /// cells and fine reads, refinement samples per pass).
    pub work: u32,
    /// The work budget ([`NavConfig::work_budget`]) skipped a stage or capped a stage's
    /// samples or passes in this frame.
    pub over_budget: bool,
}

impl FrameReport {
    /// A frame nothing has been run on yet: no fix (too few features), every counter zero.
    fn nothing_yet() -> Self {
        Self {
            outcome: Err(NoFix::TooFewFeatures),
            features: 0,
            features_dropped: 0,
            matches: 0,
            inliers: 0,
            msac_iterations: 0,
            affine: None,
            match_stats: MatchStats::default(),
            detect_stats: crate::detector::DetectStats::default(),
            detected: false,
            search_first: false,
            refine_sample_passes: 0,
            refine: None,
            needed_confirmation: false,
            search: None,
            search_work: crate::search::SearchWork::default(),
            work: 0,
            over_budget: false,
        }
    }

    /// Add `w` work units.
    fn charge(&mut self, w: u32) {
        self.work = self.work.saturating_add(w);
    }
}

/// Caller-owned working memory for one frame: slope buffer, SURF scratch, up to `MAX_KP` frame
/// features and `MAX_MATCHES` matches. See `docs/bounds.md` for its size.
pub struct NavWorkspace<
    const MAX_PX: usize,
    const MAX_W: usize,
    const MAX_KP: usize,
    const MAX_MATCHES: usize,
> {
    slope: SlopeBuffer<MAX_PX>,
    surf: SurfWorkspace<MAX_PX, MAX_W>,
    features: Features<MAX_KP>,
    matches: heapless::Vec<Match, MAX_MATCHES>,
    pts: [Correspondence; MAX_MATCHES],
    inlier: [bool; MAX_MATCHES],
}

impl<const MAX_PX: usize, const MAX_W: usize, const MAX_KP: usize, const MAX_MATCHES: usize> Default
    for NavWorkspace<MAX_PX, MAX_W, MAX_KP, MAX_MATCHES>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX_PX: usize, const MAX_W: usize, const MAX_KP: usize, const MAX_MATCHES: usize>
    NavWorkspace<MAX_PX, MAX_W, MAX_KP, MAX_MATCHES>
{
    /// Zeroed workspace (`const`, so it can be a `static`).
    pub const fn new() -> Self {
        Self {
            slope: SlopeBuffer::new(),
            surf: SurfWorkspace::new(),
            features: Features::new(),
            matches: heapless::Vec::new(),
            pts: [Correspondence {
                x: 0.0,
                y: 0.0,
                tx: 0.0,
                ty: 0.0,
                scale: 1.0,
            }; MAX_MATCHES],
            inlier: [false; MAX_MATCHES],
        }
    }
    /// Size in bytes.
    pub const fn footprint_bytes() -> usize {
        core::mem::size_of::<Self>()
    }
    /// The slope buffer, SURF scratch and feature list, borrowed apart (keyframe capture).
    pub(crate) fn parts_mut(
        &mut self,
    ) -> (
        &mut SlopeBuffer<MAX_PX>,
        &mut SurfWorkspace<MAX_PX, MAX_W>,
        &mut Features<MAX_KP>,
    ) {
        (&mut self.slope, &mut self.surf, &mut self.features)
    }
    /// No features, matches or inlier flags: a frame that ends before its feature path must not
    /// show the last frame's through [`Self::features`], [`Self::matches`] or [`Self::inliers`].
    fn forget_features(&mut self) {
        self.features.clear();
        self.matches.clear();
        self.inlier.fill(false);
    }
    /// The frame features of the last call (frame pixel coordinates).
    pub fn features(&self) -> &Features<MAX_KP> {
        &self.features
    }
    /// The putative matches of the last call.
    pub fn matches(&self) -> &[Match] {
        &self.matches
    }
    /// MSAC inlier flags of the last call, parallel to [`Self::matches`]; all false when the
    /// call's consensus did not run.
    pub fn inliers(&self) -> &[bool] {
        self.inlier.get(..self.matches.len()).unwrap_or(&[])
    }
}

/// Binning factor (1 = none, at most [`crate::slope::MAX_BIN`]) that brings a DEM frame of
/// `frame_pixel_m` metres per pixel near a tile of `tile_pixel_m` metres: ⌊T / p + 0.3⌋, so
/// it rounds down unless nearly up and binning never makes the frame much coarser than the
/// tile (a 2.5× finer frame bins by 2, a 1.8× finer one still by 2). 1 for inputs that are
/// not positive.
pub fn bin_factor_for(tile_pixel_m: f32, frame_pixel_m: f32) -> usize {
    if !(frame_pixel_m > 0.0 && tile_pixel_m > 0.0) {
        return 1;
    }
    let k = libm::floorf(tile_pixel_m / frame_pixel_m + 0.3);
    if k >= 2.0 {
        (k as usize).min(crate::slope::MAX_BIN)
    } else {
        1
    }
}

/// Blur variance, in pixels², that block averaging and Horn's 3 × 3 gradient add to a slope
/// image beyond its Gaussian smoothing, per axis and averaged over the two gradient components:
/// the block mean k × k adds 1/12; the central difference of the derivative's own axis 1/3 (its
/// response sin ωΔ / Δ is ω·(1 − ω²Δ²/6 + …), a Gaussian of variance Δ²/3 to second order); the
/// 1-2-1 weights across it 1/2: (1/12 + 1/3 + 1/12 + 1/2) / 2 = 1/2.
pub const GRID_BLUR_VAR_PX2: f32 = 0.5;

/// Gaussian σ, in pixels of `binned_pixel_m` metres, that gives a frame slope image the same
/// total blur as a tile of `tile_pixel_m` metres smoothed by `tile_smoothing_m` (metres, 1σ):
/// `√(s² + c·(T² − b²)) / b` with c = [`GRID_BLUR_VAR_PX2`], T the tile's pixel and b the
/// binned frame's. The grid's own blur grows with its pixel, so a frame binned finer than the
/// tile takes a little more Gaussian, a coarser one a little less (never below 0).
///
/// Why: with `s / b` alone, frames binned to 15–17 m against a 20 m tile lacked blur the
/// tile carries, and their fixes moved by up to three times their error at 20 m, always in
/// the same direction for a given patch of ground, so the refinement's covariance, built from
/// residuals, could not see it: on the smooth plains (300 frames, seed 1, 7.4–9 m pixels,
/// prior) mean NEES 3.4; with the matched blur 1.7 (docs/registration.md, "Matched blur").
/// 0 when any input is not positive and finite, or σ overflows (no tile that parses gets there:
/// `tile::MAX_SMOOTHING_M`). nav-core cuts the Gaussian at `slope::MAX_SMOOTH_RADIUS`; the σ
/// here does not allow for that cut (docs/registration.md, "Matched blur", Limits).
pub fn matched_smoothing_px(tile_smoothing_m: f32, tile_pixel_m: f32, binned_pixel_m: f32) -> f32 {
    let ok = |x: f32| x.is_finite() && x > 0.0;
    if !(ok(tile_smoothing_m) && ok(tile_pixel_m) && ok(binned_pixel_m)) {
        return 0.0;
    }
    let (s, t, b) = (tile_smoothing_m, tile_pixel_m, binned_pixel_m);
    let v = s * s + GRID_BLUR_VAR_PX2 * (t * t - b * b);
    let sigma = libm::sqrtf(v.max(0.0)) / b;
    if sigma.is_finite() { sigma } else { 0.0 }
}

/// Matches frames against one reference tile.
#[derive(Debug, Clone, Copy)]
pub struct Navigator<'t> {
    tile: Tile<'t>,
    cfg: NavConfig,
}

impl<'t> Navigator<'t> {
    /// Navigator over a parsed tile.
    pub fn new(tile: Tile<'t>, cfg: NavConfig) -> Self {
        Self { tile, cfg }
    }
    /// The tile.
    pub fn tile(&self) -> &Tile<'t> {
        &self.tile
    }
    /// The configuration.
    pub fn config(&self) -> &NavConfig {
        &self.cfg
    }

    /// Binning factor for a DEM frame of `frame_pixel_m` metres per pixel (1 = none).
    pub fn bin_factor(&self, frame_pixel_m: f32) -> usize {
        if self.cfg.bin_to_tile {
            bin_factor_for(self.tile.header().pixel_m() as f32, frame_pixel_m)
        } else {
            1
        }
    }

    /// Gaussian σ, in pixels of `binned_pixel_m` metres, by which a DEM frame is smoothed to
    /// match the tile ([`matched_smoothing_px`]; 0 when the tile is unsmoothed or
    /// [`NavConfig::match_tile_smoothing`] is off).
    pub fn frame_smoothing_px(&self, binned_pixel_m: f32) -> f32 {
        let h = self.tile.header();
        if self.cfg.match_tile_smoothing {
            matched_smoothing_px(h.smoothing_m, h.pixel_m() as f32, binned_pixel_m)
        } else {
            0.0
        }
    }

    /// SURF settings for a frame of `frame_pixel_m` metres per pixel: the tile's, with the
    /// minimum scale raised for frames finer than the tile.
    pub fn frame_surf_config(&self, frame_pixel_m: f32) -> SurfConfig {
        let mut cfg = self.tile.header().surf_config();
        if self.cfg.work_budget != u32::MAX {
            // Under a work budget the lazy layers are capped so detection stays inside what
            // `cost` charges for it on any input.
            cfg.detector.max_lazy_responses = crate::detector::MAX_LAZY_RESPONSES;
        }
        let ratio = self.tile.header().pixel_m() as f32 / frame_pixel_m;
        if self.cfg.auto_min_scale && ratio > 1.25 {
            cfg.detector.min_scale_px = cfg.detector.min_scale_px.max(SMALLEST_SCALE_PX) * ratio;
            // The tile's largest scales appear `ratio` times larger in the frame: one more
            // octave per doubling keeps them detectable.
            let extra = libm::roundf(libm::log2f(ratio)).clamp(0.0, 2.0) as u8;
            cfg.detector.octaves =
                (cfg.detector.octaves + extra).min(crate::detector::MAX_OCTAVES as u8);
        } else {
            cfg.detector.min_scale_px = 0.0;
        }
        cfg
    }

    /// Locate a DEM patch (heights in metres): slope, SURF, match, MSAC, gate.
    pub fn locate_dem<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        dem: &DemPatch<'_>,
        prior: Option<&Prior>,
    ) -> Result<FrameReport, NavError> {
        let k = self.bin_factor(dem.pixel_m());
        let (w, h) = (dem.width(), dem.height());
        if self.cfg.search_first
            && self.cfg.search.enabled
            && prior.is_some()
            && self.tile.slope_raster().is_some()
        {
            self.slope_dem(ws, dem, k)?;
            let img = ws.slope.image()?;
            let binned_px = img.width() * img.height();
            let info = self.frame_info(&img, k, true);
            let mut first = FrameReport {
                search_first: true,
                ..FrameReport::nothing_yet()
            };
            first.charge(cost::fixed_first_stage(binned_px, ws.slope.nodata_sums()));
            self.area_search(&mut first, &img, k, &info, (w, h), prior);
            if first.outcome.is_ok() {
                ws.forget_features();
                return Ok(first);
            }
            // The feature path's detection, a whole keypoint budget and their matching must
            // fit in what the search left, or the frame ends here.
            let n_tile = self.tile.len();
            let candidates = self.candidates(prior, w, h);
            let need = cost::detection_stage(binned_px, K)
                .saturating_add(cost::matching(K, n_tile, candidates));
            if need > self.room(&first) {
                ws.forget_features();
                first.outcome = Err(NoFix::OverBudget);
                first.over_budget = true;
                return Ok(first);
            }
            self.features_of_slope(ws, k)?;
            let spent = first
                .work
                .saturating_add(cost::detection_stage(binned_px, ws.features.len()));
            let mut report = self.locate_extracted_dem(ws, (w, h), k, prior, false, spent)?;
            // The search's verdict stays in the report (it ran, and why it gave nothing).
            report.search = first.search;
            report.search_work = first.search_work;
            report.search_first = true;
            report.over_budget |= first.over_budget;
            report.refine_sample_passes = report
                .refine_sample_passes
                .saturating_add(first.refine_sample_passes);
            if report.refine.is_none() {
                report.refine = first.refine;
            }
            return Ok(report);
        }
        if let Some(refused) = self.extract_dem(ws, dem, k)? {
            return Ok(refused);
        }
        let spent = self.extraction_work(ws);
        self.locate_extracted_dem(ws, (w, h), k, prior, true, spent)
    }

    /// Work of the slope and features now in `ws` (binned as they were computed).
    pub(crate) fn extraction_work<
        const P: usize,
        const W: usize,
        const K: usize,
        const M: usize,
    >(
        &self,
        ws: &NavWorkspace<P, W, K, M>,
    ) -> u32 {
        let binned_px = ws.slope.image().map_or(0, |i| i.width() * i.height());
        cost::fixed_first_stage(binned_px, ws.slope.nodata_sums())
            .saturating_add(cost::detection_stage(binned_px, ws.features.len()))
    }

    /// What is left of the frame's work budget after `report`'s work.
    fn room(&self, report: &FrameReport) -> u32 {
        self.cfg.work_budget.saturating_sub(report.work)
    }

    /// Refine `initial` under `cfg` with the samples × passes the rest of `report`'s budget
    /// pays for, and charge what it ran (marking the report when the budget stopped it).
    #[allow(clippy::too_many_arguments)]
    fn refine_charged(
        &self,
        report: &mut FrameReport,
        img: &SlopeImage<'_>,
        k: usize,
        raster: &crate::tile::SlopeRaster<'_>,
        initial: &Affine,
        info: &FrameInfo,
        cfg: &RefineConfig,
    ) -> Result<Refined, RefineError> {
        let allowance = self.room(report) / cost::REFINE_PER_SAMPLE_PASS;
        let rcfg = RefineConfig {
            max_sample_passes: cfg.max_sample_passes.min(allowance),
            ..*cfg
        };
        let mut work = 0u32;
        let result = refine_metered(img, k, raster, initial, info, &rcfg, &mut work);
        report.refine_sample_passes = report.refine_sample_passes.saturating_add(work);
        report.charge(cost::refine(work));
        if result == Err(RefineError::OverBudget) {
            report.over_budget = true;
        }
        result
    }

    /// The frame's slope alone (binned by `k`, smoothed as the tile says) into `ws`.
    fn slope_dem<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        dem: &DemPatch<'_>,
        k: usize,
    ) -> Result<(), NavError> {
        let sigma_px = self.frame_smoothing_px(dem.pixel_m() * k as f32);
        if k > 1 || sigma_px > 0.0 {
            ws.slope
                .compute_binned_smoothed::<W>(dem, k, sigma_px, self.cfg.fill_dropouts)?;
        } else if self.cfg.fill_dropouts {
            ws.slope.compute_from_filled(dem)?;
        } else {
            ws.slope.compute_from(dem)?;
        }
        Ok(())
    }

    /// SURF on the slope already in `ws` (binned by `k`), features in frame pixels.
    fn features_of_slope<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        k: usize,
    ) -> Result<(), NavError> {
        let NavWorkspace {
            slope,
            surf,
            features,
            ..
        } = ws;
        let img = slope.image()?;
        let cfg = self.frame_surf_config(img.pixel_m());
        extract(&img, &cfg, surf.scratch(), features)?;
        features.unbin(k);
        Ok(())
    }

    /// The first half of [`Self::locate_dem`] on the features-first path: the frame's slope
    /// (binned by `k`, smoothed as the tile says) into `ws`, then, if its detection and a whole
    /// keypoint budget fit in the work budget after the slope, its features (in frame pixels).
    /// `Some(report)` (no fix, [`NoFix::OverBudget`], the slope's work) when they do not: the
    /// smoothing over missing heights ([`cost::slope_nodata`]) can take up to 7.3 M of a
    /// 100 × 100 binned frame, and nothing after the slope may push a frame past the budget.
    pub(crate) fn extract_dem<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        dem: &DemPatch<'_>,
        k: usize,
    ) -> Result<Option<FrameReport>, NavError> {
        self.slope_dem(ws, dem, k)?;
        let binned_px = ws.slope.image().map_or(0, |i| i.width() * i.height());
        let slope = cost::fixed_first_stage(binned_px, ws.slope.nodata_sums());
        if slope.saturating_add(cost::detection_stage(binned_px, K)) > self.cfg.work_budget {
            ws.forget_features();
            let mut refused = FrameReport {
                outcome: Err(NoFix::OverBudget),
                over_budget: true,
                ..FrameReport::nothing_yet()
            };
            refused.charge(slope);
            return Ok(Some(refused));
        }
        self.features_of_slope(ws, k)?;
        Ok(None)
    }

    /// The part of [`Self::locate_dem`] after the frame's slope and features are in `ws`:
    /// matching, consensus, refinement, prior gate and (with `area_search`) the area search,
    /// the frame having spent `spent` work units before ([`FrameReport::work`]). The atlas
    /// ([`crate::atlas`]) calls it again on a neighbour tile whose extraction settings equal
    /// the first tile's, so the frame is not extracted twice.
    pub(crate) fn locate_extracted_dem<
        const P: usize,
        const W: usize,
        const K: usize,
        const M: usize,
    >(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        (width, height): (usize, usize),
        k: usize,
        prior: Option<&Prior>,
        area_search: bool,
        spent: u32,
    ) -> Result<FrameReport, NavError> {
        let mut report = self.locate_features(ws, width, height, prior, spent);
        let img = ws.slope.image()?;
        let info = self.frame_info(&img, k, true);
        self.refine_fix(&mut report, &img, k, &info, width, height);
        self.prior_gate(&mut report, prior);
        if area_search {
            self.area_search(&mut report, &img, k, &info, (width, height), prior);
        }
        Ok(report)
    }

    /// The area search of [`Self::locate_dem`] on a report of [`Self::locate_extracted_dem`]
    /// made without it (same workspace, same frame).
    pub(crate) fn area_search_extracted<
        const P: usize,
        const W: usize,
        const K: usize,
        const M: usize,
    >(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        report: &mut FrameReport,
        width: usize,
        height: usize,
        k: usize,
        prior: Option<&Prior>,
    ) -> Result<(), NavError> {
        let img = ws.slope.image()?;
        let info = self.frame_info(&img, k, true);
        self.area_search(report, &img, k, &info, (width, height), prior);
        Ok(())
    }

    /// Locate a slope image.
    pub fn locate_slope<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        img: &SlopeImage<'_>,
        prior: Option<&Prior>,
    ) -> Result<FrameReport, NavError> {
        let k = self.bin_factor(img.pixel_m());
        if k > 1 {
            let binned = ws.slope.bin_from(img, k)?;
            let cfg = self.frame_surf_config(binned.pixel_m());
            extract(&binned, &cfg, ws.surf.scratch(), &mut ws.features)?;
            ws.features.unbin(k);
        } else {
            let cfg = self.frame_surf_config(img.pixel_m());
            extract(img, &cfg, ws.surf.scratch(), &mut ws.features)?;
        }
        // The image comes with its slope: the frame is charged from detection on.
        let binned_px = (img.width() / k.max(1)) * (img.height() / k.max(1));
        let spent = cost::detection_stage(binned_px, ws.features.len());
        let mut report = self.locate_features(ws, img.width(), img.height(), prior, spent);
        let binned;
        let used = if k > 1 {
            binned = ws.slope.image()?;
            &binned
        } else {
            img
        };
        // A slope image comes as it is: no smoothing here, so no border band to leave out.
        let info = self.frame_info(used, k, false);
        self.refine_fix(&mut report, used, k, &info, img.width(), img.height());
        self.prior_gate(&mut report, prior);
        self.area_search(
            &mut report,
            used,
            k,
            &info,
            (img.width(), img.height()),
            prior,
        );
        Ok(report)
    }

    /// What the refinement knows of a frame's slope image `img` (binned by `k`): the scale its
    /// pixel size implies (tile pixels per unbinned frame pixel) and, when nav-core smoothed
    /// the heights it came from (`smoothed`: the DEM path, [`Self::extract_dem`]), the border
    /// band whose smoothing kernel was cut ([`crate::slope::smoothing_radius`] + 1).
    fn frame_info(&self, img: &SlopeImage<'_>, k: usize, smoothed: bool) -> FrameInfo {
        let tile_m = self.tile.header().pixel_m();
        let s = img.pixel_m() as f64 / k.max(1) as f64 / tile_m;
        let r = if smoothed {
            crate::slope::smoothing_radius(self.frame_smoothing_px(img.pixel_m()))
        } else {
            0
        };
        FrameInfo {
            scale: (s.is_finite() && s > 0.0).then_some(s),
            border_px: if r > 0 { r + 1 } else { 0 },
        }
    }

    /// Refine a feature fix over the frame's pixels (`img` binned by `k` from the
    /// `frame_w × frame_h` frame); an unrefinable fix stands as it was.
    fn refine_fix(
        &self,
        report: &mut FrameReport,
        img: &SlopeImage<'_>,
        k: usize,
        info: &FrameInfo,
        frame_w: usize,
        frame_h: usize,
    ) {
        let Ok(fix) = &mut report.outcome else {
            return;
        };
        let initial = fix.affine;
        let result = match self.tile.slope_raster() {
            None if self.cfg.refine.enabled => Err(RefineError::NoRaster),
            None => Err(RefineError::Disabled),
            Some(raster) => {
                self.refine_charged(report, img, k, raster, &initial, info, &self.cfg.refine)
            }
        };
        let Ok(fix) = &mut report.outcome else {
            return;
        };
        if let Ok(r) = &result {
            *fix = fix.with_refinement(r, self.tile.header(), frame_w, frame_h);
        }
        let gate = &self.cfg.gate;
        let confirmed = matches!(&result, Ok(r) if r.ncc_after >= gate.verify_min_ncc);
        let contradicted = match &result {
            Ok(r) => r.ncc_after < gate.verify_min_ncc,
            Err(e) => matches!(e, RefineError::MovedTooFar | RefineError::WorseCorrelation),
        };
        if (report.needed_confirmation && !confirmed) || (gate.reject_contradicted && contradicted)
        {
            report.outcome = Err(NoFix::Unconfirmed);
        }
        // A fix the budget left unchecked does not stand: on the InSAR plains (seed 2, no
        // prior) two such fixes were 66 and 95 m off, refinements having refused or moved them.
        if result == Err(RefineError::OverBudget) {
            report.outcome = Err(NoFix::OverBudget);
        }
        // A fix the refinement could not check stands on its features alone; the frame knows
        // its own scale, and a consensus far from it is a wrong one. (A refined fix has had its
        // scale pulled to the frame's, and a thin feature consensus off by more than this is
        // often right where it matters, its position: the refinement rescues it.)
        if let (Ok(fix), Some(s)) = (&report.outcome, info.scale)
            && !fix.refined
            && !(libm::fabs(fix.similarity.scale / s - 1.0) <= gate.max_scale_error as f64)
        {
            report.outcome = Err(NoFix::ScaleOutOfRange);
        }
        report.refine = Some(result);
    }

    /// With a prior and no fix, search the prior's window by slope correlation; a hit the
    /// refinement confirms (converged, correlation ≥ the search's `confirm_min_ncc`) and the prior
    /// gate accepts becomes the fix, with the refinement's covariance.
    fn area_search(
        &self,
        report: &mut FrameReport,
        img: &SlopeImage<'_>,
        k: usize,
        info: &FrameInfo,
        (frame_w, frame_h): (usize, usize),
        prior: Option<&Prior>,
    ) {
        let Some(p) = prior else { return };
        // After a refused feature fix that was refined, the frame has spent the refinement's
        // share of the instruction budget, and a fix the slope correlation contradicted is no
        // case for another correlation: the search runs only where features were too few or
        // found no consensus.
        if report.outcome.is_ok() || report.refine.is_some() || !self.cfg.search.enabled {
            return;
        }
        let Some(raster) = self.tile.slope_raster() else {
            report.search = Some(Err(SearchError::NoRaster));
            return;
        };
        let rcfg = RefineConfig {
            max_samples: self.cfg.search.refine_max_samples,
            max_iterations: self.cfg.search.refine_max_iterations,
            ..self.cfg.refine
        };
        // The whole lattice and a hit's shortest refinement (a step and its final pass) must
        // fit in what is left.
        let need = cost::search_worst().saturating_add(
            cost::refine_pass(rcfg.max_samples)
                .saturating_mul(1 + crate::refine::SANDWICH_PASS_WEIGHT),
        );
        if need > self.room(report) {
            report.search = Some(Err(SearchError::OverBudget));
            report.over_budget = true;
            return;
        }
        let mut work = crate::search::SearchWork::default();
        let hit = search_metered(img, k, raster, p, &self.cfg.search, &mut work);
        report.search = Some(hit);
        report.search_work = work;
        report.charge(search_work(&work));
        let Ok(hit) = hit else { return };
        // A refused hit leaves the refinement's verdict in the report (why no fix).
        let result = self.refine_charged(report, img, k, raster, &hit.affine, info, &rcfg);
        let r = match result {
            Ok(r) if r.ncc_after >= self.cfg.search.confirm_min_ncc => r,
            Ok(_) => {
                report.refine = Some(Err(RefineError::WorseCorrelation));
                return;
            }
            Err(e) => {
                report.refine = Some(Err(e));
                return;
            }
        };
        let fix = Fix::from_area_search(&r, self.tile.header(), frame_w, frame_h);
        let sim = fix.similarity;
        let gate = &self.cfg.gate;
        if !(sim.scale >= gate.scale_min as f64 && sim.scale <= gate.scale_max as f64) {
            return;
        }
        let saved = core::mem::replace(&mut report.outcome, Ok(fix));
        self.prior_gate(report, prior);
        if report.outcome.is_ok() {
            report.refine = Some(Ok(r));
        } else {
            report.outcome = saved;
        }
    }

    /// Refuse a fix farther from the prior than its gate allows.
    fn prior_gate(&self, report: &mut FrameReport, prior: Option<&Prior>) {
        if let (Ok(fix), Some(p)) = (&report.outcome, prior) {
            let gate = self.cfg.prior_gate_sigmas as f64;
            if !within_prior_gate(fix.center_tile_px, &fix.center_cov_tile_px2, p, gate) {
                report.outcome = Err(NoFix::InconsistentWithPrior);
            }
        }
    }

    /// Fill the correspondences from the match list and run MSAC on them, with at most the
    /// samples the rest of `report`'s budget pays for once `reserve` is set aside (charged to
    /// it). `None`: not one sample fits. Otherwise MSAC's result, and whether the lowered
    /// sample cap bound (MSAC drew up to it; the report is marked then).
    fn consensus<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        report: &mut FrameReport,
        reserve: u32,
    ) -> Option<(Option<crate::msac::MsacResult>, bool)> {
        let n = ws.matches.len();
        let per_sample = cost::msac_sample(n).max(1);
        let affordable = self.room(report).saturating_sub(reserve) / per_sample;
        let mut mcfg = self.cfg.msac;
        let capped = affordable < mcfg.max_iterations as u32;
        if capped {
            if affordable == 0 {
                report.over_budget = true;
                return None;
            }
            mcfg.max_iterations = affordable as u16;
        }
        let feats = ws.features.as_slice();
        for (m, slot) in ws.matches.iter().zip(ws.pts.iter_mut()) {
            let tk = self.tile.keypoint(m.tile as usize);
            if let Some(f) = feats.get(m.frame as usize) {
                *slot = Correspondence {
                    x: f.keypoint.x_px,
                    y: f.keypoint.y_px,
                    tx: tk.x_px,
                    ty: tk.y_px,
                    scale: tk.scale_px,
                };
            }
        }
        let pts = ws.pts.get(..n).unwrap_or(&[]);
        let mut drawn = 0u16;
        let r = msac_counted(pts, &mut ws.inlier, &mcfg, &mut drawn);
        report.charge(u32::from(drawn).saturating_mul(per_sample));
        let bound = capped && drawn >= mcfg.max_iterations;
        report.over_budget |= bound;
        Some((r, bound))
    }

    /// Whether tile feature `j` may match a `frame_w × frame_h` frame under `prior`: every
    /// feature without one; with one, those within the frame's predicted half-diagonal (at the
    /// largest plausible scale) plus 3σ of position.
    fn footprint(
        &self,
        prior: Option<&Prior>,
        frame_w: usize,
        frame_h: usize,
    ) -> impl Fn(usize) -> bool + '_ {
        let footprint = prior.map(|p| {
            let half_diag = 0.5 * libm::hypotf(frame_w as f32, frame_h as f32);
            let scale_hi = p.scale + 3.0 * p.scale_sigma.abs();
            let r = half_diag * scale_hi + 3.0 * p.sigma_px.abs();
            (p.center_tile_px, r * r)
        });
        move |j: usize| match footprint {
            None => true,
            Some(([cx, cy], r2)) => {
                let (kx, ky) = self.tile.position_px(j);
                let (dx, dy) = (kx - cx, ky - cy);
                dx * dx + dy * dy <= r2
            }
        }
    }

    /// Tile features in the footprint of a `frame_w × frame_h` frame under `prior`
    /// ([`Self::footprint`]): matching's candidates.
    fn candidates(&self, prior: Option<&Prior>, frame_w: usize, frame_h: usize) -> usize {
        let in_reach = self.footprint(prior, frame_w, frame_h);
        (0..self.tile.len()).filter(|&j| in_reach(j)).count()
    }

    /// Work set aside for the shortest refinement of a feature fix (a step and its final
    /// pass), when the frame will be refined.
    fn refine_reserve(&self) -> u32 {
        if self.cfg.refine.enabled && self.tile.slope_raster().is_some() {
            cost::refine_pass(self.cfg.refine.max_samples)
                .saturating_mul(1 + crate::refine::SANDWICH_PASS_WEIGHT)
        } else {
            0
        }
    }

    /// Replace the match list by guided matches under `affine`; false if too few were found.
    fn guided_matches<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        affine: &Affine,
    ) -> bool {
        let feats = ws.features.as_slice();
        let tile = &self.tile;
        let scale = crate::pose::similarity(affine).scale as f32;
        let r2 = self.cfg.guided_radius_px * self.cfg.guided_radius_px;
        let mut guided: heapless::Vec<Match, M> = heapless::Vec::new();
        for (i, f) in feats.iter().enumerate().take(u16::MAX as usize) {
            let (px, py) = affine.apply(f.keypoint.x_px as f64, f.keypoint.y_px as f64);
            let (px, py) = (px as f32, py as f32);
            let expect_scale = f.keypoint.scale_px * scale;
            let mut best: Option<(f32, usize)> = None;
            for j in 0..tile.len().min(u16::MAX as usize) {
                // Position first (most tile features are far away), the full record after.
                let (kx, ky) = tile.position_px(j);
                let (dx, dy) = (kx - px, ky - py);
                if dx * dx + dy * dy > r2 {
                    continue;
                }
                let k = tile.keypoint(j);
                if k.laplacian_positive != f.keypoint.laplacian_positive {
                    continue;
                }
                let ratio = k.scale_px / expect_scale;
                if !(0.67..=1.5).contains(&ratio) {
                    continue;
                }
                let bound = best.map_or(self.cfg.guided_max_ssd, |b| b.0);
                let d = crate::matching::ssd_to_tile(&f.descriptor, tile, j, bound);
                if d <= bound && best.is_none_or(|b| d < b.0) {
                    best = Some((d, j));
                }
            }
            if let Some((ssd, j)) = best {
                // A full list keeps the first M frame features (strongest first).
                let _ = guided.push(Match {
                    frame: i as u16,
                    tile: j as u16,
                    ssd,
                });
            }
        }
        if guided.len() < self.cfg.gate.min_matches as usize {
            return false;
        }
        ws.matches = guided;
        true
    }

    fn locate_features<const P: usize, const W: usize, const K: usize, const M: usize>(
        &self,
        ws: &mut NavWorkspace<P, W, K, M>,
        frame_w: usize,
        frame_h: usize,
        prior: Option<&Prior>,
        spent: u32,
    ) -> FrameReport {
        let feats = ws.features.as_slice();
        let mut report = FrameReport {
            features: feats.len() as u16,
            features_dropped: ws.features.dropped,
            detect_stats: ws.features.stats,
            detected: true,
            work: spent,
            ..FrameReport::nothing_yet()
        };
        ws.matches.clear();
        // A frame whose consensus never runs (too few matches) must not show the last frame's
        // inlier flags through `inliers()`.
        ws.inlier.fill(false);
        if feats.len() < self.cfg.gate.min_matches as usize {
            return report;
        }
        let tile = &self.tile;
        let use_tile = self.footprint(prior, frame_w, frame_h);
        // Matching (over the tile features in the prior's footprint) must fit.
        let n_tile = tile.len();
        let candidates = self.candidates(prior, frame_w, frame_h);
        if cost::matching(feats.len(), n_tile, candidates) > self.room(&report) {
            report.outcome = Err(NoFix::OverBudget);
            report.over_budget = true;
            return report;
        }
        report.match_stats =
            match_features(feats, tile, &self.cfg.matching, use_tile, &mut ws.matches);
        report.charge(cost::matching(
            feats.len(),
            n_tile,
            report.match_stats.tile_candidates as usize,
        ));
        // Orientation gate from the prior heading: a true match's orientations differ by the heading.
        let upright = tile.header().upright;
        if let Some(p) = prior
            && !upright
            && p.heading_sigma_rad < core::f32::consts::FRAC_PI_4
        {
            let tol = (3.0 * p.heading_sigma_rad).max(0.35);
            ws.matches.retain(|m| {
                let fo = feats
                    .get(m.frame as usize)
                    .map_or(0.0, |f| f.keypoint.orientation_rad);
                let to = tile.keypoint(m.tile as usize).orientation_rad;
                let d = libm::remainderf(to - fo - p.heading_rad, core::f32::consts::TAU);
                libm::fabsf(d) <= tol
            });
        }
        report.matches = ws.matches.len() as u16;
        if ws.matches.len() < self.cfg.gate.min_matches as usize {
            report.outcome = Err(NoFix::TooFewMatches);
            return report;
        }
        // MSAC leaves room for the shortest refinement: a fix the budget cannot check does
        // not stand anyway.
        let reserve = self.refine_reserve();
        let mut r = match self.consensus(ws, &mut report, reserve) {
            Some((Some(r), _)) => r,
            Some((None, false)) => {
                report.outcome = Err(NoFix::TooFewInliers);
                return report;
            }
            Some((None, true)) | None => {
                report.outcome = Err(NoFix::OverBudget);
                return report;
            }
        };
        // Guided matching runs only if it and a whole second MSAC fit (its list has at most
        // one match per frame feature); otherwise the first consensus stands.
        let n_feat = ws.features.len();
        let guided_need = cost::guided_matching(n_feat, n_tile)
            .saturating_add(
                cost::msac_sample(n_feat).saturating_mul(u32::from(self.cfg.msac.max_iterations)),
            )
            .saturating_add(reserve);
        let guided_fits = guided_need <= self.room(&report);
        if self.cfg.guided_radius_px > 0.0 && !guided_fits {
            report.over_budget = true;
        }
        if self.cfg.guided_radius_px > 0.0 && guided_fits {
            let guided = self.guided_matches(ws, &r.affine);
            report.charge(cost::guided_matching(n_feat, n_tile));
            if guided {
                match self.consensus(ws, &mut report, reserve) {
                    Some((Some(g), _)) if g.inliers >= r.inliers => r = g,
                    // Cannot happen in practice (the first inliers are among the guided
                    // candidates, and the whole second MSAC fits); if it does, the frame is
                    // inconsistent and no fix is the safe answer.
                    _ => {
                        report.outcome = Err(NoFix::TooFewInliers);
                        return report;
                    }
                }
                report.matches = ws.matches.len() as u16;
            }
        }
        let n = ws.matches.len();
        let pts = ws.pts.get(..n).unwrap_or(&[]);
        report.inliers = r.inliers;
        report.msac_iterations = r.iterations;
        report.affine = Some(r.affine);
        let inlier_pts = pts
            .iter()
            .zip(ws.inlier.iter())
            .filter(|(_, f)| **f)
            .map(|(p, _)| (p.x, p.y));
        let gate = &self.cfg.gate;
        report.outcome = make_fix(
            &r,
            tile.header(),
            frame_w,
            frame_h,
            gate,
            inlier_pts.clone(),
        );
        let can_confirm = self.cfg.refine.enabled && tile.slope_raster().is_some();
        // Thin or clustered consensus: a frame-wide correlation can still confirm it.
        if matches!(
            report.outcome,
            Err(NoFix::TooFewInliers | NoFix::DegenerateGeometry)
        ) && can_confirm
            && gate.min_inliers_verified > 0
            && r.inliers >= gate.min_inliers_verified
        {
            let relaxed = GateConfig {
                min_inliers: gate.min_inliers_verified,
                min_inlier_spread_px: 0.0,
                ..*gate
            };
            report.outcome = make_fix(&r, tile.header(), frame_w, frame_h, &relaxed, inlier_pts);
            report.needed_confirmation = report.outcome.is_ok();
        }
        report
    }
}

/// Whether a fix centred at `center` (tile pixels) with position covariance `c` (tile px²)
/// lies within `gate` σ of the prior: the Mahalanobis length of the offset of centres under
/// the prior's and the fix's covariances summed. A fix elongated along one axis (a ridge, a
/// bowl's rotation) is gated by its own ellipse, not by one axis' variance. An infinite prior
/// σ constrains nothing; a covariance that is not positive definite, or NaN anywhere, fails.
fn within_prior_gate(center: [f64; 2], c: &[[f64; 2]; 2], p: &Prior, gate: f64) -> bool {
    if p.sigma_px == f32::INFINITY {
        return true;
    }
    let (dx, dy) = (
        center[0] - p.center_tile_px[0] as f64,
        center[1] - p.center_tile_px[1] as f64,
    );
    let sp2 = (p.sigma_px as f64) * (p.sigma_px as f64);
    let (sxx, sxy, syy) = (sp2 + c[0][0], 0.5 * (c[0][1] + c[1][0]), sp2 + c[1][1]);
    let det = sxx * syy - sxy * sxy;
    let d2 = (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det;
    sxx > 0.0 && det > 0.0 && d2 <= gate * gate
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gate(x: f64, y: f64, cov: [[f64; 2]; 2], p: &Prior) -> bool {
        within_prior_gate([x, y], &cov, p, 5.0)
    }

    fn prior(sigma_px: f32) -> Prior {
        Prior {
            center_tile_px: [100.0, 100.0],
            sigma_px,
            heading_rad: 0.0,
            heading_sigma_rad: 0.1,
            scale: 0.5,
            scale_sigma: 0.02,
        }
    }

    #[test]
    fn frames_bin_down_unless_nearly_up_and_within_the_cap() {
        assert_eq!(bin_factor_for(20.0, 10.0), 2);
        assert_eq!(bin_factor_for(20.0, 11.5), 2); // 1.74× finer: still 2
        assert_eq!(bin_factor_for(20.0, 13.0), 1);
        assert_eq!(bin_factor_for(20.0, 7.5), 2); // 2.67×: down to 2
        assert_eq!(bin_factor_for(20.0, 7.4), 3); // 2.70×: nearly up, 3
        assert_eq!(bin_factor_for(20.0, 0.5), crate::slope::MAX_BIN);
        for bad in [0.0, -1.0, f32::NAN] {
            assert_eq!(bin_factor_for(20.0, bad), 1);
            assert_eq!(bin_factor_for(bad, 10.0), 1);
        }
    }

    #[test]
    fn the_matched_blur_equals_the_tiles_at_every_binned_pixel() {
        let (s, t) = (40.0f32, 20.0f32);
        // At the tile's own pixel the grid blur is shared: plain s / b.
        assert_eq!(matched_smoothing_px(s, t, t), s / t);
        for b in [12.0f32, 15.4, 17.0, 21.0, 27.0] {
            let sigma = matched_smoothing_px(s, t, b);
            // Total blur variance, m²: Gaussian plus the grid's, frame against tile.
            let frame = (sigma * b).powi(2) + GRID_BLUR_VAR_PX2 * b * b;
            let tile = s * s + GRID_BLUR_VAR_PX2 * t * t;
            assert!(
                (frame - tile).abs() < 1e-3 * tile,
                "b {b}: {frame} vs {tile}"
            );
            // Finer than the tile: more Gaussian than s / b; coarser: less.
            assert_eq!(sigma > s / b, b < t, "b {b}");
        }
        // A frame so coarse that its grid alone blurs more than the tile: no Gaussian.
        assert_eq!(matched_smoothing_px(4.0, 20.0, 60.0), 0.0);
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(matched_smoothing_px(bad, t, 15.0), 0.0);
            assert_eq!(matched_smoothing_px(s, bad, 15.0), 0.0);
            assert_eq!(matched_smoothing_px(s, t, bad), 0.0);
        }
        assert_eq!(matched_smoothing_px(f32::MAX, t, 15.0), 0.0);
    }

    #[test]
    fn the_prior_gate_reads_the_whole_ellipse() {
        // Prior σ 1 px; the fix is 20 px off along y, and its own σ along y is 6 px (along x
        // 0.1 px): 20 / √(1 + 36) = 3.3σ passes a 5σ gate; x's variance alone would say 20σ.
        let long_y = [[0.01, 0.0], [0.0, 36.0]];
        assert!(gate(100.0, 120.0, long_y, &prior(1.0)));
        // The same offset along x, where the ellipse is narrow, fails.
        assert!(!gate(120.0, 100.0, long_y, &prior(1.0)));
        // Correlation counts: an ellipse along the diagonal passes a diagonal offset and
        // refuses the crossing one.
        let diag = [[18.0, 17.9], [17.9, 18.0]];
        assert!(gate(114.0, 114.0, diag, &prior(1.0)));
        assert!(!gate(114.0, 86.0, diag, &prior(1.0)));
        // An infinite prior σ gates nothing; NaN anywhere refuses.
        assert!(gate(900.0, -900.0, long_y, &prior(f32::INFINITY)));
        assert!(!gate(100.0, 100.0, long_y, &prior(f32::NAN)));
        let nan = [[f64::NAN, 0.0], [0.0, 1.0]];
        assert!(!gate(100.0, 100.0, nan, &prior(1.0)));
    }
}
