//! The InSAR chain: an SLC pair (or a DEM, through the SAR simulation) to a geocoded DEM with
//! coherence, height bound and mask.

use std::time::Instant;

use rayon::prelude::*;

use serde::{Deserialize, Serialize};

use super::coreg::{
    ResidualOffset, estimate_residual_offset, predicted_offset_gates, resample_range,
};
use super::cycles::{CycleChoice, CyclePrior, choose_cycles, coarse_prior, max_cycles};
pub use super::demfilter::{
    DemFilter, DemFilterKind, LookNoise, dem_filter_noise_factor, dem_filter_noise_factors,
    error_blur_m, filter_dem, gaussian_filter,
};
use super::geocode::{
    GeocodeParams, OutputGrid, RadarPixels, eq20_mask, geocode, label, ray_trace_mask,
};
use super::geometry::{PairGeometry, wrap_rad};
use super::looks::{
    LookWindow, equivalent_looks_1d, multilook, multilook_noise_correlation, parallax_bound_factor,
    passes_thermal_coherence, stacked_phase_crlb_rad,
};
use super::unwrap::unwrap_quality_guided;
use super::{InsarError, InsarResult};
use crate::dem::Dem;
use crate::dem::stats::CellCounts;
use crate::sar::kernel::SincKernel;
use crate::sar::pipeline::{InsarPair, SimOptions, Timings, simulate_with};
use crate::sar::{Antenna, C32, Polarisation, SarConfig, SarDem, Slc};

/// Processing parameters. Defaults are the paper's (8×8 window, step 4, 20 m) plus our
/// thresholds, documented in `docs/insar.md`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct InsarConfig {
    /// Multilook window (paper: 8×8, step 4).
    pub window: LookWindow,
    /// Output grid pixel, m (paper: 20).
    pub pixel_m: f64,
    /// Coherence below which a pixel's height is dropped (σ_h ≥ 25 m at 0.5 with 21 looks).
    pub min_coherence: f64,
    /// Height uncertainty allowed to the geometric masks, in units of each cell's Cramér–Rao
    /// height bound: the ray tracing of shadow and layover on the generated DEM
    /// ([`ray_trace_mask`]) only counts a cell as blocking or folding when it does so by more
    /// than this many σ_h (of it and of the cell it is compared with), so height noise makes no
    /// mask. Dark but coherent ground is never masked for being dark.
    pub geometry_tolerance_sigmas: f64,
    /// Mean radar power this many dB below the scene median = no echo, masked as shadow
    /// (`f64::INFINITY` = never: masks by geometry and coherence only). Default 12 dB: without
    /// it the chain keeps dark cells whose phase is another echo's (see docs/insar.md, "Masks").
    pub shadow_below_median_db: f64,
    /// Unwrap the flat-removed phase (quality-guided). Without it the phase is used wrapped.
    pub unwrap: bool,
    /// Search a residual range offset by coherence (a check of the geometric coregistration).
    pub check_coregistration: bool,
    /// Geocoding limits.
    pub geocode: GeocodeParams,
    /// Kernel of the filter applied to the geocoded DEM ([`DemFilterKind`]). Default the
    /// Gaussian mean; the local quadratic fit makes a better DEM but not yet a better tile
    /// (`docs/insar.md`, "A filter without curvature bias"). Not in the paper.
    pub dem_filter: DemFilterKind,
    /// σ of the DEM filter's Gaussian weights, output pixels (0 = no filter, the paper's
    /// processing). Default 1 px for the mean ([`DemFilterKind::default_sigma_px`]): it halves
    /// the pixel-scale height noise that the slope operator amplifies (measured in
    /// `docs/insar.md`).
    pub dem_filter_sigma_px: f64,
    /// Detect the reference tile's features on the DEM with its small holes filled
    /// (`reference::holes`; the tile's slope raster keeps them). On by default since the bound
    /// carries the parallax term: docs/insar.md, "The parallax of the height error, and holes
    /// in the tile".
    pub fill_tile_holes: bool,
    /// Passes of the speckle-centroid correction ([`recentre_heights`]; 0 = none, the paper's
    /// processing). Not in the paper: see `docs/insar.md`.
    pub recentre_passes: usize,
    /// Range sampling rate over the processed bandwidth (SAR default 2), for the looks.
    pub range_oversampling: f64,
    /// PRF over the processed Doppler bandwidth (SAR default 2), for the looks.
    pub azimuth_oversampling: f64,
    /// Hamming coefficient of the focusing windows (SAR default 0.54), for the looks.
    pub hamming_alpha: f64,
    /// Cell of the coarse prior DEM that picks the unwrapped phase's whole cycles, m
    /// ([`super::cycles`]; 0 = none: the unwrapper's datum rule alone). Default 240 m, the
    /// scale of LOLA's global gridded topography (≈ 237 m at 128 pixels per degree); the
    /// simulation averages the truth over such cells. It chooses cycles only, never a height.
    pub prior_dem_cell_m: f64,
    /// Passes of one track stacked into one interferogram per look, 1–[`MAX_PASSES`]
    /// ([`process_stack`]; default 1). The simulation flies them over the same ground (the
    /// same speckle: a conservative repeat of the track) with independent receiver noise; the
    /// orbit of every pass is known exactly (no orbit error is modelled).
    pub passes: usize,
    /// A second, longer baseline, m, whose heights replace the short pair's where they agree
    /// and are better ([`super::baselines`]; 0 = none, the default). It must be longer than
    /// the radar's own baseline.
    pub long_baseline_m: f64,
    /// σ, output pixels, of the Gaussian mean that filters the long pair's DEM (0 = none;
    /// only with the Gaussian kernel); `None` (the default): the short pair's
    /// [`Self::dem_filter_sigma_px`] (`super::baselines::long_config`).
    pub long_filter_sigma_px: Option<f64>,
}

impl Default for InsarConfig {
    fn default() -> Self {
        Self {
            window: LookWindow::default(),
            pixel_m: 20.0,
            min_coherence: 0.5,
            geometry_tolerance_sigmas: 1.0,
            shadow_below_median_db: 12.0,
            unwrap: true,
            check_coregistration: true,
            geocode: GeocodeParams::default(),
            dem_filter: DemFilterKind::Gaussian,
            dem_filter_sigma_px: DemFilterKind::Gaussian.default_sigma_px(),
            fill_tile_holes: true,
            recentre_passes: 2,
            range_oversampling: 2.0,
            azimuth_oversampling: 2.0,
            hamming_alpha: 0.54,
            prior_dem_cell_m: DEFAULT_PRIOR_DEM_CELL_M,
            passes: 1,
            long_baseline_m: 0.0,
            long_filter_sigma_px: None,
        }
    }
}

/// Default [`InsarConfig::prior_dem_cell_m`], m.
pub const DEFAULT_PRIOR_DEM_CELL_M: f64 = 240.0;

impl InsarConfig {
    /// Take the look-relevant radar values from the SAR configuration that made the SLCs.
    pub fn with_radar(mut self, sar: &SarConfig) -> Self {
        self.range_oversampling = sar.range_oversampling;
        self.azimuth_oversampling = sar.azimuth_oversampling;
        self.hamming_alpha = sar.hamming_alpha;
        self
    }

    /// The DEM filter ([`Self::dem_filter`] at [`Self::dem_filter_sigma_px`]).
    pub fn filter(&self) -> DemFilter {
        DemFilter {
            kind: self.dem_filter,
            sigma_px: self.dem_filter_sigma_px,
        }
    }

    /// Gaussian-equivalent σ, metres, that the output DEM's heights carry beyond the averaging
    /// of its own pixel: the multilook window (a box `size/step` output pixels wide, variance
    /// `L²/12` per axis, less the pixel's own `pixel²/12`) and the DEM filter's second moment
    /// ([`DemFilter::signal_sigma_m`]: the mean's σ, none for the quadratic fit). With the
    /// defaults `sqrt((40² − 20²)/12 + 20²)` = 22.4 m (10 m with the quadratic fit). The
    /// reference tile tops this up to its target. The height *noise* is correlated further
    /// ([`error_blur_m`]).
    pub fn inherent_smoothing_m(&self) -> f64 {
        let box_px = self.window.size as f64 / self.window.step.max(1) as f64;
        let window_var = (box_px * box_px - 1.0).max(0.0) * self.pixel_m.powi(2) / 12.0;
        let filter = self.filter().signal_sigma_m(self.pixel_m);
        (window_var + filter * filter).sqrt()
    }

