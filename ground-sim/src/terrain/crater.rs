//! Crater shapes: small superposed craters (fresh morphometry + diffusive degradation) and the
//! large host crater of each preset.
//!
//! Small simple craters, fresh (Pike 1977, "Size-dependence in the shape of fresh impact craters
//! on the Moon"): rim-to-floor depth `d ≈ 0.196 D`, rim height `h ≈ 0.036 D`; a bowl
//! (a slightly conical one, see [`FRESH_BOWL_EXP`]) inside the rim and an ejecta blanket outside whose thickness decays as `(r/R)^-3` (McGetchin,
//! Settle & Head 1973), tapered to zero at 3 R. Degradation is topographic diffusion (Fassett &
//! Thomson 2014, JGR Planets 119: κ ≈ 5.5 m²/Myr): the radial profile is smoothed by a Gaussian of
//! σ = sqrt(2 κ t), which lowers the rim, fills the bowl and widens the crater as the real ones do.

use super::sfd::CraterDraw;

/// Topographic diffusivity in m²/Myr measured on ~3–3.5 Gyr maria (Fassett & Thomson 2014).
pub const KAPPA_M2_PER_MYR: f64 = 5.5;
/// Age of the surfaces on which [`KAPPA_M2_PER_MYR`] was calibrated, Gyr.
const KAPPA_CALIBRATION_AGE_GYR: f64 = 3.5;

/// Diffusivity per flux-equivalent Myr: Fassett & Thomson's value assumed a constant flux over
/// their surfaces' real age; re-expressed per unit of flux-equivalent time (see
/// [`super::sfd::flux_equivalent_age_gyr`]) it is `κ · T_cal / τ(T_cal)` ≈ 3.4 m²/Myr.
pub fn kappa_flux_m2_per_myr() -> f64 {
    KAPPA_M2_PER_MYR * KAPPA_CALIBRATION_AGE_GYR
        / super::sfd::flux_equivalent_age_gyr(KAPPA_CALIBRATION_AGE_GYR)
}
/// Fresh depth/diameter ratio of simple craters (Pike 1977).
pub const FRESH_D_OVER_D: f64 = 0.196;
/// Fresh rim height/diameter ratio of simple craters (Pike 1977).
pub const FRESH_RIM_OVER_D: f64 = 0.036;
/// Exponent α of the fresh bowl `z = h − d (1 − ρ^α)`. A paraboloid (α = 2) with d/D = 0.196
/// would meet the rim at 38°, steeper than the ~30–35° angle of repose that fresh lunar crater
/// walls show; α = 1.7 puts the steepest wall, at the rim, at 33.7°.
pub const FRESH_BOWL_EXP: f64 = 1.7;
/// Outer radius of the ejecta blanket, in crater radii.
pub const EJECTA_OUTER_R: f64 = 3.0;
/// Diffusion length σ (in crater radii) at which a crater counts as no longer visible; its
/// visibility lifetime is `(SIGMA_VISIBLE_R · R)² / (2 κ)`. At σ = 1.5 R the smoothed bowl keeps
/// under 30 % of its fresh depth (d/D ≲ 0.06), a faint, rimless depression.
pub const SIGMA_VISIBLE_R: f64 = 1.5;
/// Lookup-table samples per crater radius; the rim crest (rho = 1) falls on a sample.
const STEPS_PER_R: f64 = 32.0;

/// A small crater ready to stamp: radial height lookup table (metres) over `0..=rho_end` radii.
#[derive(Debug, Clone)]
pub struct CraterStamp {
    /// Centre x, metres.
    pub x_m: f64,
    /// Centre y, metres.
    pub y_m: f64,
    /// Rim radius, metres.
    pub r_m: f64,
    /// Footprint radius in crater radii.
    pub rho_end: f64,
    /// Heights (metres) at `rho = i / STEPS_PER_R`, up to `rho_end`.
    pub lut: Vec<f32>,
    /// Age given to the crater, flux-equivalent Myr.
    pub age_myr: f64,
}

