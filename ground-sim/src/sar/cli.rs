//! Command-line glue: `ground-sim sar` and `ground-sim psf`.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use super::config::{Polarisation, RadarPreset, SarConfig};
use super::geometry::SarDem;
use super::pipeline::{MeshOffset, SceneFrame, SimOptions, simulate_with};
use super::products::write_products;
use super::psf::run_point_target;
use super::scattering::splitmix64;
use super::scene::{AnalyticSurface, analytic_dem};
use crate::insar::blocks::{BlockLayout, BlockSpec};

/// Radar parameters: a TOML file, then individual overrides.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RadarArgs {
    /// Named radar design the file and flags start from (default `mission`: 32 m baseline,
    /// thermal noise at NESZ −25 dB, the Moon's diffuse echo at −17 dB, both look directions
    /// for InSAR; `paper`: the paper's noise-free model, 8 m baseline, one look; docs/insar.md).
    #[arg(long, value_enum)]
    pub radar: Option<RadarPreset>,
    /// TOML file with any `SarConfig` keys (others keep the preset's values; the InSAR look
    /// count is not a `SarConfig` key: it follows `--radar` and `--looks`).
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
    /// Noise-equivalent σ0, dB (default: the preset's; `mission` −25 dB, `paper` none).
    #[arg(long, allow_hyphen_values = true, conflicts_with = "no_noise")]
    pub nesz_db: Option<f64>,
    /// Disable thermal noise only (the design's baseline, diffuse echo and looks stay;
    /// `--radar paper` for the paper's whole noise-free model).
    #[arg(long)]
    pub no_noise: bool,
    /// Diffuse backscatter at normal incidence, dB, of a σ0_d·cos θ law added to the paper's
    /// two-scale surface (default: the preset's; `mission` −17 dB, derived for the Moon at L
    /// band in docs/insar.md; `paper` and `-inf`: none).
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
    /// The named design these arguments start from ([`RadarPreset::Mission`] unless given).
    pub fn preset(&self) -> RadarPreset {
        self.radar.unwrap_or_default()
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
    /// Largest core block side, DEM pixels: a scene wider or taller than this is simulated in
    /// overlapping blocks, each alone (memory bounded by the block), seen from the whole
    /// scene's track, with the scene's speckle; SLCs of block i go to OUT/blocks/block-iii/.
    /// 0 = always one piece.
    #[arg(long, default_value_t = 0)]
    pub block_px: usize,
    /// Margin added to each side of a block, DEM pixels.
    #[arg(long, default_value_t = 50)]
    pub block_overlap_px: usize,
    /// Simulate only block I of N (0-based, e.g. a job-array task); N must be the scene's
    /// block count (`--block-px` cuts it).
    #[arg(long, value_name = "I/N", requires = "block_px")]
    pub block: Option<crate::evaluation::shard::Shard>,
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
    if args.block_px > 0 && (dem.width > args.block_px || dem.height > args.block_px) {
        return run_sar_blocks(&args, &cfg, &dem);
    }
    if args.block.is_some() {
        bail!(
            "--block: the scene ({}×{} px) fits one block of --block-px {}; run without --block",
            dem.width,
            dem.height,
            args.block_px
        );
    }
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

/// What `sar` writes beside a block's SLCs (`block.json`): where the block lies in the scene.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SarBlockRecord {
    /// The layout, in DEM pixels.
    pub layout: BlockLayout,
    /// This block: core and extent, DEM pixels (rows = azimuth, columns = ground range).
    pub block: BlockSpec,
    /// The extent's first node in the scene's SAR frame (azimuth, ground range), m; the SLCs'
    /// `first_azimuth_m` / `first_range_m` are in the same frame as the whole scene's.
    pub origin_m: [f64; 2],
    /// The whole scene's centre the track is placed for (azimuth, ground range, height), m.
    pub scene_centre_m: [f64; 3],
    /// Seed of this block's thermal noise (the speckle is the scene's).
    pub noise_seed: u64,
    /// Facets simulated.
    pub facets: usize,
    /// Echo simulation time, s.
    pub echoes_s: f64,
    /// Whole block time (scene, echoes, focusing), s.
    pub total_s: f64,
}