    /// Check the parameters (window, pixel, coherence, filter, passes, prior cell); the chain calls it
    /// first, the commands before any simulation.
    pub fn validate(&self) -> InsarResult<()> {
        let w = self.window;
        if w.size == 0 || w.step == 0 || w.step > w.size {
            return Err(InsarError::Input(format!(
                "look window {}×{} step {} invalid",
                w.size, w.size, w.step
            )));
        }
        if !(self.pixel_m > 0.0 && (0.0..1.0).contains(&self.min_coherence)) {
            return Err(InsarError::Input(
                "pixel_m must be > 0 and min_coherence in [0, 1)".into(),
            ));
        }
        if !(1..=MAX_PASSES).contains(&self.passes) {
            return Err(InsarError::Input(format!(
                "passes must be 1–{MAX_PASSES}, got {}",
                self.passes
            )));
        }
        let sigma = self.dem_filter_sigma_px;
        let (lo, hi) = (
            super::demfilter::MIN_SIGMA_PX,
            super::demfilter::MAX_SIGMA_PX,
        );
        if !(sigma == 0.0 || (lo..=hi).contains(&sigma)) {
            return Err(InsarError::Input(format!(
                "the DEM filter's σ must be 0 (none) or {lo}–{hi} px, got {sigma}"
            )));
        }
        if self.long_filter_sigma_px.is_some()
            && !(self.long_baseline_m > 0.0 && self.dem_filter == DemFilterKind::Gaussian)
        {
            return Err(InsarError::Input(
                "the long pair's DEM filter width needs a long baseline and the Gaussian mean \
                 (--long-baseline-m, --dem-filter gaussian)"
                    .into(),
            ));
        }
        if let Some(long) = self.long_filter_sigma_px
            && !(long == 0.0 || (lo..=hi).contains(&long))
        {
            return Err(InsarError::Input(format!(
                "the long pair's DEM filter σ must be 0 (none) or {lo}–{hi} px, got {long}"
            )));
        }
        if !(self.prior_dem_cell_m.is_finite() && self.prior_dem_cell_m >= 0.0) {
            return Err(InsarError::Input(format!(
                "the prior DEM's cell must be ≥ 0 m (0 = no prior), got {}",
                self.prior_dem_cell_m
            )));
        }
        if !(self.long_baseline_m.is_finite() && self.long_baseline_m >= 0.0) {
            return Err(InsarError::Input(format!(
                "the long baseline must be ≥ 0 m (0 = none), got {}",
                self.long_baseline_m
            )));
        }
        if self.long_baseline_m > 0.0 && !self.unwrap {
            return Err(InsarError::Input(
                "a long baseline needs its phase unwrapped (its cycles are chosen against the \
                 short map): drop --no-unwrap, or fly the radar's own pair alone \
                 (--long-baseline-m 0)"
                    .into(),
            ));
        }
        Ok(())
    }
}

/// Coregistration figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CoregReport {
    /// Predicted A2 − A1 offset at the first gate, gates.
    pub offset_near_gates: f64,
    /// Predicted offset at the last gate, gates.
    pub offset_far_gates: f64,
    /// Coherence search around the prediction (if run).
    pub check: Option<ResidualOffset>,
}

/// Unwrapping figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UnwrapReport {
    /// Whether unwrapping ran.
    pub ran: bool,
    /// Span of the unwrapped flat-removed phase over good pixels, rad (≥ 2π means wrapping
    /// was necessary).
    pub phase_span_rad: f64,
    /// Height span that phase span stands for (with the centre height of ambiguity), m.
    pub height_span_m: f64,
    /// Height of ambiguity at the scene centre, m per 2π.
    pub ambiguity_height_m: f64,
    /// Pixels where the unwrapped phase differs from the wrapped one by a multiple of 2π.
    pub pixels_changed: usize,
    /// Separate regions grown.
    pub regions: usize,
    /// Whole cycles chosen patch by patch with the coarse prior DEM (absent in reports made
    /// before session 22).
    #[serde(default)]
    pub prior: CycleChoice,
}

/// Fractions of the output grid per mask code.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct MaskFractions {
    /// Valid heights.
    pub valid: f64,
    /// Layover.
    pub layover: f64,
    /// Shadow.
    pub shadow: f64,
    /// Low coherence.
    pub low_coherence: f64,
    /// Outside the radar image.
    pub outside: f64,
}

impl MaskFractions {
    /// Fractions of `labels` per code.
    pub fn of(labels: &[u8]) -> Self {
        let n = labels.len().max(1) as f64;
        let f = |l: u8| labels.iter().filter(|&&x| x == l).count() as f64 / n;
        Self {
            valid: f(label::VALID),
            layover: f(label::LAYOVER),
            shadow: f(label::SHADOW),
            low_coherence: f(label::LOW_COHERENCE),
            outside: f(label::OUTSIDE),
        }
    }
}

/// Radar-geometry (multilooked) layers, row-major `lines × cols`, for pictures and checks.
#[derive(Debug, Clone)]
pub struct RadarLayers {
    /// Multilooked lines.
    pub lines: usize,
    /// Multilooked range columns.
    pub cols: usize,
    /// Azimuth spacing of the lines, m.
    pub line_spacing_m: f64,
    /// Interferometric phase Δφ0 with the flat-Moon phase (wrapped), rad — Fig. 5a/c.
    pub phase_with_flat_rad: Vec<f32>,
    /// Flat-removed phase Δφ (wrapped), rad — Fig. 5b/d.
    pub phase_rad: Vec<f32>,
    /// Unwrapped flat-removed phase, rad.
    pub phase_unwrapped_rad: Vec<f32>,
    /// Coherence.
    pub coherence: Vec<f32>,
    /// Height from eq 17, m (absolute, the DEM's datum).
    pub height_m: Vec<f32>,
    /// Ground range of each pixel after parallax correction, m.
    pub ground_y_m: Vec<f64>,
    /// Mask code per pixel.
    pub labels: Vec<u8>,
}

/// Everything the chain produced for one pair.
#[derive(Debug, Clone)]
pub struct InsarProduct {
    /// Pair geometry.
    pub geometry: PairGeometry,
    /// Configuration used.
    pub config: InsarConfig,
    /// Output grid.
    pub grid: OutputGrid,
    /// Generated DEM on the grid, m (NaN = nodata).
    pub dem: Dem,
    /// Coherence on the grid (NaN = nodata).
    pub coherence: Dem,
    /// Per-pixel Cramér–Rao height bound on the grid, m (NaN = nodata).
    pub crlb_m: Dem,
    /// Mask codes on the grid ([`label`]).
    pub labels: Vec<u8>,
    /// Radar-geometry layers.
    pub radar: RadarLayers,
    /// Equivalent independent looks of one window, times the stacked passes
    /// ([`InsarConfig::passes`]): the receiver noise's looks. The surface's decorrelation has one
    /// pass's looks (the passes share their speckle; `looks::stacked_phase_crlb_rad`).
    pub effective_looks: f64,
    /// Factor, 0–1, by which the DEM filter shrank the height CRLB of every cell whose filter
    /// kernel lay on valid cells ([`dem_filter_noise_factor`]; 1 without the filter). Cells by
    /// a hole or the edge have their own ([`dem_filter_noise_factors`]).
    pub crlb_filter_factor: f64,
    /// Correlation length of the height noise after the DEM filter: σ, metres, of the Gaussian
    /// blur of white noise with the same neighbour correlation ([`error_blur_m`]). Reported
    /// for the quadratic DEM filter, whose signal blur is not its noise's; the rehearsal draws
    /// the map's error with it.
    pub error_blur_m: f64,
    /// Coregistration figures.
    pub coreg: CoregReport,
    /// Unwrapping figures.
    pub unwrap: UnwrapReport,
    /// Mask fractions of the grid.
    pub mask: MaskFractions,
    /// Pixels removed by the eq 20 test on the generated DEM (after the ray tracing).
    pub eq20_removed: usize,
    /// Pixels removed by the ray-traced shadow and layover of the generated DEM.
    pub geometry_removed: usize,
    /// Mean coherence of all multilooked radar pixels.
    pub coherence_mean_radar: f64,
    /// Processing time, s.
    pub seconds: f64,
    /// With two look directions: how the passes were fused (the other fields describe the
    /// east-looking pass, except `dem`, `coherence`, `crlb_m`, `labels` and `mask`, which are
    /// the fused map's).
    pub look_fusion: Option<LookFusion>,
    /// With a long baseline ([`InsarConfig::long_baseline_m`]): how it entered the map, one
    /// entry per look direction (east first); empty without one.
    pub baseline_fusion: Vec<super::baselines::BaselineFusion>,
}

impl InsarProduct {
    /// Gaussian-equivalent σ, metres, the map's heights carry beyond their pixel's
    /// ([`InsarConfig::inherent_smoothing_m`] of its chain). Where a long baseline replaced
    /// cells with heights filtered at another width ([`super::baselines::long_config`]), the
    /// variance is mixed by the share of cells each gave, averaged over the looks.
    pub fn inherent_smoothing_m(&self) -> f64 {
        super::baselines::mixed_inherent_smoothing_m(&self.config, &self.baseline_fusion)
    }
}

/// Look directions of an InSAR map (the commands' default is the radar preset's,
/// [`LookDirections::of_preset`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum LookDirections {
    /// One pass, the radar looking east (towards +columns), as the paper.
    One,
    /// A second pass looking west, fused with the first cell by cell.
    Both,
}

impl LookDirections {
    /// The look directions a radar design flies: the paper one pass, the mission two (east and
    /// west: the second look is what takes lost-in-space TRN on the noisy floors from 20–36 % to
    /// 92–100 %, docs/insar.md, "Walls under noise" and "The default radar").
    pub fn of_preset(preset: crate::sar::RadarPreset) -> Self {
        match preset {
            crate::sar::RadarPreset::Paper => LookDirections::One,
            crate::sar::RadarPreset::Mission => LookDirections::Both,
        }
    }

    /// The name the CLI and the JSON use (`one`, `both`).
    pub fn name(self) -> &'static str {
        match self {
            LookDirections::One => "one",
            LookDirections::Both => "both",
        }
    }
}