/// Fresh profile in units of D for scatter parameters (depth ratio, rim ratio).
fn fresh(rho: f64, d_ratio: f64, h_ratio: f64) -> f64 {
    if rho <= 1.0 {
        h_ratio - d_ratio * (1.0 - rho.powf(FRESH_BOWL_EXP))
    } else if rho < EJECTA_OUTER_R {
        let t = ((rho - 2.0) / (EJECTA_OUTER_R - 2.0)).clamp(0.0, 1.0);
        let taper = 1.0 - t * t * (3.0 - 2.0 * t);
        h_ratio * rho.powi(-3) * taper
    } else {
        0.0
    }
}

/// Build the stamp of a drawn crater; `kappa_factor` scales diffusivity (steep host slopes
/// degrade craters faster), `surface_age_myr` (flux-equivalent Myr) caps its age.
pub fn make_stamp(c: &CraterDraw, kappa_factor: f64, surface_age_myr: f64) -> CraterStamp {
    let r = c.d_m / 2.0;
    let kappa = kappa_flux_m2_per_myr() * kappa_factor.max(f64::MIN_POSITIVE);
    let life_myr = ((SIGMA_VISIBLE_R * r).powi(2) / (2.0 * kappa)).min(surface_age_myr);
    let age_myr = c.u_age * life_myr;
    // ±15 % depth and ±25 % rim scatter about Pike's means (his fits scatter about that much).
    let d_ratio = FRESH_D_OVER_D * (0.85 + 0.30 * c.u_shape);
    let h_ratio = FRESH_RIM_OVER_D * (0.75 + 0.50 * c.u_rim);
    let s = (2.0 * kappa * age_myr).sqrt() / r;
    let len = ((EJECTA_OUTER_R + 3.0 * s) * STEPS_PER_R).ceil() as usize + 1;
    let step = 1.0 / STEPS_PER_R;
    let rho_end = (len - 1) as f64 * step;
    let lut = if s < 0.5 * step {
        (0..len)
            .map(|i| (c.d_m * fresh(i as f64 * step, d_ratio, h_ratio)) as f32)
            .collect()
    } else {
        // Gaussian smoothing of the even extension of the profile. The fresh profile is sampled
        // once on a grid fine enough for both the rim (step / 2) and the kernel (σ / 4).
        let fine = (step / 2.0).max(s / 4.0);
        let k = (3.0 * s / fine).ceil() as usize;
        let weights: Vec<f64> = (0..=2 * k)
            .map(|j| (-0.5 * ((j as f64 - k as f64) * fine / s).powi(2)).exp())
            .collect();
        let wsum: f64 = weights.iter().sum();
        // Output sample i sits at rho_i = i·step = i·(step/fine) fine cells; taps reach k cells
        // either side, so tabulate |rho| from −k·fine to rho_end + k·fine.
        let ratio = step / fine;
        let n_fine = ((rho_end / fine).ceil() as usize) + 2 * k + 2;
        let base: Vec<f64> = (0..n_fine)
            .map(|m| fresh(((m as f64 - k as f64) * fine).abs(), d_ratio, h_ratio))
            .collect();
        (0..len)
            .map(|i| {
                // Centre position in fine cells (may fall between cells when fine ≠ step/2).
                let centre = i as f64 * ratio + k as f64;
                let c0 = centre.floor();
                let t = centre - c0;
                let c0 = c0 as usize;
                let acc: f64 = weights
                    .iter()
                    .enumerate()
                    .map(|(j, w)| {
                        let m = c0 + j - k;
                        let a = base.get(m).copied().unwrap_or(0.0);
                        let b = base.get(m + 1).copied().unwrap_or(0.0);
                        w * (a + t * (b - a))
                    })
                    .sum();
                (c.d_m * acc / wsum) as f32
            })
            .collect()
    };
    CraterStamp {
        x_m: c.x_m,
        y_m: c.y_m,
        r_m: r,
        rho_end,
        lut,
        age_myr,
    }
}

