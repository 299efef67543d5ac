//! Interferometric geometry of an SLC pair: baseline, flat-Moon phase, height from phase (eq 17)
//! and the ground position of a pixel from its slant range and height.
//!
//! Frame: the local flat-Moon frame of `ground_sim::sar` (metres): `x` along track, `y` ground
//! range (look direction), `z` up. Both antennas fly along `+x`; A1's track is at
//! `(y_1, z_1)`, A2's at `(y_2, z_2) = (y_1, z_1) + B_L·(cos α, sin α)`. A point `P` seen by A1
//! at zero-Doppler slant range `R1` and look angle `θ` (from the vertical) lies at
//! `(y, z) = (y_1 + R1·sin θ, z_1 − R1·cos θ)`.
//!
//! Phase convention: the SLCs keep `exp(−i4πR/λ)`, so the interferogram `A1·conj(A2)` has the
//! phase `φ = −4π(R1 − R2)/λ` (ping-pong: each antenna transmits its own pulses).

use super::{InsarError, InsarResult};
use crate::sar::Slc;

/// Baseline, datum and range axis shared by the two SLCs of a pair.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairGeometry {
    /// `(y, z)` of antenna A1's track, m.
    pub a1_yz_m: [f64; 2],
    /// `(y, z)` of antenna A2's track, m.
    pub a2_yz_m: [f64; 2],
    /// Baseline length B_L = |A2 − A1|, m.
    pub baseline_m: f64,
    /// Baseline tilt α above the horizontal (towards `+y`), rad.
    pub tilt_rad: f64,
    /// Wavelength λ, m.
    pub wavelength_m: f64,
    /// Height `z_ref` of the flat datum the flat phase refers to, m.
    pub datum_m: f64,
    /// Slant range of gate 0 (both SLCs), m.
    pub first_range_m: f64,
    /// Gate spacing (slant), m.
    pub range_spacing_m: f64,
    /// Along-track position of line 0, m.
    pub first_azimuth_m: f64,
    /// Line spacing, m.
    pub azimuth_spacing_m: f64,
}

impl PairGeometry {
    /// Check that `a1` and `a2` are the two antennas of one acquisition (same grid, channel and
    /// wavelength) and derive the baseline.
    pub fn from_slcs(a1: &Slc, a2: &Slc) -> InsarResult<Self> {
        use crate::sar::Antenna;
        if a1.antenna != Antenna::A1 || a2.antenna != Antenna::A2 {
            return Err(InsarError::Input(format!(
                "need antennas A1 and A2, got {:?} and {:?}",
                a1.antenna, a2.antenna
            )));
        }
        if a1.polarisation != a2.polarisation {
            return Err(InsarError::Input(
                "the two SLCs have different channels".into(),
            ));
        }
        let same = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(1.0);
        if (a1.lines, a1.gates) != (a2.lines, a2.gates)
            || !same(a1.first_range_m, a2.first_range_m)
            || !same(a1.range_spacing_m, a2.range_spacing_m)
            || !same(a1.first_azimuth_m, a2.first_azimuth_m)
            || !same(a1.azimuth_spacing_m, a2.azimuth_spacing_m)
            || !same(a1.wavelength_m, a2.wavelength_m)
            || !same(a1.reference_height_m, a2.reference_height_m)
        {
            return Err(InsarError::Input(
                "the two SLCs do not share one image grid, wavelength and datum".into(),
            ));
        }
        if a1.lines < 2 || a1.gates < 2 || a1.data.len() != a1.lines * a1.gates {
            return Err(InsarError::Input(format!(
                "SLC of {}×{} with {} samples",
                a1.lines,
                a1.gates,
                a1.data.len()
            )));
        }
        let dy = a2.antenna_yz_m[0] - a1.antenna_yz_m[0];
        let dz = a2.antenna_yz_m[1] - a1.antenna_yz_m[1];
        let baseline_m = dy.hypot(dz);
        if !(baseline_m > 1e-3) {
            return Err(InsarError::Input(format!(
                "baseline {baseline_m} m is too short"
            )));
        }
        let g = Self {
            a1_yz_m: a1.antenna_yz_m,
            a2_yz_m: a2.antenna_yz_m,
            baseline_m,
            tilt_rad: dz.atan2(dy),
            wavelength_m: a1.wavelength_m,
            datum_m: a1.reference_height_m,
            first_range_m: a1.first_range_m,
            range_spacing_m: a1.range_spacing_m,
            first_azimuth_m: a1.first_azimuth_m,
            azimuth_spacing_m: a1.azimuth_spacing_m,
        };
        if !(g.first_range_m > g.platform_height_m()) {
            return Err(InsarError::Input(
                "the first gate is nearer than the datum below the platform".into(),
            ));
        }
        Ok(g)
    }

