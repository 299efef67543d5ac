//! Landing-zone truth terrain: a fine DEM around a landing target with the detail that matters
//! at a lander's scale — rocks, small craters and sub-metre roughness — and the truth safety
//! tools that score a touchdown on it.
//!
//! Descents fly over maps of 10–20 m per pixel; below ~2 km the flyer's ranging frames get finer
//! than that (pixel = AGL × 2.63e-3 rad, 0.5 m at 190 m AGL). A landing zone is a square, north-up
//! grid (default 512 m at 0.25 m, 2048²) in the coarse DEM's own map frame (metres, x east,
//! y north, same CRS keys) whose heights are
//!
//! ```text
//! z(x, y) = coarse(x, y) + w(x, y) · [ roughness + small craters + rocks ](x, y)
//! ```
//!
//! - `coarse`: the coarse DEM, bilinearly interpolated between its pixel centres
//!   ([`crate::flyer::frames::height_at_geo`]).
//! - `[…]`, the detail, is high-passed before it is added: its Gaussian low-pass at the coarse
//!   pixel (σ = one coarse pixel; [`remove_coarse_scale`]) is taken out, so that the zone refines
//!   the coarse DEM without changing it at the coarse DEM's own scale. Without that, the craters'
//!   net bowls left the zone 0.39 m lower on average with 0.37 m RMS over 20 m blocks (Shoemaker
//!   16 km map, seed 4): ground that no map made from the coarse DEM shows, and which biased
//!   every TRN fix of the descent's last minute by up to 1.5 m, growing as the frames shrank
//!   onto the zone (docs/registration.md, "Landing zones and the map").
//! - `w`: the taper, a smoothstep from 0 on the outermost pixel centres to 1 at `taper_m` inside
//!   them, so that the zone's border equals the interpolated coarse DEM exactly (no seam).
//! - roughness: a self-affine field ([`fractal_field`]) continuing the coarse scene's law
//!   `ν(L) = ν5 (L / 5 m)^H` (Rosenburg et al. 2011) down to the fine pixel; H ≈ 0.9 is the
//!   median Hurst exponent that LROC NAC DTMs show at metre to hectometre baselines in maria and
//!   highlands alike (Cai & Fa 2020, JGR Planets, doi:10.1029/2020JE006429). The spectrum rolls
//!   off at twice the coarse pixel or more: longer wavelengths are already in the coarse DEM.
//! - small craters: diameters from [`LandingZoneConfig::crater_d_min_m`] (1 m) up to the smallest
//!   crater the coarse scene draws (3 coarse pixels, at least 10 m; [`super::MIN_CRATER_PX`],
//!   [`super::MIN_CRATER_M`]), so that the two populations join. Below 10 m the Neukum
//!   production function is not defined; small lunar craters there are in the empirical
//!   equilibrium (steady state) `N(>D) = 10^-1.1 D^-2` per km², D in km (Trask 1966,
//!   [`sfd::n_equilibrium_per_km2`]), which Surveyor 7 saw from 13 cm to 3 m as at the mare
//!   Surveyor sites (Shoemaker et al. 1969, JGR 74, 6081). Shapes are [`crater::make_stamp`]'s:
//!   Pike's fresh morphometry smoothed by diffusion, each crater at a uniform fraction of its
//!   visible life (the steady-state spread from fresh to barely visible; the shapes do not
//!   depend on κ, since σ = 1.5 R √u).
//! - rocks: the Golombek & Rapp (1997, JGR 102, doi:10.1029/96JE03319) model: the cumulative
//!   fractional area covered by rocks of diameter ≥ D is `F_k(D) = k exp(−q(k) D)`,
//!   `q(k) = 1.79 + 0.152 / k` (D in metres); each rock is a half-ellipsoid of diameter D and
//!   height `rock_height_ratio·D`.
//!   Overlapping rocks merge (the higher one shows) and sit on the cratered, rough surface.
//!   See [`DEFAULT_ROCK_K`] for the choice of k.
//!
//! Numbers and sources are written up in `docs/terrain.md` ("Landing zones").
//!
//! Determinism: every random number comes from PCG64 streams seeded from `seed` (one stream per
//! component), drawn sequentially; parallel loops only do per-pixel work, per-site work or add
//! stamps in fixed row bands in a fixed order (rocks by a maximum, which is order-free), so a
//! zone is bit-identical for a seed whatever the thread count.

use std::f64::consts::PI;

use rand::{RngExt, SeedableRng};
use rayon::prelude::*;

use super::crater::{self, CraterStamp, make_stamp};
use super::roughness::{Roughness, fractal_field};
use super::sfd::{self, CraterDraw, std_normal};
use super::{CraterBin, MIN_CRATER_M, MIN_CRATER_PX};
use crate::dem::{Dem, DemError, GeoRef, GeoTransform};
use crate::flyer::frames::height_at_geo;

/// Largest landing-zone side in pixels (8192² f32 heights are 256 MiB).
pub const MAX_ZONE_SIDE_PX: usize = 8192;
/// Smallest landing-zone side in pixels.
pub const MIN_ZONE_SIDE_PX: usize = 16;
/// Constant term of Golombek & Rapp's (1997) `q(k) = 1.79 + 0.152 / k`, per metre.
pub const ROCK_Q0_PER_M: f64 = 1.79;
/// Coefficient of `1 / k` in Golombek & Rapp's (1997) `q(k)`, per metre.
pub const ROCK_Q1_PER_M: f64 = 0.152;
/// Default rock abundance k of the Golombek & Rapp model (0.08): chosen so that the model's
/// cumulative fractional area of rocks ≥ 1 m, `F_k(1 m) = 0.08 e^{-3.69} = 0.20 %`, equals the
/// rock abundance measured in situ on the old floor of Von Kármán crater at Chang'E-4 (0.21 %,
/// Wu et al. 2021, EPSL 553, 116666, consistent with orbital data). That figure counts every rock
/// from decimetres up, so it bounds the metre-sized ones from above: the choice is conservative
/// (rockier) for landing safety, and old, regolith-mantled PSR floors are if anything less rocky
/// (rock abundance falls with surface age: Bandfield et al. 2011, JGR 116,
/// doi:10.1029/2011JE003866; Vanga et al. 2022, GRL, doi:10.1029/2021GL096710). `q(k)` was
/// fitted on Mars and Earth; at a literal lunar k of ~0.002 it would put all rock area below
/// ~5 cm, which is not what lunar sites show, so k here is an equivalent k for the hazard sizes:
/// it over-states 0.25–1 m rocks (3.2 % of the area is covered by rocks ≥ 0.25 m).
pub const DEFAULT_ROCK_K: f64 = 0.08;
/// Default width of the border band over which the added detail fades out, metres.
pub const DEFAULT_TAPER_M: f64 = 32.0;
/// Rows per band when stamping craters and rocks in parallel.
const BAND_ROWS: usize = 16;
/// Steps of the rock-diameter inverse-CDF table (log-spaced).
const ROCK_TABLE_STEPS: usize = 512;
/// PRNG stream constants (mixed into the seed), one per component.
const STREAM_ROUGHNESS: u64 = 0x4c5a_5247_4855_4f52;
const STREAM_CRATERS: u64 = 0x4c5a_4352_4154_4552;
const STREAM_ROCKS: u64 = 0x4c5a_524f_434b_5321;

