//! Built-in synthetic lunar terrain for permanently shadowed crater floors.
//!
//! A scene is the sum of three parts, evaluated on a north-up grid whose map frame has the host
//! crater's centre at (0, 0) m, x east, y north:
//! 1. the host crater ([`crater::HostProfile`]): Shackleton (simple, ~21 km), Shoemaker
//!    (complex, ~51 km, flat floor, terraced walls) or a fresh 2.3 km simple crater, with a
//!    slightly irregular rim; none for the plains (`lola`, `plains`), which may have a regional
//!    tilt instead (map frame origin at the scene centre);
//! 2. superposed small craters drawn from a Neukum production function capped by the empirical
//!    equilibrium density ([`sfd`]), each with Pike's fresh morphometry and degraded by
//!    topographic diffusion according to its age ([`crater`]);
//! 3. self-affine roughness by spectral synthesis ([`roughness`]).
//!
//! The models, their parameters and sources are written up in `docs/terrain.md`.
//! Determinism: every random number comes from PCG64 streams seeded from `seed`, drawn
//! sequentially; parallel loops only split pure per-pixel work or row bands whose additions happen
//! in a fixed order, so the DEM is bit-identical for a seed whatever the thread count.

pub mod crater;
pub mod landing;
pub mod roughness;
pub mod sfd;

use indicatif::ProgressBar;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;

use crate::dem::{Dem, DemError, GeoRef};
use crater::{CraterStamp, HostCrater, HostProfile, make_stamp};
use roughness::{Roughness, fractal_field};
use sfd::draw_craters;

/// Largest grid side in pixels (nav-core's frame limit).
pub const MAX_SIDE_PX: usize = nav_core::frame::MAX_FRAME_SIDE;
/// Smallest grid side in pixels.
pub const MIN_SIDE_PX: usize = 8;
/// Smallest crater drawn, in pixels (smaller ones are not resolved by a 3×3 slope operator).
pub const MIN_CRATER_PX: f64 = 3.0;
/// Smallest crater drawn in metres (lower validity bound of the Neukum production function).
pub const MIN_CRATER_M: f64 = 10.0;
/// Rows per band when stamping craters in parallel.
const BAND_ROWS: usize = 16;

/// Named scene presets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// A window in Shackleton (89.7°S, 130°E): ~21 km simple crater, ~4.2 km deep, 30–35° walls.
    Shackleton,
    /// The flat floor of Shoemaker (88.1°S, 40.2°E): ~51 km complex crater, old cratered floor.
    Shoemaker,
    /// An old intercrater plain calibrated on LOLA's 5 m south-pole tile (outside Shoemaker's
    /// rim): no host crater, a crater population as sparse as LOLA's 5 m grid shows it.
    Lola,
    /// Smooth, young mare-like plains: few craters, low roughness (the weak case for TRN).
    Plains,
    /// A fresh simple crater (2.3 km, d/D ≈ 0.2, 30–35° walls) in `lola`'s cratered plains.
    Fresh,
}