/// How two look directions were fused on the output grid.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LookFusion {
    /// Mask fractions of the east-looking pass alone.
    pub east_mask: MaskFractions,
    /// Mask fractions of the west-looking pass alone.
    pub west_mask: MaskFractions,
    /// Fraction of cells valid in both passes (height = inverse-variance mean by their CRLB).
    pub both_valid: f64,
    /// Fraction valid in the east pass only.
    pub east_only: f64,
    /// Fraction valid in the west pass only.
    pub west_only: f64,
    /// Fraction valid in both passes whose heights disagree by more than
    /// [`FUSE_CONSISTENCY_SIGMAS`] combined CRLBs; dropped (labelled low coherence).
    pub inconsistent: f64,
    /// Whole cycles removed from the west pass to align its unwrapping on the east pass's
    /// ([`fuse_looks`]); 0 when they agreed. For a map made in blocks: how many blocks were
    /// shifted (each block's own shift is in the report's `blocks.per_block`).
    #[serde(default)]
    pub west_cycles_shifted: i64,
    /// Largest share of one-look cells among the valid cells of any square window of
    /// [`ONE_LOOK_WINDOW_M`] on the grid (windows at least half valid; clipped to a narrower
    /// grid), 0–1: what the frame over the most one-look ground carries
    /// ([`LookFusion::one_look_share_for_frames`]). NaN when not known (reports before session
    /// 24, or no valid cell). For a map in blocks: the largest of its blocks'.
    #[serde(
        default = "nan",
        deserialize_with = "crate::evaluation::shard::f64_or_nan"
    )]
    pub worst_window_one_look_share: f64,
    /// The map's height error measured against its own bound, from the two looks'
    /// disagreement: per octave band of `dem::spectrum::BAND_EDGES` (cycles per map pixel),
    /// the power of the east − west height difference over the cells valid in both, divided
    /// by the power the bound predicts for that difference (√(σ_e² + σ_w²) per cell times
    /// noise with the map's error correlation, masked alike). 1: the bound is right in that
    /// octave; 2: the real error has twice its power. Errors both looks share do not show, nor
    /// do the cells whose looks disagree beyond [`FUSE_CONSISTENCY_SIGMAS`] (dropped from the
    /// map as well). An octave with fewer than [`ERROR_SPECTRUM_MIN_COEFFICIENTS`] Fourier
    /// coefficients on the grid (the coarsest, on a small map), or with no power on either
    /// side, reads 1: not measured, the bound taken as it is. `None` with fewer than
    /// [`ERROR_SPECTRUM_MIN_CELLS`] cells valid in both. For a map made in blocks: the
    /// measuring blocks' ratios weighted by the cells they own.
    #[serde(default)]
    pub error_spectrum_ratio: Option<[f64; crate::dem::spectrum::BAND_EDGES.len()]>,
}

/// Least cells valid in both looks for [`LookFusion::error_spectrum_ratio`].
pub const ERROR_SPECTRUM_MIN_CELLS: usize = 1024;
/// Least Fourier coefficients an octave needs on the grid for its ratio to be measured (half
/// of them independent for a real field: 32 give a ratio within ≈ 25 %, 1σ, from the
/// measured side's own scatter). The coarsest octave of a 200² map holds ≈ 120.
pub const ERROR_SPECTRUM_MIN_COEFFICIENTS: usize = 64;
/// Draws of the bound's noise averaged for the ratio's denominator (the measured side's
/// scatter, ≈ 13 % in the coarsest octave of a 200² map, is not averaged away).
const ERROR_SPECTRUM_DRAWS: u64 = 4;

/// [`LookFusion::error_spectrum_ratio`] from the two looks' heights and bounds on one grid
/// (`w` wide), the cells `both` valid and consistent, the error's correlation `blur_px`.
fn look_error_spectrum(
    (ze, zw): (&[f32], &[f32]),
    (se, sw): (&[f32], &[f32]),
    both: &[bool],
    w: usize,
    blur_px: f64,
) -> Option<[f64; crate::dem::spectrum::BAND_EDGES.len()]> {
    use crate::dem::spectrum::{band_powers, correlated_noise};
    let n = both.len();
    let h = n / w.max(1);
    let var: Vec<f64> = (0..n)
        .map(|i| {
            let v = f64::from(se[i]).powi(2) + f64::from(sw[i]).powi(2);
            if both[i] && v.is_finite() && v > 0.0 {
                v
            } else {
                0.0
            }
        })
        .collect();
    let cells = var.iter().filter(|&&v| v > 0.0).count();
    if cells < ERROR_SPECTRUM_MIN_CELLS || w * h != n {
        return None;
    }
    // Each field less its mean over the cells it has (a bias between the looks is not an
    // error the draw should shape), zero elsewhere.
    let centred = |f: &dyn Fn(usize) -> f64| -> Vec<f64> {
        let mean = (0..n).filter(|&i| var[i] > 0.0).map(f).sum::<f64>() / cells as f64;
        (0..n)
            .map(|i| if var[i] > 0.0 { f(i) - mean } else { 0.0 })
            .collect()
    };
    let diff = centred(&|i| f64::from(ze[i]) - f64::from(zw[i]));
    let measured = band_powers(&diff, w, h);
    let mut model = [0.0; crate::dem::spectrum::BAND_EDGES.len()];
    for k in 0..ERROR_SPECTRUM_DRAWS {
        let u = correlated_noise(w, h, blur_px, 0x4C4F_4F4B_5350_4543 ^ k);
        let m = centred(&|i| var[i].sqrt() * u[i]);
        for (a, b) in model.iter_mut().zip(band_powers(&m, w, h)) {
            *a += b / ERROR_SPECTRUM_DRAWS as f64;
        }
    }
    let counts = crate::dem::spectrum::band_counts(w, h);
    Some(core::array::from_fn(|b| {
        let r = measured[b] / model[b];
        if r.is_finite() && r > 0.0 && counts[b] >= ERROR_SPECTRUM_MIN_COEFFICIENTS {
            r
        } else {
            1.0
        }
    }))
}

fn nan() -> f64 {
    f64::NAN
}

/// Side of the windows [`LookFusion::worst_window_one_look_share`] scans, metres: a flight
/// frame's footprint (200 px at 10 m).
pub const ONE_LOOK_WINDOW_M: f64 = 2000.0;

impl LookFusion {
    /// The share of one-look cells a tile's reference error must cover
    /// (`reference::reference_sigma_m`): the worst frame-sized window's
    /// ([`LookFusion::worst_window_one_look_share`]), else the whole map's. A frame's fix
    /// moves by the share of its own cells that keep one look's shift; one-look cells cluster
    /// on the walls each look cannot see, so the map's mean under-covers the frames there (the
    /// fresh rim's fixes read NEES 6.6 with it).
    pub fn one_look_share_for_frames(&self) -> f64 {
        if self.worst_window_one_look_share.is_finite() {
            self.worst_window_one_look_share
        } else {
            self.one_look_share()
        }
    }

    /// Share of the fused map's valid cells made by one look alone, 0–1 (1 when no cell is
    /// valid): the cells whose range-direction shift the second look did not cancel
    /// (`reference::reference_sigma_m`).
    pub fn one_look_share(&self) -> f64 {
        let one = self.east_only + self.west_only;
        let valid = one + self.both_valid;
        if valid > 0.0 { one / valid } else { 1.0 }
    }
}

/// Least cells valid in both looks for [`fuse_looks`] to align the two unwrappings' cycles.
pub const CYCLE_ALIGN_MIN_CELLS: usize = 100;

/// Height, m, that one whole cycle of `p`'s unwrapped phase makes in grid column `col` (its
/// height of ambiguity at that column's slant range on the datum).
pub fn cycle_height_m(p: &InsarProduct, col: usize) -> f64 {
    let g = &p.geometry;
    let r1 = (p.grid.y_m(col) - g.a1_yz_m[0]).hypot(g.a1_yz_m[1] - g.datum_m);
    g.ambiguity_height_m(r1)
}

/// Two looks' heights of one cell that differ by more than this many combined per-cell CRLBs
/// are not fused but dropped. The heights differ by more than their noise: each look's window
/// sees a slope from its own side, and the noise-free chain has its own error floor
/// ([`FUSE_MIN_BOUND_M`]); so agreeing measurements must pass well beyond 3σ, while a wrong 2π
/// cycle in one look (183 m for the 32 m boom, 733 m for the paper's) is caught wherever the
/// bounds are below ≈ 18 m. (Until session 24 the CRLB ignored the DEM filter and read 1.8×
/// the noise; the check was then 4 of those bounds with a 1 m floor: the same thresholds
/// within a few per cent.)
pub const FUSE_CONSISTENCY_SIGMAS: f64 = 7.0;

/// Smallest per-look bound, m, the consistency check uses: the chain's error without thermal
/// noise (window resolution, speckle centroids; 0.59 m on a tilted plane, the stacked-passes
/// test, whose noise-free CRLB reads 0.66 m there but less where the surface decorrelates
/// less).
pub const FUSE_MIN_BOUND_M: f64 = 0.6;

/// Whether two looks' heights `a`, `b` (m) with per-cell bounds `sa`, `sb` (m) differ by more
/// than [`FUSE_CONSISTENCY_SIGMAS`] combined bounds. A bound below [`FUSE_MIN_BOUND_M`] counts
/// as that; a missing bound never disagrees.
pub fn looks_disagree(a: f32, b: f32, sa: f32, sb: f32) -> bool {
    let bound = |s: f32| {
        let s = f64::from(s);
        if s.is_finite() {
            s.max(FUSE_MIN_BOUND_M)
        } else {
            f64::INFINITY
        }
    };
    (f64::from(a) - f64::from(b)).abs() > FUSE_CONSISTENCY_SIGMAS * bound(sa).hypot(bound(sb))
}

/// Run the InSAR chain on `a1`, `a2` onto `grid`. `prior`: a coarse DEM on `grid` (heights,
/// m, row-major) that picks the unwrapped phase's whole cycles ([`super::cycles`]); `None`
/// leaves them to the unwrapper's datum rule.
pub fn process_pair(
    a1: &Slc,
    a2: &Slc,
    grid: &OutputGrid,
    cfg: &InsarConfig,
    prior: Option<&[f32]>,
) -> InsarResult<InsarProduct> {
    process_stack(&[(a1, a2)], grid, cfg, prior)
}

