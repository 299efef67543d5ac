//! Radar, orbit and scattering parameters (paper table in `shared/design.md`) and the values
//! derived from them (eqs 14, 15 and the RDA relations).

use serde::{Deserialize, Serialize};

use super::scattering::TwoScaleModel;
use super::{SPEED_OF_LIGHT_M_S, SarError, SarResult};

/// Baseline of the [`RadarPreset::Mission`] design, m: four times the paper's 8 m, so the
/// height of ambiguity is ≈ 183 m per 2π instead of ≈ 733 m and the height noise of a given
/// coherence a quarter. The shortest of the baselines measured (8, 16, 24, 32 m) that keeps
/// height RMSE ≤ 3 m and slope RMSE ≤ 3° on the floor scenes at NESZ −25 dB (docs/insar.md,
/// "Radar design under NESZ −25 dB"); a boom of that length has flown (SRTM's 60 m mast).
pub const MISSION_BASELINE_M: f64 = 32.0;

/// Second, longer baseline of the [`RadarPreset::Mission`] design, m: a second satellite in
/// formation whose 128 m interferogram gives each look's heights wherever it agrees with the
/// [`MISSION_BASELINE_M`] one and claims a smaller bound (the InSAR chain's
/// `insar::InsarConfig::long_baseline_m`; twice the SAR time). What takes the 16 km descents
/// over the smooth plains' InSAR map from 4.4 m to 1.7–2.0 m at touchdown (p95, with
/// velocimeter) and every descent map within the touchdown bars (docs/insar.md, "A second,
/// longer baseline"; session 49 made it the default).
pub const MISSION_LONG_BASELINE_M: f64 = 128.0;

/// Thermal noise of the [`RadarPreset::Mission`] design (the default radar), NESZ in dB: the
/// noise level of a typical spaceborne L-band SAR (SAOCOM's L-band instrument, at 1275 MHz, is
/// specified at −28 dB in its single and dual polarisation modes; −25 dB leaves 3 dB for a
/// smaller lunar orbiter). docs/insar.md, "Radar design under NESZ −25 dB".
pub const MISSION_NESZ_DB: f64 = -25.0;

/// Diffuse backscatter of the Moon's surface at normal incidence, dB, of the `σ0_d·cos θ` law
/// the [`RadarPreset::Mission`] scenes carry beside the paper's two-scale model: a 20–25 %
/// diffuse share of the Moon's total radar cross-section (≈ 0.07 of its disk, Earth-based
/// radar), fixed before any scene was run with it (docs/insar.md, "Walls under noise").
pub const MOON_DIFFUSE_DB: f64 = -17.0;

/// Named radar designs (with the surface model they are flown over). The default is
/// [`RadarPreset::Mission`]: a realistic radar with thermal noise; [`RadarPreset::Paper`]
/// reproduces the paper's noise-free echo model exactly.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum RadarPreset {
    /// The paper's model: 8 m baseline tilted 30° (height of ambiguity ≈ 733 m), no thermal
    /// noise, the two-scale surface alone, one look (east).
    Paper,
    /// The mission design: the paper's radar with a [`MISSION_BASELINE_M`] boom, thermal noise
    /// at [`MISSION_NESZ_DB`], the Moon's diffuse echo ([`MOON_DIFFUSE_DB`]), a second
    /// [`MISSION_LONG_BASELINE_M`] pair ([`RadarPreset::long_baseline_m`]) and two passes
    /// looking east and west (the look count and the second pair are the InSAR chain's:
    /// `insar::pipeline::LookDirections::of_preset`).
    #[default]
    Mission,
}

impl RadarPreset {
    /// The preset's configuration: [`SarConfig::default`] (the paper's table) with the
    /// preset's baseline, thermal noise and diffuse term.
    pub fn config(self) -> SarConfig {
        let mut c = SarConfig::default();
        match self {
            RadarPreset::Paper => {
                c.noise_equivalent_sigma0_db = f64::NEG_INFINITY;
                c.diffuse_sigma0_db = f64::NEG_INFINITY;
            }
            RadarPreset::Mission => {
                c.baseline_m = MISSION_BASELINE_M;
                c.noise_equivalent_sigma0_db = MISSION_NESZ_DB;
                c.diffuse_sigma0_db = MOON_DIFFUSE_DB;
            }
        }
        c
    }

