//! Error-state Kalman filter fusing IMU propagation with TRN fixes (and altitude).
//!
//! Navigation frame: local flat-Moon East-North-Up (x east, y north, z up, metres), gravity
//! along −z. Body frame: x forward, y left, z up. Nominal state: position, velocity, attitude
//! (unit quaternion body → nav), accelerometer bias, gyro bias, the error of the current TRN
//! fix and its drift with footprint size. Error state ([`STATE_DIM`]): δp, δv, δθ (small
//! rotation in the nav frame, `q_true = exp(δθ) ⊗ q`), δb_a, δb_g, δf (the fix error: east m,
//! north m, yaw rad), δk (a keyframe's position, for odometry offsets) and δd (east, north m per
//! unit log footprint side).
//!
//! Why a fix-error state: successive frames at 1 Hz image mostly the same ground (a 2 km
//! footprint moves ~80 m per frame), so their fix errors, which come from that ground and from
//! the map under it, are nearly the same error seen again. A filter that took each fix as
//! independent would average them down and grow confident in a shared error. Here the fix
//! error has two parts. The ground's share ([`FilterConfig::fix_shared_fraction`] `s` of the
//! fix's covariance `C`) is a first-order Gauss–Markov process over the ground: between two
//! fixes it keeps the fraction `ρ` = the overlap of their footprints
//! ([`footprint_correlation`]) and gains fresh error with covariance `(1 − ρ²)·s·C`, more when
//! the new fix's share `s·C` exceeds what the process carries (fixes grow less precise as a
//! descent's frames get finer; see `NavFilter::move_fix_error`). The rest,
//! `(1 − s)·C`, is the frame's own (its range noise, which keypoints it kept) and is white. A
//! fix from new ground (`ρ = 0`) is an ordinary independent measurement of covariance `C`; a
//! fix of the same ground adds only its white part's worth. `s` is the larger of the default
//! and the fix's [`FixMeasurement::map_share`]: over a noisy map (InSAR) nearly all of a fix's
//! error is the map's ([`map_noise_share`]).
//!
//! As a descent's footprint shrinks, the ground error changes smoothly (the map's error is
//! averaged over less ground), in one direction over many fixes. The Gauss–Markov step takes
//! its changes as independent, so without a velocimeter the filter read the trend as a
//! velocity error and trusted it. The drift state δd carries the trend instead: at each fix the
//! ground error moves by `Δℓ·δd` (`Δℓ` the change of log footprint side), and δd is itself a
//! Gauss–Markov process (over Δℓ, and restarting with the footprints' overlap like δf) of
//! size [`FilterConfig::fix_scale_drift`] × the ground error's σ.
//!
//! Yaw ψ is the rotation of the body x axis about +z from +x (east) towards +y (north). A TRN
//! fix's heading measured in a north-up tile's pixel axes (from +x towards +y = south) is −ψ.
//!
//! Everything is `f64`, bounded (fixed-size matrices, no loops beyond their size) and
//! deterministic. Updates are gated on the normalised innovation squared (NIS).

use core::fmt;
use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

/// Error-state size: δp, δv, δθ, δb_a, δb_g (3 each), the fix error δf (east, north, yaw),
/// the keyframe position δk (east, north) and the fix error's drift with footprint size δd
/// (east, north).
pub const STATE_DIM: usize = 22;
type MatN = SMatrix<f64, STATE_DIM, STATE_DIM>;
/// Index of the fix-error block in the error state.
const FIX: usize = 15;
/// Index of the keyframe-position block in the error state.
const KEY: usize = 18;
/// Index of the fix-error drift block (east, north) in the error state.
const DRIFT: usize = 20;
/// Correlation length of the fix-error drift in log footprint side: the drift's correlation
/// between two footprints whose sides differ by the factor `e^Δℓ` is `e^(−|Δℓ|/L)`. Chosen,
/// not fitted: the measured change stayed smooth up to Δℓ = 0.32, the largest span measured
/// (docs/registration.md, session 33), so L is above that; 0.5 was the only value flown.
const DRIFT_LENGTH_LN: f64 = 0.5;
/// Largest footprint correlation used: a fix always carries some fresh error (the frame's own
/// range noise is new each time), so its covariance never vanishes.
pub const MAX_FIX_CORRELATION: f64 = 0.999;

