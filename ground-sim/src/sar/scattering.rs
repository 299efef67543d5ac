//! Two-scale facet reflectivity (eqs 2–10).
//!
//! In the facet's local (principal) polarisation basis the reflectivity is
//! `γ' = diag(a_HH, a_VV)·w(θ)` (eq 4), θ the local incidence angle. At small θ the Kirchhoff
//! approximation (KA, eqs 5–7) describes quasi-specular scattering; at large θ the
//! small-perturbation method (SPM, eqs 8–10). The paper uses KA "when ⟨|γ'_pq|²⟩ of KA is
//! large at small incidence angles, otherwise SPM": here each channel uses KA below the angle
//! where its KA and SPM mean powers cross ([`TwoScaleModel::switch_angle_rad`], ≈ 12.3° for the
//! default parameters) and SPM above it.
//!
//! `w` is complex Gaussian: `w = sqrt(⟨|w|²⟩)·g` with `g` a unit-power circular Gaussian drawn
//! once per facet from a counter-based generator ([`complex_gaussian`]), so the same seed gives
//! the same surface for both antennas and for any thread schedule. The local matrix is rotated
//! to the radar's H/V basis with eqs 2–3: `γ = U⁻¹(Δ)·γ'·U(Δ)`.
//!
//! With `S = γ·sqrt(A/4π)` (eq 1) the facet's mean radar cross-section is `|γ|²·A`, so
//! `⟨|γ_pq|²⟩` is the facet's σ0.
//!
//! Beyond the paper, a diffuse term `σ0_d·cos θ` ([`TwoScaleModel::diffuse_sigma0`]; off in
//! `SarConfig::default()` and `--radar paper`, −17 dB in the default mission design) adds the Moon's non-directional echo (wavelength-scale rocks and the
//! regolith's volume), which the two-scale model lacks: with its Gaussian SPM spectrum the
//! paper's σ0 falls to −40 dB at 59° local incidence, below any real radar's noise, so a
//! 33° wall facing away from the radar vanishes under NESZ −25 dB. The term is added in power
//! to each local channel (independent Gaussian scatterers sum to one Gaussian of the summed
//! power), so each facet still draws one `g`; see docs/insar.md, "Walls under noise".

use serde::{Deserialize, Serialize};

use super::config::{Polarisation, SarConfig};
use super::{C64, SPEED_OF_LIGHT_M_S};

/// Which scattering model a facet uses for a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Regime {
    /// Kirchhoff approximation (quasi-specular, small local incidence).
    Kirchhoff,
    /// Small-perturbation method (Bragg, large local incidence).
    SmallPerturbation,
}

/// Surface and dielectric parameters of the two-scale model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwoScaleModel {
    /// Relative permittivity ε_r (real).
    pub permittivity: f64,
    /// KA rms slope √2·δ1/L1.
    pub ka_rms_slope: f64,
    /// SPM k·L2.
    pub spm_kl: f64,
    /// SPM k·δ2.
    pub spm_ks: f64,
    /// Wavenumber k = 2π/λ, rad/m (kept for reference; SPM depends only on kL and kδ).
    pub wavenumber_rad_m: f64,
    /// Diffuse σ0 at normal incidence, linear, of the `σ0_d·cos θ` law added to both
    /// co-polarised channels (0 = none, the paper's model).
    #[serde(default)]
    pub diffuse_sigma0: f64,
}

impl TwoScaleModel {
    /// Parameters from a configuration.
    pub fn from_config(cfg: &SarConfig) -> Self {
        Self {
            permittivity: cfg.permittivity,
            ka_rms_slope: cfg.ka_rms_slope,
            spm_kl: cfg.spm_kl,
            spm_ks: cfg.spm_ks,
            wavenumber_rad_m: 2.0 * std::f64::consts::PI * cfg.carrier_hz / SPEED_OF_LIGHT_M_S,
            diffuse_sigma0: cfg.diffuse_sigma0_linear(),
        }
    }

    /// Diffuse σ0 at local incidence `theta` (rad), linear: `σ0_d·cos θ` (0 when off).
    pub fn sigma0_diffuse(&self, theta: f64) -> f64 {
        self.diffuse_sigma0 * theta.cos().max(0.0)
    }

    /// KA amplitude factor (eqs 5, 6; the same for HH and VV): the normal-incidence Fresnel
    /// coefficient `(1 − √ε)/(1 + √ε)`.
    pub fn ka_amplitude(&self) -> f64 {
        let n = self.permittivity.sqrt();
        (1.0 - n) / (1.0 + n)
    }