/// [`process_pair`] on several passes of one track (`(A1, A2)` per pass, the same geometry and
/// size): each pass's interferogram is formed as in one pass and the multilook sums add
/// ([`super::looks::Looks::add_pass`]), so the phase and coherence are estimated from all
/// passes' samples. The CRLB credits the passes' looks to the receiver noise only (they share
/// their speckle; [`super::looks::stacked_phase_crlb_rad`]). The coregistration check and the
/// radar layers come from the first pass.
pub fn process_stack(
    pairs: &[(&Slc, &Slc)],
    grid: &OutputGrid,
    cfg: &InsarConfig,
    prior: Option<&[f32]>,
) -> InsarResult<InsarProduct> {
    let t0 = Instant::now();
    cfg.validate()?;
    let Some(&(a1, a2)) = pairs.first() else {
        return Err(InsarError::Input("no pass to process".into()));
    };
    if let Some(p) = prior
        && p.len() != grid.width * grid.height
    {
        return Err(InsarError::Input(format!(
            "the prior DEM has {} cells, the output grid {}×{}",
            p.len(),
            grid.width,
            grid.height
        )));
    }
    let g = PairGeometry::from_slcs(a1, a2)?;
    let (lines, gates) = (a1.lines, a1.gates);
    for (k, &(b1, b2)) in pairs.iter().enumerate().skip(1) {
        if (b1.lines, b1.gates, b2.lines, b2.gates) != (lines, gates, lines, gates)
            || PairGeometry::from_slcs(b1, b2)? != g
        {
            return Err(InsarError::Input(format!(
                "pass {} is not on the first pass's track (size or geometry differ): passes \
                 stack only on one track",
                k + 1
            )));
        }
    }
    let w = cfg.window;
    if w.outputs(lines) < 2 || w.outputs(gates) < 2 {
        return Err(InsarError::Input(format!(
            "SLC {lines}×{gates} too small for a {}-pixel window",
            w.size
        )));
    }

    // 1. Range coregistration.
    let kernel = SincKernel::new();
    let offset: Vec<f64> = (0..gates)
        .map(|j| predicted_offset_gates(&g, j as f64))
        .collect();
    let a2c = resample_range(&a2.data, lines, gates, &offset, 0.0, &kernel);
    let check = cfg
        .check_coregistration
        .then(|| estimate_residual_offset(&a1.data, &a2.data, lines, gates, &offset, w, &kernel));

    // 2. Interferogram, flat phase removed, multilook, coherence.
    let flat: Vec<f64> = (0..gates)
        .map(|j| g.flat_phase_rad(g.range_m(j as f64)))
        .collect();
    let mut looks = multilook(&a1.data, &a2c, lines, gates, &flat, w);
    for &(b1, b2) in &pairs[1..] {
        let b2c = resample_range(&b2.data, lines, gates, &offset, 0.0, &kernel);
        if !looks.add_pass(&multilook(&b1.data, &b2c, lines, gates, &flat, w)) {
            return Err(InsarError::Input(
                "a pass's multilook differs in shape from the first's".into(),
            ));
        }
    }
    let (lo, co) = (looks.lines, looks.gates);
    let coh = looks.coherence();
    let wrapped: Vec<f64> = looks.cross.iter().map(|c| c.arg()).collect();
    let n_win = (w.size * w.size) as f64;
    let power: Vec<f64> = looks
        .power1
        .iter()
        .zip(&looks.power2)
        .map(|(a, b)| 0.5 * (a + b) / n_win)
        .collect();
    let median_power = {
        let mut p = power.clone();
        p.sort_by(f64::total_cmp);
        p.get(p.len() / 2).copied().unwrap_or(0.0)
    };
    let shadow_power = median_power * 10f64.powf(-cfg.shadow_below_median_db / 10.0);

    // 3. Radar-geometry labels: no echo (if that rule is on), then low coherence. Shadow and
    //    layover proper come from the geometry (steps 6 and 7).
    let mut labels: Vec<u8> = (0..lo * co)
        .map(|i| {
            if power[i] <= shadow_power {
                label::SHADOW
            } else if f64::from(coh[i]) < cfg.min_coherence {
                label::LOW_COHERENCE
            } else {
                label::VALID
            }
        })
        .collect();

    // 4. Unwrapping (quality = coherence, masked pixels last).
    let quality: Vec<f32> = coh
        .iter()
        .zip(&labels)
        .map(|(&c, &l)| if l == label::VALID { c } else { 0.0 })
        .collect();
    let centre_r = g.range_m(0.5 * (gates as f64 - 1.0));
    let hoa = g.ambiguity_height_m(centre_r);
    let (unw, unwrap) = if cfg.unwrap {
        let mut u = unwrap_quality_guided(&wrapped, &quality, co, lo, cfg.min_coherence as f32);
        let prior_choice = prior.map(|heights_m| {
            let valid: Vec<bool> = labels.iter().map(|&l| l == label::VALID).collect();
            let place = |i: usize, phase: f64| {
                let (k, m) = (i / co, i % co);
                let r1 = g.range_m(w.centre(m));
                let z = g.datum_m + g.height_m(phase, r1);
                (g.azimuth_m(w.centre(k)), g.ground_y_m(r1, z), z)
            };
            let p = CyclePrior { heights_m, grid };
            choose_cycles(&mut u.phase_rad, &valid, co, &p, max_cycles(hoa), place)
        });
        let good: Vec<f64> = (0..lo * co)
            .filter(|&i| labels[i] == label::VALID)
            .map(|i| u.phase_rad[i])
            .collect();
        let span = span(&good);
        let rep = UnwrapReport {
            ran: true,
            phase_span_rad: span,
            height_span_m: span / std::f64::consts::TAU * hoa,
            ambiguity_height_m: hoa,
            pixels_changed: u.pixels_changed,
            regions: u.regions,
            prior: prior_choice.unwrap_or_default(),
        };
        (u.phase_rad, rep)
    } else {
        let good: Vec<f64> = (0..lo * co)
            .filter(|&i| labels[i] == label::VALID)
            .map(|i| wrapped[i])
            .collect();
        let span = span(&good);
        let rep = UnwrapReport {
            ran: false,
            phase_span_rad: span,
            height_span_m: span / std::f64::consts::TAU * hoa,
            ambiguity_height_m: hoa,
            pixels_changed: 0,
            regions: 0,
            prior: CycleChoice::default(),
        };
        (wrapped.clone(), rep)
    };

    // 5. Heights (eq 17 with each pixel's R1 and θ1), CRLB.
    // Stacked passes multiply the looks of the receiver noise only: they share their speckle,
    // so what the surface decorrelates is the same in every pass (`stacked_phase_crlb_rad`,
    // with the thermal share measured between the passes themselves).
    let looks_pass = equivalent_looks_1d(w.size, cfg.azimuth_oversampling, cfg.hamming_alpha)
        * equivalent_looks_1d(w.size, cfg.range_oversampling, cfg.hamming_alpha);
    let looks_eff = looks_pass * pairs.len() as f64;
    let thermal = if pairs.len() > 1 {
        let p1: Vec<&[C32]> = pairs.iter().map(|(a, _)| a.data.as_slice()).collect();
        let p2: Vec<&[C32]> = pairs.iter().map(|(_, b)| b.data.as_slice()).collect();
        let t = passes_thermal_coherence(&p1, &p2, lines, gates, w)
            .ok_or_else(|| InsarError::Input("the passes' SLCs differ in shape".into()))?;
        debug_assert_eq!(t.len(), lo * co);
        Some(t)
    } else {
        None
    };
    let mut z = vec![0.0f64; lo * co];
    let mut sig = vec![0.0f64; lo * co];
    for k in 0..lo {
        for m in 0..co {
            let i = k * co + m;
            let r1 = g.range_m(w.centre(m));
            z[i] = g.datum_m + g.height_m(unw[i], r1);
            // No estimate (0) credits nothing to the stack; the lengths agree by construction.
            let t = thermal
                .as_ref()
                .and_then(|t| t.get(i))
                .map_or(0.0, |&v| f64::from(v));
            sig[i] = stacked_phase_crlb_rad(f64::from(coh[i]), t, looks_pass, pairs.len())
                * g.ambiguity_height_m(r1)
                / std::f64::consts::TAU;
        }
    }

    let positions = |z: &[f64], labels: &[u8], radii: &[usize]| -> Vec<f64> {
        let mut gy = vec![0.0f64; lo * co];
        for k in 0..lo {
            for m in 0..co {
                let mut zs = g.datum_m;
                for &radius in radii {
                    let (mut acc, mut n) = (0.0, 0.0);
                    for kk in k.saturating_sub(radius)..(k + radius + 1).min(lo) {
                        for mm in m.saturating_sub(radius)..(m + radius + 1).min(co) {
                            let j = kk * co + mm;
                            if labels[j] == label::VALID {
                                acc += z[j];
                                n += 1.0;
                            }
                        }
                    }
                    if n > 0.0 {
                        zs = acc / n;
                        break;
                    }
                }
                gy[k * co + m] = g.ground_y_m(g.range_m(w.centre(m)), zs);
            }
        }
        gy
    };
    // Radar pixels centred beyond the scene (the grid's extent, which is the DEM the radar
    // saw) hold no ground of their own, only the scene edge's sidelobes: outside. Their own
    // heights are wrong, so this test places them with the mean height of a 9×9 block (mostly
    // pixels inside). It comes before the centroid correction, whose gradients they would spoil.
    // The grid's cell edges, widened by the geocoding's own edge extension: a pixel that
    // close still serves the outermost cells, as it did before this test.
    let half = (0.5 + cfg.geocode.edge_px) * grid.pixel_m;
    let (y_lo, y_hi) = (grid.y_m(0) - half, grid.y_m(grid.width.max(1) - 1) + half);
    let (x_lo, x_hi) = (grid.x_m(0) - half, grid.x_m(grid.height.max(1) - 1) + half);
    let gy0 = positions(&z, &labels, &[4, 8]);
    for k in 0..lo {
        let x = g.azimuth_m(w.centre(k));
        for m in 0..co {
            let i = k * co + m;
            if !(x_lo..=x_hi).contains(&x) || !(y_lo..=y_hi).contains(&gy0[i]) {
                labels[i] = label::OUTSIDE;
            }
        }
    }
    // 5b. Speckle moves the point whose phase a window measures by 1–2 samples from its centre
    //     (the |A1·A2|-weighted centroid); on a slope that is a height error of slope × offset,
    //     the largest error of the noise-free chain. Move each height back to its window centre
    //     with the local gradient.
    if cfg.recentre_passes > 0 {
        let valid: Vec<bool> = labels.iter().map(|&l| l == label::VALID).collect();
        z = recentre_heights(
            &z,
            &valid,
            co,
            w.step as f64,
            &looks.centroid,
            cfg.recentre_passes,
        );
    }

    // 6. True ground positions from R1 and the height. The position uses the 3×3 mean height of
    //    valid neighbours: the parallax is Δz·cot θ ≈ 2Δz, so per-pixel height noise would
    //    otherwise jitter positions by twice its size and fold neighbours over each other.
    //    Masked pixels (whose own height is unreliable) take the mean of the nearest valid
    //    ones, searching up to 8 pixels away, else the datum.
    let mut gy = positions(&z, &labels, &[1, 2, 4, 8]);
    // Folds (a pixel nearer on the ground than one before it by more than a quarter of the
    // nominal ground spacing) are layover; smaller reversals are noise and are clamped so that
    // each line's positions never decrease.
    let theta_c = g.flat_look_angle_rad(centre_r);
    let fold_tol = 0.25 * g.range_spacing_m * w.step as f64 / theta_c.sin();
    // A fold reaches no further than a wall as high as the scene's height span can throw its
    // echo: span / tan θ on the ground. Comparing only within that reach keeps one pixel with a
    // wrong height (an unwrapping error) from marking the rest of its line.
    let reach_m = fold_reach_m(&z, &labels, theta_c);
    let ml_ground_m = g.range_spacing_m * w.step as f64 / theta_c.sin();
    let reach_px = (reach_m / ml_ground_m).ceil().max(1.0) as usize;
    for k in 0..lo {
        let row = k * co;
        for m in 0..co {
            let i = row + m;
            if labels[i] != label::VALID {
                continue;
            }
            let run_max = (m.saturating_sub(reach_px)..m)
                .map(|mm| row + mm)
                .filter(|&j| labels[j] == label::VALID)
                .map(|j| gy[j])
                .fold(f64::NEG_INFINITY, f64::max);
            if gy[i] < run_max - fold_tol {
                labels[i] = label::LAYOVER;
                for mm in (m.saturating_sub(reach_px)..m).rev() {
                    let j = row + mm;
                    if gy[j] > gy[i] {
                        labels[j] = label::LAYOVER;
                    } else if labels[j] == label::VALID {
                        break;
                    }
                }
            } else {
                gy[i] = gy[i].max(run_max);
            }
        }
    }

    // 6b. The parallax of a height error (session 39). The position above took the 3×3 mean
    //     height, so its error δh̄ moves the point by δh̄·cot θ across the slope; on ground that
    //     rises by s per metre away from the radar the cell then reads δh − s·cot θ·δh̄. With the
    //     windows' noise correlation that scales the bound by √(1 + 2kρ + k²a²), k = −s·cot θ
    //     (`looks::parallax_bound_factor`): 1.7× on a 33° slope facing away. Facing the radar
    //     the formula falls below 1, but foreshortening's interpolation error there (not
    //     modelled) is larger still, so no reduction is credited (docs/insar.md).
    let (rho, a2) = parallax_correlations(w, cfg);
    // Slant range the slope's span covers, metres.
    let span_slant_m = 2.0 * PARALLAX_SLOPE_RADIUS as f64 * g.range_spacing_m * w.step as f64;
    let zm = valid_mean(&z, &labels, lo, co, PARALLAX_SLOPE_RADIUS);
    for k in 0..lo {
        for m in PARALLAX_SLOPE_RADIUS..co.saturating_sub(PARALLAX_SLOPE_RADIUS) {
            let i = k * co + m;
            let (a, b) = (i - PARALLAX_SLOPE_RADIUS, i + PARALLAX_SLOPE_RADIUS);
            if labels[i] != label::VALID || !(zm[a] - zm[b]).is_finite() {
                continue;
            }
            let dz = g.a1_yz_m[1] - zm[i].clamp(zm[a].min(zm[b]), zm[a].max(zm[b]));
            let r1 = g.range_m(w.centre(m));
            let across = (r1 * r1 - dz * dz).max(0.0).sqrt();
            let dy = gy[b] - gy[a];
            // Ground facing away spreads over more samples: a slant span δr covers
            // δr·cos s / sin(θ + s) of ground, at least δr·sin θ (at the shadow limit). A span
            // shorter than a share of that is a clamped fold or noise, not a slope.
            let sin_theta = across / r1.max(f64::MIN_POSITIVE);
            if !(across > 0.0 && dy > PARALLAX_MIN_SPAN * span_slant_m * sin_theta) {
                continue;
            }
            let s = (zm[b] - zm[a]) / dy;
            // No ground seen faces away more steeply than the grazing ray (s = −cot θ).
            let cot = dz / across;
            sig[i] *= parallax_bound_factor((-s * cot).min(cot * cot), rho, a2);
        }
    }

    // 7. Geometric correction onto the grid, then eq 20 on the generated DEM.
    let coh64: Vec<f64> = coh.iter().map(|&c| f64::from(c)).collect();
    let radar = RadarPixels {
        lines: lo,
        cols: co,
        x0_m: g.azimuth_m(w.centre(0)),
        dx_m: g.azimuth_spacing_m * w.step as f64,
        ground_y_m: &gy,
        labels: &labels,
    };
    let geo = geocode(&radar, &[&z, &coh64, &sig], grid, &cfg.geocode);
    let mut out_labels = geo.labels;
    let mut heights = geo.channels[0].clone();
    // Shadow and layover ray-traced on the generated DEM smoothed by one output pixel
    // (NaN-aware), tolerating the cells' own height bound so that pixel-scale height noise
    // neither blocks rays nor folds ranges; then eq 20 on the DEM itself, as the paper.
    let smooth = gaussian_filter(&heights, grid.width, grid.height, 1.0);
    let tol: Vec<f64> = geo.channels[2]
        .iter()
        .map(|&s| {
            if s.is_finite() {
                s * cfg.geometry_tolerance_sigmas
            } else {
                0.0
            }
        })
        .collect();
    let traced = ray_trace_mask(&smooth, &tol, grid, g.a1_yz_m, reach_m);
    let mut geometry_removed = 0;
    for (l, &t) in out_labels.iter_mut().zip(&traced) {
        if t != label::VALID {
            if *l == label::VALID {
                geometry_removed += 1;
            }
            *l = label::worst(*l, t);
        }
    }
    let eq20_removed = eq20_mask(&heights, &mut out_labels, grid, g.a1_yz_m);
    for (h, &l) in heights.iter_mut().zip(&out_labels) {
        if l != label::VALID {
            *h = f64::NAN;
        }
    }
    let masked = |ch: &[f64]| -> Vec<f32> {
        ch.iter()
            .zip(&out_labels)
            .map(|(&v, &l)| {
                if l == label::VALID {
                    v as f32
                } else {
                    f32::NAN
                }
            })
            .collect()
    };
    heights = filter_dem(&heights, grid.width, grid.height, cfg.filter());
    let dem = grid.raster(masked(&heights))?;
    let coherence = grid.raster(masked(&geo.channels[1]))?;
    // The bound follows the heights through the DEM filter: it averages noise that is
    // correlated over the multilook windows' overlap, not white (`dem_filter_noise_factor`).
    let lags = [
        grid.pixel_m / (g.azimuth_spacing_m * w.step as f64),
        grid.pixel_m / ml_ground_m,
    ];
    // Per cell: a kernel cut by a hole or the edge averages differently. The filter keeps
    // NaN as NaN, so the filtered heights tell which cells it averaged.
    let valid: Vec<bool> = heights.iter().map(|v| v.is_finite()).collect();
    let noise = LookNoise {
        size: w.size,
        step: w.step,
        lag_per_px: lags,
        oversampling: [cfg.azimuth_oversampling, cfg.range_oversampling],
        alpha: cfg.hamming_alpha,
    };
    let (crlb_filter_factor, factors) =
        dem_filter_noise_factors(&valid, grid.width, grid.height, cfg.filter(), noise);
    let error_blur_m = error_blur_m(cfg.filter(), noise, grid.pixel_m);
    let sig_filtered: Vec<f64> = geo.channels[2]
        .iter()
        .zip(&factors)
        .map(|(&v, &f)| v * f)
        .collect();
    let crlb_m = grid.raster(masked(&sig_filtered))?;
    let mask = MaskFractions::of(&out_labels);
    let coherence_mean_radar = coh64.iter().sum::<f64>() / coh64.len().max(1) as f64;

    let radar_layers = RadarLayers {
        lines: lo,
        cols: co,
        line_spacing_m: radar.dx_m,
        phase_with_flat_rad: looks.cross_raw.iter().map(|c| c.arg() as f32).collect(),
        phase_rad: wrapped.iter().map(|&p| wrap_rad(p) as f32).collect(),
        phase_unwrapped_rad: unw.iter().map(|&p| p as f32).collect(),
        coherence: coh,
        height_m: z.iter().map(|&v| v as f32).collect(),
        ground_y_m: gy,
        labels,
    };
    Ok(InsarProduct {
        geometry: g,
        config: *cfg,
        grid: grid.clone(),
        dem,
        coherence,
        crlb_m,
        labels: out_labels,
        radar: radar_layers,
        effective_looks: looks_eff,
        crlb_filter_factor,
        error_blur_m,
        coreg: CoregReport {
            offset_near_gates: offset.first().copied().unwrap_or(0.0),
            offset_far_gates: offset.last().copied().unwrap_or(0.0),
            check,
        },
        unwrap,
        mask,
        eq20_removed,
        geometry_removed,
        coherence_mean_radar,
        seconds: t0.elapsed().as_secs_f64(),
        look_fusion: None,
        baseline_fusion: Vec::new(),
    })
}