/// Age of the `lola` plain (and of `fresh`'s surroundings), Gyr: the pre-Nectarian intercrater
/// plains around Shoemaker; old enough that craters below ~1 km are in equilibrium.
pub const LOLA_PLAIN_AGE_GYR: f64 = 4.0;
/// Factor on `N_obs` below [`LOLA_RESOLVED_D_M`] for the `lola`, `plains` and `fresh` presets:
/// the share of the equilibrium population of small craters that LOLA's 5 m grid (interpolated
/// between tracks tens of metres apart) still shows. Calibrated on the 5 m south-pole tile's
/// closed depressions (docs/terrain.md).
pub const LOLA_CRATER_DENSITY: f64 = 0.18;
/// Crater diameter (metres) from which `lola` sees the full model density.
pub const LOLA_RESOLVED_D_M: f64 = 100.0;
/// Largest superposed crater of the `lola` and `fresh` plains, metres.
pub const LOLA_MAX_CRATER_M: f64 = 800.0;
/// Regional slope of the `lola` plain, degrees: the plane fitted to the 5 m tile dips 3.25°
/// (it lies on the regional rise outside Shoemaker's rim).
pub const LOLA_REGIONAL_SLOPE_DEG: f64 = 3.25;
/// Roughness of the `lola` plain: H as for the highlands, ν5 and the roll-off calibrated on the
/// tile's slope percentiles (long wavelengths carry the tile's gentle regional relief).
pub const LOLA_ROUGHNESS: Roughness = Roughness {
    hurst: 0.9,
    nu5_m: 0.18,
    rolloff_m: 1500.0,
};
/// Age of the `plains` surface, Gyr: a young (Eratosthenian) mare flow.
pub const PLAINS_AGE_GYR: f64 = 1.2;
/// Hurst exponent of the `plains` roughness: below the highlands' 0.9, as maria have less
/// long-baseline relief (Rosenburg et al. 2011); the value itself is our choice.
pub const PLAINS_HURST: f64 = 0.8;
/// Largest superposed crater of the `plains`, metres: on a young surface the few large craters
/// are fresh; a window between craters larger than 500 m keeps slope p90 at 3.5–5°.
pub const PLAINS_MAX_CRATER_M: f64 = 500.0;
/// Regional slope of the `plains`, degrees (mare surfaces are nearly level).
pub const PLAINS_REGIONAL_SLOPE_DEG: f64 = 0.0;
/// RMS height difference at 5 m of the `plains` roughness, metres.
pub const PLAINS_NU5_M: f64 = 0.1;
/// Roll-off wavelength of the `plains` roughness, metres.
pub const PLAINS_ROLLOFF_M: f64 = 800.0;
/// Rim diameter of the `fresh` crater, metres.
pub const FRESH_DIAMETER_M: f64 = 2300.0;
/// Rim-to-floor depth of the `fresh` crater, metres (d/D = 0.2, Pike 1977).
pub const FRESH_DEPTH_M: f64 = 460.0;
/// Rim height of the `fresh` crater above the plain, metres (0.036 D, Pike 1977).
pub const FRESH_RIM_HEIGHT_M: f64 = 83.0;
/// Floor diameter of the `fresh` crater, metres: the wall then spans (D − F)/2 = 797 m
/// horizontally for 460 m of rise, a 30° mean slope.
pub const FRESH_FLOOR_DIAMETER_M: f64 = 706.0;
/// Age of the `fresh` crater, Gyr (Copernican: few superposed craters).
pub const FRESH_AGE_GYR: f64 = 0.1;

/// Where the scene window sits in the host crater (presets without one, `lola` and `plains`,
/// give the same scene, centred on the map origin, for every window).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Window {
    /// Centred on the crater centre: the floor (the whole crater if the window is large).
    Floor,
    /// Centred half-way up the wall (east side).
    Wall,
    /// Centred on the rim crest (east side): inner wall, rim and ejecta flank.
    Rim,
}

/// Parameters of one synthetic scene.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TerrainParams {
    /// Scene preset.
    pub preset: Preset,
    /// Window placement.
    pub window: Window,
    /// PRNG seed.
    pub seed: u64,
    /// Side of the square window, metres.
    pub size_m: f64,
    /// Pixel size (ground sample distance), metres.
    pub pixel_m: f64,
}

impl TerrainParams {
    /// Defaults: a 4 km × 4 km window at 5 m (800 × 800), floor window, seed 1.
    pub fn new(preset: Preset) -> Self {
        Self {
            preset,
            window: Window::Floor,
            seed: 1,
            size_m: 4000.0,
            pixel_m: 5.0,
        }
    }
}

/// Physical description of a preset.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct PresetModel {
    /// Host crater shape; `None` for a plain (the map frame's origin is then the window centre).
    pub host: Option<HostCrater>,
    /// Age of the host crater in Gyr when it is younger than the surface around it (`None`: as
    /// old as the surface). Craters older than the host are erased inside its rim and buried
    /// where its ejecta is thicker than their depth; only craters formed since (the density of
    /// a surface of this age) are drawn there, with ages capped by it.
    pub host_age_gyr: Option<f64>,
    /// Age of the surface in Gyr (sets the crater density).
    pub age_gyr: f64,
    /// Factor on the observed crater density `N_obs` below `resolved_d_m` (1 = the published
    /// production/equilibrium model; below 1 for surfaces calibrated on data that resolve fewer
    /// small craters). Applied by thinning the drawn craters.
    pub crater_density: f64,
    /// Diameter in metres from which craters are seen at the full model density: the factor
    /// rises from `crater_density` at `resolved_d_m` to 1 at twice it (smoothstep in log D).
    pub resolved_d_m: f64,
    /// Largest superposed crater drawn, metres (`None`: half the window side). An intercrater
    /// plain is by definition a window chosen between the larger craters.
    pub max_crater_m: Option<f64>,
    /// Regional slope of the surface, degrees (a plane tilt under the scene, downhill azimuth
    /// drawn from the seed); 0 for none.
    pub regional_slope_deg: f64,
    /// Residual roughness.
    pub roughness: Roughness,
}