    /// KA `⟨|w|²⟩` (eq 7) at local incidence `theta` (rad): geometric-optics slope distribution
    /// with `4δ1²/L1² = 2·s²`, s the rms slope.
    pub fn ka_w2(&self, theta: f64) -> f64 {
        let two_s2 = 2.0 * self.ka_rms_slope * self.ka_rms_slope;
        let c = theta.cos();
        let t = theta.tan();
        (-(t * t) / two_s2).exp() / (two_s2 * c.powi(4))
    }

    /// SPM HH amplitude (eq 8), real for real ε_r.
    pub fn spm_hh(&self, theta: f64) -> f64 {
        let (s, c) = theta.sin_cos();
        let root = (self.permittivity - s * s).sqrt();
        (c - root) / (c + root)
    }

    /// SPM VV amplitude (eq 9).
    pub fn spm_vv(&self, theta: f64) -> f64 {
        let e = self.permittivity;
        let (s, c) = theta.sin_cos();
        let s2 = s * s;
        (e - 1.0) * (s2 - e * (1.0 + s2)) / (e * c + (e - s2).sqrt()).powi(2)
    }

    /// SPM `⟨|w|²⟩` (eq 10): `4(kδ2)²(kL2)²·cos⁴θ·exp(−(kL2·sin θ)²)`.
    pub fn spm_w2(&self, theta: f64) -> f64 {
        let (s, c) = theta.sin_cos();
        4.0 * self.spm_ks.powi(2)
            * self.spm_kl.powi(2)
            * c.powi(4)
            * (-(self.spm_kl * s).powi(2)).exp()
    }

    /// Mean σ0 of the KA model for a channel, linear.
    pub fn sigma0_ka(&self, _pol: Polarisation, theta: f64) -> f64 {
        self.ka_amplitude().powi(2) * self.ka_w2(theta)
    }

    /// Mean σ0 of the SPM model for a channel, linear.
    pub fn sigma0_spm(&self, pol: Polarisation, theta: f64) -> f64 {
        let a = match pol {
            Polarisation::HH => self.spm_hh(theta),
            Polarisation::VV => self.spm_vv(theta),
        };
        a * a * self.spm_w2(theta)
    }