    /// A1's height above the datum, m.
    pub fn platform_height_m(&self) -> f64 {
        self.a1_yz_m[1] - self.datum_m
    }

    /// Slant range of (fractional) gate `j`, m.
    pub fn range_m(&self, j: f64) -> f64 {
        self.first_range_m + j * self.range_spacing_m
    }

    /// Along-track position of (fractional) line `i`, m.
    pub fn azimuth_m(&self, i: f64) -> f64 {
        self.first_azimuth_m + i * self.azimuth_spacing_m
    }

    /// Look angle from the vertical of a point at height `z_m` and A1 slant range `r1_m`, rad.
    pub fn look_angle_rad(&self, r1_m: f64, z_m: f64) -> f64 {
        ((self.a1_yz_m[1] - z_m) / r1_m).clamp(-1.0, 1.0).acos()
    }

    /// Flat-datum look angle (= incidence on the flat Moon) at A1 slant range `r1_m`, rad.
    pub fn flat_look_angle_rad(&self, r1_m: f64) -> f64 {
        self.look_angle_rad(r1_m, self.datum_m)
    }

    /// Ground range `y` of the point at A1 slant range `r1_m` and height `z_m`, m.
    pub fn ground_y_m(&self, r1_m: f64, z_m: f64) -> f64 {
        let dz = self.a1_yz_m[1] - z_m;
        self.a1_yz_m[0] + (r1_m * r1_m - dz * dz).max(0.0).sqrt()
    }

    /// Slant range from A2 to the datum point A1 sees at `r1_m`, m.
    pub fn flat_range2_m(&self, r1_m: f64) -> f64 {
        let y = self.ground_y_m(r1_m, self.datum_m);
        (y - self.a2_yz_m[0]).hypot(self.datum_m - self.a2_yz_m[1])
    }

    /// Flat-Moon interferometric phase `−4π(R1 − R2)/λ` of the datum point at `r1_m`, rad
    /// (not wrapped).
    pub fn flat_phase_rad(&self, r1_m: f64) -> f64 {
        -4.0 * std::f64::consts::PI * (r1_m - self.flat_range2_m(r1_m)) / self.wavelength_m
    }

    /// Height of ambiguity `λR1·sin θ/(2B_L·cos(θ − α))` at `r1_m` on the datum, m per 2π.
    pub fn ambiguity_height_m(&self, r1_m: f64) -> f64 {
        let th = self.flat_look_angle_rad(r1_m);
        self.wavelength_m * r1_m * th.sin() / (2.0 * self.baseline_m * (th - self.tilt_rad).cos())
    }

    /// Eq 17: height above the datum from the flat-removed phase `dphi_rad` at A1 slant range
    /// `r1_m`, with the look angle `θ1` given, m:
    /// `h = −Δφ·λ·R1·sin θ1 / (4π·B_L·cos(θ1 − α))`.
    pub fn eq17_height_m(&self, dphi_rad: f64, r1_m: f64, theta1_rad: f64) -> f64 {
        -dphi_rad * self.wavelength_m * r1_m * theta1_rad.sin()
            / (4.0 * std::f64::consts::PI * self.baseline_m * (theta1_rad - self.tilt_rad).cos())
    }

    /// Height above the datum from the flat-removed phase with eq 17 evaluated at this pixel's
    /// own `R1` and `θ1`, m. Eq 17 is the derivative of the phase with respect to height; taking
    /// `θ1` half-way between the flat look angle and the look angle of the point it returns
    /// (three fixed-point iterations) makes it exact to `O(Δθ²/24)`, below 1 mm for the
    /// scenes here. [`PairGeometry::exact_height_m`] is the closed-form reference.
    pub fn height_m(&self, dphi_rad: f64, r1_m: f64) -> f64 {
        let th_f = self.flat_look_angle_rad(r1_m);
        let mut th1 = th_f;
        let mut h = 0.0;
        for _ in 0..3 {
            h = self.eq17_height_m(dphi_rad, r1_m, th1);
            let th_t = self.look_angle_rad(r1_m, self.datum_m + h);
            th1 = 0.5 * (th_f + th_t);
        }
        h
    }

    /// Closed-form inversion (the slow, obvious reference): from the absolute phase
    /// `φ = flat + Δφ` get `R2 = R1 + φλ/4π`, then `sin(θ − α) = (R1² + B² − R2²)/(2·R1·B)`
    /// and `h = z_1 − R1·cos θ − z_ref`. Returns the height above the datum, m.
    pub fn exact_height_m(&self, dphi_rad: f64, r1_m: f64) -> f64 {
        let phi = self.flat_phase_rad(r1_m) + dphi_rad;
        let r2 = r1_m + phi * self.wavelength_m / (4.0 * std::f64::consts::PI);
        let b = self.baseline_m;
        let s = ((r1_m * r1_m + b * b - r2 * r2) / (2.0 * r1_m * b)).clamp(-1.0, 1.0);
        let th = self.tilt_rad + s.asin();
        self.a1_yz_m[1] - r1_m * th.cos() - self.datum_m
    }