/// Ground distance, m, over which layover or shadow can act in a scene whose valid heights
/// (`labels` = [`label::VALID`]) span `p98 − p2` (percentiles, so a few wrong heights do not
/// count): a wall that high, seen at look angle `theta_rad`, folds its echo over at most
/// `span·cot θ` of ground and casts a shadow at most `span·tan θ` long. At least 100 m.
pub fn fold_reach_m(z: &[f64], labels: &[u8], theta_rad: f64) -> f64 {
    let mut v: Vec<f64> = z
        .iter()
        .zip(labels)
        .filter(|(h, l)| **l == label::VALID && h.is_finite())
        .map(|(h, _)| *h)
        .collect();
    if v.is_empty() {
        return 100.0;
    }
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    let span = q(0.98) - q(0.02);
    let t = theta_rad.tan();
    (span * t.max(1.0 / t)).max(100.0)
}

/// Heights `z` (row-major, `cols` per line) measured at the window centroids `centroid`
/// (`(Δline, Δgate)`, SLC samples) moved to the window centres: `z − ∇z·Δ`, with `∇z` by central
/// differences of valid neighbours `step` samples apart, re-estimated from the corrected heights
/// on each of `passes` passes. Invalid pixels are returned unchanged.
pub fn recentre_heights(
    z: &[f64],
    valid: &[bool],
    cols: usize,
    step: f64,
    centroid: &[(f64, f64)],
    passes: usize,
) -> Vec<f64> {
    let lines = z.len() / cols.max(1);
    let mut cur = z.to_vec();
    for _ in 0..passes {
        let next: Vec<f64> = (0..z.len())
            .into_par_iter()
            .map(|i| {
                if !valid[i] {
                    return z[i];
                }
                let (k, m) = (i / cols, i % cols);
                // Derivative along one axis from the valid neighbours at −1 and +1.
                let deriv = |lo: Option<usize>, hi: Option<usize>| -> f64 {
                    let lo = lo.filter(|&j| valid[j]);
                    let hi = hi.filter(|&j| valid[j]);
                    match (lo, hi) {
                        (Some(a), Some(b)) => (cur[b] - cur[a]) / (2.0 * step),
                        (Some(a), None) => (cur[i] - cur[a]) / step,
                        (None, Some(b)) => (cur[b] - cur[i]) / step,
                        (None, None) => 0.0,
                    }
                };
                let along_line = deriv(
                    k.checked_sub(1).map(|kk| kk * cols + m),
                    (k + 1 < lines).then(|| (k + 1) * cols + m),
                );
                let along_gate = deriv(
                    m.checked_sub(1).map(|mm| k * cols + mm),
                    (m + 1 < cols).then(|| k * cols + m + 1),
                );
                let (dl, dg) = centroid[i];
                z[i] - along_line * dl - along_gate * dg
            })
            .collect();
        cur = next;
    }
    cur
}

