//! Command-line glue: `ground-sim sar` and `ground-sim psf`.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use super::config::{Polarisation, RadarPreset, SarConfig};
use super::geometry::SarDem;
use super::pipeline::{SimOptions, simulate_with};
use super::products::write_products;
use super::psf::run_point_target;
use super::scene::{AnalyticSurface, analytic_dem};

/// Radar parameters: a TOML file, then individual overrides.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RadarArgs {
    /// Named radar design the file and flags start from (default `paper`: the paper's 8 m
    /// baseline; `mission`: the 32 m baseline that keeps the InSAR DEM within its targets at
    /// NESZ −25 dB, docs/insar.md).
    #[arg(long, value_enum)]
    pub radar: Option<RadarPreset>,
    /// TOML file with any `SarConfig` keys (others keep the preset's values).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Platform altitude above the scene mean, m.
    #[arg(long)]
    pub altitude_m: Option<f64>,
    /// Platform speed, m/s.
    #[arg(long)]
    pub velocity_m_s: Option<f64>,
    /// Incidence at the scene centre, degrees.
    #[arg(long)]
    pub incidence_deg: Option<f64>,
    /// Chirp pulse width, µs.
    #[arg(long)]
    pub pulse_width_us: Option<f64>,
    /// Baseline length, m.
    #[arg(long)]
    pub baseline_m: Option<f64>,
    /// Baseline tilt above horizontal, degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub baseline_tilt_deg: Option<f64>,
    /// Noise-equivalent σ0, dB.
    #[arg(long, allow_hyphen_values = true)]
    pub nesz_db: Option<f64>,
    /// Disable thermal noise.
    #[arg(long)]
    pub no_noise: bool,
    /// Diffuse backscatter at normal incidence, dB, of a σ0_d·cos θ law added to the paper's
    /// two-scale surface (`-inf`: none; docs/insar.md derives −17 dB for the Moon at L band).
    #[arg(long, allow_hyphen_values = true)]
    pub diffuse_db: Option<f64>,
    /// Seed of the surface reflectivity and the noise.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Polarisations, e.g. `HH` or `HH,VV`.
    #[arg(long, value_delimiter = ',')]
    pub pol: Vec<Polarisation>,
    /// Triangle mesh spacing, m.
    #[arg(long)]
    pub mesh_spacing_m: Option<f64>,
}

impl RadarArgs {
    /// The named design these arguments start from ([`RadarPreset::Paper`] unless given).
    pub fn preset(&self) -> RadarPreset {
        self.radar.unwrap_or(RadarPreset::Paper)
    }

    /// Defaults ← TOML file ← flags, validated.
    pub fn resolve(&self) -> anyhow::Result<SarConfig> {
        let mut cfg = match &self.config {
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("reading {}", p.display()))?;
                SarConfig::from_toml_str_over(&text, self.preset().config())?
            }
            None => self.preset().config(),
        };
        let set = |dst: &mut f64, v: Option<f64>| {
            if let Some(v) = v {
                *dst = v;
            }
        };
        set(&mut cfg.altitude_m, self.altitude_m);
        set(&mut cfg.velocity_m_s, self.velocity_m_s);
        set(&mut cfg.incidence_centre_deg, self.incidence_deg);
        set(
            &mut cfg.pulse_width_s,
            self.pulse_width_us.map(|u| u * 1e-6),
        );
        set(&mut cfg.baseline_m, self.baseline_m);
        set(&mut cfg.baseline_tilt_deg, self.baseline_tilt_deg);
        set(&mut cfg.noise_equivalent_sigma0_db, self.nesz_db);
        set(&mut cfg.diffuse_sigma0_db, self.diffuse_db);
        set(&mut cfg.mesh_spacing_m, self.mesh_spacing_m);
        if self.no_noise {
            cfg.noise_equivalent_sigma0_db = f64::NEG_INFINITY;
        }
        if let Some(s) = self.seed {
            cfg.seed = s;
        }
        if !self.pol.is_empty() {
            cfg.polarisations = self.pol.clone();
        }
        cfg.validate()?;
        Ok(cfg)
    }
}