    /// The second, longer baseline the design's InSAR maps fuse in, m (0 = none): the paper's
    /// radar has one pair, the mission's a second at [`MISSION_LONG_BASELINE_M`]. Like the
    /// look count it is the InSAR chain's choice, not the SAR simulation's ([`SarConfig`] is
    /// the first pair's radar).
    pub fn long_baseline_m(self) -> f64 {
        match self {
            RadarPreset::Paper => 0.0,
            RadarPreset::Mission => MISSION_LONG_BASELINE_M,
        }
    }

    /// The name the CLI and the reports use (`paper`, `mission`).
    pub fn name(self) -> &'static str {
        match self {
            RadarPreset::Paper => "paper",
            RadarPreset::Mission => "mission",
        }
    }
}

/// Polarisation channel: transmit and receive both horizontal, or both vertical.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Polarisation {
    /// Horizontal transmit, horizontal receive.
    HH,
    /// Vertical transmit, vertical receive.
    VV,
}

impl Polarisation {
    /// Lower-case tag used in file names (`hh`, `vv`).
    pub fn tag(self) -> &'static str {
        match self {
            Polarisation::HH => "hh",
            Polarisation::VV => "vv",
        }
    }
    /// Code stored in SLC file headers (0 = HH, 1 = VV).
    pub fn code(self) -> u8 {
        match self {
            Polarisation::HH => 0,
            Polarisation::VV => 1,
        }
    }
    /// Inverse of [`Polarisation::code`].
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(Polarisation::HH),
            1 => Some(Polarisation::VV),
            _ => None,
        }
    }
}

impl std::str::FromStr for Polarisation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_uppercase().as_str() {
            "HH" => Ok(Polarisation::HH),
            "VV" => Ok(Polarisation::VV),
            other => Err(format!("unknown polarisation {other:?} (HH or VV)")),
        }
    }
}

/// Every input parameter of the SAR simulation. Defaults are the paper's values (with thermal
/// noise at −30 dB, which the paper does not have; the commands start from a [`RadarPreset`]
/// instead, the [`RadarPreset::Mission`] design unless told otherwise); the pulse
/// width (not given by the paper) is 10 µs: 684 samples at `fs = 2B`, a time–bandwidth product
/// of 342, long enough for a clean chirp spectrum and short enough to keep the echo window
/// (chirp + swath) under 2048 samples for a 4 km scene.
///
/// Loadable from TOML (every key optional, unknown keys rejected).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SarConfig {
    /// Carrier frequency f0, Hz.
    pub carrier_hz: f64,
    /// Platform altitude H above the scene's mean height, m.
    pub altitude_m: f64,
    /// Platform speed v along `+x`, m/s.
    pub velocity_m_s: f64,
    /// Incidence angle θ0 at the scene centre on the flat datum, degrees.
    pub incidence_centre_deg: f64,
    /// Nominal ground-range resolution r_g (eq 14), m; sets the chirp bandwidth.
    pub ground_range_resolution_m: f64,
    /// Nominal azimuth resolution r_a = L_A/2 (eq 15), m; sets the antenna length.
    pub azimuth_resolution_m: f64,
    /// Range sampling rate over chirp bandwidth, fs/B (paper: 2).
    pub range_oversampling: f64,
    /// PRF over Doppler bandwidth (paper: 2).
    pub azimuth_oversampling: f64,
    /// Chirp pulse width τ, s (documented choice, see type docs).
    pub pulse_width_s: f64,
    /// Antenna baseline length B_L, m.
    pub baseline_m: f64,
    /// Baseline tilt α above the horizontal, degrees (A2 = A1 + B_L·(0, cos α, sin α)).
    pub baseline_tilt_deg: f64,
    /// Relative permittivity ε_r of the regolith (real).
    pub permittivity: f64,
    /// Kirchhoff rms slope √2·δ1/L1.
    pub ka_rms_slope: f64,
    /// SPM normalised correlation length k·L2.
    pub spm_kl: f64,
    /// SPM normalised height standard deviation k·δ2.
    pub spm_ks: f64,
    /// Diffuse backscatter at normal incidence, dB, of a `σ0_d·cos θ` law added to the
    /// two-scale model (`-inf` = none: the paper's model and this struct's default; the
    /// [`RadarPreset::Mission`] design the commands fly by default sets [`MOON_DIFFUSE_DB`]). Not in the paper:
    /// the Moon's non-directional echo, which dominates beyond ≈ 40° local incidence
    /// (docs/insar.md, "Walls under noise", derives −17 dB from lunar radar measurements).
    pub diffuse_sigma0_db: f64,
    /// Polarisations to simulate (1 or 2 of HH, VV).
    pub polarisations: Vec<Polarisation>,
    /// Seed of the facet reflectivity `w` (shared by both antennas) and of the thermal noise.
    pub seed: u64,
    /// Noise-equivalent σ0 of the thermal noise, dB; `-inf` (or any non-finite value) disables
    /// the noise.
    pub noise_equivalent_sigma0_db: f64,
    /// Triangle mesh spacing, m; the DEM is bilinearly resampled to it (paper: 10 m → 5 m).
    pub mesh_spacing_m: f64,
    /// Hamming coefficient of the range and azimuth windows (0.54: classic Hamming).
    pub hamming_alpha: f64,
}