/// Parameters of a landing zone. Lengths in metres.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct LandingZoneConfig {
    /// Side of the square zone, metres (rounded to a whole number of pixels).
    pub side_m: f64,
    /// Pixel size (ground sample distance), metres.
    pub pixel_m: f64,
    /// Width of the border band over which the added detail fades from full to zero, metres
    /// (0: no fade; must leave an interior: `2 · taper_m < side_m`).
    pub taper_m: f64,
    /// Sub-metre roughness: Hurst exponent H, RMS height difference ν5 at a 5 m baseline
    /// (scaled to the fine pixel as `ν5 (pixel / 5 m)^H`), and the roll-off wavelength, which is
    /// raised to twice the coarse pixel if smaller (the coarse DEM holds the longer wavelengths).
    /// Default H = 0.9, ν5 = 0.2 m (the crater-floor presets' values, Rosenburg et al. 2011;
    /// H ≈ 0.9 holds down to metre baselines, Cai & Fa 2020), roll-off 0 (= twice the coarse
    /// pixel). ν5 = 0 turns roughness off.
    pub roughness: Roughness,
    /// Smallest crater drawn, metres (default 1 m: 4 pixels at 0.25 m; smaller pits are left to
    /// the roughness).
    pub crater_d_min_m: f64,
    /// Largest crater drawn, metres; `None` (default): the coarse scene's smallest crater,
    /// `max(3 coarse pixels, 10 m)`, so that the two populations join.
    pub crater_d_max_m: Option<f64>,
    /// Factor on the equilibrium crater density (1 = Trask's equilibrium; 0 turns craters off).
    pub crater_density: f64,
    /// Rock abundance k of the Golombek & Rapp model (total fractional area of all rocks; 0 turns
    /// rocks off). Default [`DEFAULT_ROCK_K`].
    pub rock_k: f64,
    /// Smallest rock drawn, metres (default 0.25 m).
    pub rock_d_min_m: f64,
    /// Largest rock drawn, metres (default 4 m; `F_k` beyond it is ~1e-8 at the default k).
    pub rock_d_max_m: f64,
    /// Rock height over diameter (default 0.5: a hemisphere). Golombek & Rapp (1997) derived
    /// linear height–diameter relations from the Viking lander rocks, heights of about half the
    /// diameter; we use that ratio for lunar rocks too (an assumption).
    pub rock_height_ratio: f64,
}

impl Default for LandingZoneConfig {
    fn default() -> Self {
        Self {
            side_m: 512.0,
            pixel_m: 0.25,
            taper_m: DEFAULT_TAPER_M,
            roughness: Roughness {
                hurst: 0.9,
                nu5_m: 0.2,
                rolloff_m: 0.0,
            },
            crater_d_min_m: 1.0,
            crater_d_max_m: None,
            crater_density: 1.0,
            rock_k: DEFAULT_ROCK_K,
            rock_d_min_m: 0.25,
            rock_d_max_m: 4.0,
            rock_height_ratio: 0.5,
        }
    }
}

/// Rocks of one size class: model and drawn cumulative fractional area.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RockBin {
    /// Diameter threshold D, metres: the bin holds rocks of diameter ≥ D (up to the largest
    /// drawn).
    pub d_min_m: f64,
    /// Model fractional area `F_k(D) − F_k(D_max)`.
    pub model_area_frac: f64,
    /// Fractional area of the drawn rocks (centred in the zone) of diameter ≥ D: their summed
    /// disc areas over the zone's area.
    pub drawn_area_frac: f64,
    /// Number of drawn rocks (centred in the zone) of diameter ≥ D.
    pub drawn: usize,
    /// Model number of rocks in the zone of diameter ≥ D.
    pub model_count: f64,
}

/// What a landing zone holds, for reports and tests.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LandingZoneReport {
    /// The configuration used.
    pub config: LandingZoneConfig,
    /// PRNG seed.
    pub seed: u64,
    /// Zone centre in the coarse DEM's map frame, metres (x east, y north).
    pub centre_m: [f64; 2],
    /// Side in pixels.
    pub side_px: usize,
    /// Side in metres (`side_px · pixel_m`).
    pub side_m: f64,
    /// Pixel size of the coarse DEM, metres.
    pub coarse_pixel_m: f64,
    /// Roughness actually used (roll-off raised to twice the coarse pixel if smaller).
    pub roughness: Roughness,
    /// Diameter range of the craters drawn, metres.
    pub crater_range_m: (f64, f64),
    /// Expected number of craters centred in the zone.
    pub craters_expected: f64,
    /// Craters drawn with their centre in the zone.
    pub craters_drawn: usize,
    /// Counts per factor-2 diameter bin (craters centred in the zone); `fresh` = younger than a
    /// quarter of their visible life.
    pub crater_bins: Vec<CraterBin>,
    /// Mean rim-to-floor depth over diameter of the craters centred in the zone.
    pub crater_mean_depth_over_d: f64,
    /// Golombek & Rapp `q(k)`, per metre.
    pub rock_q_per_m: f64,
    /// Expected number of rocks centred in the zone.
    pub rocks_expected: f64,
    /// Rocks drawn with their centre in the zone.
    pub rocks_drawn: usize,
    /// Rocks higher than 0.3 m (with their centre in the zone).
    pub rocks_over_0_3m_high: usize,
    /// Cumulative fractional area, model and drawn, at a few diameters.
    pub rock_bins: Vec<RockBin>,
}

/// Golombek & Rapp's `q(k) = 1.79 + 0.152 / k`, per metre (`k > 0`).
pub fn rock_q_per_m(k: f64) -> f64 {
    ROCK_Q0_PER_M + ROCK_Q1_PER_M / k
}

/// Cumulative fractional area covered by rocks of diameter ≥ `d_m` metres, `F_k(D) = k e^{−q D}`
/// (0 for `k ≤ 0`).
pub fn rock_area_fraction(k: f64, d_m: f64) -> f64 {
    if !(k > 0.0) {
        return 0.0;
    }
    k * (-rock_q_per_m(k) * d_m).exp()
}

/// Number density of rocks per m² of ground per metre of diameter at `d_m`:
/// `n(D) = −F_k'(D) / (π D² / 4) = 4 k q e^{−q D} / (π D²)`.
pub fn rock_number_density(k: f64, d_m: f64) -> f64 {
    if !(k > 0.0 && d_m > 0.0) {
        return 0.0;
    }
    let q = rock_q_per_m(k);
    4.0 * k * q * (-q * d_m).exp() / (PI * d_m * d_m)
}

/// Rocks per m² with a diameter in `[d_lo_m, d_hi_m]` (numerical integral of
/// [`rock_number_density`]).
pub fn rock_count_per_m2(k: f64, d_lo_m: f64, d_hi_m: f64) -> f64 {
    if !(d_hi_m > d_lo_m && d_lo_m > 0.0) {
        return 0.0;
    }
    RockTable::new(k, d_lo_m, d_hi_m).total()
}

/// Inverse-CDF table of rock diameters: `cum[i]` = rocks per m² with D in `[d_i, d_max]`, on a
/// log-spaced grid (trapezoids in ln D).
struct RockTable {
    log_d: Vec<f64>,
    cum: Vec<f64>,
}

impl RockTable {
    fn new(k: f64, d_lo: f64, d_hi: f64) -> Self {
        let (l0, l1) = (d_lo.ln(), d_hi.ln());
        let log_d: Vec<f64> = (0..=ROCK_TABLE_STEPS)
            .map(|i| l0 + (l1 - l0) * i as f64 / ROCK_TABLE_STEPS as f64)
            .collect();
        // Density per unit ln D.
        let f: Vec<f64> = log_d
            .iter()
            .map(|&l| rock_number_density(k, l.exp()) * l.exp())
            .collect();
        let mut cum = vec![0.0; ROCK_TABLE_STEPS + 1];
        for i in (0..ROCK_TABLE_STEPS).rev() {
            cum[i] = cum[i + 1] + 0.5 * (f[i] + f[i + 1]) * (log_d[i + 1] - log_d[i]);
        }
        Self { log_d, cum }
    }

    fn total(&self) -> f64 {
        self.cum.first().copied().unwrap_or(0.0)
    }

    /// Diameter (metres) with a share `u` of the rocks at or above it.
    fn sample(&self, u: f64) -> f64 {
        sfd::invert_descending(&self.cum, &self.log_d, u * self.total()).exp()
    }
}

/// A drawn rock (map metres).
#[derive(Debug, Clone, Copy)]
struct Rock {
    x_m: f64,
    y_m: f64,
    d_m: f64,
}

/// Poisson-distributed count with mean `lambda` (multiplication method below 30, rounded normal
/// above: determinism matters more than the exact tail).
fn poisson<R: rand::Rng>(rng: &mut R, lambda: f64) -> usize {
    if !(lambda > 0.0) {
        return 0;
    }
    if lambda < 30.0 {
        let limit = (-lambda).exp();
        let mut p = 1.0;
        let mut k = 0usize;
        loop {
            p *= rng.random::<f64>();
            if p <= limit {
                return k;
            }
            k += 1;
        }
    }
    (lambda + lambda.sqrt() * std_normal(rng)).round().max(0.0) as usize
}

/// Smoothstep `3t² − 2t³` of `t` clamped to [0, 1].
fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn invalid(msg: String) -> DemError {
    DemError::Invalid(msg)
}