/// `ground-sim sar`: simulate both antennas over a DEM and write SLCs, σ0 PNGs and a report.
#[derive(Debug, Clone, clap::Args)]
pub struct SarArgs {
    /// Input DEM: single-band GeoTIFF of heights in metres (rows = azimuth, columns = range).
    #[arg(
        long,
        conflicts_with = "synthetic",
        required_unless_present = "synthetic"
    )]
    pub dem: Option<PathBuf>,
    /// Use an analytic surface instead of a DEM file.
    #[arg(long, value_enum)]
    pub synthetic: Option<AnalyticSurface>,
    /// Side of the synthetic scene, m.
    #[arg(long, default_value_t = 4000.0)]
    pub size_m: f64,
    /// Node spacing of the synthetic DEM (resampled to the mesh spacing), m.
    #[arg(long, default_value_t = 10.0)]
    pub synthetic_pixel_m: f64,
    /// Override the DEM pixel size taken from the georeferencing, m.
    #[arg(long)]
    pub dem_pixel_m: Option<f64>,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Radar parameters.
    #[command(flatten)]
    pub radar: RadarArgs,
    /// Hide progress bars.
    #[arg(long)]
    pub no_progress: bool,
}

/// `ground-sim psf`: point-target analysis on a flat scene with one bright target.
#[derive(Debug, Clone, clap::Args)]
pub struct PsfArgs {
    /// Where to write the JSON report.
    #[arg(long)]
    pub json: PathBuf,
    /// Radar parameters.
    #[command(flatten)]
    pub radar: RadarArgs,
}

/// Read a single-band GeoTIFF DEM with the shared reader ([`crate::dem::read_geotiff`]) into a
/// [`SarDem`] (origin (0, 0), rows = azimuth, columns = ground range; nodata filled from
/// neighbours, see [`SarDem::from_dem`]). `pixel_override` replaces the pixel size taken from
/// the georeferencing (for grids whose map unit is not the metre).
pub fn read_geotiff_dem(path: &Path, pixel_override: Option<f64>) -> anyhow::Result<SarDem> {
    let dem =
        crate::dem::read_geotiff(path).with_context(|| format!("reading {}", path.display()))?;
    let (mut sdem, filled) = SarDem::from_dem(&dem)?;
    if filled > 0 {
        eprintln!("SAR: filled {filled} nodata heights from their neighbours");
    }
    if let Some(p) = pixel_override {
        if !(p.is_finite() && p > 0.0) {
            bail!("--dem-pixel-m must be > 0");
        }
        sdem.pixel_m = p;
    }
    Ok(sdem)
}

/// Run `ground-sim sar`.
pub fn run_sar(args: SarArgs) -> anyhow::Result<()> {
    let cfg = args.radar.resolve()?;
    let dem = match (&args.dem, args.synthetic) {
        (Some(p), _) => read_geotiff_dem(p, args.dem_pixel_m)?,
        (None, Some(s)) => {
            if !(args.synthetic_pixel_m > 0.0 && args.size_m >= 2.0 * args.synthetic_pixel_m) {
                bail!("--size-m must cover at least two --synthetic-pixel-m");
            }
            let n = (args.size_m / args.synthetic_pixel_m).round() as usize + 1;
            analytic_dem(s, n, args.synthetic_pixel_m)?
        }
        (None, None) => bail!("give --dem or --synthetic"),
    };
    eprintln!(
        "SAR: DEM {}×{} at {} m, mesh {} m, {} channel(s), both antennas",
        dem.width,
        dem.height,
        dem.pixel_m,
        cfg.mesh_spacing_m,
        cfg.polarisations.len()
    );
    let opts = SimOptions {
        progress: !args.no_progress,
        ..SimOptions::default()
    };
    let pair = simulate_with(&dem, &cfg, &opts)?;
    let report = write_products(&pair, [dem.width, dem.height], dem.pixel_m, &args.out)?;
    let t = &pair.timings;
    eprintln!(
        "done: scene {:.2} s, echoes {:.2} s, focusing {:.2} s, total {:.2} s; report {}",
        t.scene_s,
        t.echoes_s,
        t.focusing_s,
        t.total_s,
        report.display()
    );
    Ok(())
}