/// Noise and gating settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FilterConfig {
    /// Accelerometer white noise density, m/s²/√Hz.
    pub accel_noise: f64,
    /// Gyro white noise density, rad/s/√Hz.
    pub gyro_noise: f64,
    /// Accelerometer bias random walk, m/s³/√Hz.
    pub accel_bias_walk: f64,
    /// Gyro bias random walk, rad/s²/√Hz.
    pub gyro_bias_walk: f64,
    /// Lunar gravity magnitude, m/s².
    pub gravity_mps2: f64,
    /// NIS gate for a 3-dof TRN fix (x, y, ψ); 16.27 is the 99.9 % point of χ²(3).
    pub fix_gate_chi2: f64,
    /// NIS gate for a 1-dof altitude update; 10.83 is the 99.9 % point of χ²(1).
    pub altitude_gate_chi2: f64,
    /// Longest accepted propagation step, s.
    pub max_dt_s: f64,
    /// Share of a TRN fix's covariance that belongs to the ground under the frame (kept by
    /// the next fix in proportion to the footprints' overlap); the rest is the frame's own
    /// error, new at every fix. In [0, 1]. Session 9 measured successive fix errors over truth
    /// tiles correlating 0.94 (LOLA-like terrain) and 0.6 (plains) and chose an even split.
    /// Re-measured in session 33 on the 16 km descents' histories, after the dense refinement
    /// and the area search changed how fixes err: over truth-built tiles successive errors are
    /// now nearly independent (their mean squared change one second apart is 1.4–1.6 of the 2
    /// independence gives), so 0.5 is conservative there; over InSAR maps 95–98 % of a fix's
    /// error is still there a second later. It is a floor: a fix over a map with its own
    /// height noise carries the larger [`FixMeasurement::map_share`] on position.
    pub fix_shared_fraction: f64,
    /// How fast the ground error of a fix changes as the footprint shrinks or grows: the 1σ
    /// change per e-fold of footprint side, in units of the ground error's own 1σ. Shrinking a
    /// footprint averages the map's error over less ground, which changes the fix error
    /// smoothly, in one direction over many fixes; a filter without this drift (and without a
    /// velocimeter) reads it as velocity. 0 disables the drift state. Measured on the 16 km
    /// InSAR descents (session 33, docs/registration.md): over a 0.18–0.32 change of log
    /// footprint side, beyond what the lag alone moved it, the fix error moved by 1–2.2 of its
    /// σ per unit; 2 takes the upper end. Keyframe offsets drift alike (flown without: no
    /// better landings, a lower final-phase NEES).
    pub fix_scale_drift: f64,
}

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            accel_noise: 3.0e-3,
            gyro_noise: 5.0e-5,
            accel_bias_walk: 1.0e-4,
            gyro_bias_walk: 1.0e-6,
            gravity_mps2: 1.62,
            fix_gate_chi2: 16.27,
            altitude_gate_chi2: 10.83,
            max_dt_s: 1.0,
            fix_shared_fraction: 0.5,
            fix_scale_drift: 2.0,
        }
    }
}

/// Initial estimate and its 1σ uncertainties.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InitialState {
    /// Position, m (ENU).
    pub position_m: [f64; 3],
    /// Velocity, m/s (ENU).
    pub velocity_mps: [f64; 3],
    /// Yaw ψ, rad (roll and pitch start at 0).
    pub yaw_rad: f64,
    /// 1σ position, m (per axis).
    pub position_sigma_m: f64,
    /// 1σ velocity, m/s (per axis).
    pub velocity_sigma_mps: f64,
    /// 1σ attitude, rad (per axis).
    pub attitude_sigma_rad: f64,
    /// 1σ accelerometer bias, m/s².
    pub accel_bias_sigma: f64,
    /// 1σ gyro bias, rad/s.
    pub gyro_bias_sigma: f64,
}

/// A TRN fix as a measurement in the navigation frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixMeasurement {
    /// East, m.
    pub x_m: f64,
    /// North, m.
    pub y_m: f64,
    /// Yaw ψ, rad.
    pub yaw_rad: f64,
    /// Position covariance, m² (row-major 2 × 2, east/north).
    pub position_cov_m2: [[f64; 2]; 2],
    /// 1σ yaw, rad.
    pub yaw_sigma_rad: f64,
    /// Side of the frame's footprint on the ground, m (frame width × ground pixel): how far
    /// the flyer must move before the next fix sees new ground. 0 or less: this fix's error is
    /// independent of the previous fix's.
    pub footprint_m: f64,
    /// Share of the covariance that comes from the map's own height noise, in [0, 1]
    /// ([`map_noise_share`]; 0 on a map that claims none). That error belongs to the ground
    /// too: the filter carries the larger of this and
    /// [`FilterConfig::fix_shared_fraction`] as shared. Non-finite values are refused.
    pub map_share: f64,
}

/// Share of a fix's error due to the map's own height noise rather than the frame's: the two
/// white noises' powers per unit area, `m` = [`crate::TileHeader::noise_power_m4`] (m⁴) and
/// the frame's range noise `frame_noise_m`² × its ground pixel `frame_pixel_m`², compared as
/// `m / (m + f)`. Both go through the same smoothing and slope before registration, which
/// scales them alike, so their ratio is the ratio of what they leave in the fix. In [0, 1]; 0
/// without map noise or for non-finite or negative input (or a pixel of 0), 1 for a noiseless
/// frame over a noisy map.
///
/// Why it matters: on InSAR maps successive fixes' errors are nearly all the map's (their
/// mean squared fix-to-fix change is 3–10 % of their variance at one fix per second, against
/// 70–80 % of the 2 independent errors give over
/// truth-built tiles; docs/registration.md, session 33), so averaging them as if half were new
/// each time made the filter overconfident.
pub fn map_noise_share(map_noise_power_m4: f64, frame_noise_m: f64, frame_pixel_m: f64) -> f64 {
    let m = map_noise_power_m4;
    let f = frame_noise_m * frame_noise_m * frame_pixel_m * frame_pixel_m;
    let frame_ok = frame_noise_m >= 0.0 && frame_pixel_m > 0.0 && f.is_finite();
    if !(m.is_finite() && m > 0.0 && frame_ok) {
        return 0.0;
    }
    (m / (m + f)).clamp(0.0, 1.0)
}