/// `sar` over a scene larger than `--block-px`: every block (or the one `--block` names)
/// simulated alone from the whole scene's track and written to `OUT/blocks/block-iii/`.
fn run_sar_blocks(args: &SarArgs, cfg: &SarConfig, dem: &SarDem) -> anyhow::Result<()> {
    let layout = BlockLayout::new(dem.width, dem.height, args.block_px, args.block_overlap_px)?;
    let indices: Vec<usize> = match args.block {
        Some(b) => {
            if b.count != layout.count() {
                bail!(
                    "--block {}/{}: the scene cuts into {} blocks at --block-px {} (overlap {})",
                    b.index,
                    b.count,
                    layout.count(),
                    args.block_px,
                    args.block_overlap_px
                );
            }
            vec![b.index]
        }
        None => (0..layout.count()).collect(),
    };
    let p = dem.pixel_m;
    let centre = [
        0.5 * (dem.height - 1) as f64 * p,
        0.5 * (dem.width - 1) as f64 * p,
        dem.mean_height_m(),
    ];
    eprintln!(
        "SAR in blocks: {} × {} blocks of <= {} px (+{} each side); running {}",
        layout.rows,
        layout.cols,
        args.block_px,
        args.block_overlap_px,
        if indices.len() == 1 {
            format!("block {}", indices[0])
        } else {
            "all".into()
        }
    );
    for i in indices {
        let spec = layout.block(i)?;
        let e = spec.extent;
        let (r0, c0, w, h) = (e.row0, e.col0, e.width(), e.height());
        let block_dem = dem.crop(r0, c0, w, h)?;
        let origin = block_dem.origin_m;
        // Speckle by place in the scene's mesh (as `insar` blocks do), so overlapping blocks
        // see the same ground alike.
        let mesh_offset = MeshOffset::for_block(p, cfg.mesh_spacing_m, r0, c0, dem.width);
        let noise_seed = splitmix64(cfg.seed ^ splitmix64(i as u64 + 1));
        let opts = SimOptions {
            progress: !args.no_progress,
            scene: Some(SceneFrame {
                centre_m: centre,
                mesh_offset,
                noise_seed,
            }),
            ..SimOptions::default()
        };
        let pair = simulate_with(&block_dem, cfg, &opts)
            .with_context(|| format!("simulating block {i}"))?;
        let dir = args.out.join("blocks").join(format!("block-{i:03}"));
        write_products(&pair, [w, h], p, &dir)?;
        let record = SarBlockRecord {
            layout,
            block: spec,
            origin_m: origin,
            scene_centre_m: centre,
            noise_seed,
            facets: pair.stats.facets,
            echoes_s: pair.timings.echoes_s,
            total_s: pair.timings.total_s,
        };
        std::fs::write(
            dir.join("block.json"),
            serde_json::to_string_pretty(&record)? + "\n",
        )
        .with_context(|| format!("writing {}", dir.join("block.json").display()))?;
        eprintln!(
            "block {i}: {w}×{h} px from ({r0}, {c0}), {} facets, echoes {:.1} s, total {:.1} s -> {}",
            pair.stats.facets,
            pair.timings.echoes_s,
            pair.timings.total_s,
            dir.display()
        );
    }
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
    fn the_default_radar_is_the_noisy_mission_and_paper_is_noise_free() {
        use crate::sar::{MISSION_BASELINE_M, MISSION_NESZ_DB, MOON_DIFFUSE_DB};
        let def = RadarArgs::default().resolve().unwrap();
        assert_eq!(def.baseline_m, MISSION_BASELINE_M);
        assert_eq!(def.noise_equivalent_sigma0_db, MISSION_NESZ_DB);
        assert_eq!(def.diffuse_sigma0_db, MOON_DIFFUSE_DB);
        assert!(def.noise_sigma0_linear().is_some());
        let paper = RadarArgs {
            radar: Some(RadarPreset::Paper),
            ..RadarArgs::default()
        }
        .resolve()
        .unwrap();
        // The paper's table, without noise or diffuse echo.
        assert_eq!(paper.baseline_m, 8.0);
        assert!(paper.noise_sigma0_linear().is_none());
        assert_eq!(paper.diffuse_sigma0_db, f64::NEG_INFINITY);
        let quiet_mission = RadarArgs {
            no_noise: true,
            ..RadarArgs::default()
        }
        .resolve()
        .unwrap();
        assert!(quiet_mission.noise_sigma0_linear().is_none());
        assert_eq!(quiet_mission.baseline_m, MISSION_BASELINE_M);
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
        assert_eq!(cfg.noise_equivalent_sigma0_db, MISSION_NESZ_DB);
        // Over the paper's preset, whose noise and diffuse echo are -inf in the TOML base.
        let cfg = RadarArgs {
            radar: Some(RadarPreset::Paper),
            config: Some(dir.path().join("sar.toml")),
            ..RadarArgs::default()
        }
        .resolve()
        .unwrap();
        assert_eq!(cfg.altitude_m, 90_000.0);
        assert_eq!(cfg.baseline_m, 8.0);
        assert!(cfg.noise_sigma0_linear().is_none());
        assert_eq!(cfg.diffuse_sigma0_db, f64::NEG_INFINITY);
    }
}
