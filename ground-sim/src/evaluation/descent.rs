//! Closed-loop hops: a flyer released over the truth terrain flies to a landing target, its IMU
//! propagates nav-core's filter, its ranging sensor's frames go through nav-core's Navigator
//! against the reference tile (with the filter's prior), the fixes update the filter, and simple
//! guidance steers on the estimate. Scores: landing error, navigation error, filter consistency.
//!
//! Frames: navigation ENU (x east, y north, z up, the DEM's projection metres). Body yaw ψ from
//! east towards north; the flyer stays level. The sensor looks down with columns along body x,
//! so a frame's heading (clockwise from east) is −ψ.

use nav_core::Prior;
use nav_core::filter::{
    FilterConfig, FixMeasurement, InitialState, NavFilter, OffsetMeasurement, UpdateOutcome,
    map_noise_share,
};
use nav_core::hazard::{AimDecision, CONFIRM_MAX_PIXEL_M, HazardConfig};
use nav_core::odometry::KeyframePose;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::evaluation::shard::f64_or_nan;
use crate::flyer::frames::{FramePose, SensorModel, Terrain, synth_frame_on};
use crate::flyer::onboard::{GroundKeyframe, MapNav, Workspace, capture_keyframe, run_odometry};
use crate::terrain::landing::{SafetyThresholds, site_safety};

/// The hazard map of the flight budget's capacity (the ground flies it too).
pub type GroundHazardMap = nav_core::flight::HazardMap;

/// A hazard map as pictured: the frame, the safe flags of its site lattice, the aim and target.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HazardPicture {
    /// Frame heights, m, row-major (NaN = dropout; JSON `null`).
    #[serde(deserialize_with = "f32s_or_nan")]
    pub heights_m: Vec<f32>,
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// Safe flag per lattice site, row-major.
    pub safe: Vec<bool>,
    /// Lattice size (columns, rows).
    pub lattice: (usize, usize),
    /// Frame pixel of site (0, 0).
    pub site_px: [f32; 2],
    /// Frame pixels between sites.
    pub step_px: f32,
    /// The aim after this map, frame pixels.
    pub aim_px: [f32; 2],
    /// The original target (a confirmation: the aim before it), frame pixels.
    pub target_px: [f32; 2],
    /// Frame pixel, m.
    pub pixel_m: f64,
    /// A confirmation map (a window around the chosen aim) rather than the first map.
    #[serde(default)]
    pub confirmation: bool,
}

/// Serde default of a figure missing from an older report: not measured.
fn nan() -> f64 {
    f64::NAN
}

/// Heights written by serde_json (NaN as `null`) read back.
fn f32s_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<f32>, D::Error> {
    let v: Vec<Option<f32>> = Deserialize::deserialize(d)?;
    Ok(v.into_iter().map(|x| x.unwrap_or(f32::NAN)).collect())
}

/// Frame pixel of an east/north offset `d` (m) from the centre of a `w × h` frame whose +x is
/// `heading` clockwise from east.
pub fn en_to_frame_px(d: [f64; 2], heading: f64, pixel_m: f64, w: usize, h: usize) -> [f32; 2] {
    let (s, c) = heading.sin_cos();
    // Inverse of FramePose::frame_to_geo's rotation (its matrix is its own inverse).
    let u = c * d[0] - s * d[1];
    let v = -s * d[0] - c * d[1];
    [
        ((w as f64 - 1.0) / 2.0 + u / pixel_m) as f32,
        ((h as f64 - 1.0) / 2.0 + v / pixel_m) as f32,
    ]
}

/// East/north offset (m) from the frame centre of frame pixel `q` (inverse of
/// [`en_to_frame_px`]).
pub fn frame_px_to_en(q: [f32; 2], heading: f64, pixel_m: f64, w: usize, h: usize) -> [f64; 2] {
    let u = (q[0] as f64 - (w as f64 - 1.0) / 2.0) * pixel_m;
    let v = (q[1] as f64 - (h as f64 - 1.0) / 2.0) * pixel_m;
    let (s, c) = heading.sin_cos();
    [u * c - v * s, -u * s - v * c]
}

/// Radius around the target over which [`RunResult::target_area_safe_frac`] is taken, m: about
/// the landing error a flyer without hazard avoidance makes (p95 of a few metres) plus the
/// guidance's own spread.
pub const TARGET_AREA_RADIUS_M: f64 = 10.0;

/// Fraction of the 1 m lattice sites within `radius_m` of `centre` that are safe on `zone`
/// (NaN if none can be judged).
pub fn area_safe_fraction(
    zone: &crate::dem::Dem,
    centre: [f64; 2],
    radius_m: f64,
    t: &SafetyThresholds,
) -> f64 {
    let n = radius_m.floor() as i64;
    let (mut safe, mut all) = (0usize, 0usize);
    for j in -n..=n {
        for i in -n..=n {
            let (dx, dy) = (i as f64, j as f64);
            if dx.hypot(dy) > radius_m {
                continue;
            }
            if let Some(s) = site_safety(zone, centre[0] + dx, centre[1] + dy, t) {
                all += 1;
                safe += usize::from(s.safe);
            }
        }
    }
    if all == 0 {
        f64::NAN
    } else {
        safe as f64 / all as f64
    }
}

/// Relative 1σ of a keyframe's pixel size: the ranging sensor's height above the terrain is
/// known to about a metre at kilometres, i.e. 10⁻³ or better.
pub const KEYFRAME_PIXEL_REL_SIGMA: f64 = 1e-3;

