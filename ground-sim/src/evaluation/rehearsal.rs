//! The navigability map by rehearsal: fly the flight code against the reference over the map
//! before the flyer does, with frames synthesised from the reference DEM itself.
//!
//! What the ground has before flight is the reference folder: the tile, the DEM it was built
//! from and, for an InSAR map, the per-cell height σ the processing reported (its Cramér–Rao
//! bound). The flyer's frames will come from the true terrain, which differs from the map by the
//! map's error. A rehearsal therefore flies frames from one plausible truth: a draw of the
//! terrain given the reference DEM and that error (Gaussian, at the reported σ, correlated by
//! the DEM's blur, scaled per octave by what a two-look map measured of its own error;
//! [`plausible_truth`]; a truth-built map claims none, and its DEM is the truth), its holes
//! (the InSAR mask) filled smoothly, so frames there carry nothing the tile could match. Sites
//! lie on a regular grid over the box where a frame fits the map; each flies a few frames at
//! stratified headings, random pixel sizes in the campaign's range, the sensor's noise and, if
//! asked, a prior drawn like a campaign's. A site's success fraction is the prediction;
//! between sites it is interpolated bilinearly.
//!
//! Unlike the footprint rule ([`super::navmap`]), nothing here is a threshold on a proxy
//! (feature counts, slope texture): whatever makes the flight code fail (too few features,
//! repeated texture, a search with two peaks alike) fails in the rehearsal too, in whichever
//! prior mode is asked. What it cannot see is error the map does not report (e.g. a whole-map
//! offset), which `ground-sim suite` measures by scoring it against every campaign.

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, anyhow, bail};
use indicatif::ProgressBar;
use nav_core::{NavConfig, Navigator, Tile};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

use std::path::Path;

use crate::dem::spectrum::{BAND_EDGES, band_of, fft2};
use crate::dem::{Dem, read_geotiff};
use crate::evaluation::campaign::{CampaignSpec, centre_box, fly_posed, normal};
use crate::flyer::frames::FramePose;
use crate::flyer::onboard::{WORKSPACE_STACK, new_workspace};

/// Default spacing of rehearsal sites, metres (a tenth of a 200-px frame at 10 m: the outcome
/// changes over a few hundred metres, the frame's overlap with a feature cluster).
pub const REHEARSAL_STEP_M: f64 = 100.0;
/// Default frames flown per site.
pub const REHEARSAL_FRAMES: usize = 8;
/// Default smallest interpolated success fraction for "go".
pub const REHEARSAL_MIN_SUCCESS: f64 = 0.9;
/// Salt of the rehearsal's random streams (a campaign's trial streams use the bare seed).
const REHEARSAL_SALT: u64 = 0x7265_6865_6172_7365;
/// Most sites per axis (bounds the work: 64² sites × frames).
pub const REHEARSAL_MAX_SITES_PER_AXIS: usize = 64;

/// How a rehearsal flies.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RehearsalSpec {
    /// Spacing of the sites, metres.
    pub step_m: f64,
    /// Frames per site (headings stratified over 360°).
    pub frames_per_site: usize,
    /// Smallest interpolated success fraction for "go".
    pub min_success: f64,
    /// Seed of the error draw and of every frame.
    pub seed: u64,
}

/// Slack of the "go" comparison: success fractions are k/n stored as f32 (9/10 is 0.89999998),
/// so a site exactly at the threshold is "go".
const GO_SLACK: f64 = 1e-6;

impl RehearsalSpec {
    /// Refuse settings a rehearsal cannot fly: spacing not a positive finite number of metres,
    /// no frame per site, a threshold outside 0–1.
    pub fn validate(&self) -> anyhow::Result<()> {
        if !(self.step_m.is_finite() && self.step_m > 0.0) {
            bail!("rehearsal site spacing must be > 0 m, got {}", self.step_m);
        }
        if self.frames_per_site == 0 {
            bail!("a rehearsal needs at least one frame per site");
        }
        if !(0.0..=1.0).contains(&self.min_success) {
            bail!(
                "the go threshold is a fraction in 0..1, got {}",
                self.min_success
            );
        }
        Ok(())
    }

    /// Whether a predicted success fraction `p` is "go".
    pub fn is_go(&self, p: f64) -> bool {
        p >= self.min_success - GO_SLACK
    }
}

impl Default for RehearsalSpec {
    /// [`REHEARSAL_STEP_M`], [`REHEARSAL_FRAMES`], [`REHEARSAL_MIN_SUCCESS`], seed 1.
    fn default() -> Self {
        Self {
            step_m: REHEARSAL_STEP_M,
            frames_per_site: REHEARSAL_FRAMES,
            min_success: REHEARSAL_MIN_SUCCESS,
            seed: 1,
        }
    }
}