impl Preset {
    /// The physical model of the preset (see `docs/terrain.md` for sources).
    pub fn model(self) -> PresetModel {
        match self {
            // Zuber et al. 2012 (Nature 486): 21 km rim diameter, 4.2 km deep, ~6.6 km floor,
            // walls ~30–35°. Age ~3.15 Gyr (Tye et al. 2015, Icarus 255).
            Self::Shackleton => PresetModel {
                host: Some(HostCrater {
                    diameter_m: 21_000.0,
                    floor_diameter_m: 6_600.0,
                    depth_m: 4_200.0,
                    rim_height_m: 500.0,
                    floor_bowl_m: 60.0,
                    wall_p: 0.3,
                    terraces: 0,
                }),
                host_age_gyr: None,
                age_gyr: 3.15,
                crater_density: 1.0,
                resolved_d_m: 0.0,
                max_crater_m: None,
                regional_slope_deg: 0.0,
                roughness: Roughness {
                    hurst: 0.9,
                    nu5_m: 0.2,
                    rolloff_m: 800.0,
                },
            },
            // Complex-crater morphometry of Pike (1977) for D = 51 km: depth 1.044 D^0.301 ≈
            // 3.4 km, floor 0.187 D^1.249 ≈ 25 km, rim 0.236 D^0.399 ≈ 1.1 km. Floor age ~4.15 Gyr
            // (Tye et al. 2015).
            Self::Shoemaker => PresetModel {
                host: Some(HostCrater {
                    diameter_m: 51_000.0,
                    floor_diameter_m: 25_500.0,
                    depth_m: 3_400.0,
                    rim_height_m: 1_100.0,
                    floor_bowl_m: 20.0,
                    wall_p: 0.5,
                    terraces: 4,
                }),
                host_age_gyr: None,
                age_gyr: 4.15,
                crater_density: 1.0,
                resolved_d_m: 0.0,
                max_crater_m: None,
                regional_slope_deg: 0.0,
                roughness: Roughness {
                    hurst: 0.9,
                    nu5_m: 0.2,
                    rolloff_m: 800.0,
                },
            },
            Self::Lola => PresetModel {
                host: None,
                host_age_gyr: None,
                age_gyr: LOLA_PLAIN_AGE_GYR,
                crater_density: LOLA_CRATER_DENSITY,
                resolved_d_m: LOLA_RESOLVED_D_M,
                max_crater_m: Some(LOLA_MAX_CRATER_M),
                regional_slope_deg: LOLA_REGIONAL_SLOPE_DEG,
                roughness: LOLA_ROUGHNESS,
            },
            Self::Plains => PresetModel {
                host: None,
                host_age_gyr: None,
                age_gyr: PLAINS_AGE_GYR,
                crater_density: LOLA_CRATER_DENSITY,
                resolved_d_m: LOLA_RESOLVED_D_M,
                max_crater_m: Some(PLAINS_MAX_CRATER_M),
                regional_slope_deg: PLAINS_REGIONAL_SLOPE_DEG,
                roughness: Roughness {
                    hurst: PLAINS_HURST,
                    nu5_m: PLAINS_NU5_M,
                    rolloff_m: PLAINS_ROLLOFF_M,
                },
            },
            // A fresh simple crater: Pike (1977) d/D ≈ 0.196 and rim height ≈ 0.036 D; the floor
            // diameter puts the mean wall slope at 30° (the angle of repose), the steepest at
            // ~34° with the same wall shape as Shackleton.
            Self::Fresh => PresetModel {
                host: Some(HostCrater {
                    diameter_m: FRESH_DIAMETER_M,
                    floor_diameter_m: FRESH_FLOOR_DIAMETER_M,
                    depth_m: FRESH_DEPTH_M,
                    rim_height_m: FRESH_RIM_HEIGHT_M,
                    floor_bowl_m: 15.0,
                    wall_p: 0.3,
                    terraces: 0,
                }),
                host_age_gyr: Some(FRESH_AGE_GYR),
                age_gyr: LOLA_PLAIN_AGE_GYR,
                crater_density: LOLA_CRATER_DENSITY,
                resolved_d_m: LOLA_RESOLVED_D_M,
                max_crater_m: Some(LOLA_MAX_CRATER_M),
                regional_slope_deg: 0.0,
                roughness: LOLA_ROUGHNESS,
            },
        }
    }
}