impl Default for SarConfig {
    fn default() -> Self {
        Self {
            carrier_hz: 1.25e9,
            altitude_m: 100e3,
            velocity_m_s: 1600.0,
            incidence_centre_deg: 26.0,
            ground_range_resolution_m: 10.0,
            azimuth_resolution_m: 10.0,
            range_oversampling: 2.0,
            azimuth_oversampling: 2.0,
            pulse_width_s: 10e-6,
            baseline_m: 8.0,
            baseline_tilt_deg: 30.0,
            permittivity: 4.0,
            ka_rms_slope: 0.08,
            spm_kl: 3.0,
            spm_ks: 0.3,
            diffuse_sigma0_db: f64::NEG_INFINITY,
            polarisations: vec![Polarisation::HH, Polarisation::VV],
            seed: 0x5EED_2023,
            noise_equivalent_sigma0_db: -30.0,
            mesh_spacing_m: 5.0,
            hamming_alpha: 0.54,
        }
    }
}

/// Values derived from a [`SarConfig`]; all at the scene centre on the flat datum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Derived {
    /// Wavelength λ = c/f0, m.
    pub wavelength_m: f64,
    /// Slant range to the scene centre H/cos θ0, m.
    pub slant_range_centre_m: f64,
    /// Chirp bandwidth B = c/(2·r_g·sin θ0) (eq 14), Hz.
    pub bandwidth_hz: f64,
    /// Range sampling rate fs, Hz.
    pub sampling_rate_hz: f64,
    /// Slant-range sample spacing c/(2fs), m.
    pub range_spacing_slant_m: f64,
    /// Ground-range sample spacing at the centre, m.
    pub range_spacing_ground_m: f64,
    /// Chirp rate K_r = B/τ, Hz/s.
    pub chirp_rate_hz_s: f64,
    /// Chirp length in samples (τ·fs).
    pub chirp_samples: f64,
    /// Antenna length L_A = 2·r_a (eq 15), m.
    pub antenna_length_m: f64,
    /// Doppler bandwidth 2v/L_A, Hz.
    pub doppler_bandwidth_hz: f64,
    /// Pulse repetition frequency, Hz.
    pub prf_hz: f64,
    /// Azimuth sample spacing v/PRF, m.
    pub azimuth_spacing_m: f64,
    /// Synthetic aperture (azimuth footprint) L_s = λR/L_A at the centre, m.
    pub synthetic_aperture_m: f64,
    /// Pulses in one synthetic aperture at the centre.
    pub aperture_pulses: f64,
    /// Azimuth FM rate K_a = 2v²/(λR) at the centre, Hz/s.
    pub azimuth_fm_rate_hz_s: f64,
    /// Range cell migration at the aperture edge, m.
    pub rcm_aperture_edge_m: f64,
    /// Range cell migration at the aperture edge in slant-range samples.
    pub rcm_aperture_edge_samples: f64,
    /// Height of ambiguity λR·sin θ/(2·B_L·cos(θ−α)) (eq 17, ping-pong), m per 2π.
    pub height_of_ambiguity_m: f64,
    /// Hamming −3 dB width factor (≈1.30 for α = 0.54), in units of 1/bandwidth.
    pub hamming_irw_factor: f64,
    /// Theoretical range IRW, slant range, m.
    pub range_irw_theory_m: f64,
    /// Theoretical range IRW projected to the ground at the centre, m.
    pub range_irw_theory_ground_m: f64,
    /// Theoretical azimuth IRW, m.
    pub azimuth_irw_theory_m: f64,
    /// Local incidence below which KA is used for HH (KA and SPM σ0 cross), degrees.
    pub ka_spm_switch_hh_deg: f64,
    /// Local incidence below which KA is used for VV, degrees.
    pub ka_spm_switch_vv_deg: f64,
}