/// Scenario and vehicle settings.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct DescentConfig {
    /// Cruise height above the release point's terrain, m.
    pub cruise_agl_m: f64,
    /// Sensor angular pixel size, rad: frame pixel = height above terrain × this.
    pub ifov_rad: f64,
    /// Cruise ground speed, m/s.
    pub cruise_speed_mps: f64,
    /// Largest descent rate, m/s.
    pub descent_rate_mps: f64,
    /// Largest commanded acceleration per axis, m/s².
    pub accel_max_mps2: f64,
    /// TRN frames per second.
    pub frame_rate_hz: f64,
    /// IMU samples per second.
    pub imu_rate_hz: f64,
    /// No TRN below this height above terrain (frames too fine for the tile), m.
    pub min_fix_agl_m: f64,
    /// Below `min_fix_agl_m`, locate each frame on a keyframe of the flyer's own
    /// ([`nav_core::odometry`]) and feed the displacement to the filter.
    #[serde(default)]
    pub odometry: bool,
    /// No frames below this height above terrain, m (the last seconds before touchdown).
    #[serde(default)]
    pub min_frame_agl_m: f64,
    /// Consecutive odometry frames without a fix after which a new keyframe is captured.
    #[serde(default)]
    pub odometry_max_misses: usize,
    /// Map hazards in the final frames and fly to the safe site nearest the target
    /// ([`nav_core::hazard`]).
    #[serde(default)]
    pub hazard_avoidance: bool,
    /// Hazard maps are made from frames with pixels this fine or finer, m.
    #[serde(default)]
    pub hazard_max_pixel_m: f64,
    /// No new hazard map below this height above terrain, m (the aim must stay steady for the
    /// last metres).
    #[serde(default)]
    pub hazard_min_agl_m: f64,
    /// The lander's tolerances and the site choice's limits.
    #[serde(skip)]
    pub hazard: HazardConfig,
    /// Once a site is chosen, confirm it on one finer frame
    /// ([`nav_core::hazard::CONFIRM_MAX_PIXEL_M`] or finer): a map of the window around the
    /// aim ([`nav_core::hazard::HazardMap::build_around`]) under `hazard_confirm_cfg`, which
    /// keeps the aim or moves it a few metres.
    #[serde(default)]
    pub hazard_confirm: bool,
    /// The confirmation map's settings.
    #[serde(skip, default = "HazardConfig::confirmation")]
    pub hazard_confirm_cfg: HazardConfig,
    /// Shortest hop, m.
    pub hop_min_m: f64,
    /// Longest hop, m.
    pub hop_max_m: f64,
    /// 1σ of the initial horizontal position knowledge, m.
    pub release_sigma_m: f64,
    /// 1σ accelerometer bias of the unit (drawn per run), m/s².
    pub accel_bias_sigma: f64,
    /// 1σ gyro bias of the unit (drawn per run), rad/s.
    pub gyro_bias_sigma: f64,
    /// 1σ altimeter noise, m.
    pub altimeter_sigma_m: f64,
    /// 1σ star-tracker attitude noise per axis, rad (0: no star tracker). Without it, gyro bias
    /// tilts the estimated vertical and g·tilt drifts the position once TRN stops.
    pub star_tracker_sigma_rad: f64,
    /// 1σ Doppler-velocimeter noise per axis, m/s (0: none). Below the last TRN fix (frames too
    /// fine for the 20 m tile) only velocity aiding keeps the position from drifting.
    pub velocimeter_sigma_mps: f64,
    /// Ranging sensor.
    pub sensor: SensorModel,
    /// Filter noise model (also the IMU's simulated noise densities).
    #[serde(skip)]
    pub filter: FilterConfig,
}

impl Default for DescentConfig {
    fn default() -> Self {
        Self {
            cruise_agl_m: 3800.0,
            ifov_rad: 10.0 / 3800.0,
            cruise_speed_mps: 80.0,
            descent_rate_mps: 40.0,
            accel_max_mps2: 3.0,
            frame_rate_hz: 1.0,
            imu_rate_hz: 100.0,
            min_fix_agl_m: 2000.0,
            odometry: true,
            // 30 m: frame pixels of 8 cm, finer than any landing-zone DEM the ground makes.
            min_frame_agl_m: 30.0,
            odometry_max_misses: 3,
            hazard_avoidance: true,
            // 0.4 m pixels (152 m up): ten pixels across the 4 m footprint, range noise 4 cm.
            hazard_max_pixel_m: 0.4,
            hazard_min_agl_m: 60.0,
            hazard: HazardConfig::default(),
            hazard_confirm: true,
            hazard_confirm_cfg: HazardConfig::confirmation(),
            hop_min_m: 2000.0,
            hop_max_m: 15000.0,
            release_sigma_m: 100.0,
            accel_bias_sigma: 0.003,
            gyro_bias_sigma: 2e-5,
            altimeter_sigma_m: 1.0,
            // 10 arcsec, a common star-tracker class; PSRs still see the sky.
            star_tracker_sigma_rad: 4.8e-5,
            velocimeter_sigma_mps: 0.05,
            sensor: SensorModel::default(),
            filter: FilterConfig::default(),
        }
    }
}

/// One sample of a run's history (at the frame rate).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Sample {
    /// Time since release, s.
    pub t_s: f64,
    /// True position, m.
    pub truth_m: [f64; 3],
    /// Estimated position, m.
    pub est_m: [f64; 3],
    /// 1σ of east and north, m.
    pub sigma_m: [f64; 2],
    /// Horizontal NEES (χ² with 2 dof if consistent; ∞ for a singular covariance, read back
    /// from JSON as NaN).
    #[serde(deserialize_with = "f64_or_nan")]
    pub nees: f64,
    /// 0 no frame, 1 fix accepted, 2 fix rejected by the filter gate, 3 no fix; odometry: 4
    /// offset accepted, 5 offset rejected by the gate, 6 no offset, 7 keyframe captured.
    pub fix_state: u8,
    /// Fix position (if any), m.
    pub fix_m: Option<[f64; 2]>,
    /// Covariance of the fix (east/north, m²) as nav-core reported it: a TRN fix's own, or an
    /// odometry offset's (relative to the keyframe, whose error the filter carries).
    #[serde(default)]
    pub fix_cov_m2: Option<[[f64; 2]; 2]>,
    /// An odometry offset's displacement since the keyframe (east/north, m), as measured; its
    /// covariance is `fix_cov_m2`.
    #[serde(default)]
    pub offset_m: Option<[f64; 2]>,
}