fn span(v: &[f64]) -> f64 {
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if hi >= lo { hi - lo } else { 0.0 }
}

/// The truth on the product's grid, two ways.
#[derive(Debug, Clone)]
pub struct TruthOnGrid {
    /// The truth resampled to the output grid (block mean for integer ratios): the reference
    /// the accuracy requirements are stated against.
    pub grid: Dem,
    /// The truth averaged over the multilook window's ground footprint centred on each pixel
    /// (a diagnostic separating noise from the product's coarser resolution).
    pub window: Dem,
    /// Side of that footprint, m.
    pub window_side_m: f64,
}

/// One run of the whole chain from a DEM: SAR simulation, InSAR, grid aligned with the truth.
#[derive(Debug, Clone)]
pub struct ChainRun {
    /// The SAR simulation (SLCs and geometry of the first pass; timings of every stacked pass).
    pub pair: InsarPair,
    /// Heights filled before the SAR simulation (nodata in the input DEM).
    pub filled_nodata: usize,
    /// The truth on the output grid.
    pub truth: TruthOnGrid,
    /// The InSAR product.
    pub product: InsarProduct,
}

/// Simulate the radar over `truth` with `sar` (only the channel `pol`), then run the InSAR
/// chain onto the truth's grid at `cfg.pixel_m`.
pub fn run_from_dem(
    truth: &Dem,
    sar: &SarConfig,
    pol: Polarisation,
    cfg: &InsarConfig,
    progress: bool,
) -> anyhow::Result<ChainRun> {
    cfg.validate()?;
    check_long_baseline(sar, cfg)?;
    let (sdem, filled) = SarDem::from_dem(truth)?;
    let mut sar = sar.clone();
    sar.polarisations = vec![pol];
    // Pass 0 is the configuration's own; further passes of the same track see the same ground
    // (speckle) through their own receiver noise.
    let passes = fly_passes(&sdem, &sar, cfg.passes, progress, &|k| {
        (k > 0).then(|| pass_noise_seed(sar.seed, k))
    })?;
    let cfg = cfg.with_radar(&sar);
    let (truth_on_grid, mut product) = process_simulated_stack(truth, &passes, pol, &cfg)?;
    // The run's SAR time is every pass's.
    let mut timings = stack_timings(&passes);
    if let Some(long) = fly_long_pair(
        &sdem,
        &sar,
        pol,
        &cfg,
        progress,
        &truth_on_grid.grid,
        &mut product,
    )? {
        timings += &long;
    }
    let mut pair = passes
        .into_iter()
        .next()
        .ok_or_else(|| anyhow::anyhow!("no pass simulated"))?;
    pair.timings = timings;
    Ok(ChainRun {
        pair,
        filled_nodata: filled,
        truth: truth_on_grid,
        product,
    })
}

/// `passes` (at least one) passes of `radar` over `sdem`, pass `k` with the receiver noise
/// seed `noise(k)` (`None`: the radar's own).
fn fly_passes(
    sdem: &SarDem,
    radar: &SarConfig,
    passes: usize,
    progress: bool,
    noise: &dyn Fn(usize) -> Option<u64>,
) -> Result<Vec<InsarPair>, crate::sar::SarError> {
    (0..passes.max(1))
        .map(|k| {
            let opts = SimOptions {
                progress,
                noise_seed: noise(k),
                ..SimOptions::default()
            };
            simulate_with(sdem, radar, &opts)
        })
        .collect()
}

/// The second pair of a run whose `cfg` asks for one ([`InsarConfig::long_baseline_m`] > 0):
/// fly it over `sdem` (`cfg.passes` passes, each with its own receiver noise) and fuse its
/// heights into `product`, whose own pair was flown with `sar` (only the channel `pol`) and
/// whose truth on the grid is `truth_grid` (for the coarse cycle prior). Returns the long
/// passes' SAR time, or `None` (nothing flown) without a second baseline.
pub fn fly_long_pair(
    sdem: &SarDem,
    sar: &SarConfig,
    pol: Polarisation,
    cfg: &InsarConfig,
    progress: bool,
    truth_grid: &Dem,
    product: &mut InsarProduct,
) -> anyhow::Result<Option<Timings>> {
    if cfg.long_baseline_m <= 0.0 {
        return Ok(None);
    }
    check_long_baseline(sar, cfg)?;
    let long_sar = super::baselines::long_radar(sar, cfg.long_baseline_m);
    let long_passes = fly_passes(sdem, &long_sar, cfg.passes, progress, &|k| {
        Some(super::baselines::long_noise_seed(sar.seed, k))
    })?;
    let coarse =
        (cfg.prior_dem_cell_m > 0.0).then(|| coarse_prior(truth_grid, cfg.prior_dem_cell_m));
    super::baselines::add_long_baseline(
        product,
        &slc_pairs(&long_passes, pol)?,
        coarse.as_deref(),
        cfg,
    )?;
    Ok(Some(stack_timings(&long_passes)))
}

/// [`run_from_dem`] with a choice of look directions. `Both` flies a second pass over the
/// mirrored scene (columns reversed, the same georeference): the same radar, looking west
/// instead of east, so that slopes in layover or shadow for one look face the other look at a
/// gentle angle, and any range-direction shift of one pass is mirrored in the other. Its grid
/// layers are mirrored back and fused with the first pass by [`fuse_looks`]; the rest of the
/// run (SLCs, radar layers, report geometry) is the east pass's.
pub fn run_from_dem_looks(
    truth: &Dem,
    sar: &SarConfig,
    pol: Polarisation,
    cfg: &InsarConfig,
    progress: bool,
    looks: LookDirections,
) -> anyhow::Result<ChainRun> {
    let mut east = run_from_dem(truth, sar, pol, cfg, progress)?;
    if looks == LookDirections::One {
        return Ok(east);
    }
    // The second pass draws its own seed (its speckle and its noise, as a pass from the other
    // side would): the mirrored scene's cells near the centre column are the same cells, and one
    // seed would give them the same noise in both looks.
    let west_sar = SarConfig {
        seed: west_pass_seed(sar.seed),
        ..sar.clone()
    };
    let west = run_from_dem(&mirrored_dem(truth)?, &west_sar, pol, cfg, progress)?;
    fuse_looks(&mut east.product, &west.product)?;
    // The run's SAR time is both passes' (as a map in blocks reports it).
    east.pair.timings += &west.pair.timings;
    Ok(east)
}