/// Crater count in one diameter bin: model expectation and what was drawn.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CraterBin {
    /// Lower diameter bound, metres.
    pub d_min_m: f64,
    /// Upper diameter bound, metres.
    pub d_max_m: f64,
    /// Expected count in the window from the SFD model.
    pub model: f64,
    /// Craters drawn with their centre in the window.
    pub drawn: usize,
    /// Of those, craters still fresh (younger than a quarter of their visible life).
    pub fresh: usize,
}

/// What was generated, for reports.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TerrainReport {
    /// Inputs.
    pub params: TerrainParams,
    /// Physical model used.
    pub model: PresetModel,
    /// Window centre in the host-crater frame, metres.
    pub window_centre_m: (f64, f64),
    /// Smallest and largest crater diameters drawn, metres.
    pub crater_range_m: (f64, f64),
    /// Counts per diameter bin (factor-2 bins from the smallest diameter).
    pub crater_bins: Vec<CraterBin>,
}

/// Whether a drawn crater lies where a younger host crater reset the surface: inside its rim
/// (excavated) or under ejecta thicker than the crater's fresh depth (buried). Always false when
/// the host is as old as the surface.
fn reset_by_host(h: &HostCrater, host_age_gyr: f64, c: &sfd::CraterDraw, m: &PresetModel) -> bool {
    if host_age_gyr >= m.age_gyr {
        return false;
    }
    let r_rim = h.diameter_m / 2.0;
    let r = c.x_m.hypot(c.y_m).max(1e-9);
    if r <= r_rim {
        return true;
    }
    let ejecta_m = h.rim_height_m * (r / r_rim).powi(-3);
    ejecta_m > crater::FRESH_D_OVER_D * c.d_m
}

/// Fraction of the model's craters of diameter `d_m` (metres) that the preset shows:
/// `crater_density` up to `resolved_d_m`, rising to 1 at twice it (smoothstep in log₂ D).
fn resolved_share(d_m: f64, m: &PresetModel) -> f64 {
    if m.crater_density >= 1.0 {
        return 1.0;
    }
    let t = if m.resolved_d_m > 0.0 {
        (d_m / m.resolved_d_m).log2().clamp(0.0, 1.0)
    } else {
        1.0
    };
    let s = t * t * (3.0 - 2.0 * t);
    m.crater_density + (1.0 - m.crater_density) * s
}

/// Fraction of the surface population of diameter `d_m` (metres) that formed after a host of
/// age `host_age_gyr`: `N_obs(D, host age) / N_obs(D, surface age)`, in [0, 1].
fn young_share(d_m: f64, host_age_gyr: f64, m: &PresetModel) -> f64 {
    let d_km = d_m / 1000.0;
    let old = sfd::n_observed_per_km2(d_km, m.age_gyr);
    if old <= 0.0 {
        return 0.0;
    }
    (sfd::n_observed_per_km2(d_km, host_age_gyr) / old).clamp(0.0, 1.0)
}

/// Generate a scene. `progress` receives the stage names and a position out of 4 stages.
pub fn generate(
    p: &TerrainParams,
    progress: &ProgressBar,
) -> Result<(Dem, TerrainReport), DemError> {
    generate_with_model(p, &p.preset.model(), progress)
}