/// Outcome of one hop. Undefined figures are NaN (JSON `null`, read back as NaN).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunResult {
    /// Run index.
    pub run: usize,
    /// Release point, m.
    pub release_m: [f64; 2],
    /// Target, m.
    pub target_m: [f64; 2],
    /// Hop length, m.
    #[serde(deserialize_with = "f64_or_nan")]
    pub hop_m: f64,
    /// Flight time, s.
    #[serde(deserialize_with = "f64_or_nan")]
    pub flight_s: f64,
    /// Over an atlas: TRN frames located on more than one tile (the frame straddled a tile
    /// edge and the first tile gave no fix).
    #[serde(default)]
    pub atlas_retries: usize,
    /// Over an atlas: times the tile a TRN frame's report came from changed.
    #[serde(default)]
    pub atlas_tile_switches: usize,
    /// Horizontal distance from the landing point to the spot aimed at, m, truth: the spot the
    /// last map that decided judged (the safe site it chose, or the ground under the aim it
    /// kept, as its frame saw it; a map that found no site leaves the spot before it); the
    /// target where no map decided.
    #[serde(deserialize_with = "f64_or_nan")]
    pub landing_err_m: f64,
    /// Horizontal navigation error at touchdown, m.
    #[serde(deserialize_with = "f64_or_nan")]
    pub nav_err_at_landing_m: f64,
    /// Horizontal navigation error at the last accepted fix, m.
    #[serde(deserialize_with = "f64_or_nan")]
    pub nav_err_at_last_fix_m: f64,
    /// Horizontal velocity error at the last accepted fix, m/s.
    #[serde(deserialize_with = "f64_or_nan")]
    pub vel_err_at_last_fix_mps: f64,
    /// Time from the last accepted fix or odometry offset to touchdown, s.
    #[serde(deserialize_with = "f64_or_nan")]
    pub unaided_s: f64,
    /// RMS horizontal navigation error over the flight (frame times), m.
    #[serde(deserialize_with = "f64_or_nan")]
    pub nav_err_rms_m: f64,
    /// Fixes accepted by the filter.
    pub fixes: usize,
    /// Fixes rejected by the filter's gate.
    pub rejected_fixes: usize,
    /// Frames without a fix.
    pub no_fixes: usize,
    /// Odometry offsets accepted by the filter.
    #[serde(default)]
    pub odometry_fixes: usize,
    /// Odometry offsets rejected by the filter's gate.
    #[serde(default)]
    pub odometry_rejected: usize,
    /// Odometry frames without a fix on the keyframe.
    #[serde(default)]
    pub odometry_none: usize,
    /// Keyframes captured.
    #[serde(default)]
    pub keyframes: usize,
    /// Σ over the offsets (all, before the filter's gate) of their NEES against the truth
    /// displacement under their own covariance (χ²(2) if the covariance is right: mean 2).
    #[serde(default)]
    pub offset_nees_sum: f64,
    /// Offsets whose NEES lies in the 95 % χ²(2) band.
    #[serde(default)]
    pub offsets_in_band: usize,
    /// Whether the touchdown spot is safe by the truth landing zone
    /// ([`crate::terrain::landing::site_safety`] with the default thresholds); `None` without a
    /// zone or off it.
    #[serde(default)]
    pub touchdown_safe: Option<bool>,
    /// Tilt of the ground plane under the touchdown footprint (truth), degrees.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub touchdown_slope_deg: f64,
    /// Largest height above or below that plane in the footprint (truth), m.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub touchdown_relief_m: f64,
    /// Whether the spot aimed at (the chosen site, truth) is itself safe: an unsafe touchdown on
    /// a safe site is the lander's dispersion, on an unsafe one the map's miss.
    #[serde(default)]
    pub site_safe: Option<bool>,
    /// Relief of the truth under the spot aimed at, m.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub site_relief_m: f64,
    /// Fraction of safe sites within [`TARGET_AREA_RADIUS_M`] of the target (1 m lattice, truth):
    /// the chance of a safe touchdown for a lander that does not look.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub target_area_safe_frac: f64,
    /// Fraction of safe sites within the site choice's reach of the target
    /// ([`HazardConfig::max_reach_m`], truth): the landing zone the lander can choose from.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub reach_safe_frac: f64,
    /// Distance from the target to the spot finally aimed at (the site the last map chose or
    /// kept, which includes the navigation error of that map's moment; 0 without a map), m,
    /// truth.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub site_from_target_m: f64,
    /// Hazard maps made.
    #[serde(default)]
    pub hazard_maps: usize,
    /// Times the aim moved to a new safe site.
    #[serde(default)]
    pub site_changes: usize,
    /// Maps on which the aim was unsafe and no safe site was within reach.
    #[serde(default)]
    pub hazard_no_site: usize,
    /// Confirmation maps made (finer frames, window around the chosen aim).
    #[serde(default)]
    pub confirm_maps: usize,
    /// Confirmation maps that moved the aim.
    #[serde(default)]
    pub confirm_moves: usize,
    /// Clearance of the spot finally aimed at on the flyer's own map that last judged it
    /// (kept, chosen, or left in place because nothing better was in reach; 0 if that map
    /// called it unsafe), m; NaN if no map judged it.
    #[serde(default = "nan", deserialize_with = "f64_or_nan")]
    pub site_clearance_m: f64,
    /// The last hazard map, then the last confirmation map (pictured run only).
    #[serde(skip)]
    pub hazard_pictures: Vec<HazardPicture>,
    /// Height above terrain of the last accepted measurement (fix or offset), m.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub last_aid_agl_m: f64,
    /// Fraction of frame times with the horizontal NEES inside the 95 % χ²(2) band.
    #[serde(deserialize_with = "f64_or_nan")]
    pub nees_in_band_frac: f64,
    /// Mean horizontal NEES (2 for a consistent filter; smaller: pessimistic covariance).
    #[serde(deserialize_with = "f64_or_nan")]
    pub nees_mean: f64,
    /// Frame times below the TRN floor (`min_fix_agl_m`): the final phase.
    #[serde(default)]
    pub final_samples: usize,
    /// Of those, frame times with the horizontal NEES inside the 95 % χ²(2) band.
    #[serde(default)]
    pub final_nees_in_band: usize,
    /// Mean horizontal NEES over the final phase.
    #[serde(default, deserialize_with = "f64_or_nan")]
    pub final_nees_mean: f64,
    /// History at the frame rate.
    #[serde(skip)]
    pub history: Vec<Sample>,
}