/// Refuse a long baseline no longer than the radar's own (it would add noise, not remove it).
pub fn check_long_baseline(sar: &SarConfig, cfg: &InsarConfig) -> InsarResult<()> {
    if cfg.long_baseline_m > 0.0 && cfg.long_baseline_m <= sar.baseline_m {
        return Err(InsarError::Input(format!(
            "the long baseline ({} m) must be longer than the radar's baseline ({} m)",
            cfg.long_baseline_m, sar.baseline_m
        )));
    }
    Ok(())
}

/// Radar seed of the west-looking pass of a one-piece two-look run whose east-looking pass
/// uses `seed`: it draws that pass's speckle and noise. (A map in blocks salts only the west
/// pass's noise, `blocks::run_block`: its speckle is the scene mesh's, the same for every
/// block that sees a facet.)
pub fn west_pass_seed(seed: u64) -> u64 {
    crate::sar::scattering::splitmix64(seed ^ WEST_PASS_SALT)
}

/// Fixed salt of [`west_pass_seed`] ("west" in ASCII).
const WEST_PASS_SALT: u64 = 0x7765_7374;

/// Thermal-noise seed of pass `k` ≥ 1 of a stack whose first pass uses `seed`
/// ([`InsarConfig::passes`]).
pub fn pass_noise_seed(seed: u64, k: usize) -> u64 {
    crate::sar::scattering::splitmix64(seed ^ crate::sar::scattering::splitmix64(k as u64))
}

/// Most passes one stack may hold ([`InsarConfig::passes`]).
pub const MAX_PASSES: usize = 16;

/// The scene mirrored left to right under the same georeference: what a west-looking pass of
/// the east-looking radar sees ([`run_from_dem_looks`]).
pub fn mirrored_dem(truth: &Dem) -> anyhow::Result<Dem> {
    let (w, h) = (truth.width(), truth.height());
    let mut mirrored = Dem::new(
        w,
        h,
        mirror_columns(truth.heights_m(), w),
        truth.geo.clone(),
    )?;
    mirrored.nodata = truth.nodata;
    mirrored.sample = truth.sample;
    Ok(mirrored)
}

/// Half-width, radar pixels, of the slope the parallax term reads (a 5-pixel span of 5×5 mean
/// heights: its own noise stays a few hundredths on the floors).
const PARALLAX_SLOPE_RADIUS: usize = 2;
/// Shortest ground span of that slope, as a share of the span of ground facing away at the
/// shadow limit (slant span × sin θ, the least any ground the radar sees can have): shorter
/// spans are clamped folds, which get no parallax factor.
const PARALLAX_MIN_SPAN: f64 = 0.75;

/// Noise correlations of a pixel's height with the 3×3 mean that places it
/// (`ρ = cov(δh, δh̄)/σ²`) and of that mean with itself (`a² = var(δh̄)/σ²`), from the multilook
/// windows' overlap (`looks::multilook_noise_correlation`) along both axes.
fn parallax_correlations(w: LookWindow, cfg: &InsarConfig) -> (f64, f64) {
    let axis = |os: f64| {
        let c = |lag: f64| multilook_noise_correlation(w.size, w.step, lag, os, cfg.hamming_alpha);
        let (r1, r2) = (c(1.0), c(2.0));
        ((1.0 + 2.0 * r1) / 3.0, (3.0 + 4.0 * r1 + 2.0 * r2) / 9.0)
    };
    let (ra, aa) = axis(cfg.azimuth_oversampling);
    let (rr, ar) = axis(cfg.range_oversampling);
    (ra * rr, aa * ar)
}

/// Mean of the valid values within `radius` pixels (a square), NaN where none.
fn valid_mean(z: &[f64], labels: &[u8], lines: usize, cols: usize, radius: usize) -> Vec<f64> {
    let mut out = vec![f64::NAN; lines * cols];
    for k in 0..lines {
        for m in 0..cols {
            let (mut acc, mut n) = (0.0, 0usize);
            for kk in k.saturating_sub(radius)..(k + radius + 1).min(lines) {
                for mm in m.saturating_sub(radius)..(m + radius + 1).min(cols) {
                    let j = kk * cols + mm;
                    if labels[j] == label::VALID && z[j].is_finite() {
                        acc += z[j];
                        n += 1;
                    }
                }
            }
            if n > 0 {
                out[k * cols + m] = acc / n as f64;
            }
        }
    }
    out
}

/// Each row of a row-major `w`-wide raster reversed.
pub fn mirror_columns<T: Copy>(v: &[T], w: usize) -> Vec<T> {
    v.chunks(w.max(1))
        .flat_map(|row| row.iter().rev().copied())
        .collect()
}

/// Fuse the west-looking pass `west` (computed on the mirrored scene, so its grid layers are
/// mirrored here) into the east-looking `east`, cell by cell: a cell valid in both takes the
/// inverse-variance mean of the two heights by their CRLB (and that variance's fused bound),
/// unless they disagree beyond [`FUSE_CONSISTENCY_SIGMAS`], when it is dropped; a cell valid in
/// one takes that one; a cell valid in neither keeps the worse label.
pub fn fuse_looks(east: &mut InsarProduct, west: &InsarProduct) -> anyhow::Result<LookFusion> {
    let w = east.grid.width;
    let n = east.labels.len();
    anyhow::ensure!(
        west.labels.len() == n && west.grid.width == w && west.grid.height == east.grid.height,
        "the two looks' grids differ"
    );
    let mut wd = mirror_columns(west.dem.heights_m(), w);
    let wc = mirror_columns(west.coherence.heights_m(), w);
    let ws = mirror_columns(west.crlb_m.heights_m(), w);
    let wl = mirror_columns(&west.labels, w);
    // Each pass's cycles come from the coarse prior DEM (`cycles`), or without one from the
    // unwrapper's datum rule; with the datum rule, where the relief spans a cycle and the two
    // passes see different ground (layover), they can sit whole cycles apart. Align the west
    // pass on the east by the median whole-cycle difference of the cells both see (each cell's
    // cycle at the west pass's own range); when the prior chose both, the median is 0.
    let cycle: Vec<f64> = (0..n)
        .map(|i| cycle_height_m(west, w - 1 - i % w.max(1)))
        .collect();
    let mut apart: Vec<f64> = (0..n)
        .filter(|&i| {
            east.labels[i] == label::VALID
                && wl[i] == label::VALID
                && east.dem.heights_m()[i].is_finite()
                && wd[i].is_finite()
        })
        .map(|i| (f64::from(wd[i]) - f64::from(east.dem.heights_m()[i])) / cycle[i])
        .collect();
    let mut west_cycles_shifted = 0i64;
    if apart.len() >= CYCLE_ALIGN_MIN_CELLS {
        apart.sort_by(f64::total_cmp);
        west_cycles_shifted = apart[apart.len() / 2].round() as i64;
        if west_cycles_shifted != 0 {
            for (v, c) in wd.iter_mut().zip(&cycle) {
                *v = (f64::from(*v) - west_cycles_shifted as f64 * c) as f32;
            }
        }
    }
    let east_mask = east.mask;
    let (mut both, mut e_only, mut w_only, mut inconsistent) = (0usize, 0usize, 0usize, 0usize);
    let mut dem = east.dem.heights_m().to_vec();
    let mut coh = east.coherence.heights_m().to_vec();
    let mut sig = east.crlb_m.heights_m().to_vec();
    // Per cell: valid after fusion, made by one look alone, and valid and consistent in both.
    let (mut valid_fused, mut one_look) = (vec![false; n], vec![false; n]);
    let mut both_ok = vec![false; n];
    for i in 0..n {
        let ev = east.labels[i] == label::VALID && dem[i].is_finite();
        let wv = wl[i] == label::VALID && wd[i].is_finite();
        valid_fused[i] = ev || wv;
        one_look[i] = ev != wv;
        match (ev, wv) {
            (true, true) if looks_disagree(dem[i], wd[i], sig[i], ws[i]) => {
                // Two measurements of one height that differ by more than their errors allow:
                // one of them took a wrong 2π cycle (or a sidelobe's phase); a mean of the two
                // would be wrong by a fraction of a cycle that no mask shows, so neither is
                // kept.
                inconsistent += 1;
                valid_fused[i] = false;
                east.labels[i] = label::LOW_COHERENCE;
                dem[i] = f32::NAN;
                coh[i] = f32::NAN;
                sig[i] = f32::NAN;
            }
            (true, true) => {
                both += 1;
                both_ok[i] = true;
                // Inverse-variance weights; equal weights where a bound is missing.
                let (se, sw) = (f64::from(sig[i]), f64::from(ws[i]));
                let (ie, iw) = if se > 0.0 && sw > 0.0 && se.is_finite() && sw.is_finite() {
                    (1.0 / (se * se), 1.0 / (sw * sw))
                } else {
                    (1.0, 1.0)
                };
                let t = ie + iw;
                dem[i] = ((f64::from(dem[i]) * ie + f64::from(wd[i]) * iw) / t) as f32;
                coh[i] = ((f64::from(coh[i]) * ie + f64::from(wc[i]) * iw) / t) as f32;
                if se > 0.0 && sw > 0.0 && se.is_finite() && sw.is_finite() {
                    sig[i] = (1.0 / t.sqrt()) as f32;
                }
            }
            (true, false) => e_only += 1,
            (false, true) => {
                w_only += 1;
                dem[i] = wd[i];
                coh[i] = wc[i];
                sig[i] = ws[i];
                east.labels[i] = label::VALID;
            }
            (false, false) => {
                east.labels[i] = label::worst(east.labels[i], wl[i]);
                dem[i] = f32::NAN;
                coh[i] = f32::NAN;
                sig[i] = f32::NAN;
            }
        }
    }
    let worst_window_one_look_share = worst_window_share(
        &one_look,
        &valid_fused,
        w,
        ONE_LOOK_WINDOW_M / east.grid.pixel_m,
    );
    // The error's correlation as the rehearsal models it (`evaluation::rehearsal::ErrorModel`):
    // the quadratic filter's noise blur, else the DEM's own signal blur.
    let blur_m = if east.config.dem_filter == DemFilterKind::Quadratic {
        east.error_blur_m
    } else {
        east.inherent_smoothing_m()
    };
    let error_spectrum_ratio = look_error_spectrum(
        (east.dem.heights_m(), &wd),
        (east.crlb_m.heights_m(), &ws),
        &both_ok,
        w,
        blur_m / east.grid.pixel_m,
    );
    east.dem = east.grid.raster(dem)?;
    east.coherence = east.grid.raster(coh)?;
    east.crlb_m = east.grid.raster(sig)?;
    east.mask = MaskFractions::of(&east.labels);
    let frac = |k: usize| k as f64 / n.max(1) as f64;
    let fusion = LookFusion {
        east_mask,
        west_mask: west.mask,
        both_valid: frac(both),
        east_only: frac(e_only),
        west_only: frac(w_only),
        inconsistent: frac(inconsistent),
        west_cycles_shifted,
        worst_window_one_look_share,
        error_spectrum_ratio,
    };
    east.look_fusion = Some(fusion);
    // With the long pair at its own filter width each look's factor is its own cells' mix
    // (`baselines::fuse_baselines`): the map's is the looks' mean. Under one width the two
    // are the same chain's and the east's stays as it is.
    if east
        .baseline_fusion
        .iter()
        .chain(&west.baseline_fusion)
        .any(|f| {
            f.long_filter_sigma_px
                .is_some_and(|s| s != east.config.dem_filter_sigma_px)
        })
    {
        east.crlb_filter_factor = 0.5 * (east.crlb_filter_factor + west.crlb_filter_factor);
    }
    east.baseline_fusion
        .extend(west.baseline_fusion.iter().copied());
    east.seconds += west.seconds;
    Ok(fusion)
}