    /// Exact interferometric phase `−4π(R1 − R2)/λ` of a point `(y, z)`, rad, and its A1 range.
    pub fn point_phase_rad(&self, y_m: f64, z_m: f64) -> (f64, f64) {
        let r1 = (y_m - self.a1_yz_m[0]).hypot(z_m - self.a1_yz_m[1]);
        let r2 = (y_m - self.a2_yz_m[0]).hypot(z_m - self.a2_yz_m[1]);
        (
            -4.0 * std::f64::consts::PI * (r1 - r2) / self.wavelength_m,
            r1,
        )
    }
}

/// Wrap an angle to `(−π, π]`, rad.
pub fn wrap_rad(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let w = a - t * (a / t).round();
    if w <= -std::f64::consts::PI { w + t } else { w }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::sar::{Antenna, Polarisation};

    /// An empty SLC pair with the default radar's geometry (no samples needed for geometry).
    pub(crate) fn pair_geometry() -> PairGeometry {
        let mk = |antenna, yz: [f64; 2]| Slc {
            antenna,
            polarisation: Polarisation::HH,
            lines: 2,
            gates: 2,
            data: vec![Default::default(); 4],
            first_range_m: 109_000.0,
            range_spacing_m: 2.19,
            first_azimuth_m: 0.0,
            azimuth_spacing_m: 5.0,
            wavelength_m: 0.2398,
            antenna_yz_m: yz,
            velocity_m_s: 1600.0,
            range_energy_width_m: 3.0,
            azimuth_energy_width_m: 7.0,
            reference_height_m: -3000.0,
        };
        let a = 30f64.to_radians();
        let y1 = 2000.0 - 100e3 * 26f64.to_radians().tan();
        let z1 = -3000.0 + 100e3;
        let a1 = mk(Antenna::A1, [y1, z1]);
        let a2 = mk(Antenna::A2, [y1 + 8.0 * a.cos(), z1 + 8.0 * a.sin()]);
        PairGeometry::from_slcs(&a1, &a2).unwrap()
    }

    #[test]
    fn ambiguity_height_is_the_design_value() {
        let g = pair_geometry();
        let r = 100e3 / 26f64.to_radians().cos();
        assert!(
            (g.ambiguity_height_m(r) - 732.9).abs() < 0.5,
            "{}",
            g.ambiguity_height_m(r)
        );
        assert!((g.tilt_rad.to_degrees() - 30.0).abs() < 1e-9);
        assert!((g.baseline_m - 8.0).abs() < 1e-9);
    }

    #[test]
    fn flat_phase_matches_the_point_phase_of_datum_points() {
        let g = pair_geometry();
        for y in [1500.0, 2000.0, 5000.0] {
            let (phi, r1) = g.point_phase_rad(y, g.datum_m);
            assert!((g.flat_phase_rad(r1) - phi).abs() < 1e-6);
            assert!((g.ground_y_m(r1, g.datum_m) - y).abs() < 1e-6);
        }
    }

    #[test]
    fn eq17_with_the_midpoint_look_angle_matches_the_exact_inversion() {
        let g = pair_geometry();
        for &(y, h) in &[
            (2000.0, 0.0),
            (1000.0, 50.0),
            (3000.0, -120.0),
            (2500.0, 350.0),
        ] {
            let z = g.datum_m + h;
            let (phi, r1) = g.point_phase_rad(y, z);
            let dphi = phi - g.flat_phase_rad(r1);
            let exact = g.exact_height_m(dphi, r1);
            assert!((exact - h).abs() < 1e-3, "exact {exact} vs {h}");
            let eq17 = g.height_m(dphi, r1);
            assert!((eq17 - h).abs() < 5e-3, "eq 17 {eq17} vs {h}");
            assert!((g.ground_y_m(r1, z) - y).abs() < 1e-6);
            // Eq 17 at the flat look angle alone is off by up to ~1 % of h (the paper's
            // first-order form); the midpoint angle removes it.
            let flat = g.eq17_height_m(dphi, r1, g.flat_look_angle_rad(r1));
            assert!(
                (flat - h).abs() <= 1e-2 * h.abs() + 1e-3,
                "flat eq 17 {flat} vs {h}"
            );
        }
    }

    #[test]
    fn wrap_is_in_the_half_open_interval() {
        use std::f64::consts::PI;
        assert!((wrap_rad(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_rad(-PI) - PI).abs() < 1e-12);
        assert!((wrap_rad(0.5) - 0.5).abs() < 1e-15);
        assert!((wrap_rad(-7.0) - (-7.0 + 2.0 * PI)).abs() < 1e-12);
    }
}