/// Run `ground-sim psf`.
pub fn run_psf(args: PsfArgs) -> anyhow::Result<()> {
    let cfg = args.radar.resolve()?;
    let r = run_point_target(&cfg)?;
    let text = serde_json::to_string_pretty(&r)?;
    if let Some(parent) = args.json.parent()
        && !parent.as_os_str().is_empty()
    {
        std::fs::create_dir_all(parent)?;
    }
    std::fs::write(&args.json, text)?;
    println!(
        "range   IRW {:.3} m (theory {:.3} m, {:+.2} %), PSLR {:.2} dB, ISLR {:.2} dB",
        r.range.irw_m,
        r.range.irw_theory_m,
        r.range.irw_error_pct,
        r.range.pslr_db,
        r.range.islr_db
    );
    println!(
        "azimuth IRW {:.3} m (theory {:.3} m, {:+.2} %), PSLR {:.2} dB, ISLR {:.2} dB",
        r.azimuth.irw_m,
        r.azimuth.irw_theory_m,
        r.azimuth.irw_error_pct,
        r.azimuth.pslr_db,
        r.azimuth.islr_db
    );
    println!(
        "peak offset {:.4} px (range {:+.4}, azimuth {:+.4}); amplitude {:.4}",
        r.peak_offset_px, r.peak_offset_range_px, r.peak_offset_azimuth_px, r.peak_amplitude_ratio
    );
    println!(
        "interferometric phase {:.4}° (expected {:.4}°, error {:+.4}°); A1 phase error {:+.4}°",
        r.interferometric_phase_deg,
        r.interferometric_phase_expected_deg,
        r.interferometric_phase_error_deg,
        r.slc_phase_error_deg
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dem::{Dem, GeoRef, write_geotiff};

    #[test]
    fn reads_a_geotiff_with_the_shared_reader() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("dem.tif");
        let (w, h) = (7usize, 5usize);
        let mut z: Vec<f32> = (0..w * h).map(|i| i as f32 * 0.5 - 3.0).collect();
        z[3] = f32::NAN;
        let dem = Dem::new(w, h, z, GeoRef::local(100.0, 200.0, 10.0, "t")).unwrap();
        write_geotiff(&dem, &p, None).unwrap();
        let s = read_geotiff_dem(&p, None).unwrap();
        assert_eq!((s.width, s.height, s.pixel_m), (7, 5, 10.0));
        assert_eq!(s.at(1, 2), 9.0 * 0.5 - 3.0);
        // The nodata height is filled from its neighbours (2, 4 and 10 → mean).
        assert!((s.at(0, 3) - (-2.0 + -1.0 + 2.0) / 3.0).abs() < 1e-6);
        assert_eq!(read_geotiff_dem(&p, Some(5.0)).unwrap().pixel_m, 5.0);
        assert!(read_geotiff_dem(&dir.path().join("missing.tif"), None).is_err());
    }

    #[test]
    fn flags_override_toml() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sar.toml");
        std::fs::write(&p, "altitude_m = 90000.0\nseed = 7\n").unwrap();
        let args = RadarArgs {
            config: Some(p),
            seed: Some(9),
            no_noise: true,
            pol: vec![Polarisation::VV],
            ..RadarArgs::default()
        };
        let cfg = args.resolve().unwrap();
        assert_eq!(cfg.altitude_m, 90_000.0);
        assert_eq!(cfg.seed, 9);
        assert!(cfg.noise_sigma0_linear().is_none());
        assert_eq!(cfg.polarisations, vec![Polarisation::VV]);
    }

    #[test]
    fn the_default_radar_is_the_paper_and_mission_is_named() {
        use crate::sar::MISSION_BASELINE_M;
        let def = RadarArgs::default().resolve().unwrap();
        assert_eq!(format!("{def:?}"), format!("{:?}", SarConfig::default()));
        let mission = RadarArgs {
            radar: Some(RadarPreset::Mission),
            ..RadarArgs::default()
        }
        .resolve()
        .unwrap();
        assert_eq!(mission.baseline_m, MISSION_BASELINE_M);
        // A TOML file overrides the preset's keys and keeps the others.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sar.toml");
        std::fs::write(&p, "altitude_m = 90000.0\n").unwrap();
        let cfg = RadarArgs {
            radar: Some(RadarPreset::Mission),
            config: Some(p),
            ..RadarArgs::default()
        }
        .resolve()
        .unwrap();
        assert_eq!(cfg.altitude_m, 90_000.0);
        assert_eq!(cfg.baseline_m, MISSION_BASELINE_M);
    }
}