/// Check the configuration; returns the side in pixels.
fn check_config(cfg: &LandingZoneConfig, centre_m: [f64; 2]) -> Result<usize, DemError> {
    let pos = |v: f64| v.is_finite() && v > 0.0;
    let non_neg = |v: f64| v.is_finite() && v >= 0.0;
    if !(pos(cfg.side_m) && pos(cfg.pixel_m)) {
        return Err(invalid(format!(
            "landing zone side {} m and pixel {} m must be finite and > 0",
            cfg.side_m, cfg.pixel_m
        )));
    }
    if !(centre_m[0].is_finite() && centre_m[1].is_finite()) {
        return Err(invalid(format!(
            "landing zone centre {centre_m:?} m is not finite"
        )));
    }
    let n = (cfg.side_m / cfg.pixel_m).round();
    if !(MIN_ZONE_SIDE_PX as f64..=MAX_ZONE_SIDE_PX as f64).contains(&n) {
        return Err(invalid(format!(
            "landing zone of {} m at {} m/px is {n} px a side; it must be \
             {MIN_ZONE_SIDE_PX}..={MAX_ZONE_SIDE_PX} px",
            cfg.side_m, cfg.pixel_m
        )));
    }
    let side = n * cfg.pixel_m;
    if !(non_neg(cfg.taper_m) && 2.0 * cfg.taper_m < side) {
        return Err(invalid(format!(
            "taper {} m must be >= 0 and leave an interior in a {side} m zone (2 x taper < side)",
            cfg.taper_m
        )));
    }
    let r = &cfg.roughness;
    if !(pos(r.hurst) && r.hurst <= 1.0 && non_neg(r.nu5_m) && non_neg(r.rolloff_m)) {
        return Err(invalid(format!(
            "roughness needs 0 < H <= 1, nu5 >= 0 and roll-off >= 0 (got {r:?})"
        )));
    }
    if !(pos(cfg.crater_d_min_m) && non_neg(cfg.crater_density)) {
        return Err(invalid(format!(
            "smallest crater {} m must be > 0 and the crater density factor {} >= 0",
            cfg.crater_d_min_m, cfg.crater_density
        )));
    }
    if let Some(d) = cfg.crater_d_max_m
        && !(d.is_finite() && d > cfg.crater_d_min_m)
    {
        return Err(invalid(format!(
            "largest crater {d} m must be finite and above the smallest ({} m)",
            cfg.crater_d_min_m
        )));
    }
    if !(non_neg(cfg.rock_k) && non_neg(cfg.rock_height_ratio)) {
        return Err(invalid(format!(
            "rock abundance k {} and height ratio {} must be finite and >= 0",
            cfg.rock_k, cfg.rock_height_ratio
        )));
    }
    let rock_sizes_ok = pos(cfg.rock_d_min_m)
        && cfg.rock_d_max_m.is_finite()
        && cfg.rock_d_max_m > cfg.rock_d_min_m;
    if cfg.rock_k > 0.0 && !rock_sizes_ok {
        return Err(invalid(format!(
            "rock diameters {}..{} m must be finite, > 0 and increasing",
            cfg.rock_d_min_m, cfg.rock_d_max_m
        )));
    }
    Ok(n as usize)
}

/// Heights below this (metres) are not stamped: 0.1 mm, below f32 resolution at lunar heights
/// of ~1 km.
const STAMP_FLOOR_M: f32 = 1e-4;

/// Radius (metres) beyond which a crater stamp's table stays below [`STAMP_FLOOR_M`].
fn effective_reach_m(s: &CraterStamp) -> f64 {
    let last = s.lut.iter().rposition(|v| v.abs() >= STAMP_FLOOR_M);
    match (last, s.lut.len()) {
        (Some(i), len) if len > 1 => {
            s.footprint_m() * ((i + 1).min(len - 1)) as f64 / (len - 1) as f64
        }
        _ => 0.0,
    }
}

/// Rows `lo..=hi` of an `n`-row north-up grid (top edge `y_top`, pixel `px`) whose centres lie
/// within `reach` metres of `y`; `None` if none.
fn row_span(y: f64, reach: f64, y_top: f64, px: f64, n: usize) -> Option<(usize, usize)> {
    let lo = ((y_top - (y + reach)) / px - 0.5).ceil();
    let hi = ((y_top - (y - reach)) / px - 0.5).floor();
    if hi < 0.0 || lo > (n - 1) as f64 || hi < lo {
        return None;
    }
    Some((lo.max(0.0) as usize, (hi as usize).min(n - 1)))
}

/// Per-band lists of item indices, items given as (centre y, reach) in metres.
fn band_lists(
    items: impl Iterator<Item = (f64, f64)>,
    y_top: f64,
    px: f64,
    n: usize,
) -> Vec<Vec<usize>> {
    let mut bands: Vec<Vec<usize>> = vec![Vec::new(); n.div_ceil(BAND_ROWS)];
    for (i, (y, reach)) in items.enumerate() {
        if let Some((lo, hi)) = row_span(y, reach, y_top, px, n) {
            for b in bands
                .iter_mut()
                .take(hi / BAND_ROWS + 1)
                .skip(lo / BAND_ROWS)
            {
                b.push(i);
            }
        }
    }
    bands
}

/// Generate a landing zone centred on `centre_m` (metres in `coarse`'s map frame, x east,
/// y north). See the module documentation for the model; [`landing_zone_with_report`] also
/// returns what was drawn.
///
/// Errors ([`DemError::Invalid`] unless noted): non-finite or non-positive sizes, a side outside
/// [`MIN_ZONE_SIDE_PX`]`..=`[`MAX_ZONE_SIDE_PX`] pixels, a taper that leaves no interior, bad
/// model parameters, a zone not inside the coarse DEM's pixel-centre extent;
/// [`DemError::Unsupported`] for a rotated or non-square coarse grid.
pub fn landing_zone(
    coarse: &Dem,
    centre_m: [f64; 2],
    cfg: &LandingZoneConfig,
    seed: u64,
) -> Result<Dem, DemError> {
    landing_zone_with_report(coarse, centre_m, cfg, seed).map(|(dem, _)| dem)
}

/// Take out of an `n`×`n` row-major field its low-pass at a Gaussian of `sigma_px` pixels (three
/// passes of a box mean per axis, of half-width `h` with `h(h + 1) ≈ σ²` so that their
/// variances add to σ²), leaving the field's short wavelengths: the kept fraction is
/// `1 − exp(−2π²σ²/λ²)`, 0.9 at λ ≈ 2.9σ, 0.5 at λ ≈ 5.3σ. Near the border the box mean is over
/// the pixels inside (renormalised), so no false low-pass leaks in from outside; the passes
/// reach 3h pixels in, which the zone's taper covers on 10 m maps (30 m against 32 m) but not
/// on coarser ones. Deterministic: each pass is a fixed-order running sum per row or column.
/// Not [`crate::insar::pipeline::gaussian_filter`] (an exact kernel cut at 3σ, one thread): at
/// σ = 40 zone pixels that is 241 taps per pixel and pass, ~2·10⁹ multiply-adds per 2048² zone
/// and every descent run makes one; this costs 0.1–0.2 s (zone 1.16–1.20 s → 1.34–1.42 s).
pub fn remove_coarse_scale(field: &mut [f32], n: usize, sigma_px: f64) {
    if n == 0 || field.len() != n * n || !(sigma_px.is_finite() && sigma_px > 0.0) {
        return;
    }
    // Three boxes of half-width h: variance 3·((2h+1)² − 1)/12 = h(h+1) ≈ σ².
    let h = ((0.25 + sigma_px * sigma_px).sqrt() - 0.5).round().max(1.0) as usize;
    let mut low: Vec<f64> = field.iter().map(|&v| f64::from(v)).collect();
    let box_rows = |buf: &mut [f64]| {
        buf.par_chunks_mut(n).for_each(|row| {
            let mut prefix = Vec::with_capacity(n + 1);
            prefix.push(0.0f64);
            for &v in row.iter() {
                prefix.push(prefix.last().copied().unwrap_or(0.0) + v);
            }
            for (i, v) in row.iter_mut().enumerate() {
                let lo = i.saturating_sub(h);
                let hi = (i + h + 1).min(n);
                let sum =
                    prefix.get(hi).copied().unwrap_or(0.0) - prefix.get(lo).copied().unwrap_or(0.0);
                *v = sum / (hi - lo) as f64;
            }
        });
    };
    // Transpose `src` into `dst` (square n × n).
    let transpose = |src: &[f64], dst: &mut [f64]| {
        dst.par_chunks_mut(n).enumerate().for_each(|(c, col)| {
            for (r, v) in col.iter_mut().enumerate() {
                *v = src.get(r * n + c).copied().unwrap_or(0.0);
            }
        });
    };
    // Two n² buffers in all (the field's own f32 aside).
    let mut other = vec![0.0f64; n * n];
    for _ in 0..3 {
        box_rows(&mut low);
    }
    transpose(&low, &mut other);
    for _ in 0..3 {
        box_rows(&mut other);
    }
    transpose(&other, &mut low);
    drop(other);
    field.par_iter_mut().zip(low.par_iter()).for_each(|(v, l)| {
        *v = (f64::from(*v) - l) as f32;
    });
}