/// A rehearsal's outcome: success fraction per site on a regular geo grid.
#[derive(Debug, Clone, Serialize)]
pub struct Rehearsal {
    /// Geo x of the first site column, metres.
    pub x0_m: f64,
    /// Geo y of the first site row, metres (the southernmost: rows run northwards, the
    /// reverse of a north-up raster's).
    pub y0_m: f64,
    /// Site spacing along x, metres (0 with one column).
    pub step_x_m: f64,
    /// Site spacing along y, metres (0 with one row).
    pub step_y_m: f64,
    /// Site columns.
    pub nx: usize,
    /// Site rows.
    pub ny: usize,
    /// Fraction of each site's frames with a correct fix, row-major from (`x0_m`, `y0_m`):
    /// index `row * nx + col` is the site at (`x0_m + col·step_x_m`, `y0_m + row·step_y_m`).
    pub success: Vec<f32>,
    /// Frames flown in all.
    pub frames: usize,
    /// How it flew.
    pub spec: RehearsalSpec,
}

impl Rehearsal {
    /// Interpolated success fraction for a frame centred at geo `(x, y)` metres; up to half the
    /// nominal site spacing outside the sites' box it takes the edge's value (a campaign's
    /// truth DEM may give its centre box a few metres more than the reference DEM's), further
    /// out NaN (a frame there would leave the map).
    pub fn success_at(&self, x_m: f64, y_m: f64) -> f64 {
        let tol = 0.5 * self.spec.step_m;
        let axis = |v: f64, v0: f64, step: f64, n: usize| -> Option<(usize, f64)> {
            if n == 1 || step == 0.0 {
                return ((v - v0).abs() <= tol).then_some((0, 0.0));
            }
            let t = (v - v0) / step;
            let last = (n - 1) as f64;
            let slack = tol / step.abs();
            if !(t >= -slack && t <= last + slack) {
                return None;
            }
            let t = t.clamp(0.0, last);
            let i = (t.floor() as usize).min(n - 2);
            Some((i, t - i as f64))
        };
        let (Some((i, fx)), Some((j, fy))) = (
            axis(x_m, self.x0_m, self.step_x_m, self.nx),
            axis(y_m, self.y0_m, self.step_y_m, self.ny),
        ) else {
            return f64::NAN;
        };
        let at = |i: usize, j: usize| {
            let (i, j) = (i.min(self.nx - 1), j.min(self.ny - 1));
            f64::from(self.success[j * self.nx + i])
        };
        let top = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
        let bot = at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bot * fy
    }

    /// Whether a frame centred at geo `(x, y)` is predicted to fix.
    pub fn go_at(&self, x_m: f64, y_m: f64) -> bool {
        self.spec.is_go(self.success_at(x_m, y_m))
    }

    /// The interpolated success fraction on the tile's grid (NaN where a frame would leave the
    /// map), row-major.
    pub fn success_layer(&self, tile: &Tile<'_>) -> Vec<f32> {
        let h = tile.header();
        let (w, hh) = (h.width_px as usize, h.height_px as usize);
        (0..w * hh)
            .map(|i| {
                let (x, y) = h.pixel_to_geo((i % w) as f64, (i / w) as f64);
                self.success_at(x, y) as f32
            })
            .collect()
    }