/// A keyframe-relative fix (odometry): the flyer's horizontal displacement since the keyframe
/// was captured ([`NavFilter::set_keyframe`]), in the navigation frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OffsetMeasurement {
    /// East displacement, m.
    pub east_m: f64,
    /// North displacement, m.
    pub north_m: f64,
    /// Covariance, m² (row-major 2 × 2, east/north).
    pub cov_m2: [[f64; 2]; 2],
    /// Side of the frame's footprint on the ground, m: successive offsets against the same
    /// keyframe share that keyframe's own error, modelled like successive TRN fixes (see the
    /// module docs) with the footprints' overlap as correlation.
    pub footprint_m: f64,
}

/// Correlation of the errors of two fixes whose square footprints (centres in metres, sides
/// `side_a`, `side_b` in metres) overlap: the shared area over the geometric mean of the two
/// areas, in [0, [`MAX_FIX_CORRELATION`]]. 0 for disjoint footprints or a non-positive side.
pub fn footprint_correlation(a: [f64; 2], side_a: f64, b: [f64; 2], side_b: f64) -> f64 {
    if !(side_a > 0.0 && side_b > 0.0) {
        return 0.0;
    }
    let overlap = |ca: f64, cb: f64| {
        let lo = (ca - 0.5 * side_a).max(cb - 0.5 * side_b);
        let hi = (ca + 0.5 * side_a).min(cb + 0.5 * side_b);
        (hi - lo).max(0.0)
    };
    let shared = overlap(a[0], b[0]) * overlap(a[1], b[1]);
    let rho = shared / (side_a * side_b);
    if rho.is_finite() {
        rho.clamp(0.0, MAX_FIX_CORRELATION)
    } else {
        0.0
    }
}

/// What an update did.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdateOutcome {
    /// Applied; normalised innovation squared.
    Accepted {
        /// NIS of the innovation.
        nis: f64,
    },
    /// Refused by the gate (an outlier fix); the state is unchanged.
    Rejected {
        /// NIS of the innovation.
        nis: f64,
    },
}

/// Why the filter refused an input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FilterError {
    /// Non-finite input.
    NotFinite,
    /// Time step not in (0, `max_dt_s`].
    BadTimeStep,
    /// Innovation covariance not positive definite (bad measurement covariance).
    Singular,
    /// A keyframe-relative update before any keyframe was set.
    NoKeyframe,
}

impl fmt::Display for FilterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NotFinite => "non-finite input",
            Self::BadTimeStep => "time step out of range",
            Self::Singular => "innovation covariance not positive definite",
            Self::NoKeyframe => "offset update without a keyframe",
        })
    }
}
impl core::error::Error for FilterError {}

/// The error-state Kalman filter.
#[derive(Debug, Clone)]
pub struct NavFilter {
    p: Vector3<f64>,
    v: Vector3<f64>,
    q: UnitQuaternion<f64>,
    ba: Vector3<f64>,
    bg: Vector3<f64>,
    /// Estimated error of the current fix (east m, north m, yaw rad).
    fix_err: Vector3<f64>,
    /// Centre (east, north, m) and side (m) of the last fix's footprint; side 0: none yet.
    last_fix: ([f64; 2], f64),
    /// Modelled prior variance of the current fix's ground error (east m², north m², yaw rad²),
    /// before any update: the floor the top-up of [`Self::move_fix_error`] compares a new fix's
    /// share with. The carried covariance after updates is smaller.
    fix_ground_var: [f64; 3],
    /// Estimated drift of the fix error per unit log footprint side (east, north, m).
    fix_drift: [f64; 2],
    /// Modelled prior variance of the drift (east, north, m²), as `fix_ground_var`.
    drift_var: [f64; 2],
    /// Horizontal position (east, north, m) cloned at the current keyframe, if any.
    key: Option<[f64; 2]>,
    cov: MatN,
    cfg: FilterConfig,
}

fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// Element `(i, j)` (0 outside the matrix, which the fixed sizes rule out).
fn at<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>, i: usize, j: usize) -> f64 {
    m.get((i, j)).copied().unwrap_or(0.0)
}

fn wrap_pi(a: f64) -> f64 {
    libm::remainder(a, core::f64::consts::TAU)
}

/// The shared part of a fix covariance `cf` (east, north, yaw) for shares `[s_xy, s_yaw]`:
/// `S^½·cf·S^½` with `S = diag(s_xy, s_xy, s_yaw)` (within a block that is the block times its
/// share, exactly).
fn split(cf: &Matrix3<f64>, shared: [f64; 2]) -> Matrix3<f64> {
    let [sxy, syaw] = shared;
    Matrix3::from_fn(|i, j| {
        let s = match (i < 2, j < 2) {
            (true, true) => sxy,
            (false, false) => syaw,
            _ => libm::sqrt(sxy * syaw),
        };
        cf.get((i, j)).copied().unwrap_or(0.0) * s
    })
}

