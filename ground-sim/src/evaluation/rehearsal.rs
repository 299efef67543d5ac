//! The navigability map by rehearsal: fly the flight code against the reference over the map
//! before the flyer does, with frames synthesised from the reference DEM itself.
//!
//! What the ground has before flight is the reference folder: the tile, the DEM it was built
//! from and, for an InSAR map, the per-cell height σ the processing reported (its Cramér–Rao
//! bound). The flyer's frames will come from the true terrain, which differs from the map by the
//! map's error. A rehearsal therefore flies frames from one plausible truth: the reference DEM
//! plus an independent draw of that error (Gaussian, per map cell, at the reported σ; a
//! truth-built map claims none), its holes (the InSAR mask) filled smoothly, so frames there
//! carry nothing the tile could match. Sites lie on a regular grid over the box where a frame
//! fits the map; each flies a few frames at stratified headings, random pixel sizes in the
//! campaign's range, the sensor's noise and, if asked, a prior drawn like a campaign's. A
//! site's success fraction is the prediction; between sites it is interpolated bilinearly.
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

use crate::dem::{Dem, read_geotiff};
use crate::evaluation::campaign::{CampaignSpec, centre_box, fly_posed, normal};
use crate::flyer::frames::FramePose;
use crate::flyer::onboard::{WORKSPACE_STACK, new_workspace};
use crate::insar::pipeline::gaussian_filter;

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
/// correlation, a Gaussian of the DEM's own blur (what the tile builder recorded as the
/// smoothing the DEM already had: an InSAR DEM's multilook window, through which its noise
/// passed like its signal). Measured on the suite's InSAR height-error maps (plains and lola,
/// both seeds): neighbour correlation 0.80–0.82 at 20 m, 0.46–0.53 at 40 m, against 0.78 and
/// 0.37 for a Gaussian of the recorded 22.4 m blur.
#[derive(Debug, Clone)]
pub struct ErrorModel {
    /// Height 1σ per cell, metres, on the reference DEM's grid (`None`: the map claims none).
    pub sigma: Option<Dem>,
    /// Correlation: σ of the Gaussian the error field is smoothed with, metres (0: white).
    pub blur_m: f64,
}

impl ErrorModel {
    /// No error: a truth-built map.
    pub fn none() -> Self {
        Self {
            sigma: None,
            blur_m: 0.0,
        }
    }

    /// Read it from a reference folder: `height-crlb.tif` when present, the blur from
    /// `tile.json` (`sqrt(smoothing_m² − smoothing_applied_m²)`; 0 without the file). A DEM
    /// blurred more than the tile's target smoothing had none applied, and its blur reads as
    /// the target: an underestimate (not the case for any map the project's chain makes).
    pub fn load(dir: &Path) -> anyhow::Result<Self> {
        let crlb = dir.join(crate::insar::products::CRLB_FILE);
        let sigma = crlb
            .exists()
            .then(|| read_geotiff(&crlb).with_context(|| format!("reading {}", crlb.display())))
            .transpose()?;
        let meta = dir.join(crate::reference::META_FILE);
        let blur_m = if meta.exists() {
            let t = std::fs::read_to_string(&meta)
                .with_context(|| format!("reading {}", meta.display()))?;
            let v: serde_json::Value =
                serde_json::from_str(&t).with_context(|| format!("parsing {}", meta.display()))?;
            let total = v["smoothing_m"].as_f64().unwrap_or(0.0);
            let applied = v["smoothing_applied_m"].as_f64().unwrap_or(total);
            (total * total - applied * applied).max(0.0).sqrt()
        } else {
            0.0
        };
        Ok(Self { sigma, blur_m })
    }
}