impl SarConfig {
    /// Load from a TOML string; absent keys keep the defaults.
    pub fn from_toml_str(text: &str) -> SarResult<Self> {
        let cfg: SarConfig = toml::from_str(text).map_err(|e| SarError::Config(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Like [`SarConfig::from_toml_str`], but keys missing from `text` keep the values of
    /// `base` (e.g. a [`RadarPreset`]) instead of the paper's defaults.
    pub fn from_toml_str_over(text: &str, base: SarConfig) -> SarResult<Self> {
        let err = |e: String| SarError::Config(e);
        let mut table = toml::Table::try_from(&base).map_err(|e| err(e.to_string()))?;
        let over: toml::Table = toml::from_str(text).map_err(|e| err(e.to_string()))?;
        table.extend(over);
        let cfg: SarConfig = table
            .try_into()
            .map_err(|e: toml::de::Error| err(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Check every value once; later stages rely on it.
    pub fn validate(&self) -> SarResult<()> {
        let positive = [
            ("carrier_hz", self.carrier_hz),
            ("altitude_m", self.altitude_m),
            ("velocity_m_s", self.velocity_m_s),
            ("ground_range_resolution_m", self.ground_range_resolution_m),
            ("azimuth_resolution_m", self.azimuth_resolution_m),
            ("pulse_width_s", self.pulse_width_s),
            ("baseline_m", self.baseline_m),
            ("ka_rms_slope", self.ka_rms_slope),
            ("spm_kl", self.spm_kl),
            ("spm_ks", self.spm_ks),
            ("mesh_spacing_m", self.mesh_spacing_m),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(SarError::Config(format!(
                    "{name} must be finite and > 0, got {v}"
                )));
            }
        }
        if !(self.incidence_centre_deg > 1.0 && self.incidence_centre_deg < 80.0) {
            return Err(SarError::Config(format!(
                "incidence_centre_deg must be in (1, 80), got {}",
                self.incidence_centre_deg
            )));
        }
        if !(self.range_oversampling >= 1.2 && self.range_oversampling <= 8.0) {
            return Err(SarError::Config(
                "range_oversampling must be in [1.2, 8] (the RCMC kernel needs a guard band)"
                    .into(),
            ));
        }
        if !(self.azimuth_oversampling >= 1.2 && self.azimuth_oversampling <= 8.0) {
            return Err(SarError::Config(
                "azimuth_oversampling must be in [1.2, 8]".into(),
            ));
        }
        if !(self.permittivity.is_finite() && self.permittivity > 1.0) {
            return Err(SarError::Config("permittivity must be > 1".into()));
        }
        if !(self.baseline_tilt_deg.is_finite() && self.baseline_tilt_deg.abs() <= 90.0) {
            return Err(SarError::Config(
                "baseline_tilt_deg must be in [-90, 90]".into(),
            ));
        }
        if !(self.hamming_alpha >= 0.5 && self.hamming_alpha <= 1.0) {
            return Err(SarError::Config("hamming_alpha must be in [0.5, 1]".into()));
        }
        if self.polarisations.is_empty() || self.polarisations.len() > super::MAX_POLARISATIONS {
            return Err(SarError::Config(
                "polarisations: give 1 or 2 of HH, VV".into(),
            ));
        }
        if self.polarisations.len() == 2 && self.polarisations[0] == self.polarisations[1] {
            return Err(SarError::Config("polarisations must be distinct".into()));
        }
        if self.diffuse_sigma0_db.is_nan() || self.diffuse_sigma0_db > 0.0 {
            return Err(SarError::Config(
                "diffuse_sigma0_db must be ≤ 0 dB (or -inf for none)".into(),
            ));
        }
        if self.noise_equivalent_sigma0_db.is_nan() {
            return Err(SarError::Config(
                "noise_equivalent_sigma0_db is NaN (use -inf)".into(),
            ));
        }
        let chirp = self.pulse_width_s * self.range_oversampling * self.bandwidth_hz();
        if !(8.0..=1.0e5).contains(&chirp) {
            return Err(SarError::Config(format!(
                "pulse gives {chirp:.0} chirp samples; need 8 ..= 100000"
            )));
        }
        Ok(())
    }

    /// Chirp bandwidth from eq 14, Hz.
    pub fn bandwidth_hz(&self) -> f64 {
        SPEED_OF_LIGHT_M_S
            / (2.0 * self.ground_range_resolution_m * self.incidence_centre_deg.to_radians().sin())
    }

    /// Diffuse σ0 at normal incidence, linear (0 when the term is off).
    pub fn diffuse_sigma0_linear(&self) -> f64 {
        let db = self.diffuse_sigma0_db;
        if db.is_finite() {
            10f64.powf(db / 10.0)
        } else {
            0.0
        }
    }

    /// Thermal-noise σ0 as a linear value, `None` when the noise is disabled.
    pub fn noise_sigma0_linear(&self) -> Option<f64> {
        let db = self.noise_equivalent_sigma0_db;
        db.is_finite().then(|| 10f64.powf(db / 10.0))
    }

    /// All derived values (validate first).
    pub fn derived(&self) -> SarResult<Derived> {
        self.validate()?;
        let c = SPEED_OF_LIGHT_M_S;
        let theta = self.incidence_centre_deg.to_radians();
        let wavelength_m = c / self.carrier_hz;
        let r0 = self.altitude_m / theta.cos();
        let bandwidth_hz = self.bandwidth_hz();
        let fs = self.range_oversampling * bandwidth_hz;
        let dr = c / (2.0 * fs);
        let antenna_length_m = 2.0 * self.azimuth_resolution_m;
        let doppler_bandwidth_hz = 2.0 * self.velocity_m_s / antenna_length_m;
        let prf_hz = self.azimuth_oversampling * doppler_bandwidth_hz;
        let dx = self.velocity_m_s / prf_hz;
        let ls = wavelength_m * r0 / antenna_length_m;
        let ka = 2.0 * self.velocity_m_s.powi(2) / (wavelength_m * r0);
        let rcm = (r0 * r0 + 0.25 * ls * ls).sqrt() - r0;
        let alpha = self.baseline_tilt_deg.to_radians();
        let hoa = wavelength_m * r0 * theta.sin() / (2.0 * self.baseline_m * (theta - alpha).cos());
        let k_irw = hamming_irw_factor(self.hamming_alpha);
        let model = TwoScaleModel::from_config(self);
        Ok(Derived {
            wavelength_m,
            slant_range_centre_m: r0,
            bandwidth_hz,
            sampling_rate_hz: fs,
            range_spacing_slant_m: dr,
            range_spacing_ground_m: dr / theta.sin(),
            chirp_rate_hz_s: bandwidth_hz / self.pulse_width_s,
            chirp_samples: self.pulse_width_s * fs,
            antenna_length_m,
            doppler_bandwidth_hz,
            prf_hz,
            azimuth_spacing_m: dx,
            synthetic_aperture_m: ls,
            aperture_pulses: ls / dx,
            azimuth_fm_rate_hz_s: ka,
            rcm_aperture_edge_m: rcm,
            rcm_aperture_edge_samples: rcm / dr,
            height_of_ambiguity_m: hoa,
            hamming_irw_factor: k_irw,
            range_irw_theory_m: k_irw * c / (2.0 * bandwidth_hz),
            range_irw_theory_ground_m: k_irw * c / (2.0 * bandwidth_hz) / theta.sin(),
            azimuth_irw_theory_m: k_irw * self.velocity_m_s / doppler_bandwidth_hz,
            ka_spm_switch_hh_deg: model.switch_angle_rad(Polarisation::HH).to_degrees(),
            ka_spm_switch_vv_deg: model.switch_angle_rad(Polarisation::VV).to_degrees(),
        })
    }
}

/// Amplitude response at time `t` (units of 1/bandwidth) of a spectrum weighted by the
/// generalised Hamming window `α − (1−α)·cos(2πf)` over `f ∈ [0, 1]`, normalised to 1 at `t = 0`.
pub fn hamming_response(alpha: f64, t: f64) -> f64 {
    // Closed form: α·sinc(t) + (1−α)/2·(sinc(t−1) + sinc(t+1)) (the window's cosine splits
    // into two shifted sincs).
    let sinc = |u: f64| {
        if u.abs() < 1e-12 {
            1.0
        } else {
            (std::f64::consts::PI * u).sin() / (std::f64::consts::PI * u)
        }
    };
    (alpha * sinc(t) + 0.5 * (1.0 - alpha) * (sinc(t - 1.0) + sinc(t + 1.0))) / alpha
}

/// −3 dB (half-power) width of [`hamming_response`], in units of 1/bandwidth.
pub fn hamming_irw_factor(alpha: f64) -> f64 {
    // Bisection for |h(t)|² = 1/2 on (0, 1): h falls monotonically over the main lobe.
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if hamming_response(alpha, mid).powi(2) > 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo + hi
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derived_values_match_the_design_table() {
        let d = SarConfig::default().derived().unwrap();
        assert!((d.wavelength_m - 0.2398).abs() < 1e-4);
        assert!((d.slant_range_centre_m - 111_260.0).abs() < 5.0);
        assert!((d.bandwidth_hz - 34.19e6).abs() < 0.01e6);
        assert!((d.range_spacing_slant_m - 2.19).abs() < 0.01);
        assert!((d.range_spacing_ground_m - 5.0).abs() < 1e-9);
        assert!((d.doppler_bandwidth_hz - 160.0).abs() < 1e-9);
        assert!((d.prf_hz - 320.0).abs() < 1e-9);
        assert!((d.azimuth_spacing_m - 5.0).abs() < 1e-9);
        assert!((d.synthetic_aperture_m - 1334.0).abs() < 1.0);
        assert!((d.aperture_pulses - 267.0).abs() < 0.5);
        assert!((d.azimuth_fm_rate_hz_s - 191.9).abs() < 0.1);
        assert!((d.rcm_aperture_edge_m - 2.0).abs() < 0.05);
        assert!((d.height_of_ambiguity_m - 733.0).abs() < 1.0);
        assert!((d.hamming_irw_factor - 1.303).abs() < 0.005);
        assert!((d.range_irw_theory_m - 5.71).abs() < 0.01);
    }

    #[test]
    fn toml_overrides_and_rejects_unknown_keys() {
        let cfg =
            SarConfig::from_toml_str("altitude_m = 50000.0\npolarisations = [\"HH\"]\n").unwrap();
        assert_eq!(cfg.altitude_m, 50_000.0);
        assert_eq!(cfg.polarisations, vec![Polarisation::HH]);
        assert!(SarConfig::from_toml_str("altitude = 1.0").is_err());
        assert!(SarConfig::from_toml_str("velocity_m_s = -3.0").is_err());
        let off = SarConfig::from_toml_str("noise_equivalent_sigma0_db = -inf").unwrap();
        assert!(off.noise_sigma0_linear().is_none());
    }
}