/// One Gauss–Markov step of a modelled prior variance `model` towards `target` with
/// correlation `r` (`model ← r²·model + (1 − r²)·target`), except that a target above the
/// model (or a non-finite model) resets it to the target: the new error is the carried one plus
/// an independent part. Returns the variance to add beyond the plain step's `(1 − r²)·target`:
/// `r²·(target − model)` on such a reset, else 0.
fn top_up(model: &mut f64, target: f64, r: f64) -> f64 {
    if target > *model || !model.is_finite() {
        let extra = if model.is_finite() {
            r * r * (target - *model)
        } else {
            0.0
        };
        *model = target;
        extra
    } else {
        *model = r * r * *model + (1.0 - r * r) * target;
        0.0
    }
}

fn finite3(a: &[f64; 3]) -> bool {
    a.iter().all(|v| v.is_finite())
}

impl NavFilter {
    /// Filter at the initial estimate.
    pub fn new(init: &InitialState, cfg: FilterConfig) -> Self {
        let sig = [
            init.position_sigma_m,
            init.velocity_sigma_mps,
            init.attitude_sigma_rad,
            init.accel_bias_sigma,
            init.gyro_bias_sigma,
        ];
        let cov = MatN::from_fn(|i, j| {
            let s = sig.get(i / 3).copied().unwrap_or(0.0);
            if i == j { s * s } else { 0.0 }
        });
        Self {
            p: Vector3::from(init.position_m),
            v: Vector3::from(init.velocity_mps),
            q: UnitQuaternion::from_euler_angles(0.0, 0.0, init.yaw_rad),
            ba: Vector3::zeros(),
            bg: Vector3::zeros(),
            fix_err: Vector3::zeros(),
            last_fix: ([0.0; 2], 0.0),
            fix_ground_var: [0.0; 3],
            fix_drift: [0.0; 2],
            drift_var: [0.0; 2],
            key: None,
            cov,
            cfg,
        }
    }