/// Sums over one run's history that a campaign summary needs, so that a campaign can be
/// summarised from per-run records without every run's history (shards keep only run 0's).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct HistoryTotals {
    /// Samples (frame times).
    pub samples: usize,
    /// Σ squared horizontal navigation error, m².
    pub sq_err_m2: f64,
    /// Samples with the horizontal NEES in the 95 % χ²(2) band.
    pub nees_in_band: usize,
    /// Σ of the finite horizontal NEES values.
    pub nees_finite_sum: f64,
}

/// The 95 % band of χ²(2): a consistent filter's horizontal NEES lies in it 95 % of the time.
pub const NEES2_BAND_95: std::ops::RangeInclusive<f64> = 0.0506..=7.378;

impl HistoryTotals {
    /// The totals of history `h`.
    pub fn of(h: &[Sample]) -> Self {
        Self {
            samples: h.len(),
            sq_err_m2: h
                .iter()
                .map(|s| (s.truth_m[0] - s.est_m[0]).powi(2) + (s.truth_m[1] - s.est_m[1]).powi(2))
                .sum(),
            nees_in_band: h.iter().filter(|s| NEES2_BAND_95.contains(&s.nees)).count(),
            nees_finite_sum: h.iter().map(|s| s.nees).filter(|v| v.is_finite()).sum(),
        }
    }
}

/// One hop as a campaign keeps it: its result, its history's totals and, for the run that is
/// pictured (run 0), its history.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DescentRecord {
    /// The hop's result (its `history` empty).
    pub result: RunResult,
    /// Totals over its history.
    pub totals: HistoryTotals,
    /// The history itself, kept for run 0 (its pictures), and for every run with `descent
    /// --histories`.
    pub history: Option<Vec<Sample>>,
    /// Run 0's last hazard and confirmation maps (their pictures), so merged shards draw them
    /// too.
    #[serde(default)]
    pub hazard_pictures: Vec<HazardPicture>,
}

impl DescentRecord {
    /// Keep `r`'s history totals, and its history if `keep_history`.
    pub fn new(mut r: RunResult, keep_history: bool) -> Self {
        let totals = HistoryTotals::of(&r.history);
        let history = std::mem::take(&mut r.history);
        let hazard = std::mem::take(&mut r.hazard_pictures);
        Self {
            result: r,
            totals,
            history: keep_history.then_some(history),
            hazard_pictures: if keep_history { hazard } else { Vec::new() },
        }
    }
}

/// Horizontal NEES of error `(ex, ey)` under covariance `c` (m²).
fn nees2(ex: f64, ey: f64, c: [[f64; 2]; 2]) -> f64 {
    let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
    if !(det > 0.0) {
        return f64::INFINITY;
    }
    (c[1][1] * ex * ex - (c[0][1] + c[1][0]) * ex * ey + c[0][0] * ey * ey) / det
}