/// One plausible truth: `dem` plus a draw of `error` (Gaussian, per-cell σ, correlated by its
/// blur), holes filled from their neighbours.
pub fn plausible_truth(dem: &Dem, error: &ErrorModel, seed: u64) -> anyhow::Result<Dem> {
    let mut out = dem.clone();
    let (w, h) = (out.width(), out.height());
    if let Some(s) = &error.sigma {
        if s.width() != w || s.height() != h {
            bail!(
                "the height σ map is {}×{}, the reference DEM {w}×{h}",
                s.width(),
                s.height(),
            );
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x5EED_0E22_0000_0001);
        let px = dem.pixel_m()?;
        let blur_px = error.blur_m / px;
        let field = if blur_px > 0.0 {
            // Drawn on a grid padded by the kernel's reach and cropped, so edge cells are no
            // different from inner ones (the filter renormalises a kernel cut by the edge).
            let pad = (3.0 * blur_px).ceil() as usize;
            let (pw, ph) = (w + 2 * pad, h + 2 * pad);
            let white: Vec<f64> = (0..pw * ph).map(|_| normal(&mut rng)).collect();
            let f = gaussian_filter(&white, pw, ph, blur_px);
            let crop: Vec<f64> = (0..w * h)
                .map(|i| f[(i / w + pad) * pw + i % w + pad])
                .collect();
            // Unit variance again: the σ map is the per-cell error.
            let sd = (crop.iter().map(|v| v * v).sum::<f64>() / crop.len() as f64).sqrt();
            crop.into_iter().map(|v| v / sd.max(1e-12)).collect()
        } else {
            // Drawn for every cell, so the field does not depend on where the holes are.
            (0..w * h).map(|_| normal(&mut rng)).collect::<Vec<f64>>()
        };
        for ((z, &sd), e) in out.heights_m_mut().iter_mut().zip(s.heights_m()).zip(field) {
            if z.is_finite() && sd.is_finite() && sd > 0.0 {
                *z += (f64::from(sd) * e) as f32;
            }
        }
    }
    crate::sar::geometry::fill_nodata(out.heights_m_mut(), w, h)
        .map_err(|e| anyhow!("filling the reference DEM's holes: {e}"))?;
    Ok(out)
}

/// Rehearse the map: fly `spec.frames_per_site` frames at every site against `tile` (with
/// `config`, the flight code's), from `dem` (the reference DEM) plus a draw of `error`.
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

    #[test]
    fn plausible_truth_adds_the_claimed_error_and_fills_holes() {
        use crate::dem::GeoRef;
        let geo = GeoRef::local(0.0, 0.0, 20.0, "test");
        let mut z = vec![0.0f32; 100 * 100];
        z[5050] = f32::NAN;
        let dem = Dem::new(100, 100, z, geo.clone()).unwrap();
        let sigma = Dem::new(100, 100, vec![2.0f32; 100 * 100], geo.clone()).unwrap();
        let corr1 = |t: &Dem| {
            let z = t.heights_m();
            let (mut a, mut b) = (0.0, 0.0);
            for r in 0..100 {
                for c in 0..99 {
                    a += f64::from(z[r * 100 + c]) * f64::from(z[r * 100 + c + 1]);
                    b += f64::from(z[r * 100 + c]).powi(2);
                }
            }
            a / b
        };
        for blur_m in [0.0, 22.4] {
            let e = ErrorModel {
                sigma: Some(sigma.clone()),
                blur_m,
            };
            let t = plausible_truth(&dem, &e, 3).unwrap();
            assert!(t.heights_m().iter().all(|v| v.is_finite()));
            let n = t.heights_m().len() as f64;
            let ms = t
                .heights_m()
                .iter()
                .map(|&v| f64::from(v).powi(2))
                .sum::<f64>()
                / n;
            assert!(
                (ms.sqrt() - 2.0).abs() < 0.1,
                "blur {blur_m}: rms {}",
                ms.sqrt()
            );
            // White: neighbours independent; blurred by 22.4 m on 20 m cells: a Gaussian
            // field's neighbour correlation exp(−d²/4σ²) ≈ 0.82.
            let c = corr1(&t);
            let want = if blur_m > 0.0 { 0.82 } else { 0.0 };
            assert!((c - want).abs() < 0.06, "blur {blur_m}: correlation {c}");
        }
        let none = plausible_truth(&dem, &ErrorModel::none(), 3).unwrap();
        assert!(none.heights_m().iter().all(|&v| v == 0.0));
        let small = Dem::new(10, 10, vec![1.0f32; 100], geo).unwrap();
        let bad = ErrorModel {
            sigma: Some(small),
            blur_m: 0.0,
        };
        assert!(plausible_truth(&dem, &bad, 3).is_err());
    }
}