    /// Position estimate, m (ENU).
    pub fn position_m(&self) -> [f64; 3] {
        self.p.into()
    }
    /// Velocity estimate, m/s (ENU).
    pub fn velocity_mps(&self) -> [f64; 3] {
        self.v.into()
    }
    /// Yaw estimate ψ, rad in (−π, π].
    pub fn yaw_rad(&self) -> f64 {
        self.q.euler_angles().2
    }
    /// Accelerometer bias estimate, m/s².
    pub fn accel_bias(&self) -> [f64; 3] {
        self.ba.into()
    }
    /// Gyro bias estimate, rad/s.
    pub fn gyro_bias(&self) -> [f64; 3] {
        self.bg.into()
    }
    /// Horizontal position covariance, m² (east/north).
    pub fn horizontal_cov_m2(&self) -> [[f64; 2]; 2] {
        let c = &self.cov;
        [[at(c, 0, 0), at(c, 0, 1)], [at(c, 1, 0), at(c, 1, 1)]]
    }
    /// Full 3-D position covariance, m².
    pub fn position_cov_m2(&self) -> [[f64; 3]; 3] {
        let mut c = [[0.0; 3]; 3];
        for (i, row) in c.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = at(&self.cov, i, j);
            }
        }
        c
    }
    /// 1σ yaw, rad.
    pub fn yaw_sigma_rad(&self) -> f64 {
        libm::sqrt(at(&self.cov, 8, 8).max(0.0))
    }

    /// Propagate by `dt_s` with the IMU's specific force (m/s², body) and angular rate
    /// (rad/s, body), both raw (biases are removed here).
    pub fn propagate(
        &mut self,
        dt_s: f64,
        accel_mps2: [f64; 3],
        gyro_radps: [f64; 3],
    ) -> Result<(), FilterError> {
        if !(dt_s.is_finite() && finite3(&accel_mps2) && finite3(&gyro_radps)) {
            return Err(FilterError::NotFinite);
        }
        if !(dt_s > 0.0 && dt_s <= self.cfg.max_dt_s) {
            return Err(FilterError::BadTimeStep);
        }
        let f_b = Vector3::from(accel_mps2) - self.ba;
        let w_b = Vector3::from(gyro_radps) - self.bg;
        let r = self.q.to_rotation_matrix().into_inner();
        let f_n = r * f_b;
        let a_n = f_n + Vector3::new(0.0, 0.0, -self.cfg.gravity_mps2);
        self.p += self.v * dt_s + a_n * (0.5 * dt_s * dt_s);
        self.v += a_n * dt_s;
        self.q *= UnitQuaternion::from_scaled_axis(w_b * dt_s);
        // Error dynamics, first-order discretisation Φ = I + F·dt.
        let mut phi = MatN::identity();
        let i3 = Matrix3::<f64>::identity();
        phi.fixed_view_mut::<3, 3>(0, 3).copy_from(&(i3 * dt_s));
        phi.fixed_view_mut::<3, 3>(3, 6)
            .copy_from(&(-skew(&f_n) * dt_s));
        phi.fixed_view_mut::<3, 3>(3, 9).copy_from(&(-r * dt_s));
        phi.fixed_view_mut::<3, 3>(6, 12).copy_from(&(-r * dt_s));
        let c = &self.cfg;
        // Diagonal process noise per 3-block: none on δp, then δv, δθ, δb_a, δb_g.
        // The fix error and the keyframe clone (blocks 5 and 6) are static between updates.
        let blocks = [
            0.0,
            c.accel_noise * c.accel_noise * dt_s,
            c.gyro_noise * c.gyro_noise * dt_s,
            c.accel_bias_walk * c.accel_bias_walk * dt_s,
            c.gyro_bias_walk * c.gyro_bias_walk * dt_s,
        ];
        let qd = MatN::from_fn(|i, j| {
            if i == j {
                blocks.get(i / 3).copied().unwrap_or(0.0)
            } else {
                0.0
            }
        });
        self.cov = phi * self.cov * phi.transpose() + qd;
        self.symmetrise();
        Ok(())
    }

    fn symmetrise(&mut self) {
        self.cov = (self.cov + self.cov.transpose()) * 0.5;
    }

    /// Generic gated update: innovation `y` (M), measurement matrix `h` (M × [`STATE_DIM`]), noise `r`.
    fn update<const M: usize>(
        &mut self,
        y: SVector<f64, M>,
        h: SMatrix<f64, M, STATE_DIM>,
        r: SMatrix<f64, M, M>,
        gate: f64,
    ) -> Result<UpdateOutcome, FilterError> {
        let s = h * self.cov * h.transpose() + r;
        let chol = s.cholesky().ok_or(FilterError::Singular)?;
        let nis = at(&(y.transpose() * chol.solve(&y)), 0, 0);
        if !nis.is_finite() {
            return Err(FilterError::NotFinite);
        }
        if nis > gate {
            return Ok(UpdateOutcome::Rejected { nis });
        }
        // K = P Hᵀ S⁻¹, computed as (S⁻¹ H P)ᵀ since S and P are symmetric.
        let k = chol.solve(&(h * self.cov)).transpose();
        let dx = k * y;
        let ikh = MatN::identity() - k * h;
        self.cov = ikh * self.cov * ikh.transpose() + k * r * k.transpose();
        self.symmetrise();
        self.p += dx.fixed_rows::<3>(0);
        self.v += dx.fixed_rows::<3>(3);
        let dth: Vector3<f64> = dx.fixed_rows::<3>(6).into();
        self.q = UnitQuaternion::from_scaled_axis(dth) * self.q;
        self.ba += dx.fixed_rows::<3>(9);
        self.bg += dx.fixed_rows::<3>(12);
        self.fix_err += dx.fixed_rows::<3>(FIX);
        self.fix_drift[0] += at(&dx, DRIFT, 0);
        self.fix_drift[1] += at(&dx, DRIFT + 1, 0);
        if let Some(k) = &mut self.key {
            k[0] += at(&dx, KEY, 0);
            k[1] += at(&dx, KEY + 1, 0);
        }
        Ok(UpdateOutcome::Accepted { nis })
    }

    /// Update with a TRN fix (east, north, yaw). Gated at `fix_gate_chi2`.
    ///
    /// The fix observes position + fix error: first the fix-error state moves to this fix's
    /// ground ([`Self::move_fix_error`]: kept in proportion to the footprints' overlap ρ,
    /// moved by its drift as the footprint's size changes, fresh error `(1 − ρ²)·s·C` added,
    /// `C` the fix's covariance, `s` the shared share per axis), then the update splits the
    /// innovation between the two; the white rest `(1 − s)·C` is the measurement noise. A fix
    /// the gate refuses leaves that move in place (the error process is about the ground, which
    /// the flyer has reached either way) and changes nothing else.
    pub fn update_fix(&mut self, z: &FixMeasurement) -> Result<UpdateOutcome, FilterError> {
        let c = z.position_cov_m2;
        let vals = [
            z.x_m,
            z.y_m,
            z.yaw_rad,
            c[0][0],
            c[0][1],
            c[1][0],
            c[1][1],
            z.yaw_sigma_rad,
            z.footprint_m,
            z.map_share,
        ];
        if !vals.iter().all(|v| v.is_finite()) {
            return Err(FilterError::NotFinite);
        }
        let cxy = 0.5 * (c[0][1] + c[1][0]);
        let cf = Matrix3::new(
            c[0][0],
            cxy,
            0.0,
            cxy,
            c[1][1],
            0.0,
            0.0,
            0.0,
            z.yaw_sigma_rad * z.yaw_sigma_rad,
        );
        // A covariance that is not positive definite cannot describe a fix.
        if cf.cholesky().is_none() {
            return Err(FilterError::Singular);
        }
        // The map's share was measured on position; the heading keeps the default.
        let s = self.cfg.fix_shared_fraction.clamp(0.0, 1.0);
        let shared = [s.max(z.map_share).clamp(0.0, 1.0), s];
        self.move_fix_error([z.x_m, z.y_m], z.footprint_m, &cf, shared);
        let y = SVector::<f64, 3>::new(
            z.x_m - self.p.x - self.fix_err.x,
            z.y_m - self.p.y - self.fix_err.y,
            wrap_pi(z.yaw_rad - self.yaw_rad() - self.fix_err.z),
        );
        // x, y observe δp_x + δf_x, δp_y + δf_y; yaw responds to the nav-frame rotation error
        // about +z (level flight) plus δf_ψ. The frame's own share of the noise is white.
        let h = SMatrix::<f64, 3, STATE_DIM>::from_fn(|i, j| match (i, j) {
            (0, 0) | (1, 1) | (2, 8) => 1.0,
            (i, j) if j == FIX + i => 1.0,
            _ => 0.0,
        });
        let r = cf - split(&cf, shared);
        let r = SMatrix::<f64, 3, 3>::from_fn(|i, j| r.get((i, j)).copied().unwrap_or(0.0));
        self.update(y, h, r, self.cfg.fix_gate_chi2)
    }

    /// Gauss–Markov step of the fix error to a new footprint (centre east/north m, side m) for a
    /// measurement of covariance `cf` (east, north, yaw): rows and columns of its block scale by
    /// the footprints' overlap ρ and fresh error `(1 − ρ²)·s·cf` is added. The ground error's
    /// modelled variance before any update, `g_k` per axis, follows `g_k ← ρ²·g_k + (1 − ρ²)·t_k`
    /// with `t_k = s·cf_kk` the new fix's ground share; where `t_k` exceeds `g_k`, the step adds
    /// the difference `ρ²·(t_k − g_k)` as further fresh error on that axis and `g_k = t_k`: the
    /// new fix's ground error is the carried one plus an independent part, never smaller than
    /// its share. With steady fixes this is the plain Gauss–Markov step.
    ///
    /// Why: on a descent the fixes' σ rises several-fold within a minute (finer frames,
    /// smaller footprints) while successive footprints overlap 99 % or more (ρ up to
    /// [`MAX_FIX_CORRELATION`]), so the plain step hardly refreshes the carried error and the
    /// filter took the new fixes' common error at its old, small size (16 km InSAR-map descents
    /// without velocimeter, session 32, seed 1: NEES in band 87.0 / 84.7 % before, 88.8 / 86.7 %
    /// with the top-up, still short of 90 %; seed 2: 87.1 / 85.4 → 91.0 / 94.4 %). Two other forms were flown and dropped: rescaling the carried
    /// error (and its covariances) to the new size made the fixes pull the position less and
    /// cost the velocimeter runs 4–9 points; also shrinking it when a fix claims less made
    /// the filter overconfident after momentarily confident fixes (docs/registration.md,
    /// session 32). A limit: one fix with a momentarily large σ raises `g_k`, which then decays
    /// only as the ground changes.
    fn move_fix_error(
        &mut self,
        centre: [f64; 2],
        footprint_m: f64,
        cf: &Matrix3<f64>,
        shared: [f64; 2],
    ) {
        let rho = footprint_correlation(self.last_fix.0, self.last_fix.1, centre, footprint_m);
        // Change of log footprint side since the last fix (0 without one or on new ground).
        let dl = if rho > 0.0 && self.last_fix.1 > 0.0 && footprint_m > 0.0 {
            libm::log(footprint_m / self.last_fix.1)
        } else {
            0.0
        };
        // The new fix's ground share per axis. A non-finite variance describes no ground
        // error; it must not poison the model.
        let target = [0, 1, 2].map(|k| {
            let s = if k < 2 { shared[0] } else { shared[1] };
            let t = s * cf.get((k, k)).copied().unwrap_or(0.0).max(0.0);
            if t.is_finite() { t } else { 0.0 }
        });
        self.move_drift(dl, rho, &target);
        self.last_fix = (centre, footprint_m.max(0.0));
        // Fresh error beyond the Gauss–Markov step's where the new fix's ground share exceeds
        // the modelled variance: the new error is the carried one plus an independent part.
        let mut extra = [0.0f64; 3];
        for ((g, t), e) in self.fix_ground_var.iter_mut().zip(target).zip(&mut extra) {
            *e = top_up(g, t, rho);
        }
        self.scale_block(FIX, 3, rho);
        let fresh = split(cf, shared) * (1.0 - rho * rho);
        let mut block = self.cov.fixed_view_mut::<3, 3>(FIX, FIX);
        block += fresh;
        for (k, e) in extra.iter().enumerate() {
            if let Some(v) = self.cov.get_mut((FIX + k, FIX + k)) {
                *v += e;
            }
        }
        self.fix_err *= rho;
        self.symmetrise();
    }

    /// Rows and columns `start..start + n` of the covariance scaled by `f` (a Gauss–Markov
    /// state keeping the fraction `f` of itself; its diagonal by `f²`).
    fn scale_block(&mut self, start: usize, n: usize, f: f64) {
        for i in 0..STATE_DIM {
            for k in start..start + n {
                if let Some(v) = self.cov.get_mut((k, i)) {
                    *v *= f;
                }
                if let Some(v) = self.cov.get_mut((i, k)) {
                    *v *= f;
                }
            }
        }
    }

    /// The drift part of [`Self::move_fix_error`]: the fix error moves by `Δℓ·δd` (`Δℓ` the
    /// change of log footprint side), then the drift keeps `ρ·e^(−|Δℓ|/L)` of itself (ρ the
    /// footprints' overlap: new ground, new drift) and gains fresh error towards its modelled
    /// variance `k²·g` (`k` = [`FilterConfig::fix_scale_drift`], `g` per axis the larger of the ground error's modelled
    /// variance and the new fix's share `target`, or the share alone on new ground, `ρ` = 0).
    /// The variance the move adds to the fix error is on top of the top-up's (conservative).
    fn move_drift(&mut self, dl: f64, rho: f64, target: &[f64; 3]) {
        let k = self.cfg.fix_scale_drift;
        if !(k.is_finite() && k > 0.0 && dl.is_finite()) {
            return;
        }
        // Φ = I + Δℓ·E (E: δf_xy ← δd_xy) applied as Φ·P·Φᵀ by rows, then columns.
        if dl != 0.0 {
            for a in 0..2 {
                for i in 0..STATE_DIM {
                    let d = at(&self.cov, DRIFT + a, i);
                    if let Some(v) = self.cov.get_mut((FIX + a, i)) {
                        *v += dl * d;
                    }
                }
                for i in 0..STATE_DIM {
                    let d = at(&self.cov, i, DRIFT + a);
                    if let Some(v) = self.cov.get_mut((i, FIX + a)) {
                        *v += dl * d;
                    }
                }
            }
            self.fix_err.x += dl * self.fix_drift[0];
            self.fix_err.y += dl * self.fix_drift[1];
        }
        let rd = rho * libm::exp(-dl.abs() / DRIFT_LENGTH_LN);
        self.scale_block(DRIFT, 2, rd);
        for d in &mut self.fix_drift {
            *d *= rd;
        }
        for a in 0..2 {
            let t = target.get(a).copied().unwrap_or(0.0);
            let g = if rho > 0.0 {
                self.fix_ground_var.get(a).copied().unwrap_or(0.0).max(t)
            } else {
                t
            };
            let var = k * k * g;
            let Some(m) = self.drift_var.get_mut(a) else {
                continue;
            };
            if !var.is_finite() {
                continue;
            }
            // As for the fix error: a drift model smaller than the new size is topped up.
            let add = (1.0 - rd * rd) * var + top_up(m, var, rd);
            if let Some(v) = self.cov.get_mut((DRIFT + a, DRIFT + a)) {
                *v += add;
            }
        }
        self.symmetrise();
    }

    /// Capture a keyframe: the current horizontal position (and its error) is cloned into the
    /// keyframe state, replacing any earlier keyframe, and the fix-error process restarts (the
    /// next offset's ground error is the new keyframe's, independent of the last fix's).
    /// Offsets ([`Self::update_offset`]) are then measured from this position.
    pub fn set_keyframe(&mut self) {
        // δk := δp (east, north): copy rows and columns, then the 2 × 2 block.
        for i in 0..STATE_DIM {
            for k in 0..2 {
                let v = at(&self.cov, k, i);
                if let Some(d) = self.cov.get_mut((KEY + k, i)) {
                    *d = v;
                }
                if let Some(d) = self.cov.get_mut((i, KEY + k)) {
                    *d = v;
                }
            }
        }
        for a in 0..2 {
            for b in 0..2 {
                let v = at(&self.cov, a, b);
                if let Some(d) = self.cov.get_mut((KEY + a, KEY + b)) {
                    *d = v;
                }
            }
        }
        self.key = Some([self.p.x, self.p.y]);
        self.last_fix = ([0.0; 2], 0.0);
        self.symmetrise();
    }

    /// Horizontal position cloned at the current keyframe (east, north, m), if one was set.
    pub fn keyframe_position_m(&self) -> Option<[f64; 2]> {
        self.key
    }

    /// Covariance of the displacement since the keyframe, `p − p_k` (east/north, m²): what the
    /// filter knows about where the current frame lies on the keyframe. `None` without a
    /// keyframe.
    pub fn offset_cov_m2(&self) -> Option<[[f64; 2]; 2]> {
        self.key?;
        let c = &self.cov;
        let e = |a: usize, b: usize| {
            at(c, a, b) - at(c, a, KEY + b) - at(c, KEY + a, b) + at(c, KEY + a, KEY + b)
        };
        Some([[e(0, 0), e(0, 1)], [e(1, 0), e(1, 1)]])
    }

    /// Update with a keyframe-relative fix (odometry). Gated at `fix_gate_chi2` (on 2 dof that
    /// is stricter than its 3-dof meaning, never looser). Like a TRN fix, the share
    /// [`FilterConfig::fix_shared_fraction`] of its covariance is carried as ground error
    /// correlated over overlapping footprints (here: the keyframe's own error, common to every
    /// frame registered on it). `Err(NoKeyframe)` before [`Self::set_keyframe`].
    pub fn update_offset(&mut self, z: &OffsetMeasurement) -> Result<UpdateOutcome, FilterError> {
        let c = z.cov_m2;
        let vals = [
            z.east_m,
            z.north_m,
            c[0][0],
            c[0][1],
            c[1][0],
            c[1][1],
            z.footprint_m,
        ];
        let Some(key) = self.key else {
            return Err(FilterError::NoKeyframe);
        };
        if !vals.iter().all(|v| v.is_finite()) {
            return Err(FilterError::NotFinite);
        }
        let cxy = 0.5 * (c[0][1] + c[1][0]);
        let c2 = nalgebra::Matrix2::new(c[0][0], cxy, cxy, c[1][1]);
        if c2.cholesky().is_none() {
            return Err(FilterError::Singular);
        }
        let cf = Matrix3::new(c[0][0], cxy, 0.0, cxy, c[1][1], 0.0, 0.0, 0.0, 0.0);
        let centre = [self.p.x, self.p.y];
        let s = self.cfg.fix_shared_fraction.clamp(0.0, 1.0);
        self.move_fix_error(centre, z.footprint_m, &cf, [s, s]);
        let y = SVector::<f64, 2>::new(
            z.east_m - (self.p.x - key[0]) - self.fix_err.x,
            z.north_m - (self.p.y - key[1]) - self.fix_err.y,
        );
        let h = SMatrix::<f64, 2, STATE_DIM>::from_fn(|i, j| match (i, j) {
            (0, 0) | (1, 1) => 1.0,
            (i, j) if j == FIX + i => 1.0,
            (i, j) if j == KEY + i => -1.0,
            _ => 0.0,
        });
        let r = c2 * (1.0 - s);
        let r = SMatrix::<f64, 2, 2>::from_fn(|i, j| r.get((i, j)).copied().unwrap_or(0.0));
        self.update(y, h, r, self.cfg.fix_gate_chi2)
    }

    /// Estimated error of the current TRN fix (east m, north m, yaw rad): the part of the last
    /// fix the filter attributes to the ground under it rather than to the flyer's position.
    pub fn fix_error_estimate(&self) -> [f64; 3] {
        self.fix_err.into()
    }

    /// Update with an attitude measurement (e.g. a star tracker): roll, pitch, yaw in radians
    /// (intrinsic Z-Y-X, yaw about +z from east), isotropic 1σ `sigma_rad`.
    pub fn update_attitude(
        &mut self,
        roll_rad: f64,
        pitch_rad: f64,
        yaw_rad: f64,
        sigma_rad: f64,
    ) -> Result<UpdateOutcome, FilterError> {
        if !([roll_rad, pitch_rad, yaw_rad, sigma_rad]
            .iter()
            .all(|v| v.is_finite())
            && sigma_rad > 0.0)
        {
            return Err(FilterError::NotFinite);
        }
        let meas = UnitQuaternion::from_euler_angles(roll_rad, pitch_rad, yaw_rad);
        // Nav-frame rotation from the estimate to the measurement: the δθ it observes.
        let d: Vector3<f64> = (meas * self.q.inverse()).scaled_axis();
        let y = SVector::<f64, 3>::new(d.x, d.y, d.z);
        let h = SMatrix::<f64, 3, STATE_DIM>::from_fn(|i, j| if j == 6 + i { 1.0 } else { 0.0 });
        let r =
            SMatrix::<f64, 3, 3>::from_fn(|i, j| if i == j { sigma_rad * sigma_rad } else { 0.0 });
        self.update(y, h, r, self.cfg.fix_gate_chi2)
    }

    /// Update with a velocity measurement (ENU, m/s; e.g. a Doppler lidar velocimeter), isotropic
    /// 1σ `sigma_mps`.
    pub fn update_velocity(
        &mut self,
        v_mps: [f64; 3],
        sigma_mps: f64,
    ) -> Result<UpdateOutcome, FilterError> {
        if !(finite3(&v_mps) && sigma_mps.is_finite() && sigma_mps > 0.0) {
            return Err(FilterError::NotFinite);
        }
        let y = Vector3::from(v_mps) - self.v;
        let y = SVector::<f64, 3>::new(y.x, y.y, y.z);
        let h = SMatrix::<f64, 3, STATE_DIM>::from_fn(|i, j| if j == 3 + i { 1.0 } else { 0.0 });
        let r =
            SMatrix::<f64, 3, 3>::from_fn(|i, j| if i == j { sigma_mps * sigma_mps } else { 0.0 });
        self.update(y, h, r, self.cfg.fix_gate_chi2)
    }

    /// Update with an altitude measurement (m, ENU z) of 1σ `sigma_m`.
    pub fn update_altitude(
        &mut self,
        z_m: f64,
        sigma_m: f64,
    ) -> Result<UpdateOutcome, FilterError> {
        if !(z_m.is_finite() && sigma_m.is_finite() && sigma_m > 0.0) {
            return Err(FilterError::NotFinite);
        }
        let y = SVector::<f64, 1>::new(z_m - self.p.z);
        let h = SMatrix::<f64, 1, STATE_DIM>::from_fn(|_, j| if j == 2 { 1.0 } else { 0.0 });
        let r = SMatrix::<f64, 1, 1>::new(sigma_m * sigma_m);
        self.update(y, h, r, self.cfg.altitude_gate_chi2)
    }
}