fn normal(rng: &mut rand_pcg::Pcg64) -> f64 {
    let u: f64 = rng.random::<f64>().max(1e-300);
    let v: f64 = rng.random::<f64>();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// Fly one hop from `release` to `target` (east, north; metres) over `terrain`.
#[allow(clippy::too_many_arguments)]
pub fn fly(
    run: usize,
    terrain: &Terrain<'_>,
    nav: &MapNav<'_>,
    ws: &mut Workspace,
    cfg: &DescentConfig,
    release: [f64; 2],
    target: [f64; 2],
    seed: u64,
) -> anyhow::Result<RunResult> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let g = cfg.filter.gravity_mps2;
    let ground = |x: f64, y: f64| terrain.height_at(x, y) as f64;
    let z0 = ground(release[0], release[1]);
    if !z0.is_finite() {
        anyhow::bail!("release point outside the DEM");
    }
    let z_cruise = z0 + cfg.cruise_agl_m;
    let dt = 1.0 / cfg.imu_rate_hz;
    let frame_every = (cfg.imu_rate_hz / cfg.frame_rate_hz).round().max(1.0) as usize;
    // Truth state.
    let (mut p, mut v) = ([release[0], release[1], z_cruise], [0.0f64; 3]);
    let bearing = (target[1] - release[1]).atan2(target[0] - release[0]);
    let yaw0 = bearing + 0.3 * normal(&mut rng);
    let ba = [0, 1, 2].map(|_| cfg.accel_bias_sigma * normal(&mut rng));
    let bg = [0, 1, 2].map(|_| cfg.gyro_bias_sigma * normal(&mut rng));
    // Estimate.
    let init = InitialState {
        position_m: [
            p[0] + cfg.release_sigma_m * normal(&mut rng),
            p[1] + cfg.release_sigma_m * normal(&mut rng),
            p[2] + 5.0 * normal(&mut rng),
        ],
        velocity_mps: [0.0; 3],
        yaw_rad: yaw0 + 1f64.to_radians() * normal(&mut rng),
        position_sigma_m: cfg.release_sigma_m,
        velocity_sigma_mps: 0.2,
        attitude_sigma_rad: 1f64.to_radians(),
        accel_bias_sigma: cfg.accel_bias_sigma.max(1e-4),
        gyro_bias_sigma: cfg.gyro_bias_sigma.max(1e-7),
    };
    let mut filt = NavFilter::new(&init, cfg.filter);
    let (gx0, gy0, gpx, gpy) = nav.grid();
    let tile_px = nav.pixel_m();
    let mut out = RunResult {
        run,
        release_m: release,
        target_m: target,
        hop_m: (target[0] - release[0]).hypot(target[1] - release[1]),
        flight_s: 0.0,
        atlas_retries: 0,
        atlas_tile_switches: 0,
        landing_err_m: f64::NAN,
        nav_err_at_landing_m: f64::NAN,
        nav_err_at_last_fix_m: f64::NAN,
        vel_err_at_last_fix_mps: f64::NAN,
        unaided_s: f64::NAN,
        nav_err_rms_m: f64::NAN,
        fixes: 0,
        rejected_fixes: 0,
        no_fixes: 0,
        odometry_fixes: 0,
        odometry_rejected: 0,
        odometry_none: 0,
        keyframes: 0,
        offset_nees_sum: 0.0,
        offsets_in_band: 0,
        last_aid_agl_m: f64::NAN,
        site_from_target_m: f64::NAN,
        hazard_maps: 0,
        site_changes: 0,
        hazard_no_site: 0,
        confirm_maps: 0,
        confirm_moves: 0,
        site_clearance_m: f64::NAN,
        hazard_pictures: Vec::new(),
        touchdown_safe: None,
        touchdown_slope_deg: f64::NAN,
        touchdown_relief_m: f64::NAN,
        site_safe: None,
        site_relief_m: f64::NAN,
        target_area_safe_frac: f64::NAN,
        reach_safe_frac: f64::NAN,
        nees_in_band_frac: f64::NAN,
        nees_mean: f64::NAN,
        final_samples: 0,
        final_nees_in_band: 0,
        final_nees_mean: f64::NAN,
        history: Vec::new(),
    };
    let max_steps = (1800.0 * cfg.imu_rate_hz) as usize;
    let mut landed = false;
    let mut key = Box::new(GroundKeyframe::new());
    let mut last_tile: Option<u16> = None;
    let mut hazards = Box::new(GroundHazardMap::new());
    // Where guidance flies to (estimate space) and where that spot truly is.
    let (mut aim, mut aim_truth) = (target, target);
    // Last map and last confirmation, pictured.
    let (mut last_hazard, mut last_confirm) = (None, None);
    // The pictured run keeps its last hazard map.
    let keep_history = run == 0;
    // One decision: the first map that keeps the aim or finds a site fixes it. Later, finer
    // frames would only re-read the same ground with their own noise (measured: re-deciding on
    // every frame moved the aim 7 times in 8 maps and landed no safer), and each map costs the
    // frame's odometry.
    let mut site_chosen = false;
    // ... except one confirmation of the chosen site on a finer frame, judged with a smaller
    // sensing margin over a window around the aim: the 0.4 m map misses small rocks the finer
    // frame sees (`HazardConfig::confirmation`).
    let mut confirmed = false;
    // The frame after a map without a site rests from mapping.
    let mut map_rest = false;
    let mut final_nees_sum = 0.0;
    // The truth position of the keyframe, to score offsets (never seen by the flyer).
    let mut key_truth = [0.0f64; 2];
    let mut odo_misses = 0usize;
    for step in 1..=max_steps {
        let t = step as f64 * dt;
        // Yaw: the initial heading plus a slow ±10° sweep (exercises the gyro and rotation).
        let yaw = yaw0 + 10f64.to_radians() * (std::f64::consts::TAU * t / 60.0).sin();
        let yaw_rate = 10f64.to_radians() * std::f64::consts::TAU / 60.0
            * (std::f64::consts::TAU * t / 60.0).cos();
        // Guidance on the estimate.
        let pe = filt.position_m();
        let ve = filt.velocity_mps();
        let (dx, dy) = (aim[0] - pe[0], aim[1] - pe[1]);
        let dist = dx.hypot(dy);
        let agl_est = pe[2] - ground(pe[0], pe[1]).max(f64::MIN);
        // Cruise closes in gently; over the target (the descent phase) a firmer gain lets a
        // divert to a safe site settle within seconds, not the whole descent.
        let gain = if dist > 60.0 { 0.08 } else { 0.25 };
        let speed = cfg.cruise_speed_mps.min(gain * dist);
        let (vdx, vdy) = if dist > 1e-6 {
            (speed * dx / dist, speed * dy / dist)
        } else {
            (0.0, 0.0)
        };
        let mut a_cmd = [0.6 * (vdx - ve[0]), 0.6 * (vdy - ve[1]), 0.0];
        let vz_des = if dist > 60.0 {
            0.4 * (z_cruise - pe[2]).clamp(-cfg.descent_rate_mps, cfg.descent_rate_mps)
        } else {
            // Over the target: descend fast (drift without fixes grows with time), slowing near
            // the ground for touchdown.
            -(0.1 * agl_est.max(0.0)).clamp(1.5, cfg.descent_rate_mps)
        };
        a_cmd[2] = 0.8 * (vz_des - ve[2]);
        for a in &mut a_cmd {
            *a = a.clamp(-cfg.accel_max_mps2, cfg.accel_max_mps2);
        }
        // Truth dynamics: commanded acceleration plus a small disturbance.
        let a_true = [0, 1, 2].map(|k| a_cmd[k] + 0.005 * normal(&mut rng));
        for k in 0..3 {
            p[k] += v[k] * dt + 0.5 * a_true[k] * dt * dt;
            v[k] += a_true[k] * dt;
        }
        // IMU: specific force f = a − g in the body frame (level, yawed), plus bias and noise.
        let f_n = [a_true[0], a_true[1], a_true[2] + g];
        let (s, c) = yaw.sin_cos();
        let f_b = [c * f_n[0] + s * f_n[1], -s * f_n[0] + c * f_n[1], f_n[2]];
        let an = cfg.filter.accel_noise / dt.sqrt();
        let gn = cfg.filter.gyro_noise / dt.sqrt();
        let accel = [0, 1, 2].map(|k| f_b[k] + ba[k] + an * normal(&mut rng));
        let gyro = [
            bg[0] + gn * normal(&mut rng),
            bg[1] + gn * normal(&mut rng),
            yaw_rate + bg[2] + gn * normal(&mut rng),
        ];
        filt.propagate(dt, accel, gyro)
            .map_err(|e| anyhow::anyhow!("filter: {e}"))?;
        let agl = p[2] - ground(p[0], p[1]);
        if agl.is_nan() {
            anyhow::bail!("run {run}: the flyer left the DEM at t = {t:.1} s");
        }
        if agl <= 0.0 {
            landed = true;
            out.flight_s = t;
            break;
        }
        if step % frame_every != 0 {
            continue;
        }
        let mut fix_state = 0u8;
        let mut fix_m = None;
        let mut fix_cov_m2 = None;
        let mut offset_m = None;
        filt.update_altitude(
            p[2] + cfg.altimeter_sigma_m * normal(&mut rng),
            cfg.altimeter_sigma_m,
        )
        .map_err(|e| anyhow::anyhow!("filter: {e}"))?;
        if cfg.velocimeter_sigma_mps > 0.0 {
            let sv = cfg.velocimeter_sigma_mps;
            filt.update_velocity([0, 1, 2].map(|k| v[k] + sv * normal(&mut rng)), sv)
                .map_err(|e| anyhow::anyhow!("filter: {e}"))?;
        }
        if cfg.star_tracker_sigma_rad > 0.0 {
            let st = cfg.star_tracker_sigma_rad;
            filt.update_attitude(
                st * normal(&mut rng),
                st * normal(&mut rng),
                yaw + st * normal(&mut rng),
                st,
            )
            .map_err(|e| anyhow::anyhow!("filter: {e}"))?;
        }
        // The sensor looks straight down from the truth position; its pixel grows with height.
        let frame_pose = |p: [f64; 3], yaw: f64, agl: f64| {
            let pixel_m = agl * cfg.ifov_rad;
            let pose = FramePose {
                x_m: p[0],
                y_m: p[1],
                heading_rad: -yaw,
                pixel_m,
            };
            (pixel_m, pose)
        };
        if agl >= cfg.min_fix_agl_m {
            let (pixel_m, pose) = frame_pose(p, yaw, agl);
            if let Ok(frame) = synth_frame_on(terrain, &pose, &cfg.sensor, rng.random::<u64>()) {
                let pe = filt.position_m();
                let pc = filt.horizontal_cov_m2();
                let prior = Prior {
                    center_tile_px: [((pe[0] - gx0) / gpx) as f32, ((pe[1] - gy0) / gpy) as f32],
                    sigma_px: (pc[0][0].max(pc[1][1]).sqrt() / tile_px) as f32,
                    heading_rad: (-filt.yaw_rad()) as f32,
                    heading_sigma_rad: filt.yaw_sigma_rad().max(0.5f64.to_radians()) as f32,
                    scale: (pixel_m / tile_px) as f32,
                    scale_sigma: 0.02,
                };
                let r = nav.locate(
                    ws,
                    (&frame.heights_m, frame.width, frame.height, pixel_m),
                    &prior,
                )?;
                if let Some((t, tried)) = r.atlas_tile {
                    out.atlas_retries += usize::from(tried > 1);
                    out.atlas_tile_switches += usize::from(last_tile.is_some_and(|l| l != t));
                    last_tile = Some(t);
                }
                match r.outcome {
                    Some(Ok(f)) => {
                        // The fix's own covariance as nav-core reports it; the filter models
                        // the correlation of successive fixes over the same ground.
                        let cg = f.center_cov_geo_m2;
                        let m = FixMeasurement {
                            x_m: f.center_geo_m[0],
                            y_m: f.center_geo_m[1],
                            yaw_rad: -f.similarity.rotation_rad,
                            position_cov_m2: cg,
                            yaw_sigma_rad: f.heading_sigma_rad,
                            footprint_m: cfg.sensor.width_px.max(cfg.sensor.height_px) as f64
                                * pixel_m,
                            // The map's noise against this frame's own, at its pixel.
                            map_share: map_noise_share(
                                f.map_noise_power_m4,
                                cfg.sensor.range_noise_at(pixel_m),
                                pixel_m,
                            ),
                        };
                        fix_m = Some(f.center_geo_m);
                        fix_cov_m2 = Some(cg);
                        match filt
                            .update_fix(&m)
                            .map_err(|e| anyhow::anyhow!("filter: {e}"))?
                        {
                            UpdateOutcome::Accepted { .. } => {
                                out.fixes += 1;
                                fix_state = 1;
                                let (pe, ve) = (filt.position_m(), filt.velocity_mps());
                                out.nav_err_at_last_fix_m = (p[0] - pe[0]).hypot(p[1] - pe[1]);
                                out.vel_err_at_last_fix_mps = (v[0] - ve[0]).hypot(v[1] - ve[1]);
                                out.unaided_s = t;
                                out.last_aid_agl_m = agl;
                            }
                            UpdateOutcome::Rejected { .. } => {
                                out.rejected_fixes += 1;
                                fix_state = 2;
                            }
                        }
                    }
                    Some(Err(_)) | None => {
                        out.no_fixes += 1;
                        fix_state = 3;
                    }
                }
            }
        } else if (cfg.odometry || cfg.hazard_avoidance) && agl >= cfg.min_frame_agl_m {
            let (pixel_m, pose) = frame_pose(p, yaw, agl);
            if let Ok(frame) = synth_frame_on(terrain, &pose, &cfg.sensor, rng.random::<u64>()) {
                let input = (&frame.heights_m[..], frame.width, frame.height, pixel_m);
                let yaw_sigma = filt.yaw_sigma_rad();
                // A frame does one job, as on the flight target: a hazard map (≈ 7–15 M
                // instructions) beside a keyframe capture (≈ 13.7 M) would break the 20 M budget
                // (docs/bounds.md), so the map's frame gives up its odometry.
                let map_window = cfg.hazard_avoidance
                    && !site_chosen
                    && pixel_m <= cfg.hazard_max_pixel_m
                    && agl >= cfg.hazard_min_agl_m;
                let confirm_due = cfg.hazard_avoidance
                    && cfg.hazard_confirm
                    && site_chosen
                    && !confirmed
                    && pixel_m <= f64::from(CONFIRM_MAX_PIXEL_M)
                    && agl >= cfg.hazard_min_agl_m;
                // After a map that found no site, the next frame goes to odometry: retrying on
                // every frame would leave the filter unaided down to the last map's height.
                let map_due = (map_window || confirm_due) && !map_rest;
                map_rest = false;
                if !cfg.odometry || map_due {
                    // Frames for the hazard map only.
                } else if key.needs_refresh(pixel_m) || odo_misses >= cfg.odometry_max_misses {
                    let kp = KeyframePose {
                        heading_rad: -filt.yaw_rad(),
                        heading_sigma_rad: yaw_sigma,
                        pixel_m,
                        pixel_rel_sigma: KEYFRAME_PIXEL_REL_SIGMA,
                    };
                    let surf = nav.surf_config();
                    if capture_keyframe(ws, &mut key, input, &kp, &surf).is_ok() {
                        filt.set_keyframe();
                        key_truth = [p[0], p[1]];
                        out.keyframes += 1;
                        odo_misses = 0;
                        fix_state = 7;
                    }
                } else if let (Some(k0), Some(kc)) =
                    (filt.keyframe_position_m(), filt.offset_cov_m2())
                {
                    let pe = filt.position_m();
                    let prior = key
                        .prior(
                            [pe[0] - k0[0], pe[1] - k0[1]],
                            kc,
                            -filt.yaw_rad(),
                            yaw_sigma.max(0.5f64.to_radians()),
                            pixel_m,
                            KEYFRAME_PIXEL_REL_SIGMA,
                        )
                        .map_err(|e| anyhow::anyhow!("odometry: {e}"))?;
                    let r = run_odometry(&key, nav.nav_config(), ws, input, &prior)
                        .map_err(|e| anyhow::anyhow!("odometry: {e}"))?;
                    match r.offset {
                        Some(o) => {
                            // Scored against the truth displacement since the keyframe.
                            let (tx, ty) = (p[0] - key_truth[0], p[1] - key_truth[1]);
                            let n = nees2(o.east_m - tx, o.north_m - ty, o.cov_m2);
                            out.offset_nees_sum += n;
                            out.offsets_in_band += usize::from(NEES2_BAND_95.contains(&n));
                            odo_misses = 0;
                            fix_m = Some([k0[0] + o.east_m, k0[1] + o.north_m]);
                            fix_cov_m2 = Some(o.cov_m2);
                            offset_m = Some([o.east_m, o.north_m]);
                            let m = OffsetMeasurement {
                                east_m: o.east_m,
                                north_m: o.north_m,
                                cov_m2: o.cov_m2,
                                footprint_m: o.footprint_m,
                            };
                            match filt
                                .update_offset(&m)
                                .map_err(|e| anyhow::anyhow!("filter: {e}"))?
                            {
                                UpdateOutcome::Accepted { .. } => {
                                    out.odometry_fixes += 1;
                                    out.last_aid_agl_m = agl;
                                    out.unaided_s = t;
                                    fix_state = 4;
                                }
                                UpdateOutcome::Rejected { .. } => {
                                    out.odometry_rejected += 1;
                                    fix_state = 5;
                                }
                            }
                        }
                        None => {
                            odo_misses += 1;
                            out.odometry_none += 1;
                            fix_state = 6;
                        }
                    }
                }
                if map_due {
                    let dem = nav_core::DemPatch::new_checked(
                        &frame.heights_m,
                        frame.width,
                        frame.height,
                        pixel_m as f32,
                    )
                    .map_err(|e| anyhow::anyhow!("hazard frame: {e}"))?;
                    let pe = filt.position_m();
                    let h_est = -filt.yaw_rad();
                    let (w, hh) = (frame.width, frame.height);
                    let aim_now =
                        en_to_frame_px([aim[0] - pe[0], aim[1] - pe[1]], h_est, pixel_m, w, hh);
                    // One decision, as the target makes it (`HazardMap::decide`): the first
                    // map keeps an aim safe with its clearance, else moves it near the target;
                    // the confirmation (`HazardMap::confirm`) maps the window around the aim
                    // and moves it only a few metres from there.
                    let target_px = en_to_frame_px(
                        [target[0] - pe[0], target[1] - pe[1]],
                        h_est,
                        pixel_m,
                        w,
                        hh,
                    );
                    let made = if confirm_due {
                        hazards.confirm(&dem, &cfg.hazard_confirm_cfg, aim_now)
                    } else {
                        hazards
                            .build(&dem, &cfg.hazard)
                            .map(|stats| (stats, hazards.decide(aim_now, target_px, &cfg.hazard)))
                    };
                    if let Ok((_, decision)) = made {
                        if confirm_due {
                            out.confirm_maps += 1;
                        } else {
                            out.hazard_maps += 1;
                        }
                        match decision {
                            AimDecision::Keep { clearance_m } => {
                                out.site_clearance_m = f64::from(clearance_m);
                                // The spot this map judged is the one under the aim in its
                                // frame, as for a move: the aim, off by the navigation error
                                // of the moment. Scoring a kept aim against the target instead
                                // counted that error for kept aims alone (session 36).
                                let dt = frame_px_to_en(aim_now, -yaw, pixel_m, w, hh);
                                aim_truth = [p[0] + dt[0], p[1] + dt[1]];
                                confirmed |= confirm_due;
                                site_chosen = true;
                            }
                            AimDecision::Move(site) => {
                                if confirm_due {
                                    confirmed = true;
                                    out.confirm_moves += 1;
                                }
                                out.site_clearance_m = f64::from(site.clearance_m);
                                let d = frame_px_to_en(site.frame_px, h_est, pixel_m, w, hh);
                                aim = [pe[0] + d[0], pe[1] + d[1]];
                                // Where that spot truly is: the frame is centred on the truth.
                                let dt = frame_px_to_en(site.frame_px, -yaw, pixel_m, w, hh);
                                aim_truth = [p[0] + dt[0], p[1] + dt[1]];
                                out.site_changes += 1;
                                site_chosen = true;
                            }
                            AimDecision::NoSite => {
                                // The aim stays: this map judged it last (0 if unsafe here).
                                let (i, j) = hazards.nearest_site(aim_now);
                                out.site_clearance_m = f64::from(hazards.clearance_m(i, j));
                                out.hazard_no_site += 1;
                                map_rest = true;
                            }
                        }
                        if keep_history {
                            let pic = Some(HazardPicture {
                                heights_m: frame.heights_m.clone(),
                                width: w,
                                height: hh,
                                safe: (0..hazards.size().1)
                                    .flat_map(|j| (0..hazards.size().0).map(move |i| (i, j)))
                                    .map(|(i, j)| hazards.is_safe(i, j))
                                    .collect(),
                                lattice: hazards.size(),
                                site_px: hazards.site_px(0, 0),
                                step_px: hazards.site_px(1, 1)[0] - hazards.site_px(0, 0)[0],
                                aim_px: en_to_frame_px(
                                    [aim[0] - pe[0], aim[1] - pe[1]],
                                    h_est,
                                    pixel_m,
                                    w,
                                    hh,
                                ),
                                // A confirmation's "before" is the aim it was given.
                                target_px: if confirm_due { aim_now } else { target_px },
                                pixel_m,
                                confirmation: confirm_due,
                            });
                            if confirm_due {
                                last_confirm = pic;
                            } else {
                                last_hazard = pic;
                            }
                        }
                    }
                }
            }
        }
        let pe = filt.position_m();
        let c = filt.horizontal_cov_m2();
        if agl < cfg.min_fix_agl_m {
            let n = nees2(p[0] - pe[0], p[1] - pe[1], c);
            out.final_samples += 1;
            out.final_nees_in_band += usize::from(NEES2_BAND_95.contains(&n));
            if n.is_finite() {
                final_nees_sum += n;
            }
        }
        out.history.push(Sample {
            t_s: t,
            truth_m: p,
            est_m: pe,
            sigma_m: [c[0][0].max(0.0).sqrt(), c[1][1].max(0.0).sqrt()],
            nees: nees2(p[0] - pe[0], p[1] - pe[1], c),
            fix_state,
            fix_m,
            fix_cov_m2,
            offset_m,
        });
    }
    if !landed {
        anyhow::bail!("run {run}: no touchdown within 30 minutes");
    }
    let pe = filt.position_m();
    out.landing_err_m = (p[0] - aim_truth[0]).hypot(p[1] - aim_truth[1]);
    out.site_from_target_m = (aim_truth[0] - target[0]).hypot(aim_truth[1] - target[1]);
    out.hazard_pictures = last_hazard.into_iter().chain(last_confirm).collect();
    if let Some(zone) = terrain.zone {
        let t = SafetyThresholds::default();
        if let Some(s) = site_safety(zone, p[0], p[1], &t) {
            out.touchdown_safe = Some(s.safe);
            out.touchdown_slope_deg = s.slope_deg;
            out.touchdown_relief_m = s.relief_m;
        }
        if let Some(s) = site_safety(zone, aim_truth[0], aim_truth[1], &t) {
            out.site_safe = Some(s.safe);
            out.site_relief_m = s.relief_m;
        }
        out.target_area_safe_frac = area_safe_fraction(zone, target, TARGET_AREA_RADIUS_M, &t);
        out.reach_safe_frac =
            area_safe_fraction(zone, target, f64::from(cfg.hazard.max_reach_m), &t);
    }
    out.nav_err_at_landing_m = (p[0] - pe[0]).hypot(p[1] - pe[1]);
    out.unaided_s = out.flight_s - out.unaided_s;
    let h = &out.history;
    let n = h.len().max(1) as f64;
    out.nav_err_rms_m = (h
        .iter()
        .map(|s| (s.truth_m[0] - s.est_m[0]).powi(2) + (s.truth_m[1] - s.est_m[1]).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    out.nees_in_band_frac = h.iter().filter(|s| NEES2_BAND_95.contains(&s.nees)).count() as f64 / n;
    out.nees_mean = h.iter().map(|s| s.nees).sum::<f64>() / n;
    out.final_nees_mean = final_nees_sum / out.final_samples.max(1) as f64;
    Ok(out)
}