impl CraterStamp {
    /// Height contribution (metres) at distance `dist_m` from the centre.
    #[inline]
    pub fn at(&self, dist_m: f64) -> f32 {
        let rho = dist_m / self.r_m;
        if rho >= self.rho_end {
            return 0.0;
        }
        let u = rho * STEPS_PER_R;
        let i = u as usize;
        let t = (u - i as f64) as f32;
        match (self.lut.get(i), self.lut.get(i + 1)) {
            (Some(&a), Some(&b)) => a + t * (b - a),
            (Some(&a), None) => a,
            _ => 0.0,
        }
    }

    /// Footprint radius in metres.
    pub fn footprint_m(&self) -> f64 {
        self.r_m * self.rho_end
    }

    /// Rim-to-floor depth of the (possibly degraded) stamp, metres.
    pub fn depth_m(&self) -> f64 {
        let max = self.lut.iter().copied().fold(f32::MIN, f32::max);
        let min = self.lut.iter().copied().fold(f32::MAX, f32::min);
        f64::from(max - min)
    }
}

/// Radial profile of a large host crater (rim crest at radius `r_m`), heights in metres relative
/// to the far-field surface.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct HostCrater {
    /// Rim crest diameter, metres.
    pub diameter_m: f64,
    /// Flat (or gently bowl-shaped) floor diameter, metres.
    pub floor_diameter_m: f64,
    /// Rim crest to lowest floor depth, metres.
    pub depth_m: f64,
    /// Rim height above the far-field surface, metres.
    pub rim_height_m: f64,
    /// Extra depth of the floor centre below the floor edge (a bowl floor), metres.
    pub floor_bowl_m: f64,
    /// Wall shape exponent p of `sin(π u)^p` (smaller = straighter walls, steeper maximum).
    pub wall_p: f64,
    /// Number of wall terraces (complex craters), 0 for none.
    pub terraces: u32,
}

/// Steps of the wall shape table.
const WALL_STEPS: usize = 512;

/// Precomputed host-crater profile with an azimuthal rim modulation.
#[derive(Debug, Clone)]
pub struct HostProfile {
    /// The crater parameters.
    pub crater: HostCrater,
    wall: Vec<f64>,
    /// (amplitude, harmonic, phase) of the rim radius modulation.
    modes: Vec<(f64, f64, f64)>,
}

impl HostProfile {
    /// Tabulate the wall shape `S(u) = ∫ sin(πu)^p / ∫₀¹ sin(πu)^p`, optionally terraced.
    pub fn new(crater: HostCrater, modes: Vec<(f64, f64, f64)>) -> Self {
        let mut cum = vec![0.0f64; WALL_STEPS + 1];
        for i in 1..=WALL_STEPS {
            let u = (i as f64 - 0.5) / WALL_STEPS as f64;
            cum[i] = cum[i - 1] + (std::f64::consts::PI * u).sin().powf(crater.wall_p);
        }
        let total = cum[WALL_STEPS].max(f64::MIN_POSITIVE);
        let mut wall: Vec<f64> = cum.iter().map(|c| c / total).collect();
        if crater.terraces > 0 {
            // Terraces: S + a·sin(2π n S)/(2π n) keeps S monotone (a < 1) but alternates steep
            // scarps and flatter benches.
            let n = f64::from(crater.terraces);
            let a = 0.6;
            for s in &mut wall {
                *s += a * (std::f64::consts::TAU * n * *s).sin() / (std::f64::consts::TAU * n);
            }
        }
        Self {
            crater,
            wall,
            modes,
        }
    }

    /// Rim radius scale factor at azimuth `theta` (radians).
    fn radius_factor(&self, theta: f64) -> f64 {
        1.0 + self
            .modes
            .iter()
            .map(|&(a, k, phi)| a * (k * theta + phi).cos())
            .sum::<f64>()
    }