    /// The prediction on the tile's grid: 1 go, 0 no-go, NaN off the map.
    pub fn go_layer(&self, tile: &Tile<'_>) -> Vec<f32> {
        self.success_layer(tile)
            .into_iter()
            .map(|p| {
                if !p.is_finite() {
                    f32::NAN
                } else if self.spec.is_go(f64::from(p)) {
                    1.0
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Fraction of sites whose own success fraction is "go".
    pub fn go_fraction(&self) -> f64 {
        let go = self
            .success
            .iter()
            .filter(|&&p| self.spec.is_go(f64::from(p)))
            .count();
        go as f64 / self.success.len().max(1) as f64
    }
}

/// The map's own height error as the reference folder states it: per-cell 1σ (the InSAR
/// product's Cramér–Rao bound, `height-crlb.tif`; none for a truth-built map) and its
/// correlation, a Gaussian blur of white noise: the DEM's own blur that the tile builder
/// recorded (the default chain's multilook window and 1 px mean, 22.4 m, through which its
/// noise passed like its signal: 0.82 at 20 m, where the suite's InSAR height-error maps
/// of the plains and lola read 0.81–0.83), or, for a DEM made with the quadratic filter, whose
/// signal blur (10 m) is not its noise's, the product's `error_blur_m` (30.4 m at 2 px).
/// A map made from two looks also measured how far its real error departs from that model,
/// per octave of spatial frequency, from the two looks' disagreement
/// (`insar::pipeline::LookFusion::error_spectrum_ratio`); the draw scales the model by it.
#[derive(Debug, Clone)]
pub struct ErrorModel {
    /// Height 1σ per cell, metres, on the reference DEM's grid (`None`: the map claims none).
    pub sigma: Option<Dem>,
    /// Correlation: σ of the Gaussian the error field is smoothed with, metres (0: white).
    pub blur_m: f64,
    /// The error's power over the model's (σ and blur above) in each octave band of
    /// [`BAND_EDGES`] (cycles per map pixel); all 1: the model as it stands.
    pub band_ratio: [f64; BAND_EDGES.len()],
}

impl ErrorModel {
    /// No error: a truth-built map.
    pub fn none() -> Self {
        Self {
            sigma: None,
            blur_m: 0.0,
            band_ratio: [1.0; BAND_EDGES.len()],
        }
    }

    /// A model with per-cell `sigma` and correlation `blur_m`, uncalibrated (band ratios 1).
    pub fn with_sigma(sigma: Dem, blur_m: f64) -> Self {
        Self {
            sigma: Some(sigma),
            blur_m,
            band_ratio: [1.0; BAND_EDGES.len()],
        }
    }

    /// Read it from a reference folder: `height-crlb.tif` when present; the blur from
    /// `report.json`'s `error_blur_m` when it states one (the quadratic DEM filter), else from
    /// `tile.json` (`sqrt(smoothing_m² − smoothing_applied_m²)`, the DEM's signal blur, the
    /// noise's too under the mean; 0 without the file). A DEM blurred more than the tile's
    /// target smoothing had none applied, and its blur reads as the target: an underestimate
    /// (not the case for any map the project's chain makes).
    /// Refuses an InSAR folder whose `report.json` predates the bound through the DEM filter.
    pub fn load(dir: &Path) -> anyhow::Result<Self> {
        let crlb = dir.join(crate::insar::products::CRLB_FILE);
        let sigma = crlb
            .exists()
            .then(|| read_geotiff(&crlb).with_context(|| format!("reading {}", crlb.display())))
            .transpose()?;
        // A product made before the bound followed the DEM filter (session 24) reports 1.81×
        // its noise; its report lacks the filter's factor. Drawing that would be 3.3× the
        // variance, silently.
        let report = dir.join("report.json");
        let mut reported_blur = None;
        let mut band_ratio = [1.0; BAND_EDGES.len()];
        if sigma.is_some() && report.exists() {
            let v = read_json(&report)?;
            reported_blur = v.get("error_blur_m").and_then(|b| b.as_f64());
            // The two looks' measure of the error spectrum, when the map has one.
            if let Some(r) = v
                .pointer("/looks/error_spectrum_ratio")
                .and_then(|r| r.as_array())
            {
                let r: Vec<f64> = r.iter().filter_map(|x| x.as_f64()).collect();
                if r.len() != band_ratio.len() || !r.iter().all(|x| x.is_finite() && *x > 0.0) {
                    bail!(
                        "{}: looks.error_spectrum_ratio must be {} positive numbers",
                        report.display(),
                        band_ratio.len()
                    );
                }
                band_ratio.copy_from_slice(&r);
            }
            if v.get("crlb_filter_factor").is_none() {
                bail!(
                    "{}: this InSAR product predates the height bound that follows the DEM \
                     filter (its {} is about 1.8× its noise); rerun `ground-sim insar` for it",
                    dir.display(),
                    crate::insar::products::CRLB_FILE
                );
            }
        }
        let meta = dir.join(crate::reference::META_FILE);
        let blur_m = if let Some(b) = reported_blur.filter(|b| b.is_finite() && *b >= 0.0) {
            b
        } else if meta.exists() {
            let v = read_json(&meta)?;
            let total = v["smoothing_m"].as_f64().unwrap_or(0.0);
            let applied = v["smoothing_applied_m"].as_f64().unwrap_or(total);
            (total * total - applied * applied).max(0.0).sqrt()
        } else {
            0.0
        };
        Ok(Self {
            sigma,
            blur_m,
            band_ratio,
        })
    }
}

/// A JSON file as a value, with the path in any error.
fn read_json(path: &Path) -> anyhow::Result<serde_json::Value> {
    let t = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&t).with_context(|| format!("parsing {}", path.display()))
}

/// One plausible truth: a draw of the terrain given the map `dem` and its reported `error`
/// (Gaussian, per-cell σ, correlated by its blur), holes filled from their neighbours first.
///
/// Not the map plus a fresh draw of its error: the map already carries one draw, so its
/// frames would share the map's error texture with the tile and carry a second one, twice the
/// noise power the real ground shows. The real ground shares with the map only the terrain's
/// own power and differs from it by the error's. Per spatial frequency, with `P` the map's
/// power, `N` the error's (a variance shaped by the blur's spectrum) and `S = max(P − N, 0)`
/// the terrain's: the Wiener estimate `S/P · map` plus an independent Gaussian draw of the
/// posterior variance `S·N/P` (conditional simulation). The draw has the terrain's power `S`,
/// shares `S` with the map and differs from it by `N`, as the ground does. `P` is averaged over
/// rings of equal frequency (an isotropic terrain) on the map mirrored at its edges (a periodic
/// field without jumps).
///
/// The error is not stationary: a map that mixes 1 m floors and 5–7 m walls (the fresh crater,
/// the Shackleton rim) has a mean variance 3.5–6× its median cell's. Drawn at the mean, the
/// gentle ground got several times the noise it has, and the rehearsal flew it as a worse map
/// than it is (session 26: the fresh rim lost in space 13 % predicted, 41 % flown; the same
/// rehearsal from the true terrain predicts 45 %). So the draw is made at a ladder of
/// variances (`variance_levels`, the same white noise for all) and every cell takes the
/// two rungs around its own variance, interpolated in log variance: locally the conditional
/// simulation of a map whose error had that cell's variance everywhere, with the whole map's
/// power per frequency `P` (a wall's high-σ cells are thus drawn somewhat smoother than their
/// own terrain would warrant). A map with one σ
/// everywhere takes one rung, as before. A map that reports no error is returned as it is
/// (holes filled).
pub fn plausible_truth(dem: &Dem, error: &ErrorModel, seed: u64) -> anyhow::Result<Dem> {
    let mut out = dem.clone();
    let (w, h) = (out.width(), out.height());
    crate::sar::geometry::fill_nodata(out.heights_m_mut(), w, h)
        .map_err(|e| anyhow!("filling the reference DEM's holes: {e}"))?;
    let Some(s) = &error.sigma else {
        return Ok(out);
    };
    if s.width() != w || s.height() != h {
        bail!(
            "the height σ map is {}×{}, the reference DEM {w}×{h}",
            s.width(),
            s.height(),
        );
    }
    let reported = |v: f32| v.is_finite() && v > 0.0;
    let (mut sum, mut cells) = (0.0f64, 0usize);
    for &v in s.heights_m() {
        if reported(v) {
            sum += f64::from(v).powi(2);
            cells += 1;
        }
    }
    if cells == 0 {
        return Ok(out);
    }
    let mean_var = sum / cells as f64;
    // Cells without a σ of their own (the mask's holes) take the mean.
    let var: Vec<f64> = s
        .heights_m()
        .iter()
        .map(|&v| {
            if reported(v) {
                f64::from(v).powi(2)
            } else {
                mean_var
            }
        })
        .collect();
    let blur_px = error.blur_m / dem.pixel_m()?;
    let z: Vec<f64> = out.heights_m().iter().map(|&v| f64::from(v)).collect();
    let spectra = PosteriorSpectra::new(
        &z,
        w,
        h,
        blur_px,
        error.band_ratio,
        seed ^ 0x5EED_0E22_0000_0001,
    );
    let levels = variance_levels(&var);
    let drawn = if let [only] = levels[..] {
        spectra.draw(only)
    } else {
        let (lo, hi) = (levels[0].ln(), levels[levels.len() - 1].ln());
        // Each cell's place on the ladder, in rungs.
        let rung: Vec<f64> = var
            .iter()
            .map(|v| ((v.ln() - lo) / (hi - lo) * (levels.len() - 1) as f64).max(0.0))
            .collect();
        let mut acc = vec![0.0f64; w * h];
        for (k, &level) in levels.iter().enumerate() {
            let d = spectra.draw(level);
            for ((a, &r), x) in acc.iter_mut().zip(&rung).zip(d) {
                // Hat weights: each cell sums the two rungs around its variance to 1.
                let wgt = (1.0 - (r - k as f64).abs()).max(0.0);
                *a += wgt * x;
            }
        }
        acc
    };
    for (o, v) in out.heights_m_mut().iter_mut().zip(drawn) {
        *o = v as f32;
    }
    Ok(out)
}

/// Most rungs of [`variance_levels`]' ladder (bounds the work: one inverse FFT each).
pub const MAX_VARIANCE_LEVELS: usize = 12;

/// The variances [`plausible_truth`] draws at: one when the map's σ varies by less than 1 %
/// (its mean square), else a geometric ladder from the smallest to the largest cell variance
/// (m²), rungs at most a factor 2 apart (σ within 19 % of a rung) while the largest is at most
/// 2¹¹ times the smallest, spread evenly beyond: at most [`MAX_VARIANCE_LEVELS`].
fn variance_levels(var: &[f64]) -> Vec<f64> {
    let (lo, hi) = var
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), &v| (l.min(v), h.max(v)));
    if !(lo > 0.0 && hi.is_finite()) || hi <= lo * 1.01f64.powi(2) {
        let mean = var.iter().sum::<f64>() / var.len().max(1) as f64;
        return vec![mean];
    }
    let n = ((hi / lo).log2().ceil() as usize + 1).clamp(2, MAX_VARIANCE_LEVELS);
    (0..n)
        .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
        .collect()
}

/// [`plausible_truth`]'s spectra on a hole-free `w × h` field `z`: the map's (mirrored at its
/// edges), its power per frequency ring, and one white-noise field's, so that draws at several
/// error variances share their randomness. The error is Gaussian-correlated, σ `blur_px`
/// pixels (0: white), its power scaled per octave by `band_ratio` ([`ErrorModel`]). Memory during a draw: four complex grids of the mirrored size (the map's
/// and the noise's spectra, the draw and the FFT's scratch) and a few real grids of the map's,
/// ≈ 290 B per map cell (≈ 1.2 GB for a 2048² map).
struct PosteriorSpectra {
    spec: Vec<rustfft::num_complex::Complex64>,
    white: Vec<rustfft::num_complex::Complex64>,
    power: Vec<f64>,
    shape_mean: f64,
    blur_px: f64,
    band_ratio: [f64; BAND_EDGES.len()],
    mean: f64,
    w: usize,
    h: usize,
}

impl PosteriorSpectra {
    fn new(
        z: &[f64],
        w: usize,
        h: usize,
        blur_px: f64,
        band_ratio: [f64; BAND_EDGES.len()],
        seed: u64,
    ) -> Self {
        use rustfft::num_complex::Complex64;
        let (pw, ph) = (2 * w, 2 * h);
        let n = pw * ph;
        let mean = z.iter().sum::<f64>() / z.len().max(1) as f64;
        // Mirrored at the edges: the padded field is periodic without a jump.
        let mut spec: Vec<Complex64> = (0..n)
            .map(|i| {
                let (r, c) = (i / pw, i % pw);
                let r = if r < h { r } else { ph - 1 - r };
                let c = if c < w { c } else { pw - 1 - c };
                Complex64::new(z[r * w + c] - mean, 0.0)
            })
            .collect();
        fft2(&mut spec, pw, ph, false);
        let mut me = Self {
            spec,
            white: Vec::new(),
            power: Vec::new(),
            shape_mean: 1.0,
            blur_px,
            band_ratio,
            mean,
            w,
            h,
        };
        let rings = me.rings();
        let (mut power, mut count) = (vec![0.0f64; rings], vec![0usize; rings]);
        for (i, c) in me.spec.iter().enumerate() {
            let r = me.ring(i);
            power[r] += c.norm_sqr() / n as f64;
            count[r] += 1;
        }
        for (p, &k) in power.iter_mut().zip(&count) {
            *p /= k.max(1) as f64;
        }
        me.power = power;
        me.shape_mean = (0..n).map(|i| me.shape(me.radius(i))).sum::<f64>() / n as f64;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let mut white: Vec<Complex64> = (0..n)
            .map(|_| Complex64::new(normal(&mut rng), 0.0))
            .collect();
        fft2(&mut white, pw, ph, false);
        me.white = white;
        me
    }