/// Generate a scene from an explicit physical model (calibration studies); `p.preset` still
/// seeds the PRNG streams and names the scene. [`generate`] uses `p.preset.model()`.
pub fn generate_with_model(
    p: &TerrainParams,
    model: &PresetModel,
    progress: &ProgressBar,
) -> Result<(Dem, TerrainReport), DemError> {
    let model = *model;
    if !(p.pixel_m.is_finite() && p.pixel_m > 0.0 && p.size_m.is_finite() && p.size_m > 0.0) {
        return Err(DemError::Invalid(format!(
            "size {} m and pixel {} m must be finite and > 0",
            p.size_m, p.pixel_m
        )));
    }
    let n = (p.size_m / p.pixel_m).round();
    if !(MIN_SIDE_PX as f64..=MAX_SIDE_PX as f64).contains(&n) {
        return Err(DemError::Invalid(format!(
            "{} m at {} m/px is {n} px; the side must be {MIN_SIDE_PX}..={MAX_SIDE_PX} px",
            p.size_m, p.pixel_m
        )));
    }
    let n = n as usize;
    let side_m = n as f64 * p.pixel_m;
    // Without a host crater every window is centred on the origin.
    let centre_x = match (p.window, model.host) {
        (_, None) | (Window::Floor, _) => 0.0,
        (Window::Wall, Some(h)) => (h.floor_diameter_m + h.diameter_m) / 4.0,
        (Window::Rim, Some(h)) => h.diameter_m / 2.0,
    };
    let (cx, cy) = (centre_x, 0.0);
    let x0 = cx - side_m / 2.0;
    let y_top = cy + side_m / 2.0;
    let px = p.pixel_m;

    progress.set_length(4);
    progress.set_position(0);

    // Independent streams per component (and per preset, so that two presets with one seed do
    // not share a crater layout); changing one model leaves the others' numbers unchanged.
    let seed = p.seed ^ (p.preset as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    let mut rng_rim = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x5249_4d00);
    let modes: Vec<(f64, f64, f64)> = [(0.015, 2.0), (0.010, 3.0), (0.006, 5.0), (0.004, 7.0)]
        .into_iter()
        .map(|(a, k)| (a, k, std::f64::consts::TAU * rng_rim.random::<f64>()))
        .collect();
    let host = model.host.map(|h| HostProfile::new(h, modes));
    // A regional tilt (own stream), added only when present so tilt-free presets are unchanged.
    let tilt = (model.regional_slope_deg != 0.0).then(|| {
        let mut rng_t = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x5449_4c54);
        let az = std::f64::consts::TAU * rng_t.random::<f64>();
        let g = model.regional_slope_deg.to_radians().tan();
        (g * az.cos(), g * az.sin())
    });
    let host_height = |x: f64, y: f64| {
        let h = host.as_ref().map_or(0.0, |h| h.height_m(x, y));
        match tilt {
            Some((gx, gy)) => h - gx * x - gy * y,
            None => h,
        }
    };

    progress.set_message("fractal roughness");
    let rough = fractal_field(n, n, px, &model.roughness, seed ^ 0x524f_5547);
    progress.inc(1);

    progress.set_message("host crater");
    let mut z = vec![0.0f32; n * n];
    z.par_chunks_mut(n).enumerate().for_each(|(r, row)| {
        let y = y_top - (r as f64 + 0.5) * px;
        for (c, v) in row.iter_mut().enumerate() {
            let x = x0 + (c as f64 + 0.5) * px;
            *v = host_height(x, y) as f32 + rough[r * n + c];
        }
    });
    progress.inc(1);

    progress.set_message("drawing craters");
    let d_min = (MIN_CRATER_PX * px).max(MIN_CRATER_M);
    let d_max = match model.max_crater_m {
        Some(m) => (side_m / 2.0).min(m).max(2.0 * d_min),
        None => (side_m / 2.0).max(2.0 * d_min),
    };
    let margin = d_max / 2.0 * crater::EJECTA_OUTER_R * 1.5;
    let mut rng_c = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x4352_4154);
    let draws = draw_craters(
        &mut rng_c,
        x0 - margin,
        y_top - side_m - margin,
        side_m + 2.0 * margin,
        d_min,
        d_max,
        model.age_gyr,
    );
    let tan30 = 30f64.to_radians().tan();
    // Share of the model's craters like `c` that the preset shows (resolution, young host).
    let shown_share = |c: &sfd::CraterDraw| -> f64 {
        let young_part = match model.host.zip(model.host_age_gyr) {
            Some((h, t_host)) if reset_by_host(&h, t_host, c, &model) => {
                young_share(c.d_m, t_host, &model)
            }
            _ => 1.0,
        };
        young_part * resolved_share(c.d_m, &model)
    };
    let age_myr = sfd::flux_equivalent_age_gyr(model.age_gyr) * 1000.0;
    // A host younger than the surface: craters it erased (inside its rim) or buried (under ejecta
    // thicker than their fresh depth) are replaced by the younger population, whose share of the
    // drawn one is N_young / N_surface at the crater's diameter.
    let young = model.host.zip(model.host_age_gyr);
    let host_age_myr = young.map(|(_, t)| sfd::flux_equivalent_age_gyr(t) * 1000.0);
    let stamps: Vec<Option<CraterStamp>> = draws
        .par_iter()
        .map(|c| {
            let reach =
                c.d_m / 2.0 * (crater::EJECTA_OUTER_R + 3.0 * crater::SIGMA_VISIBLE_R + 0.5);
            let outside = c.x_m + reach < x0
                || c.x_m - reach > x0 + side_m
                || c.y_m + reach < y_top - side_m
                || c.y_m - reach > y_top;
            if outside {
                return None;
            }
            // Mass wasting on steep host walls keeps them fresh: craters there degrade faster,
            // so fewer are visible at once (count ∝ lifetime ∝ 1/κ).
            let s = host
                .as_ref()
                .map_or(0.0, |h| h.slope_deg(c.x_m, c.y_m, c.d_m.max(px)))
                .to_radians()
                .tan()
                / tan30;
            let kappa_factor = 1.0 + 4.0 * s * s;
            let cap_myr = match (young, host_age_myr) {
                (Some((h, t_host)), Some(host_myr)) if reset_by_host(&h, t_host, c, &model) => {
                    host_myr.min(age_myr)
                }
                _ => age_myr,
            };
            let keep = shown_share(c);
            if c.u_keep * kappa_factor > keep {
                return None;
            }
            Some(make_stamp(c, kappa_factor, cap_myr))
        })
        .collect();
    progress.inc(1);

    progress.set_message("stamping craters");
    let bands = n.div_ceil(BAND_ROWS);
    let mut per_band: Vec<Vec<usize>> = vec![Vec::new(); bands];
    for (i, s) in stamps.iter().enumerate() {
        let Some(s) = s else { continue };
        let f = s.footprint_m();
        let r_lo = ((y_top - (s.y_m + f)) / px - 0.5).floor().max(0.0) as usize;
        let r_hi = ((y_top - (s.y_m - f)) / px - 0.5).ceil().max(0.0) as usize;
        if r_lo >= n {
            continue;
        }
        for b in per_band
            .iter_mut()
            .take((r_hi.min(n - 1)) / BAND_ROWS + 1)
            .skip(r_lo / BAND_ROWS)
        {
            b.push(i);
        }
    }
    z.par_chunks_mut(n * BAND_ROWS)
        .zip(per_band.par_iter())
        .enumerate()
        .for_each(|(b, (rows, list))| {
            let r0 = b * BAND_ROWS;
            for &i in list {
                let Some(Some(s)) = stamps.get(i) else {
                    continue;
                };
                let f = s.footprint_m();
                let c_lo = ((s.x_m - f - x0) / px - 0.5).floor().max(0.0) as usize;
                let c_hi = (((s.x_m + f - x0) / px - 0.5).ceil().max(0.0) as usize).min(n - 1);
                for (rr, row) in rows.chunks_mut(n).enumerate() {
                    let y = y_top - ((r0 + rr) as f64 + 0.5) * px;
                    let dy = y - s.y_m;
                    if dy.abs() > f {
                        continue;
                    }
                    for c in c_lo..=c_hi {
                        let dx = x0 + (c as f64 + 0.5) * px - s.x_m;
                        if let Some(v) = row.get_mut(c) {
                            *v += s.at((dx * dx + dy * dy).sqrt());
                        }
                    }
                }
            }
        });
    progress.inc(1);

    // Counts per factor-2 diameter bin for craters centred in the window.
    let area_km2 = (side_m / 1000.0).powi(2);
    let mut crater_bins = Vec::new();
    let mut lo = d_min;
    while lo < d_max {
        let hi = (lo * 2.0).min(d_max);
        let model_n = (sfd::n_observed_per_km2(lo / 1000.0, model.age_gyr)
            - sfd::n_observed_per_km2(hi / 1000.0, model.age_gyr))
            * area_km2
            * resolved_share((lo * hi).sqrt(), &model);
        let inside = |c: &sfd::CraterDraw| {
            c.u_keep <= shown_share(c)
                && c.d_m >= lo
                && c.d_m < hi
                && (x0..x0 + side_m).contains(&c.x_m)
                && (y_top - side_m..y_top).contains(&c.y_m)
        };
        let drawn = draws.iter().filter(|c| inside(c)).count();
        let fresh = draws.iter().filter(|c| inside(c) && c.u_age < 0.25).count();
        crater_bins.push(CraterBin {
            d_min_m: lo,
            d_max_m: hi,
            model: model_n,
            drawn,
            fresh,
        });
        lo = hi;
    }

    let centred_on = if model.host.is_some() {
        "the host crater"
    } else {
        "the scene"
    };
    let citation = format!(
        "Umbra synthetic {:?} terrain, seed {}, local metric grid centred on {centred_on}",
        p.preset, p.seed
    );
    let geo = GeoRef::local(x0, y_top, px, &citation);
    let dem = Dem::new(n, n, z, geo)?;
    let report = TerrainReport {
        params: *p,
        model,
        window_centre_m: (cx, cy),
        crater_range_m: (d_min, d_max),
        crater_bins,
    };
    Ok((dem, report))
}
