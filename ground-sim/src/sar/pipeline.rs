//! DEM → two focused SLCs per channel (A1, A2), with timings. The entry point of the InSAR stage.

use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};

use super::config::{Derived, Polarisation, SarConfig};
use super::echo::{EchoSimulator, RawEcho, add_thermal_noise};
use super::geometry::{AcquisitionPlan, Antenna, Geometry, SarDem};
use super::rda::RdaProcessor;
use super::scene::{SceneStats, build_facets, facet_scatterers_indexed};
use super::slc::Slc;
use super::{C32, MAX_POLARISATIONS, SarResult};

/// How raw echoes are computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum EchoMethod {
    /// Kernel deposit + one FFT–multiply–IFFT per pulse.
    #[default]
    Fast,
    /// Direct sum of eq 11 (oracle; small scenes only).
    TimeDomain,
}

/// Extra point scatterer added to the facet scene (e.g. a corner reflector).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointTarget {
    /// Position in the local frame, m.
    pub position_m: [f64; 3],
    /// Scattering amplitude S per configured channel (eq 1 units, m).
    pub amplitude: [C32; MAX_POLARISATIONS],
}

/// Options beyond the physical configuration.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Show progress bars on stderr.
    pub progress: bool,
    /// Echo method.
    pub method: EchoMethod,
    /// Multiplier of every facet amplitude (0 removes the clutter, e.g. for point-target runs).
    pub clutter_scale: f64,
    /// Point targets added to the scene.
    pub point_targets: Vec<PointTarget>,
    /// The DEM is one block of a larger scene: place the track for that scene and draw each
    /// facet's speckle by its place in the scene's mesh (`None`: the DEM is the scene).
    pub scene: Option<SceneFrame>,
    /// Seed of the thermal noise when it is not the configuration's (`SarConfig::seed`, which
    /// also draws the speckle) nor a block's: another pass over the same track, whose ground
    /// (speckle) is the same and whose receiver noise is its own.
    pub noise_seed: Option<u64>,
}

/// Where a block sits in the scene it belongs to ([`SimOptions::scene`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneFrame {
    /// The whole scene's centre on its mean height, SAR frame, m (the track is placed for it).
    pub centre_m: [f64; 3],
    /// The block mesh's node (0, 0) as a node of the scene's mesh (row, column), and the
    /// scene mesh's cells per row: facet `k` of cell `(r, c)` draws the speckle of scene facet
    /// `2·((r + row)·cells_wide + c + col) + k`, so overlapping blocks see the same ground
    /// alike.
    pub mesh_offset: Option<MeshOffset>,
    /// Seed of the block's thermal noise (blocks draw their own; the speckle stays the
    /// scene's).
    pub noise_seed: u64,
}

/// A block mesh's place in the scene mesh ([`SceneFrame::mesh_offset`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MeshOffset {
    /// Scene mesh row of the block's first row.
    pub row: usize,
    /// Scene mesh column of the block's first column.
    pub col: usize,
    /// Cells per row of the scene mesh (nodes − 1).
    pub cells_wide: usize,
}

impl MeshOffset {
    /// The mesh of a block whose first DEM node is `(row0, col0)` of a scene `scene_width`
    /// nodes wide, as a part of the scene's mesh — when the mesh spacing divides the DEM pixel
    /// (then both meshes share one lattice); `None` otherwise (the block draws its own
    /// speckle).
    pub fn for_block(
        dem_pixel_m: f64,
        mesh_spacing_m: f64,
        row0: usize,
        col0: usize,
        scene_width: usize,
    ) -> Option<Self> {
        let s = dem_pixel_m / mesh_spacing_m;
        ((s - s.round()).abs() < 1e-9 && s >= 1.0).then(|| {
            let s = s.round() as usize;
            Self {
                row: row0 * s,
                col: col0 * s,
                cells_wide: (scene_width - 1) * s,
            }
        })
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            progress: false,
            method: EchoMethod::Fast,
            clutter_scale: 1.0,
            point_targets: Vec::new(),
            scene: None,
            noise_seed: None,
        }
    }
}

/// Wall-clock time of each stage, s.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Timings {
    /// Mesh resampling, facets, shadow/layover and reflectivities.
    pub scene_s: f64,
    /// Raw echoes of both antennas (incl. noise).
    pub echoes_s: f64,
    /// Range-Doppler focusing of both antennas.
    pub focusing_s: f64,
    /// Whole simulation.
    pub total_s: f64,
}

impl std::ops::AddAssign<&Timings> for Timings {
    /// Stage by stage: a run of several simulations (both look directions, many blocks) reports
    /// their sum.
    fn add_assign(&mut self, o: &Timings) {
        self.scene_s += o.scene_s;
        self.echoes_s += o.echoes_s;
        self.focusing_s += o.focusing_s;
        self.total_s += o.total_s;
    }
}

/// Two antennas' SLCs with everything needed to interpret them.
#[derive(Debug, Clone)]
pub struct InsarPair {
    /// Configuration used.
    pub config: SarConfig,
    /// Derived radar values.
    pub derived: Derived,
    /// Geometry, pulses, echo window and crop.
    pub plan: AcquisitionPlan,
    /// Facet statistics.
    pub stats: SceneStats,
    /// Scatterers simulated (lit facets + point targets).
    pub scatterers: usize,
    /// SLCs: for each antenna (A1, A2), each configured channel in order.
    pub slcs: Vec<Slc>,
    /// Raw thermal-noise power per sample, `None` without noise.
    pub raw_noise_power: Option<f64>,
    /// Stage timings.
    pub timings: Timings,
}