    /// Frequency of coefficient `i` of the mirrored grid, cycles per pixel.
    fn radius(&self, i: usize) -> f64 {
        crate::dem::spectrum::frequency(i, 2 * self.w, 2 * self.h)
    }

    fn ring_width(&self) -> f64 {
        1.0 / (2 * self.w.max(self.h)) as f64
    }

    /// Rings of equal frequency (the farthest corner is at √0.5 cycles per pixel).
    fn rings(&self) -> usize {
        (0.75 / self.ring_width()) as usize + 2
    }

    fn ring(&self, i: usize) -> usize {
        ((self.radius(i) / self.ring_width()).round() as usize).min(self.rings() - 1)
    }

    /// The error's spectrum: white noise through the Gaussian blur.
    fn shape(&self, f: f64) -> f64 {
        (-(std::f64::consts::TAU * self.blur_px * f).powi(2)).exp()
    }

    /// The Wiener estimate of the terrain under a stationary error of variance `noise_var` (m²),
    /// plus the draw of the posterior variance; the `w × h` field.
    fn draw(&self, noise_var: f64) -> Vec<f64> {
        let (pw, ph) = (2 * self.w, 2 * self.h);
        let n = pw * ph;
        let mut out = self.spec.clone();
        for (i, (c, e)) in out.iter_mut().zip(&self.white).enumerate().skip(1) {
            // (Coefficient 0 is the mean, known.)
            let p = self.power[self.ring(i)];
            // Scaled to its variance: a periodogram's mean over all frequencies is the variance.
            // The model's spectrum, scaled by what the two looks measured in its octave.
            let f = self.radius(i);
            let noise = noise_var * self.shape(f) / self.shape_mean.max(f64::MIN_POSITIVE)
                * self.band_ratio[band_of(f)];
            let signal = (p - noise).max(0.0);
            *c = if p > 0.0 {
                *c * (signal / p) + *e * (signal * noise / p).sqrt()
            } else {
                rustfft::num_complex::Complex64::new(0.0, 0.0)
            };
        }
        fft2(&mut out, pw, ph, true);
        (0..self.w * self.h)
            .map(|i| out[(i / self.w) * pw + i % self.w].re / n as f64 + self.mean)
            .collect()
    }
}

/// Rehearse the map: fly `spec.frames_per_site` frames at every site against `tile` (with
/// `config`, the flight code's), from a draw of the terrain given `dem` (the reference DEM)
/// and its `error` ([`plausible_truth`]).
/// `campaign` gives the sensor, pixel range, prior and budget (its trial count and seed are
/// not used).
pub fn rehearse(
    tile: Tile<'_>,
    config: NavConfig,
    dem: &Dem,
    error: &ErrorModel,
    campaign: &CampaignSpec,
    spec: &RehearsalSpec,
    progress: &ProgressBar,
) -> anyhow::Result<Rehearsal> {
    spec.validate()?;
    if !(campaign.pixel_min_m > 0.0 && campaign.pixel_max_m >= campaign.pixel_min_m) {
        bail!("need 0 < smallest frame pixel ≤ largest frame pixel");
    }
    let truth = plausible_truth(dem, error, spec.seed)?;
    let (x0, x1, y0, y1) = centre_box(&tile, &truth, campaign)?;
    let sites = |span: f64| -> anyhow::Result<usize> {
        // Counted in f64 first: a tiny spacing must not overflow the cast.
        let n = (span / spec.step_m).ceil() + 1.0;
        if !(n <= REHEARSAL_MAX_SITES_PER_AXIS as f64) {
            // Readable for absurd input too (a spacing of 1e-300 m).
            let g = |v: f64| {
                if (1e-3..1e6).contains(&v) {
                    format!("{}", (v * 1e3).round() / 1e3)
                } else {
                    format!("{v:.1e}")
                }
            };
            bail!(
                "{} sites per axis at {} m spacing over {span:.0} m (at most \
                 {REHEARSAL_MAX_SITES_PER_AXIS}): use a larger spacing",
                g(n),
                g(spec.step_m)
            );
        }
        Ok((n as usize).max(2))
    };
    let (nx, ny) = (sites(x1 - x0)?, sites(y1 - y0)?);
    let step = |span: f64, n: usize| if n > 1 { span / (n - 1) as f64 } else { 0.0 };
    let (sx, sy) = (step(x1 - x0, nx), step(y1 - y0, ny));
    let k = spec.frames_per_site;
    let nav = Navigator::new(tile, config);
    let pool = rayon::ThreadPoolBuilder::new()
        .stack_size(WORKSPACE_STACK)
        .build()?;
    progress.set_length((nx * ny * k) as u64);
    let done = AtomicUsize::new(0);
    let outcomes: Vec<anyhow::Result<bool>> = pool.install(|| {
        (0..nx * ny * k)
            .into_par_iter()
            .map_init(
                || new_workspace(campaign.budget),
                |ws, n| {
                    let (site, f) = (n / k, n % k);
                    // Salted: a campaign with the same seed must not draw the same numbers.
                    let mut rng = rand_pcg::Pcg64::seed_from_u64(
                        (spec.seed ^ REHEARSAL_SALT).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                            ^ (n as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
                    );
                    let pose = FramePose {
                        x_m: x0 + sx * (site % nx) as f64,
                        y_m: y0 + sy * (site / nx) as f64,
                        // Stratified: each site sees the whole compass rose.
                        heading_rad: std::f64::consts::TAU * (f as f64 + rng.random::<f64>())
                            / k as f64,
                        pixel_m: campaign.pixel_min_m
                            + (campaign.pixel_max_m - campaign.pixel_min_m) * rng.random::<f64>(),
                    };
                    let s = fly_posed(&nav, ws, &truth, &pose, campaign, &mut rng)
                        .with_context(|| format!("rehearsal frame {n}"))?;
                    progress.set_position(done.fetch_add(1, Ordering::Relaxed) as u64 + 1);
                    Ok(s.fix && !s.false_fix)
                },
            )
            .collect()
    });
    let outcomes: Vec<bool> = outcomes.into_iter().collect::<anyhow::Result<_>>()?;
    let success = outcomes
        .chunks(k)
        .map(|c| c.iter().filter(|&&ok| ok).count() as f32 / k as f32)
        .collect();
    Ok(Rehearsal {
        x0_m: x0,
        y0_m: y0,
        step_x_m: sx,
        step_y_m: sy,
        nx,
        ny,
        success,
        frames: nx * ny * k,
        spec: *spec,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(nx: usize, ny: usize, success: Vec<f32>) -> Rehearsal {
        Rehearsal {
            x0_m: 100.0,
            y0_m: 200.0,
            step_x_m: 50.0,
            step_y_m: -50.0,
            nx,
            ny,
            success,
            frames: 0,
            spec: RehearsalSpec::default(),
        }
    }

    #[test]
    fn success_interpolates_between_sites_and_is_nan_off_the_box() {
        let r = grid(2, 2, vec![1.0, 0.0, 1.0, 0.0]);
        assert_eq!(r.success_at(100.0, 200.0), 1.0);
        assert_eq!(r.success_at(150.0, 150.0), 0.0);
        assert!((r.success_at(125.0, 175.0) - 0.5).abs() < 1e-12);
        assert!(r.go_at(100.0, 175.0));
        assert!(!r.go_at(140.0, 175.0));
        // Within half the nominal spacing (100 m) of the box: the edge's value; beyond: NaN.
        assert_eq!(r.success_at(99.0, 200.0), 1.0);
        assert_eq!(r.success_at(100.0, 249.0), 1.0);
        assert_eq!(r.success_at(199.0, 150.0), 0.0);
        assert!(r.success_at(49.0, 200.0).is_nan());
        assert!(r.success_at(100.0, 251.0).is_nan());
        assert!(r.success_at(100.0, 99.0).is_nan());
        assert!((r.go_fraction() - 0.5).abs() < 1e-12);
    }

    #[test]
    fn one_site_answers_only_at_itself() {
        let r = grid(1, 1, vec![1.0]);
        assert_eq!(r.success_at(100.0, 200.0), 1.0);
        assert_eq!(r.success_at(140.0, 200.0), 1.0);
        assert!(r.success_at(151.0, 200.0).is_nan());
    }

    /// A `w × h` Gaussian random field: white noise blurred by `blur_px`, scaled to `rms`.
    fn smooth_field(
        rng: &mut rand_pcg::Pcg64,
        w: usize,
        h: usize,
        blur_px: f64,
        rms: f64,
    ) -> Vec<f64> {
        let white: Vec<f64> = (0..w * h).map(|_| normal(rng)).collect();
        let f = crate::insar::pipeline::gaussian_filter(&white, w, h, blur_px);
        let sd = (f.iter().map(|v| v * v).sum::<f64>() / f.len() as f64).sqrt();
        f.into_iter().map(|v| v * rms / sd).collect()
    }

    /// A map whose west half is good to 0.5 m and east half to 3 m: the draw departs from it
    /// by each half's own error, not by the mean's 2.2 m everywhere.
    #[test]
    fn plausible_truth_follows_the_error_cell_by_cell() {
        use crate::dem::GeoRef;
        let (w, h) = (128, 96);
        let geo = GeoRef::local(0.0, 0.0, 20.0, "test");
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let mut field = |blur_px: f64, rms: f64| smooth_field(&mut rng, w, h, blur_px, rms);
        let terrain = field(6.0, 3.0);
        let noise = field(22.4 / 20.0, 1.0);
        let sd = |i: usize| if i % w < w / 2 { 0.5f32 } else { 3.0 };
        let z: Vec<f32> = (0..w * h)
            .map(|i| (terrain[i] + f64::from(sd(i)) * noise[i]) as f32)
            .collect();
        let map = Dem::new(w, h, z, geo.clone()).unwrap();
        let sigma = Dem::new(w, h, (0..w * h).map(sd).collect(), geo).unwrap();
        let e = ErrorModel::with_sigma(sigma, 22.4);
        let t = plausible_truth(&map, &e, 9).unwrap();
        // Away from the seam (8 px) and the edges' mirror (8 px).
        let rms = |west: bool| {
            let (mut a, mut k) = (0.0, 0usize);
            for r in 8..h - 8 {
                let cols = if west { 8..w / 2 - 8 } else { w / 2 + 8..w - 8 };
                for c in cols {
                    let d = f64::from(t.heights_m()[r * w + c] - map.heights_m()[r * w + c]);
                    a += d * d;
                    k += 1;
                }
            }
            (a / k as f64).sqrt()
        };
        let (west, east) = (rms(true), rms(false));
        assert!((0.3..0.8).contains(&west), "west: draw − map rms {west} m");
        assert!((2.3..3.7).contains(&east), "east: draw − map rms {east} m");
        assert_eq!(variance_levels(&[4.0; 5]), vec![4.0]);
        let ladder = variance_levels(&[0.25, 9.0, 1.0]);
        assert_eq!(ladder.len(), 7);
        assert!((ladder[0] - 0.25).abs() < 1e-12 && (ladder[6] - 9.0).abs() < 1e-9);
        assert_eq!(variance_levels(&[1e-6, 1e6]).len(), MAX_VARIANCE_LEVELS);
    }

    #[test]
    fn plausible_truth_has_the_terrains_texture_and_differs_by_the_error() {
        use crate::dem::GeoRef;
        let (w, h) = (128, 128);
        let geo = GeoRef::local(0.0, 0.0, 20.0, "test");
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let mut field = |blur_px: f64, rms: f64| smooth_field(&mut rng, w, h, blur_px, rms);
        // Gentle terrain (smooth, 3 m rms) under a map error of 2 m, blurred by 22.4 m.
        let terrain = field(6.0, 3.0);
        let noise = field(22.4 / 20.0, 2.0);
        let mut z: Vec<f32> = terrain
            .iter()
            .zip(&noise)
            .map(|(t, e)| (t + e) as f32)
            .collect();
        z[64 * w + 64] = f32::NAN;
        let map = Dem::new(w, h, z, geo.clone()).unwrap();
        let sigma = Dem::new(w, h, vec![2.0f32; w * h], geo.clone()).unwrap();
        let e = ErrorModel::with_sigma(sigma, 22.4);
        let t = plausible_truth(&map, &e, 3).unwrap();
        assert!(t.heights_m().iter().all(|v| v.is_finite()));
        let lag1 = |z: &[f64]| {
            let (mut a, mut k) = (0.0, 0);
            for r in 0..h {
                for c in 0..w - 1 {
                    let d = z[r * w + c + 1] - z[r * w + c];
                    if d.is_finite() {
                        a += d * d;
                        k += 1;
                    }
                }
            }
            (a / k as f64).sqrt()
        };
        let as64 = |d: &Dem| -> Vec<f64> { d.heights_m().iter().map(|&v| f64::from(v)).collect() };
        let (tz, mz) = (as64(&t), as64(&map));
        // The draw's small-scale texture is the terrain's (0.32 m per cell; drawn 0.41), not
        // the map's noise (1.24 m; the map plus a second error would read 1.7 m).
        let (want, map_lag, got) = (lag1(&terrain), lag1(&mz), lag1(&tz));
        assert!(map_lag > 2.5 * want, "map {map_lag}, terrain {want}");
        assert!(
            (got - want).abs() < 0.35 * want,
            "draw {got}, terrain {want}, map {map_lag}"
        );
        // A draw less the map (0 at the map's hole).
        let off_map = |t: &[f64]| -> Vec<f64> {
            t.iter()
                .zip(&mz)
                .map(|(a, b)| if b.is_finite() { a - b } else { 0.0 })
                .collect()
        };
        // Over the cells the map has (all but its one hole).
        let rms_off_map = |t: &[f64]| {
            let d = off_map(t);
            (d.iter().map(|d| d * d).sum::<f64>() / (d.len() - 1) as f64).sqrt()
        };
        // It differs from the map as the real ground does: by the error's 2 m (1.91 m).
        let rms = rms_off_map(&tz);
        assert!((rms - 2.0).abs() < 0.3, "draw − map rms {rms}");
        // Two looks that measured the error at a quarter of its bound's power in every
        // octave: the draw departs from the map by 1 m, not the bound's 2 m.
        let calibrated = ErrorModel {
            band_ratio: [0.25; BAND_EDGES.len()],
            ..e.clone()
        };
        let rms_q = rms_off_map(&as64(&plausible_truth(&map, &calibrated, 3).unwrap()));
        assert!(
            (rms_q - 1.0).abs() < 0.2,
            "calibrated draw − map rms {rms_q}"
        );
        // The scaling lands in its own octave: four times the power in the coarsest (where the
        // terrain dominates, so the draw departs from the map by the error drawn) and the
        // others as they were.
        let coarse = ErrorModel {
            band_ratio: [4.0, 1.0, 1.0, 1.0, 1.0, 1.0],
            ..e.clone()
        };
        let tc = as64(&plausible_truth(&map, &coarse, 3).unwrap());
        let dpow = |t: &[f64]| crate::dem::spectrum::band_powers(&off_map(t), w, h);
        let (p1, p4) = (dpow(&tz), dpow(&tc));
        let gain = |b: usize| p4[b] / p1[b];
        assert!(
            (2.5..6.0).contains(&gain(0)),
            "coarsest {} ({p1:?} → {p4:?})",
            gain(0)
        );
        for b in 2..5 {
            assert!((0.8..1.25).contains(&gain(b)), "octave {b}: {}", gain(b));
        }
        // Reproducible; another seed, another draw.
        assert_eq!(
            plausible_truth(&map, &e, 3).unwrap().heights_m(),
            t.heights_m()
        );
        assert_ne!(
            plausible_truth(&map, &e, 4).unwrap().heights_m(),
            t.heights_m()
        );
        // No claimed error: the map itself, its hole filled.
        let none = plausible_truth(&map, &ErrorModel::none(), 3).unwrap();
        for (a, b) in none.heights_m().iter().zip(map.heights_m()) {
            assert!(!b.is_finite() || a == b);
        }
        assert!(none.heights_m()[64 * w + 64].is_finite());
        let small = Dem::new(10, 10, vec![1.0f32; 100], geo).unwrap();
        let bad = ErrorModel::with_sigma(small, 0.0);
        assert!(plausible_truth(&map, &bad, 3).is_err());
    }

    #[test]
    fn an_insar_folder_whose_bound_predates_the_filter_is_refused() {
        use crate::dem::{GeoRef, write_geotiff};
        let dir = tempfile::tempdir().unwrap();
        let sigma = Dem::new(4, 4, vec![1.0f32; 16], GeoRef::local(0.0, 0.0, 20.0, "t")).unwrap();
        write_geotiff(
            &sigma,
            &dir.path().join(crate::insar::products::CRLB_FILE),
            None,
        )
        .unwrap();
        // Without a report: nothing tells, the bound is taken as it is.
        assert!(ErrorModel::load(dir.path()).unwrap().sigma.is_some());
        let report = dir.path().join("report.json");
        std::fs::write(&report, r#"{"height_rmse_m": 1.0}"#).unwrap();
        let e = ErrorModel::load(dir.path()).unwrap_err().to_string();
        assert!(e.contains("rerun `ground-sim insar`"), "{e}");
        std::fs::write(
            &report,
            r#"{"height_rmse_m": 1.0, "crlb_filter_factor": 0.553}"#,
        )
        .unwrap();
        assert!(ErrorModel::load(dir.path()).is_ok());
        // The noise's own correlation length, when the product states it, over the DEM's
        // signal blur in tile.json (which a quadratic DEM filter leaves at the window's 10 m).
        std::fs::write(
            dir.path().join(crate::reference::META_FILE),
            r#"{"smoothing_m": 50.0, "smoothing_applied_m": 48.98979485566356}"#,
        )
        .unwrap();
        let tile_blur = ErrorModel::load(dir.path()).unwrap().blur_m;
        assert!((tile_blur - 10.0).abs() < 1e-6, "{tile_blur}");
        std::fs::write(
            &report,
            r#"{"crlb_filter_factor": 0.50, "error_blur_m": 30.36}"#,
        )
        .unwrap();
        assert_eq!(ErrorModel::load(dir.path()).unwrap().blur_m, 30.36);
        // A two-look map's measure of its error spectrum scales the draw; a malformed one is
        // refused rather than ignored.
        assert_eq!(ErrorModel::load(dir.path()).unwrap().band_ratio, [1.0; 6]);
        std::fs::write(
            &report,
            r#"{"crlb_filter_factor": 0.5, "looks": {"error_spectrum_ratio": [1.5, 2, 1, 0.8, 3, 4]}}"#,
        )
        .unwrap();
        assert_eq!(
            ErrorModel::load(dir.path()).unwrap().band_ratio,
            [1.5, 2.0, 1.0, 0.8, 3.0, 4.0]
        );
        std::fs::write(
            &report,
            r#"{"crlb_filter_factor": 0.5, "looks": {"error_spectrum_ratio": [1.5, 2, 1]}}"#,
        )
        .unwrap();
        let e = ErrorModel::load(dir.path()).unwrap_err().to_string();
        assert!(e.contains("error_spectrum_ratio"), "{e}");
    }
}