    fn wall_at(&self, u: f64) -> f64 {
        let x = u.clamp(0.0, 1.0) * WALL_STEPS as f64;
        let i = (x as usize).min(WALL_STEPS - 1);
        let t = x - i as f64;
        self.wall[i] + t * (self.wall[i + 1] - self.wall[i])
    }

    /// Height in metres at map position `(x, y)` metres from the crater centre.
    pub fn height_m(&self, x: f64, y: f64) -> f64 {
        let c = &self.crater;
        let f = self.radius_factor(y.atan2(x));
        let r_rim = c.diameter_m / 2.0 * f;
        let r_floor = c.floor_diameter_m / 2.0 * f;
        let r = (x * x + y * y).sqrt();
        let floor_edge = c.rim_height_m - c.depth_m + c.floor_bowl_m;
        if r <= r_floor {
            let q = r / r_floor.max(1.0);
            floor_edge - c.floor_bowl_m * (1.0 - q * q)
        } else if r <= r_rim {
            let u = (r - r_floor) / (r_rim - r_floor).max(1.0);
            floor_edge + (c.depth_m - c.floor_bowl_m) * self.wall_at(u)
        } else {
            c.rim_height_m * (r / r_rim).powi(-3)
        }
    }

    /// Local slope (degrees) of the host profile at `(x, y)`, by central differences over `h_m`.
    pub fn slope_deg(&self, x: f64, y: f64, h_m: f64) -> f64 {
        let gx = (self.height_m(x + h_m, y) - self.height_m(x - h_m, y)) / (2.0 * h_m);
        let gy = (self.height_m(x, y + h_m) - self.height_m(x, y - h_m)) / (2.0 * h_m);
        (gx * gx + gy * gy).sqrt().atan().to_degrees()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draw(d: f64, u_age: f64) -> CraterDraw {
        CraterDraw {
            d_m: d,
            x_m: 0.0,
            y_m: 0.0,
            u_age,
            u_shape: 0.5,
            u_rim: 0.5,
            u_keep: 0.5,
        }
    }

    #[test]
    fn fresh_crater_has_pike_morphometry_and_degrades() {
        let s = make_stamp(&draw(100.0, 0.0), 1.0, 4000.0);
        // Rim crest at r = R, floor at the centre: depth ≈ 0.196 D.
        assert!((s.depth_m() / 100.0 - FRESH_D_OVER_D).abs() < 0.005);
        assert!((f64::from(s.at(50.0)) - 3.6).abs() < 0.1);
        // Half-way through its visible life (σ ≈ 1.1 R) the crater has lost most of its depth.
        let mid = make_stamp(&draw(100.0, 0.5), 1.0, 4000.0);
        assert!(mid.depth_m() < 0.6 * s.depth_m(), "{}", mid.depth_m());
        let end = make_stamp(&draw(100.0, 0.999), 1.0, 4000.0);
        assert!(end.depth_m() < 0.3 * s.depth_m(), "{}", end.depth_m());
        // Large craters on a young surface are capped by its age: still fresh-ish.
        let young = make_stamp(&draw(2000.0, 0.999), 1.0, 100.0);
        assert!(young.depth_m() > 0.9 * 0.196 * 2000.0);
    }

    #[test]
    fn host_profile_has_requested_depth_and_wall_slopes() {
        let c = HostCrater {
            diameter_m: 21_000.0,
            floor_diameter_m: 6_600.0,
            depth_m: 4_200.0,
            rim_height_m: 500.0,
            floor_bowl_m: 60.0,
            wall_p: 0.3,
            terraces: 0,
        };
        let p = HostProfile::new(c, vec![]);
        let rim = p.height_m(10_500.0, 0.0);
        let floor = p.height_m(0.0, 0.0);
        assert!((rim - floor - 4200.0).abs() < 1.0);
        let max_slope = (0..200)
            .map(|i| p.slope_deg(3_300.0 + i as f64 * 36.0, 0.0, 5.0))
            .fold(0.0, f64::max);
        assert!((31.0..36.0).contains(&max_slope), "{max_slope}");
    }
}