impl InsarPair {
    /// SLC of an antenna and channel.
    pub fn slc(&self, antenna: Antenna, pol: Polarisation) -> Option<&Slc> {
        self.slcs
            .iter()
            .find(|s| s.antenna == antenna && s.polarisation == pol)
    }
}

fn bar(enabled: bool, len: u64, msg: &'static str) -> ProgressBar {
    if !enabled {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(len).with_message(msg);
    if let Ok(style) =
        ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}")
    {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

/// Simulate both antennas over `dem` with the physical scene and the fast echo method.
pub fn simulate_insar_pair(dem: &SarDem, cfg: &SarConfig) -> SarResult<InsarPair> {
    simulate_with(dem, cfg, &SimOptions::default())
}

/// Simulate both antennas with explicit options. Also returns the raw echoes when
/// `keep_raw` is set (tests compare methods on them).
pub fn simulate_with(dem: &SarDem, cfg: &SarConfig, opts: &SimOptions) -> SarResult<InsarPair> {
    simulate_inner(dem, cfg, opts, false).map(|(pair, _)| pair)
}

/// As [`simulate_with`], also returning each antenna's raw echo.
pub fn simulate_with_raw(
    dem: &SarDem,
    cfg: &SarConfig,
    opts: &SimOptions,
) -> SarResult<(InsarPair, Vec<RawEcho>)> {
    simulate_inner(dem, cfg, opts, true)
}

fn simulate_inner(
    dem: &SarDem,
    cfg: &SarConfig,
    opts: &SimOptions,
    keep_raw: bool,
) -> SarResult<(InsarPair, Vec<RawEcho>)> {
    let t_all = Instant::now();
    let derived = cfg.derived()?;
    let mesh = dem.resampled(cfg.mesh_spacing_m)?;
    let geometry = match &opts.scene {
        Some(s) => Geometry::in_scene(&mesh, cfg, &derived, s.centre_m)?,
        None => Geometry::new(&mesh, cfg, &derived)?,
    };
    let plan = AcquisitionPlan::new(&mesh, cfg, &derived, geometry)?;
    let geom = &plan.geometry;
    let facets = build_facets(&mesh, geom)?;
    let lattice = opts.scene.and_then(|s| s.mesh_offset);
    let index = |i: usize| -> u64 {
        match lattice {
            Some(m) => {
                let cells = mesh.width - 1;
                let (cell, k) = (i / 2, i % 2);
                let (r, c) = (cell / cells, cell % cells);
                (2 * ((r + m.row) * m.cells_wide + c + m.col) + k) as u64
            }
            None => i as u64,
        }
    };
    let (mut scat, stats) =
        facet_scatterers_indexed(&facets, geom, cfg, opts.clutter_scale, &index);
    drop(facets);
    for t in &opts.point_targets {
        scat.push(geom, t.position_m, t.amplitude);
    }
    scat.sort_by_azimuth();
    let scene_s = t_all.elapsed().as_secs_f64();

    let sim = EchoSimulator::new(cfg, &derived, plan.window, plan.pulses)?;
    let rda = RdaProcessor::new(cfg, &derived, &plan)?;
    // Thermal noise: NESZ·A0/(4π) in the SLC at the scene centre, divided by the processing
    // noise gain, is the raw noise power per sample.
    let centre_r = geom.zero_doppler_range(Antenna::A1, geom.scene_centre_m);
    let centre_inc = geom.flat_incidence_rad(centre_r);
    let a0 = rda.range_energy_width_m() / centre_inc.sin() * rda.azimuth_energy_width_m();
    let raw_noise_power = cfg
        .noise_sigma0_linear()
        .map(|nesz| nesz * a0 / (4.0 * std::f64::consts::PI) / rda.noise_gain());

    let npol = cfg.polarisations.len() as u64;
    let mut slcs = Vec::new();
    let mut raws = Vec::new();
    let (mut echoes_s, mut focusing_s) = (0.0, 0.0);
    for antenna in Antenna::BOTH {
        let yz = geom.antenna_yz(antenna);
        let t = Instant::now();
        let pb = bar(
            opts.progress,
            plan.pulses.count as u64,
            if antenna == Antenna::A1 {
                "echoes A1"
            } else {
                "echoes A2"
            },
        );
        let mut raw = match opts.method {
            EchoMethod::Fast => sim.simulate_fast(&scat, antenna, yz, &pb)?,
            EchoMethod::TimeDomain => sim.simulate_time_domain(&scat, antenna, yz)?,
        };
        if let Some(p) = raw_noise_power {
            let seed = opts
                .noise_seed
                .or(opts.scene.map(|s| s.noise_seed))
                .unwrap_or(cfg.seed);
            add_thermal_noise(&mut raw, p, seed);
        }
        pb.finish();
        echoes_s += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let pb = bar(
            opts.progress,
            4 * npol,
            if antenna == Antenna::A1 {
                "focus A1"
            } else {
                "focus A2"
            },
        );
        slcs.extend(rda.focus(&raw, yz, geom.reference_height_m, &pb)?);
        pb.finish();
        focusing_s += t.elapsed().as_secs_f64();
        if keep_raw {
            raws.push(raw);
        }
    }
    let pair = InsarPair {
        config: cfg.clone(),
        derived,
        scatterers: scat.len(),
        plan,
        stats,
        slcs,
        raw_noise_power,
        timings: Timings {
            scene_s,
            echoes_s,
            focusing_s,
            total_s: t_all.elapsed().as_secs_f64(),
        },
    };
    Ok((pair, raws))
}