    /// Local incidence (rad) where KA and SPM mean powers cross for `pol`; KA is used below it.
    /// 0 if SPM dominates already at normal incidence, π/2 if KA dominates everywhere.
    pub fn switch_angle_rad(&self, pol: Polarisation) -> f64 {
        let f = |t: f64| self.sigma0_ka(pol, t).ln() - self.sigma0_spm(pol, t).ln();
        let (mut lo, mut hi) = (0.0_f64, 89.0_f64.to_radians());
        if f(lo) <= 0.0 {
            return 0.0;
        }
        if f(hi) > 0.0 {
            return std::f64::consts::FRAC_PI_2;
        }
        // KA falls as exp(−tan²θ/2s²), far faster than SPM: one crossing, found by bisection.
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if f(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// Regime used for `pol` at local incidence `theta` given its switch angle.
    #[inline]
    pub fn regime(theta: f64, switch_rad: f64) -> Regime {
        if theta < switch_rad {
            Regime::Kirchhoff
        } else {
            Regime::SmallPerturbation
        }
    }

    /// Mean σ0 of the two-scale model (the regime's closed form) plus the diffuse term, linear.
    pub fn sigma0(&self, pol: Polarisation, theta: f64) -> f64 {
        let directional = match Self::regime(theta, self.switch_angle_rad(pol)) {
            Regime::Kirchhoff => self.sigma0_ka(pol, theta),
            Regime::SmallPerturbation => self.sigma0_spm(pol, theta),
        };
        directional + self.sigma0_diffuse(theta)
    }

    /// Precompute the per-channel switch angles for facet evaluation.
    pub fn facet_evaluator(&self) -> FacetEvaluator {
        FacetEvaluator {
            model: *self,
            switch_hh: self.switch_angle_rad(Polarisation::HH),
            switch_vv: self.switch_angle_rad(Polarisation::VV),
        }
    }
}

/// Evaluates facet reflectivities with precomputed switch angles.
#[derive(Debug, Clone, Copy)]
pub struct FacetEvaluator {
    model: TwoScaleModel,
    switch_hh: f64,
    switch_vv: f64,
}

impl FacetEvaluator {
    /// Reflectivity `[γ_HH, γ_VV]` in the radar basis of a facet at local incidence `theta`
    /// (rad, must be in `[0, π/2)`), polarisation-basis rotation `delta` (rad), with unit
    /// complex Gaussian `g` (eqs 2–10).
    pub fn reflectivity(&self, theta: f64, delta: f64, g: C64) -> [C64; 2] {
        let m = &self.model;
        let local = |switch: f64, spm_a: f64| match TwoScaleModel::regime(theta, switch) {
            Regime::Kirchhoff => m.ka_amplitude() * m.ka_w2(theta).sqrt(),
            Regime::SmallPerturbation => spm_a * m.spm_w2(theta).sqrt(),
        };
        // The diffuse power joins each local channel's power; the sign of the directional
        // amplitude is kept (SPM HH is negative).
        let d = m.sigma0_diffuse(theta);
        let with_diffuse = |a: f64| {
            if d > 0.0 {
                a.signum() * (a * a + d).sqrt()
            } else {
                a
            }
        };
        let a_hh = with_diffuse(local(self.switch_hh, m.spm_hh(theta)));
        let a_vv = with_diffuse(local(self.switch_vv, m.spm_vv(theta)));
        // U⁻¹(Δ)·diag(a, b)·U(Δ): the co-pol terms mix the local channels by cos²/sin².
        let (s, c) = delta.sin_cos();
        let hh = c * c * a_hh + s * s * a_vv;
        let vv = s * s * a_hh + c * c * a_vv;
        [g * hh, g * vv]
    }

    /// Regime of a channel at local incidence `theta`.
    pub fn regime(&self, pol: Polarisation, theta: f64) -> Regime {
        let switch = match pol {
            Polarisation::HH => self.switch_hh,
            Polarisation::VV => self.switch_vv,
        };
        TwoScaleModel::regime(theta, switch)
    }
}

/// SplitMix64 step: a well-mixed 64-bit hash of a counter.
#[inline]
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Circular complex Gaussian with `E|g|² = 1`, a pure function of `(seed, stream, index)` so
/// draws are reproducible in any order (Box–Muller on two hashed uniforms).
#[inline]
pub fn complex_gaussian(seed: u64, stream: u64, index: u64) -> C64 {
    let base = splitmix64(seed ^ splitmix64(stream.wrapping_mul(0xA24B_AED4_963E_E407)));
    let h1 = splitmix64(base ^ index.wrapping_mul(2));
    let h2 = splitmix64(base ^ index.wrapping_mul(2).wrapping_add(1));
    // 53-bit uniforms; u1 in (0, 1] so the log is finite.
    let u1 = ((h1 >> 11) as f64 + 1.0) / (1u64 << 53) as f64;
    let u2 = (h2 >> 11) as f64 / (1u64 << 53) as f64;
    let r = (-u1.ln()).sqrt();
    let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
    C64::new(r * c, r * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ensemble_power(ev: &FacetEvaluator, theta: f64, ch: usize) -> f64 {
        let n = 40_000;
        (0..n)
            .map(|i| {
                ev.reflectivity(theta, 0.0, complex_gaussian(7, 1, i))
                    .map(|v| v.norm_sqr())[ch]
            })
            .sum::<f64>()
            / n as f64
    }

    fn model() -> TwoScaleModel {
        TwoScaleModel::from_config(&SarConfig::default())
    }

    #[test]
    fn ka_regime_follows_eqs_5_to_7() {
        let m = model();
        let ev = m.facet_evaluator();
        for deg in [0.0_f64, 3.0, 6.0, 9.0] {
            let t = deg.to_radians();
            assert_eq!(ev.regime(Polarisation::HH, t), Regime::Kirchhoff);
            // Closed form: |(1−√ε)/(1+√ε)|²·exp(−tan²θ/(2s²))/(2s²cos⁴θ).
            let s2 = 0.08_f64 * 0.08;
            let closed = (1.0_f64 / 3.0).powi(2) * (-(t.tan().powi(2)) / (2.0 * s2)).exp()
                / (2.0 * s2 * t.cos().powi(4));
            for ch in 0..2 {
                let got = ensemble_power(&ev, t, ch);
                assert!(
                    (got / closed - 1.0).abs() < 0.03,
                    "{deg}° ch{ch}: {got} vs {closed}"
                );
            }
        }
    }

    #[test]
    fn spm_regime_follows_eqs_8_to_10() {
        let m = model();
        let ev = m.facet_evaluator();
        let e: f64 = 4.0;
        for deg in [20.0_f64, 26.0, 40.0, 60.0] {
            let t = deg.to_radians();
            assert_eq!(ev.regime(Polarisation::VV, t), Regime::SmallPerturbation);
            let (s, c) = t.sin_cos();
            let hh = (c - (e - s * s).sqrt()) / (c + (e - s * s).sqrt());
            let vv = (e - 1.0) * (s * s - e * (1.0 + s * s)) / (e * c + (e - s * s).sqrt()).powi(2);
            let w2 = 4.0 * 0.09 * 9.0 * c.powi(4) * (-(3.0 * s).powi(2)).exp();
            for (ch, a) in [hh, vv].into_iter().enumerate() {
                let closed = a * a * w2;
                let got = ensemble_power(&ev, t, ch);
                assert!(
                    (got / closed - 1.0).abs() < 0.03,
                    "{deg}° ch{ch}: {got} vs {closed}"
                );
            }
            // VV above HH for SPM on a dielectric.
            assert!(vv * vv > hh * hh);
        }
    }

    #[test]
    fn diffuse_term_adds_its_cos_law_to_both_channels() {
        let cfg = SarConfig {
            diffuse_sigma0_db: -17.0,
            ..SarConfig::default()
        };
        let m = TwoScaleModel::from_config(&cfg);
        let plain = model().facet_evaluator();
        let ev = m.facet_evaluator();
        let d0 = 10f64.powf(-1.7);
        // The same draws as `ensemble_power`: their mean |g|² (≈ 1) scales both terms.
        let g2 = (0..40_000)
            .map(|i| complex_gaussian(7, 1, i).norm_sqr())
            .sum::<f64>()
            / 40_000.0;
        for deg in [3.0_f64, 26.0, 59.0] {
            let t = deg.to_radians();
            for ch in 0..2 {
                let want = ensemble_power(&plain, t, ch) + d0 * t.cos() * g2;
                let got = ensemble_power(&ev, t, ch);
                assert!(
                    (got / want - 1.0).abs() < 1e-9,
                    "{deg}° ch{ch}: {got} vs {want}"
                );
            }
        }
        // At 59° the paper's σ0 (≈ −40 dB HH) is far below the diffuse −19.9 dB.
        let t = 59f64.to_radians();
        let total = 10.0 * m.sigma0(Polarisation::HH, t).log10();
        assert!((total + 19.9).abs() < 0.1, "{total}");
        assert!(10.0 * model().sigma0(Polarisation::HH, t).log10() < -39.0);
    }

    #[test]
    fn switch_is_where_the_two_models_cross() {
        let m = model();
        for pol in [Polarisation::HH, Polarisation::VV] {
            let t = m.switch_angle_rad(pol);
            assert!(
                t > 5f64.to_radians() && t < 25f64.to_radians(),
                "{}",
                t.to_degrees()
            );
            let ka = m.sigma0_ka(pol, t);
            let spm = m.sigma0_spm(pol, t);
            assert!((ka / spm - 1.0).abs() < 1e-6);
            // Continuous σ0 across the switch; KA above SPM just below it.
            assert!(m.sigma0_ka(pol, t - 0.01) > m.sigma0_spm(pol, t - 0.01));
        }
    }

    #[test]
    fn rotation_mixes_channels_and_keeps_normal_case() {
        let ev = model().facet_evaluator();
        let t = 30f64.to_radians();
        let g = C64::new(1.0, 0.0);
        let [hh0, vv0] = ev.reflectivity(t, 0.0, g);
        let [hh90, vv90] = ev.reflectivity(t, std::f64::consts::FRAC_PI_2, g);
        assert!((hh0 - vv90).norm() < 1e-12 && (vv0 - hh90).norm() < 1e-12);
    }

    #[test]
    fn gaussian_has_unit_power_and_is_reproducible() {
        let n = 100_000;
        let p: f64 = (0..n)
            .map(|i| complex_gaussian(1, 2, i).norm_sqr())
            .sum::<f64>()
            / n as f64;
        assert!((p - 1.0).abs() < 0.02);
        assert_eq!(complex_gaussian(1, 2, 3), complex_gaussian(1, 2, 3));
        assert_ne!(complex_gaussian(1, 2, 3), complex_gaussian(2, 2, 3));
    }
}
