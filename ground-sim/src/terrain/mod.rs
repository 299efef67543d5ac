//! Built-in synthetic lunar terrain for permanently shadowed crater floors.
//!
//! A scene is the sum of three parts, evaluated on a north-up grid whose map frame has the host
//! crater's centre at (0, 0) m, x east, y north:
//! 1. the host crater ([`crater::HostProfile`]): Shackleton (simple, ~21 km) or Shoemaker
//!    (complex, ~51 km, flat floor, terraced walls), with a slightly irregular rim;
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
}

/// Where the scene window sits in the host crater.
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
    /// Host crater shape.
    pub host: HostCrater,
    /// Age of the surface in Gyr (sets the crater density).
    pub age_gyr: f64,
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
                host: HostCrater {
                    diameter_m: 21_000.0,
                    floor_diameter_m: 6_600.0,
                    depth_m: 4_200.0,
                    rim_height_m: 500.0,
                    floor_bowl_m: 60.0,
                    wall_p: 0.3,
                    terraces: 0,
                },
                age_gyr: 3.15,
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
                host: HostCrater {
                    diameter_m: 51_000.0,
                    floor_diameter_m: 25_500.0,
                    depth_m: 3_400.0,
                    rim_height_m: 1_100.0,
                    floor_bowl_m: 20.0,
                    wall_p: 0.5,
                    terraces: 4,
                },
                age_gyr: 4.15,
                roughness: Roughness {
                    hurst: 0.9,
                    nu5_m: 0.2,
                    rolloff_m: 800.0,
                },
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

/// Generate a scene. `progress` receives the stage names and a position out of 4 stages.
pub fn generate(
    p: &TerrainParams,
    progress: &ProgressBar,
) -> Result<(Dem, TerrainReport), DemError> {
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
    let model = p.preset.model();
    let host_c = model.host;
    let centre_x = match p.window {
        Window::Floor => 0.0,
        Window::Wall => (host_c.floor_diameter_m + host_c.diameter_m) / 4.0,
        Window::Rim => host_c.diameter_m / 2.0,
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
    let host = HostProfile::new(host_c, modes);

    progress.set_message("fractal roughness");
    let rough = fractal_field(n, n, px, &model.roughness, seed ^ 0x524f_5547);
    progress.inc(1);

    progress.set_message("host crater");
    let mut z = vec![0.0f32; n * n];
    z.par_chunks_mut(n).enumerate().for_each(|(r, row)| {
        let y = y_top - (r as f64 + 0.5) * px;
        for (c, v) in row.iter_mut().enumerate() {
            let x = x0 + (c as f64 + 0.5) * px;
            *v = host.height_m(x, y) as f32 + rough[r * n + c];
        }
    });
    progress.inc(1);

    progress.set_message("drawing craters");
    let d_min = (MIN_CRATER_PX * px).max(MIN_CRATER_M);
    let d_max = (side_m / 2.0).max(2.0 * d_min);
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
    let age_myr = sfd::flux_equivalent_age_gyr(model.age_gyr) * 1000.0;
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
                .slope_deg(c.x_m, c.y_m, c.d_m.max(px))
                .to_radians()
                .tan()
                / tan30;
            let kappa_factor = 1.0 + 4.0 * s * s;
            if c.u_keep * kappa_factor > 1.0 {
                return None;
            }
            Some(make_stamp(c, kappa_factor, age_myr))
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
            * area_km2;
        let inside = |c: &sfd::CraterDraw| {
            c.d_m >= lo
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

    let citation = format!(
        "Umbra synthetic {:?} terrain, seed {}, local metric grid centred on the host crater",
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