/// Largest share of `flag`ged cells among the `valid` cells of any `side_px`-cell square
/// window of a row-major `w`-wide grid (windows less than half valid are skipped; on a grid
/// narrower than the window, windows as wide as the grid); the whole grid's share when no
/// window qualifies; NaN when nothing is valid. Summed-area tables: linear in the grid
/// whatever the window.
pub fn worst_window_share(flag: &[bool], valid: &[bool], w: usize, side_px: f64) -> f64 {
    let n = valid.len().min(flag.len());
    let h = n / w.max(1);
    let whole = {
        let v = valid.iter().filter(|&&v| v).count();
        let f = (0..n).filter(|&i| valid[i] && flag[i]).count();
        if v == 0 {
            f64::NAN
        } else {
            f as f64 / v as f64
        }
    };
    let k = if side_px.is_finite() {
        side_px.round().clamp(1.0, 1e9) as usize
    } else {
        0
    };
    if w == 0 || h == 0 || k == 0 {
        return whole;
    }
    // A map narrower than the window (a corridor strip) scans windows as wide as it is.
    let (kx, ky) = (k.min(w), k.min(h));
    let tv = CellCounts::new(w, h, |i| valid[i]);
    let tf = CellCounts::new(w, h, |i| valid[i] && flag[i]);
    let sum = |t: &CellCounts, r: usize, c: usize| t.count(r, c, r + ky, c + kx) as i64;
    let mut worst = f64::NAN;
    for r in 0..=h - ky {
        for c in 0..=w - kx {
            let v = sum(&tv, r, c);
            if 2 * v < (kx * ky) as i64 {
                continue;
            }
            let share = sum(&tf, r, c) as f64 / v as f64;
            if !(share <= worst) {
                worst = share;
            }
        }
    }
    if worst.is_finite() { worst } else { whole }
}

/// The InSAR chain on an already simulated pair of `truth`; returns the truth on the output
/// grid and the product.
pub fn process_simulated(
    truth: &Dem,
    pair: &InsarPair,
    pol: Polarisation,
    cfg: &InsarConfig,
) -> anyhow::Result<(TruthOnGrid, InsarProduct)> {
    let a1 = pair
        .slc(Antenna::A1, pol)
        .ok_or_else(|| anyhow::anyhow!("no A1 {} SLC", pol.tag()))?;
    let a2 = pair
        .slc(Antenna::A2, pol)
        .ok_or_else(|| anyhow::anyhow!("no A2 {} SLC", pol.tag()))?;
    process_slcs(truth, a1, a2, cfg)
}

/// [`process_simulated`] on several passes of one track, stacked ([`process_stack`]).
pub fn process_simulated_stack(
    truth: &Dem,
    passes: &[InsarPair],
    pol: Polarisation,
    cfg: &InsarConfig,
) -> anyhow::Result<(TruthOnGrid, InsarProduct)> {
    process_slc_stack(truth, &slc_pairs(passes, pol)?, cfg)
}

/// The `(A1, A2)` SLCs of channel `pol` of every simulated pass, for [`process_stack`].
pub fn slc_pairs(passes: &[InsarPair], pol: Polarisation) -> anyhow::Result<Vec<(&Slc, &Slc)>> {
    passes
        .iter()
        .map(|p| {
            p.slc(Antenna::A1, pol)
                .zip(p.slc(Antenna::A2, pol))
                .ok_or_else(|| anyhow::anyhow!("no {} SLC pair in a pass", pol.tag()))
        })
        .collect()
}

/// The SAR time of every pass of a stack, summed (what the run reports as its SAR time).
pub fn stack_timings(passes: &[InsarPair]) -> Timings {
    let mut t = Timings::default();
    for p in passes {
        t += &p.timings;
    }
    t
}

/// The InSAR chain on two SLCs simulated from `truth` (the grid and the truth comparison come
/// from it); returns the truth on the output grid and the product.
pub fn process_slcs(
    truth: &Dem,
    a1: &Slc,
    a2: &Slc,
    cfg: &InsarConfig,
) -> anyhow::Result<(TruthOnGrid, InsarProduct)> {
    process_slc_stack(truth, &[(a1, a2)], cfg)
}

/// [`process_slcs`] on several passes of one track (`(A1, A2)` per pass), stacked.
pub fn process_slc_stack(
    truth: &Dem,
    pairs: &[(&Slc, &Slc)],
    cfg: &InsarConfig,
) -> anyhow::Result<(TruthOnGrid, InsarProduct)> {
    let &(a1, _) = pairs
        .first()
        .ok_or_else(|| anyhow::anyhow!("no pass to process"))?;
    let truth_grid = crate::reference::reference_dem(truth, cfg.pixel_m)?;
    let grid = OutputGrid::aligned(truth, &truth_grid)?;
    let prior =
        (cfg.prior_dem_cell_m > 0.0).then(|| coarse_prior(&truth_grid, cfg.prior_dem_cell_m));
    let product = process_stack(pairs, &grid, cfg, prior.as_deref())?;
    let g = &product.geometry;
    let centre_r = g.range_m(0.5 * (a1.gates as f64 - 1.0));
    let n = cfg.window.size as f64;
    let side = 0.5
        * (n * g.azimuth_spacing_m + n * g.range_spacing_m / g.flat_look_angle_rad(centre_r).sin());
    let window = super::accuracy::window_truth(truth, &truth_grid, side)?;
    Ok((
        TruthOnGrid {
            grid: truth_grid,
            window,
            window_side_m: side,
        },
        product,
    ))
}

#[cfg(test)]
mod spectrum_tests {
    use super::*;
    use crate::dem::spectrum::correlated_noise;

    /// Two looks whose errors are `k` times their bounds in every octave: the ratio reads k²
    /// there; terrain both looks share cancels; too few cells give none.
    #[test]
    fn the_looks_disagreement_measures_the_error_against_its_bound() {
        let (w, h) = (200, 160);
        let n = w * h;
        let blur = 22.4 / 20.0;
        // Bounds that vary over the map (a steep east half), as on a crater's map.
        let se: Vec<f32> = (0..n)
            .map(|i| if i % w < w / 2 { 1.0 } else { 3.0 })
            .collect();
        let sw = vec![1.5f32; n];
        // A tenth of the cells seen by one look only.
        let both: Vec<bool> = (0..n).map(|i| (i / w) % 10 != 3).collect();
        let (u1, u2) = (
            correlated_noise(w, h, blur, 1),
            correlated_noise(w, h, blur, 2),
        );
        // Terrain both looks see (a bowl and a ridge), hundreds of metres of relief.
        let terrain = |i: usize| {
            let (x, y) = ((i % w) as f64 - 100.0, (i / w) as f64 - 80.0);
            0.01 * (x * x + y * y) + 40.0 * (x / 7.0).sin()
        };
        for k in [1.0f64, 1.5] {
            let ze: Vec<f32> = (0..n)
                .map(|i| (terrain(i) + k * f64::from(se[i]) * u1[i]) as f32)
                .collect();
            let zw: Vec<f32> = (0..n)
                .map(|i| (terrain(i) + k * f64::from(sw[i]) * u2[i]) as f32)
                .collect();
            let r = look_error_spectrum((&ze, &zw), (&se, &sw), &both, w, blur).unwrap();
            // The octaves up to 1/2 cycle per pixel hold the blurred noise's power; the
            // corners beyond hold 0.03 % of it and are not judged.
            for (b, &v) in r.iter().enumerate().take(5) {
                assert!(
                    (v / (k * k) - 1.0).abs() < 0.25,
                    "k {k}: octave {b} reads {v} ({r:?})"
                );
            }
        }
        let few: Vec<bool> = (0..n).map(|i| i < ERROR_SPECTRUM_MIN_CELLS - 1).collect();
        let z = vec![0.0f32; n];
        assert!(look_error_spectrum((&z, &z), (&se, &sw), &few, w, blur).is_none());
    }
}