/// [`landing_zone`], with the report of what was drawn (counts against the models).
pub fn landing_zone_with_report(
    coarse: &Dem,
    centre_m: [f64; 2],
    cfg: &LandingZoneConfig,
    seed: u64,
) -> Result<(Dem, LandingZoneReport), DemError> {
    let n = check_config(cfg, centre_m)?;
    let coarse_px = coarse.pixel_m()?;
    let px = cfg.pixel_m;
    let side = n as f64 * px;
    let x0 = centre_m[0] - side / 2.0;
    let y_top = centre_m[1] + side / 2.0;
    let y_bottom = y_top - side;

    // The zone (outer corners) must lie inside the coarse DEM's pixel-centre extent, where
    // bilinear interpolation is defined.
    let (cx0, cy0, cx1, cy1) = coarse.extent_m();
    let h = coarse_px / 2.0;
    let (ix0, iy0, ix1, iy1) = (cx0 + h, cy0 + h, cx1 - h, cy1 - h);
    if !(x0 >= ix0 && x0 + side <= ix1 && y_bottom >= iy0 && y_top <= iy1) {
        return Err(invalid(format!(
            "landing zone x {:.1}..{:.1} m, y {:.1}..{:.1} m is not inside the coarse DEM \
             (pixel centres x {ix0:.1}..{ix1:.1} m, y {iy0:.1}..{iy1:.1} m)",
            x0,
            x0 + side,
            y_bottom,
            y_top
        )));
    }

    // 1. Coarse heights, bilinear.
    let mut z = vec![0.0f32; n * n];
    z.par_chunks_mut(n).enumerate().for_each(|(r, row)| {
        let y = y_top - (r as f64 + 0.5) * px;
        for (c, v) in row.iter_mut().enumerate() {
            *v = height_at_geo(coarse, x0 + (c as f64 + 0.5) * px, y);
        }
    });

    // 2. Roughness (the detail layer starts from it).
    let roughness = Roughness {
        rolloff_m: cfg.roughness.rolloff_m.max(2.0 * coarse_px),
        ..cfg.roughness
    };
    let mut detail = fractal_field(n, n, px, &roughness, seed ^ STREAM_ROUGHNESS);

    // 3. Small craters at the equilibrium density, drawn over the zone plus the reach of the
    // largest crater, so that rims and ejecta of craters outside reach in.
    let d_min = cfg.crater_d_min_m;
    let d_max = cfg
        .crater_d_max_m
        .unwrap_or((MIN_CRATER_PX * coarse_px).max(MIN_CRATER_M))
        .max(d_min);
    let reach_r = crater::EJECTA_OUTER_R + 3.0 * crater::SIGMA_VISIBLE_R + 0.5;
    let margin = d_max / 2.0 * reach_r;
    let n_eq = |d_m: f64| sfd::n_equilibrium_per_km2(d_m / 1000.0);
    let area_km2 = |s: f64| (s / 1000.0).powi(2);
    let crater_draws: Vec<CraterDraw> = {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ STREAM_CRATERS);
        let ext = side + 2.0 * margin;
        let lambda = if d_max > d_min {
            (n_eq(d_min) - n_eq(d_max)) * area_km2(ext) * cfg.crater_density
        } else {
            0.0
        };
        let count = poisson(&mut rng, lambda);
        // Truncated power law N(>D) ∝ D^-2 between d_min and d_max, by inverse CDF.
        let (a, b) = (d_min.powi(-2), d_max.powi(-2));
        (0..count)
            .map(|_| CraterDraw {
                d_m: (a - rng.random::<f64>() * (a - b)).powf(-0.5),
                x_m: x0 - margin + ext * rng.random::<f64>(),
                y_m: y_bottom - margin + ext * rng.random::<f64>(),
                u_age: rng.random::<f64>(),
                u_shape: rng.random::<f64>(),
                u_rim: rng.random::<f64>(),
                u_keep: rng.random::<f64>(),
            })
            .collect()
    };
    let stamps: Vec<CraterStamp> = crater_draws
        .par_iter()
        .filter(|c| {
            let f = c.d_m / 2.0 * reach_r;
            c.x_m + f >= x0 && c.x_m - f <= x0 + side && c.y_m + f >= y_bottom && c.y_m - f <= y_top
        })
        // Shapes do not depend on κ in steady state; the surface age does not cap metre craters.
        .map(|c| make_stamp(c, 1.0, f64::INFINITY))
        .collect();

    // 4. Rocks, drawn over the zone plus half the largest rock.
    let q = if cfg.rock_k > 0.0 {
        rock_q_per_m(cfg.rock_k)
    } else {
        f64::INFINITY
    };
    let rocks: Vec<Rock> = if cfg.rock_k > 0.0 {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ STREAM_ROCKS);
        let table = RockTable::new(cfg.rock_k, cfg.rock_d_min_m, cfg.rock_d_max_m);
        let rm = cfg.rock_d_max_m / 2.0;
        let ext = side + 2.0 * rm;
        let count = poisson(&mut rng, table.total() * ext * ext);
        (0..count)
            .map(|_| Rock {
                d_m: table.sample(rng.random::<f64>()),
                x_m: x0 - rm + ext * rng.random::<f64>(),
                y_m: y_bottom - rm + ext * rng.random::<f64>(),
            })
            .collect()
    } else {
        Vec::new()
    };

    // 5. Stamp craters (added) and rocks (merged by maximum) in row bands. A degraded crater's
    // table runs out to 3σ of smoothing; beyond the last sample above STAMP_FLOOR_M it adds
    // nothing visible in f32 heights, so each crater is stamped out to that radius only.
    let reach: Vec<f64> = stamps.iter().map(effective_reach_m).collect();
    let crater_bands = band_lists(
        stamps.iter().zip(&reach).map(|(s, &f)| (s.y_m, f)),
        y_top,
        px,
        n,
    );
    let rock_bands = band_lists(rocks.iter().map(|r| (r.y_m, r.d_m / 2.0)), y_top, px, n);
    let col_span = |x: f64, reach: f64| -> Option<(usize, usize)> {
        let lo = ((x - reach - x0) / px - 0.5).ceil();
        let hi = ((x + reach - x0) / px - 0.5).floor();
        if hi < 0.0 || lo > (n - 1) as f64 || hi < lo {
            None
        } else {
            Some((lo.max(0.0) as usize, (hi as usize).min(n - 1)))
        }
    };
    let ratio = cfg.rock_height_ratio;
    detail
        .par_chunks_mut(n * BAND_ROWS)
        .zip(crater_bands.par_iter().zip(rock_bands.par_iter()))
        .enumerate()
        .for_each(|(b, (rows, (cl, rl)))| {
            let r0 = b * BAND_ROWS;
            for (s, &f) in cl.iter().filter_map(|&i| stamps.get(i).zip(reach.get(i))) {
                for (rr, row) in rows.chunks_mut(n).enumerate() {
                    let dy = y_top - ((r0 + rr) as f64 + 0.5) * px - s.y_m;
                    if dy.abs() > f {
                        continue;
                    }
                    // Only the chord of the footprint disc on this row.
                    let Some((c_lo, c_hi)) = col_span(s.x_m, (f * f - dy * dy).sqrt()) else {
                        continue;
                    };
                    for (c, v) in row.iter_mut().enumerate().take(c_hi + 1).skip(c_lo) {
                        let dx = x0 + (c as f64 + 0.5) * px - s.x_m;
                        *v += s.at((dx * dx + dy * dy).sqrt());
                    }
                }
            }
            if rl.is_empty() {
                return;
            }
            let mut rock = vec![0.0f32; rows.len()];
            for k in rl.iter().filter_map(|&i| rocks.get(i)) {
                let rad = k.d_m / 2.0;
                let top = ratio * k.d_m;
                for (rr, row) in rock.chunks_mut(n).enumerate() {
                    let dy = y_top - ((r0 + rr) as f64 + 0.5) * px - k.y_m;
                    if dy.abs() >= rad {
                        continue;
                    }
                    let Some((c_lo, c_hi)) = col_span(k.x_m, (rad * rad - dy * dy).sqrt()) else {
                        continue;
                    };
                    for (c, v) in row.iter_mut().enumerate().take(c_hi + 1).skip(c_lo) {
                        let dx = x0 + (c as f64 + 0.5) * px - k.x_m;
                        let rho2 = (dx * dx + dy * dy) / (rad * rad);
                        if rho2 < 1.0 {
                            *v = v.max((top * (1.0 - rho2).sqrt()) as f32);
                        }
                    }
                }
            }
            for (v, r) in rows.iter_mut().zip(&rock) {
                *v += r;
            }
        });

    // 6. The detail refines the coarse DEM; it must not change it at the coarse pixel's scale.
    remove_coarse_scale(&mut detail, n, coarse_px / px);

    // 7. Coarse + taper × detail. The weight is 0 on the outermost pixel centres.
    let taper = cfg.taper_m;
    z.par_chunks_mut(n)
        .zip(detail.par_chunks(n))
        .enumerate()
        .for_each(|(r, (row, det))| {
            let dr = r.min(n - 1 - r);
            for (c, (v, d)) in row.iter_mut().zip(det).enumerate() {
                let w = if taper > 0.0 {
                    smoothstep(dr.min(c).min(n - 1 - c) as f64 * px / taper)
                } else {
                    1.0
                };
                *v += w as f32 * d;
            }
        });

    // Same CRS keys and storage form as the coarse DEM, new north-up transform.
    let geo = match &coarse.geo.keys {
        Some(_) => GeoRef {
            transform: GeoTransform::north_up(x0, y_top, px),
            ..coarse.geo.clone()
        },
        None => GeoRef::local(
            x0,
            y_top,
            px,
            &format!("Umbra landing zone, seed {seed}, coarse DEM's local metric grid"),
        ),
    };
    let dem = Dem::new(n, n, z, geo)?;

    // Report: items centred in the zone.
    let inside = |x: f64, y: f64| (x0..x0 + side).contains(&x) && (y_bottom..y_top).contains(&y);
    let zone_km2 = area_km2(side);
    let mut crater_bins = Vec::new();
    let mut lo = d_min;
    while lo < d_max {
        let hi = (lo * 2.0).min(d_max);
        let in_bin = |c: &&CraterDraw| c.d_m >= lo && c.d_m < hi && inside(c.x_m, c.y_m);
        crater_bins.push(CraterBin {
            d_min_m: lo,
            d_max_m: hi,
            model: (n_eq(lo) - n_eq(hi)) * zone_km2 * cfg.crater_density,
            drawn: crater_draws.iter().filter(in_bin).count(),
            fresh: crater_draws
                .iter()
                .filter(in_bin)
                .filter(|c| c.u_age < 0.25)
                .count(),
        });
        lo = hi;
    }
    let centred: Vec<&CraterStamp> = stamps.iter().filter(|s| inside(s.x_m, s.y_m)).collect();
    let crater_mean_depth_over_d = if centred.is_empty() {
        f64::NAN
    } else {
        centred
            .iter()
            .map(|s| s.depth_m() / (2.0 * s.r_m))
            .sum::<f64>()
            / centred.len() as f64
    };
    let rocks_in: Vec<&Rock> = rocks.iter().filter(|r| inside(r.x_m, r.y_m)).collect();
    let zone_m2 = side * side;
    let rock_bins = if cfg.rock_k > 0.0 {
        [cfg.rock_d_min_m, 0.5, 1.0, 2.0]
            .into_iter()
            .filter(|&d| d >= cfg.rock_d_min_m && d < cfg.rock_d_max_m)
            .map(|d| {
                let big = || rocks_in.iter().filter(move |r| r.d_m >= d);
                RockBin {
                    d_min_m: d,
                    model_area_frac: rock_area_fraction(cfg.rock_k, d)
                        - rock_area_fraction(cfg.rock_k, cfg.rock_d_max_m),
                    drawn_area_frac: big().map(|r| PI * r.d_m * r.d_m / 4.0).sum::<f64>() / zone_m2,
                    drawn: big().count(),
                    model_count: rock_count_per_m2(cfg.rock_k, d, cfg.rock_d_max_m) * zone_m2,
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    let report = LandingZoneReport {
        config: *cfg,
        seed,
        centre_m,
        side_px: n,
        side_m: side,
        coarse_pixel_m: coarse_px,
        roughness,
        crater_range_m: (d_min, d_max),
        craters_expected: (n_eq(d_min) - n_eq(d_max)) * zone_km2 * cfg.crater_density,
        craters_drawn: crater_draws.iter().filter(|c| inside(c.x_m, c.y_m)).count(),
        crater_bins,
        crater_mean_depth_over_d,
        rock_q_per_m: q,
        rocks_expected: if cfg.rock_k > 0.0 {
            rock_count_per_m2(cfg.rock_k, cfg.rock_d_min_m, cfg.rock_d_max_m) * zone_m2
        } else {
            0.0
        },
        rocks_drawn: rocks_in.len(),
        rocks_over_0_3m_high: rocks_in.iter().filter(|r| ratio * r.d_m > 0.3).count(),
        rock_bins,
    };
    Ok((dem, report))
}

/// What makes a touchdown site safe (the lander's tolerances).
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct SafetyThresholds {
    /// Diameter of the footprint disc over which a site is judged, metres: the lander's leg span
    /// (default 4 m).
    pub footprint_m: f64,
    /// Largest tilt of the plane fitted over the footprint, degrees (default 10°).
    pub max_slope_deg: f64,
    /// Largest height of any DEM cell above or below that plane, metres (default 0.3 m: a rock
    /// or rim the belly or a leg would strike, a hole a leg would drop into).
    pub max_relief_m: f64,
}

impl Default for SafetyThresholds {
    fn default() -> Self {
        Self {
            footprint_m: 4.0,
            max_slope_deg: 10.0,
            max_relief_m: 0.3,
        }
    }
}

/// The truth verdict on one touchdown site.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SiteSafety {
    /// Tilt of the least-squares plane over the footprint, degrees.
    pub slope_deg: f64,
    /// Largest |height − plane| over the footprint's cells, metres.
    pub relief_m: f64,
    /// `slope_deg <= max_slope_deg && relief_m <= max_relief_m`.
    pub safe: bool,
}

/// Judge the touchdown site at map position `(x_m, y_m)` (metres, the DEM's frame) on `zone`.
///
/// Precisely: the cells are those whose centres lie within `footprint_m / 2` of the site; a plane
/// `z = a + b·dx + c·dy` is fitted to their heights by least squares (dx, dy from the site);
/// `slope_deg = atan(√(b² + c²))` and `relief_m = max |z − plane|` over the same cells. `None` if
/// the disc leaves the DEM's extent, a cell in it is NaN, it holds fewer than 3 cells, the grid
/// is not north-up with square pixels, or the thresholds are not finite and positive.
pub fn site_safety(zone: &Dem, x_m: f64, y_m: f64, t: &SafetyThresholds) -> Option<SiteSafety> {
    let px = zone.pixel_m().ok()?;
    let r = t.footprint_m / 2.0;
    if !(r.is_finite() && r > 0.0 && x_m.is_finite() && y_m.is_finite()) {
        return None;
    }
    let (ex0, ey0, ex1, ey1) = zone.extent_m();
    if !(x_m - r >= ex0 && x_m + r <= ex1 && y_m - r >= ey0 && y_m + r <= ey1) {
        return None;
    }
    let (w, h) = (zone.width(), zone.height());
    let (ox, oy) = zone.origin_m();
    let (c_lo, c_hi) = {
        let lo = ((x_m - r - ox) / px - 0.5).ceil().max(0.0) as usize;
        let hi = (((x_m + r - ox) / px - 0.5).floor().max(0.0) as usize).min(w - 1);
        (lo, hi)
    };
    let (r_lo, r_hi) = {
        let lo = ((oy - (y_m + r)) / px - 0.5).ceil().max(0.0) as usize;
        let hi = (((oy - (y_m - r)) / px - 0.5).floor().max(0.0) as usize).min(h - 1);
        (lo, hi)
    };
    let heights = zone.heights_m();
    let r2 = r * r;
    let mut cells: Vec<(f64, f64, f64)> = Vec::new();
    for row in r_lo..=r_hi {
        let dy = oy - (row as f64 + 0.5) * px - y_m;
        for col in c_lo..=c_hi {
            let dx = ox + (col as f64 + 0.5) * px - x_m;
            if dx * dx + dy * dy > r2 {
                continue;
            }
            let v = f64::from(*heights.get(row * w + col)?);
            if !v.is_finite() {
                return None;
            }
            cells.push((dx, dy, v));
        }
    }
    if cells.len() < 3 {
        return None;
    }
    let z_ref = cells[0].2;
    let (mut n, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut sz, mut sxz, mut syz) = (0.0, 0.0, 0.0);
    for &(dx, dy, v) in &cells {
        let zz = v - z_ref;
        n += 1.0;
        sx += dx;
        sy += dy;
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
        sz += zz;
        sxz += dx * zz;
        syz += dy * zz;
    }
    // Normal equations [n sx sy; sx sxx sxy; sy sxy syy] (a, b, c) = (sz, sxz, syz), Cramer.
    let det3 = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let m = [[n, sx, sy], [sx, sxx, sxy], [sy, sxy, syy]];
    let d = det3(m);
    if !(d.abs() > 1e-12 * n * sxx.max(syy).powi(2)) {
        return None;
    }
    let rhs = [sz, sxz, syz];
    let solve = |k: usize| {
        let mut mk = m;
        for (row, v) in mk.iter_mut().zip(rhs) {
            row[k] = v;
        }
        det3(mk) / d
    };
    let (a, b, c) = (solve(0), solve(1), solve(2));
    let relief_m = cells
        .iter()
        .map(|&(dx, dy, v)| (v - z_ref - (a + b * dx + c * dy)).abs())
        .fold(0.0, f64::max);
    let slope_deg = b.hypot(c).atan().to_degrees();
    Some(SiteSafety {
        slope_deg,
        relief_m,
        safe: slope_deg <= t.max_slope_deg && relief_m <= t.max_relief_m,
    })
}

/// Site verdicts on a square lattice: cells of `step_m` tiling the zone's interior (the extent
/// shrunk by `margin_m` on every side), one site at each cell centre, rows from north to south.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SafetyMap {
    /// Lattice step (cell side), metres.
    pub step_m: f64,
    /// West edge of the first column of cells, metres.
    pub x_min_m: f64,
    /// North edge of the first row of cells, metres.
    pub y_max_m: f64,
    /// Cells per row.
    pub nx: usize,
    /// Rows of cells.
    pub ny: usize,
    /// Verdict per cell, row-major (`None`: the disc leaves the DEM or meets NaN).
    pub sites: Vec<Option<SiteSafety>>,
}

impl SafetyMap {
    /// Share of the judged sites that are safe (`NaN` if none was judged).
    pub fn safe_fraction(&self) -> f64 {
        let judged = self.sites.iter().flatten().count();
        let safe = self.sites.iter().flatten().filter(|s| s.safe).count();
        if judged == 0 {
            f64::NAN
        } else {
            safe as f64 / judged as f64
        }
    }

    /// The verdict of the cell holding map position `(x_m, y_m)`, if any.
    pub fn at(&self, x_m: f64, y_m: f64) -> Option<SiteSafety> {
        let i = ((x_m - self.x_min_m) / self.step_m).floor();
        let j = ((self.y_max_m - y_m) / self.step_m).floor();
        if !(i >= 0.0 && j >= 0.0 && i < self.nx as f64 && j < self.ny as f64) {
            return None;
        }
        self.sites
            .get(j as usize * self.nx + i as usize)
            .copied()
            .flatten()
    }
}

/// Judge every site of the `step_m` lattice inside `zone` less a `margin_m` border (pass the
/// zone's taper width: the band where the detail fades is not representative). An empty map for
/// a non-positive or non-finite step or margin, or a zone too small to hold a cell.
pub fn safety_map(zone: &Dem, t: &SafetyThresholds, step_m: f64, margin_m: f64) -> SafetyMap {
    let (ex0, ey0, ex1, ey1) = zone.extent_m();
    let empty = SafetyMap {
        step_m,
        x_min_m: ex0 + margin_m,
        y_max_m: ey1 - margin_m,
        nx: 0,
        ny: 0,
        sites: Vec::new(),
    };
    if !(step_m.is_finite() && step_m > 0.0 && margin_m.is_finite() && margin_m >= 0.0) {
        return empty;
    }
    let nx = ((ex1 - ex0 - 2.0 * margin_m) / step_m).floor().max(0.0) as usize;
    let ny = ((ey1 - ey0 - 2.0 * margin_m) / step_m).floor().max(0.0) as usize;
    let (xm, ym) = (ex0 + margin_m, ey1 - margin_m);
    let sites = (0..nx * ny)
        .into_par_iter()
        .map(|k| {
            let (i, j) = (k % nx, k / nx);
            let x = xm + (i as f64 + 0.5) * step_m;
            let y = ym - (j as f64 + 0.5) * step_m;
            site_safety(zone, x, y, t)
        })
        .collect();
    SafetyMap {
        nx,
        ny,
        sites,
        ..empty
    }
}

/// Share of safe sites on a `step_m` lattice inside `zone`, excluding a border band of
/// [`DEFAULT_TAPER_M`] (the default taper; use [`safe_fraction_within`] for another). Sites whose
/// disc leaves the DEM or meets NaN are not counted; `NaN` if no site was judged.
pub fn safe_fraction(zone: &Dem, t: &SafetyThresholds, step_m: f64) -> f64 {
    safe_fraction_within(zone, t, step_m, DEFAULT_TAPER_M)
}

/// [`safe_fraction`] excluding a border band of `margin_m` metres.
pub fn safe_fraction_within(zone: &Dem, t: &SafetyThresholds, step_m: f64, margin_m: f64) -> f64 {
    safety_map(zone, t, step_m, margin_m).safe_fraction()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 400 m coarse DEM at 5 m (corner at (−200, 200)): a 2° tilt plus gentle hills.
    fn coarse() -> Dem {
        let (n, px) = (80usize, 5.0);
        let z = (0..n * n)
            .map(|i| {
                let x = -200.0 + ((i % n) as f64 + 0.5) * px;
                let y = 200.0 - ((i / n) as f64 + 0.5) * px;
                (0.035 * x + 4.0 * (x / 60.0).sin() * (y / 45.0).cos()) as f32
            })
            .collect();
        Dem::new(n, n, z, GeoRef::local(-200.0, 200.0, px, "test")).unwrap()
    }

    /// A flat coarse DEM (height 0) of 400 m at 5 m.
    fn flat_coarse() -> Dem {
        let n = 80usize;
        Dem::new(
            n,
            n,
            vec![0.0; n * n],
            GeoRef::local(-200.0, 200.0, 5.0, "test"),
        )
        .unwrap()
    }

    fn small() -> LandingZoneConfig {
        LandingZoneConfig {
            side_m: 64.0,
            taper_m: 8.0,
            ..LandingZoneConfig::default()
        }
    }

    fn bits(d: &Dem) -> Vec<u32> {
        d.heights_m().iter().map(|v| v.to_bits()).collect()
    }

    #[test]
    fn the_detail_leaves_the_coarse_scale_alone() {
        // Over a flat coarse DEM the zone is its detail alone: averaged over the coarse pixel's
        // scale and more it must be ~0, or a map made from the coarse DEM would miss ground.
        let cfg = LandingZoneConfig {
            side_m: 256.0,
            taper_m: 32.0,
            ..LandingZoneConfig::default()
        };
        let zone = landing_zone(&flat_coarse(), [0.0, 0.0], &cfg, 11).unwrap();
        let n = zone.width();
        let z = zone.heights_m();
        // Interior (outside the taper), 20 m blocks (80 px).
        let (lo, blk) = (128usize, 80usize);
        let nb = (n - 2 * lo) / blk;
        let mut means = Vec::new();
        for br in 0..nb {
            for bc in 0..nb {
                let mut sum = 0.0f64;
                for r in 0..blk {
                    for c in 0..blk {
                        sum += f64::from(z[(lo + br * blk + r) * n + lo + bc * blk + c]);
                    }
                }
                means.push(sum / (blk * blk) as f64);
            }
        }
        let mean = means.iter().sum::<f64>() / means.len() as f64;
        let rms = (means.iter().map(|m| m * m).sum::<f64>() / means.len() as f64).sqrt();
        // The detail itself is decimetres (rocks to 2 m, craters to 15 m).
        let all = (z.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / z.len() as f64).sqrt();
        assert!(all > 0.1, "detail RMS {all} m");
        assert!(
            mean.abs() < 0.01 && rms < 0.03,
            "20 m block means: mean {mean} m, RMS {rms} m"
        );
    }

    #[test]
    fn removing_the_coarse_scale_keeps_fine_detail() {
        let n = 256usize;
        // A constant and a plane have no fine detail; a 4 px wave is all fine detail.
        let mut flat = vec![3.0f32; n * n];
        remove_coarse_scale(&mut flat, n, 20.0);
        assert!(flat.iter().all(|v| v.abs() < 1e-5));
        let mut plane: Vec<f32> = (0..n * n).map(|i| 0.01 * (i % n) as f32).collect();
        remove_coarse_scale(&mut plane, n, 20.0);
        assert!(
            plane[128 * n + 128].abs() < 1e-4,
            "{}",
            plane[128 * n + 128]
        );
        // Along y too (both passes count).
        let mut plane_y: Vec<f32> = (0..n * n).map(|i| 0.01 * (i / n) as f32).collect();
        remove_coarse_scale(&mut plane_y, n, 20.0);
        assert!(
            plane_y[128 * n + 128].abs() < 1e-4,
            "{}",
            plane_y[128 * n + 128]
        );
        for along_x in [true, false] {
            let wave = |i: usize| {
                let t = if along_x { i % n } else { i / n };
                (2.0 * PI * t as f64 / 4.0 + 0.3).sin() as f32
            };
            let mut fine: Vec<f32> = (0..n * n).map(wave).collect();
            remove_coarse_scale(&mut fine, n, 20.0);
            let i = 128 * n + 129;
            assert!(
                (fine[i] - wave(i)).abs() < 0.01,
                "{} vs {}",
                fine[i],
                wave(i)
            );
        }
        // An impulse: what is taken out is a bump of unit mass and variance ≈ σ² per axis.
        let sigma = 6.0;
        let mut imp = vec![0.0f32; n * n];
        imp[128 * n + 128] = 1.0;
        remove_coarse_scale(&mut imp, n, sigma);
        let (mut m0, mut m2) = (0.0f64, 0.0f64);
        for (i, v) in imp.iter().enumerate() {
            let taken = if i == 128 * n + 128 {
                1.0 - f64::from(*v)
            } else {
                -f64::from(*v)
            };
            let dx = (i % n) as f64 - 128.0;
            m0 += taken;
            m2 += taken * dx * dx;
        }
        assert!((m0 - 1.0).abs() < 1e-4, "low-pass mass {m0}");
        let var = m2 / m0;
        // h is a whole number: h(h + 1) misses σ² by at most about σ.
        assert!((var - sigma * sigma).abs() <= sigma + 0.5, "variance {var}");
    }

    #[test]
    fn same_seed_is_bit_identical_whatever_the_thread_count_and_seeds_differ() {
        let c = coarse();
        let run = |threads: usize, seed: u64| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| landing_zone(&c, [10.0, -20.0], &small(), seed).unwrap())
        };
        let one = bits(&run(1, 7));
        let three = bits(&run(3, 7));
        assert!(one == three, "thread count changed the zone");
        let other = bits(&run(2, 8));
        let differing = one.iter().zip(&other).filter(|(a, b)| a != b).count();
        // The outermost ring is the coarse DEM in both.
        assert!(differing > one.len() * 9 / 10, "{differing} differ");
    }

    #[test]
    fn border_equals_the_coarse_dem_and_the_detail_fades_in() {
        let c = coarse();
        let cfg = small();
        let z = landing_zone(&c, [10.0, -20.0], &cfg, 3).unwrap();
        let n = z.width();
        assert_eq!((n, z.height()), (256, 256));
        assert_eq!(z.pixel_m().unwrap(), 0.25);
        let (ox, oy) = z.origin_m();
        assert_eq!((ox, oy), (10.0 - 32.0, -20.0 + 32.0));
        let base = |col: usize, row: usize| {
            let (x, y) = z.pixel_centre_m(col as f64, row as f64);
            height_at_geo(&c, x, y)
        };
        for i in 0..n {
            for (col, row) in [(i, 0), (i, n - 1), (0, i), (n - 1, i)] {
                assert_eq!(z.get(col, row).unwrap(), base(col, row), "({col}, {row})");
            }
        }
        // RMS of the added detail per distance from the border: ~0 in the first pixels, full
        // beyond the taper (8 m = 32 px).
        let rms_ring = |d: usize| {
            let cells: Vec<f64> = (d..n - d)
                .flat_map(|i| [(i, d), (i, n - 1 - d), (d, i), (n - 1 - d, i)])
                .map(|(col, row)| f64::from(z.get(col, row).unwrap() - base(col, row)))
                .collect();
            (cells.iter().map(|v| v * v).sum::<f64>() / cells.len() as f64).sqrt()
        };
        let (edge, mid, full) = (rms_ring(1), rms_ring(16), rms_ring(60));
        assert!(edge < 0.01 * full, "edge {edge} vs {full}");
        assert!(mid > 0.2 * full && mid < full * 1.5, "mid {mid} vs {full}");
        assert!(full > 0.01, "no detail: {full}");
    }

    /// Variance of the fractional area covered by rocks in `[d, d_max]` over an area `a_m2`
    /// (compound Poisson: ∫ n(u) (π u² / 4)² du / A).
    fn area_frac_var(k: f64, d: f64, d_max: f64, a_m2: f64) -> f64 {
        let steps = 4000;
        let du = (d_max - d) / steps as f64;
        (0..steps)
            .map(|i| {
                let u = d + (i as f64 + 0.5) * du;
                rock_number_density(k, u) * (PI * u * u / 4.0).powi(2) * du
            })
            .sum::<f64>()
            / a_m2
    }

    #[test]
    fn rock_cumulative_area_matches_golombek_rapp() {
        // Rocks alone on a flat DEM: 128 m at 0.25 m, taper 4 m.
        let cfg = LandingZoneConfig {
            side_m: 128.0,
            taper_m: 4.0,
            roughness: Roughness {
                nu5_m: 0.0,
                ..LandingZoneConfig::default().roughness
            },
            crater_density: 0.0,
            ..LandingZoneConfig::default()
        };
        let (z, rep) = landing_zone_with_report(&flat_coarse(), [0.0, 0.0], &cfg, 11).unwrap();
        let k = cfg.rock_k;
        assert!((rep.rock_q_per_m - 3.69).abs() < 0.001);
        // F_k(1 m) at the default k is the 0.20 % the choice of k is based on.
        assert!((rock_area_fraction(k, 1.0) - 0.0020).abs() < 0.0001);
        // Drawn rocks (centred in the zone) against the model, within 4 σ of the compound
        // Poisson area fraction; counts within 4 √N.
        assert_eq!(rep.rock_bins.len(), 4);
        let a = rep.side_m * rep.side_m;
        for b in &rep.rock_bins {
            let sigma = area_frac_var(k, b.d_min_m, cfg.rock_d_max_m, a).sqrt();
            println!(
                "D >= {} m: model {:.5} drawn {:.5} (sigma {sigma:.5}), n {} vs {:.1}",
                b.d_min_m, b.model_area_frac, b.drawn_area_frac, b.drawn, b.model_count
            );
            assert!(
                (b.drawn_area_frac - b.model_area_frac).abs() <= 4.0 * sigma,
                "{b:?}"
            );
            let n = b.drawn as f64;
            assert!(
                (n - b.model_count).abs() <= 4.0 * b.model_count.sqrt() + 1.0,
                "{b:?}"
            );
        }
        // The raster: pixel centres covered by a rock (height > 0) in the untapered interior
        // cover 1 − exp(−F) of it (discs placed at random), within 4 σ and 0.1 % for pixels.
        let n = z.width();
        let m = 16; // taper 4 m = 16 px
        let mut covered = 0usize;
        let mut total = 0usize;
        for row in m..n - m {
            for col in m..n - m {
                total += 1;
                if z.get(col, row).unwrap() > 1e-4 {
                    covered += 1;
                }
            }
        }
        let f = rock_area_fraction(k, cfg.rock_d_min_m) - rock_area_fraction(k, cfg.rock_d_max_m);
        let expect = 1.0 - (-f).exp();
        let inner = ((n - 2 * m) as f64 * 0.25).powi(2);
        let sigma = area_frac_var(k, cfg.rock_d_min_m, cfg.rock_d_max_m, inner).sqrt();
        let got = covered as f64 / total as f64;
        println!("covered {got:.5} vs {expect:.5} (sigma {sigma:.5})");
        assert!(
            (got - expect).abs() <= 4.0 * sigma + 0.001,
            "{got} vs {expect}"
        );
        // Heights: the tallest rock is half its diameter.
        let tallest = f64::from(z.heights_m().iter().fold(0.0f32, |a, &b| a.max(b)));
        assert!(
            tallest <= 0.5 * cfg.rock_d_max_m && tallest > 0.3,
            "{tallest}"
        );
    }

    #[test]
    fn crater_count_matches_the_equilibrium_density() {
        let cfg = LandingZoneConfig {
            side_m: 128.0,
            pixel_m: 0.5,
            taper_m: 4.0,
            crater_d_max_m: Some(12.0),
            rock_k: 0.0,
            ..LandingZoneConfig::default()
        };
        let (_, rep) = landing_zone_with_report(&coarse(), [0.0, 0.0], &cfg, 5).unwrap();
        assert_eq!(rep.crater_range_m, (1.0, 12.0));
        // N_eq(>D) = 10^-1.1 D^-2 per km² (D in km): 0.0794 per m² above 1 m.
        let km2 = (128.0f64 / 1000.0).powi(2);
        let expect = (sfd::n_equilibrium_per_km2(0.001) - sfd::n_equilibrium_per_km2(0.012)) * km2;
        assert!((rep.craters_expected - expect).abs() < 1e-9);
        assert!((expect - 1292.4).abs() < 1.0, "{expect}");
        let n = rep.craters_drawn as f64;
        assert!((n - expect).abs() <= 4.0 * expect.sqrt(), "{n} vs {expect}");
        // Per factor-2 bin, Poisson tolerance.
        for b in &rep.crater_bins {
            let d = b.drawn as f64;
            assert!(
                (d - b.model).abs() <= 4.0 * b.model.sqrt() + 1.0,
                "{b:?} ({} craters)",
                rep.craters_drawn
            );
        }
        // A steady-state population: most craters are degraded well below Pike's fresh 0.196.
        assert!(
            (0.03..0.15).contains(&rep.crater_mean_depth_over_d),
            "{}",
            rep.crater_mean_depth_over_d
        );
        // The default largest crater joins the coarse scene's smallest: 3 px of 5 m = 15 m.
        let cfg = LandingZoneConfig {
            crater_d_max_m: None,
            ..cfg
        };
        let (_, rep) = landing_zone_with_report(&coarse(), [0.0, 0.0], &cfg, 5).unwrap();
        assert_eq!(rep.crater_range_m, (1.0, 15.0));
    }

    /// A 64 m DEM at 0.25 m: the plane `z = tan(slope)·x` plus `f(col, row)`.
    fn plane(slope_deg: f64, f: impl Fn(usize, usize) -> f32) -> Dem {
        let n = 256usize;
        let g = slope_deg.to_radians().tan();
        let z = (0..n * n)
            .map(|i| {
                let x = -32.0 + ((i % n) as f64 + 0.5) * 0.25;
                (g * x) as f32 + f(i % n, i / n)
            })
            .collect();
        Dem::new(n, n, z, GeoRef::local(-32.0, 32.0, 0.25, "plane")).unwrap()
    }

    #[test]
    fn site_safety_on_planes_and_a_bump() {
        let t = SafetyThresholds::default();
        let s5 = site_safety(&plane(5.0, |_, _| 0.0), 0.1, -0.3, &t).unwrap();
        assert!(
            (s5.slope_deg - 5.0).abs() < 1e-3 && s5.relief_m < 1e-3,
            "{s5:?}"
        );
        assert!(s5.safe);
        let s15 = site_safety(&plane(15.0, |_, _| 0.0), 0.1, -0.3, &t).unwrap();
        assert!((s15.slope_deg - 15.0).abs() < 1e-3, "{s15:?}");
        assert!(!s15.safe);
        // One 0.5 m bump (a single cell) 1 m east of the site, inside the 2 m radius.
        let bump = plane(5.0, |c, r| if (c, r) == (132, 128) { 0.5 } else { 0.0 });
        let s = site_safety(&bump, 0.0, 0.0, &t).unwrap();
        assert!(s.relief_m > 0.45 && s.slope_deg < 5.3, "{s:?}");
        assert!(!s.safe);
        // The same bump 3 m away is outside the disc.
        let s = site_safety(&bump, -2.0, 0.0, &t).unwrap();
        assert!(s.safe, "{s:?}");
        // A disc leaving the DEM, or meeting NaN, is not judged.
        assert!(site_safety(&bump, 31.0, 0.0, &t).is_none());
        let hole = plane(
            0.0,
            |c, r| if (c, r) == (128, 128) { f32::NAN } else { 0.0 },
        );
        assert!(site_safety(&hole, 0.0, 0.0, &t).is_none());
        assert!(site_safety(&hole, 10.0, 0.0, &t).unwrap().safe);
    }

    #[test]
    fn safe_fraction_of_flat_and_steep_zones() {
        let t = SafetyThresholds::default();
        let flat = plane(0.0, |_, _| 0.0);
        assert_eq!(safe_fraction_within(&flat, &t, 2.0, 4.0), 1.0);
        let m = safety_map(&flat, &t, 2.0, 4.0);
        assert_eq!((m.nx, m.ny), (28, 28));
        assert!(m.at(0.0, 0.0).unwrap().safe && m.at(-31.0, 0.0).is_none());
        assert_eq!(
            safe_fraction_within(&plane(15.0, |_, _| 0.0), &t, 2.0, 4.0),
            0.0
        );
        // The default margin (32 m) leaves nothing of a 64 m DEM.
        assert!(safe_fraction(&flat, &t, 2.0).is_nan());
        assert!(safe_fraction_within(&flat, &t, 0.0, 4.0).is_nan());
    }

    #[test]
    fn bad_input_is_refused_with_a_reason() {
        let c = coarse();
        let err = |centre: [f64; 2], cfg: LandingZoneConfig| {
            landing_zone(&c, centre, &cfg, 1).unwrap_err().to_string()
        };
        let e = err([180.0, 0.0], small());
        assert!(e.contains("not inside the coarse DEM"), "{e}");
        let e = err(
            [0.0, 0.0],
            LandingZoneConfig {
                side_m: f64::NAN,
                ..small()
            },
        );
        assert!(e.contains("finite and > 0"), "{e}");
        let e = err(
            [0.0, 0.0],
            LandingZoneConfig {
                pixel_m: 0.0,
                ..small()
            },
        );
        assert!(e.contains("finite and > 0"), "{e}");
        let e = err(
            [0.0, 0.0],
            LandingZoneConfig {
                side_m: 300.0,
                pixel_m: 0.01,
                ..small()
            },
        );
        assert!(e.contains("30000 px") && e.contains("8192"), "{e}");
        let e = err(
            [0.0, 0.0],
            LandingZoneConfig {
                taper_m: 40.0,
                ..small()
            },
        );
        assert!(e.contains("taper"), "{e}");
        let e = err([f64::NAN, 0.0], small());
        assert!(e.contains("centre"), "{e}");
        let e = err(
            [0.0, 0.0],
            LandingZoneConfig {
                rock_d_max_m: 0.1,
                ..small()
            },
        );
        assert!(e.contains("rock diameters"), "{e}");
    }
}
