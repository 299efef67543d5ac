//! The recorded frame set: a reference tile and DEM frames with known poses, generated from the
//! built-in synthetic terrain, a stress set for the timing bound, and a descent's final phase
//! (keyframes, odometry frames and a hazard map from 4 m to 0.4 m pixels over a landing zone). Written to a directory so
//! that the firmware build can link the tile and any run can replay the same frames; regenerate
//! with `hil-bridge gen`. The link protocol does not care where frames come from: a closed-loop
//! simulator can stream its own.
//!
//! Geometry: the terrain is a 10 m DEM; the tile is its 2 × 2 block mean at 20 m, so tile pixel
//! `X` covers DEM pixels `2X, 2X + 1` and its centre is DEM coordinate `2X + 0.5`. A frame of
//! `200 × 200` pixels at 10 m is sampled bilinearly from the DEM around a centre with a heading:
//! frame `(col, row)` sits at DEM `c + R(heading)·((col, row) − 99.5)`.

use crate::msg::{FrameJob, WireAim, WireKeyframePose, WireOdometryPrior};
use anyhow::{Context, Result, bail};
use ground_sim::dem::Dem;
use ground_sim::flyer::frames::{FramePose, SensorModel, Terrain, synth_frame_on};
use ground_sim::reference::tile::{GeoGrid, MAX_TILE_FEATURES, build_tile};
use ground_sim::terrain::landing::{LandingZoneConfig, landing_zone};
use ground_sim::terrain::{Preset, TerrainParams, Window, generate};
use nav_core::{SLOPE_NODATA, SlopeImage, SurfConfig};
use serde::{Deserialize, Serialize};
use std::fs;
use std::path::Path;

/// Frame side, pixels.
pub const FRAME_SIDE: usize = 200;
/// Frame ground sample distance, metres.
pub const FRAME_PIXEL_M: f32 = 10.0;
/// Terrain side, pixels at 10 m.
pub const TERRAIN_SIDE: usize = 600;
/// Tile ground sample distance, metres.
pub const TILE_PIXEL_M: f64 = 20.0;
/// Format version of the recorded set (bumped on any change of `frames.bin`'s layout or of the
/// frames the generator makes, or of the tile format its `tile.bin` and `atlas.bin` hold, so
/// that a set on disk is regenerated; 4: the noisy frames; 5: tile format 5; 6: the stress
/// confirmation's aim at the frame centre).
pub const FRAMES_FORMAT_VERSION: u32 = 6;
/// Terrain seed.
pub const TERRAIN_SEED: u64 = 8;
/// Core side of the HIL atlas's tiles, tile pixels (the 300 px map in 2 × 2 tiles).
pub const ATLAS_CORE_PX: usize = 150;
/// Overlap beyond each core edge, tile pixels (900 m): less than a 10 m frame's half-diagonal
/// (71 px), so frames near the middle straddle tile edges, as the sequence means them to.
pub const ATLAS_MARGIN_PX: usize = 45;
/// Frames of the atlas sequence across the tile edges (plus [`ATLAS_GENTLE_FRAMES`]).
pub const ATLAS_FRAMES: usize = 8;
/// Gentle frames at the atlas tiles' common corner.
pub const ATLAS_GENTLE_FRAMES: usize = 2;
/// Gentle-terrain frames (relief scaled by [`GENTLE_RELIEF`]) sent with a prior.
pub const GENTLE_FRAMES: usize = 3;
/// RMS of the correlated height noise of the noisy frames, metres (one per frame).
pub const NOISY_RMS_M: [f32; 3] = [2.0, 4.0, 8.0];
/// Correlation length of that noise, frame pixels (three box passes of this radius).
pub const NOISY_BOX_RADIUS_PX: usize = 2;

/// Height scale of the gentle frames: slopes become about a fifth of the tile's, below the
/// tile's detector threshold for most blobs.
pub const GENTLE_RELIEF: f32 = 0.2;

/// What a frame shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameKind {
    /// Terrain at a known pose (should give a fix).
    Terrain,
    /// Terrain with a prior (predicted pose) sent along.
    TerrainWithPrior,
    /// Terrain with no-data holes.
    TerrainHoles,
    /// The terrain's relief scaled down (gentle plains: slopes a fifth of the tile's), with a
    /// prior: few features, so the prior-aided area search runs.
    GentleWithPrior,
    /// A stress frame sent with a wide prior (σ 8 px, 6°): the area search's worst case after
    /// a feature path that finds nothing.
    StressWithPrior,
    /// Terrain with correlated height noise (an InSAR DEM's pixel-scale error, [`NOISY_RMS_M`])
    /// sent with a cruise prior: frames whose features find no consensus (16 keypoints, 1–2
    /// matches at 4 and 8 m) but whose slope the area search still reads, with refinements of
    /// up to 15 updates. With the feature path first they cost 24.3 and 27.9 M instructions
    /// (session 28); the search runs first since ([`nav_core::NavConfig::search_first`]).
    NoisyWithPrior,
    /// All heights equal: no features.
    Flat,
    /// Uniform random heights: many weak, unmatchable keypoints.
    Noise,
    /// 8-pixel squares of alternating height.
    Checkerboard,
    /// Sum of sinusoids at several wavelengths and directions.
    Textured,
    /// Dense random blobs at the detector's matchable scales: the keypoint budget overflows.
    MaxKeypoints,
    /// Final phase: a frame below the tile's reach made the keyframe.
    Keyframe,
    /// Final phase: a frame located on the keyframe (odometry).
    Odometry,
    /// Final phase: the hazard map and the safe-site choice.
    Hazard,
    /// Final phase worst case for odometry: a textured frame located on the keyframe with a
    /// wide prior (features fail, the area search runs its widest window).
    StressOdometry,
    /// Final phase worst case for the hazard map: gentle ground where nearly every site is
    /// safe, so every footprint is read twice (plane fit and relief), and a boulder on the aim,
    /// so the choice scans the whole lattice.
    StressHazard,
    /// Final phase: the chosen aim confirmed on a finer frame (a map of the window around it).
    Confirm,
    /// Final phase worst case for the confirmation: gentle ground, every footprint of the
    /// window read twice, and a boulder on the aim.
    StressConfirm,
    /// A frame of the atlas sequence: terrain crossing the atlas's tile edges, with a prior in
    /// atlas pixels ([`FrameJob::AtlasLocate`]).
    AtlasCrossing,
    /// The atlas sequence's gentle frames (relief scaled by [`GENTLE_RELIEF`]) at the tiles'
    /// common corner: the first tile may give no fix (area search included), and a neighbour
    /// is tried.
    AtlasGentle,
    /// An atlas frame after a long coast: the prior (σ 30 px = 600 m) sits 100 px short of
    /// the truth, deeper in a tile the frame barely touches, so the first tile gives no fix
    /// (area search included) and its neighbour is tried.
    AtlasRetry,
    /// A stress frame (no terrain) at the tiles' common corner with a prior: features that
    /// match nothing on the deepest tile, so the neighbours' feature paths run too.
    AtlasStress,
}

/// Ground truth of a terrain frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Frame centre, tile pixels `[x, y]`.
    pub center_tile_px: [f64; 2],
    /// Heading (frame +x in tile axes), radians.
    pub heading_rad: f64,
    /// Tile pixels per frame pixel.
    pub scale: f64,
}

/// One frame's description (the heights live in `frames.bin`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameMeta {
    /// Frame id on the link.
    pub id: u32,
    /// Short name.
    pub name: String,
    /// Kind.
    pub kind: FrameKind,
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// Ground sample distance, metres.
    pub pixel_m: f32,
    /// Truth for terrain frames.
    pub truth: Option<Truth>,
    /// Prior sent with the frame.
    pub prior: Option<crate::msg::WirePrior>,
    /// The job the target runs on it.
    pub job: FrameJob,
    /// For odometry frames: the true displacement since the keyframe, metres `[east, north]`.
    pub truth_offset_m: Option<[f64; 2]>,
}

/// A frame: description and heights (metres, row-major).
#[derive(Debug, Clone)]
pub struct Frame {
    /// Description.
    pub meta: FrameMeta,
    /// Heights, metres.
    pub heights_m: Vec<f32>,
}

/// The whole recorded set.
#[derive(Debug, Clone)]
pub struct FrameSet {
    /// Reference tile blob (linked into the firmware).
    pub tile: Vec<u8>,
    /// The flight atlas cut from the same map (linked into the firmware too): 2 × 2 tiles of
    /// [`ATLAS_CORE_PX`] cores and [`ATLAS_MARGIN_PX`] margins.
    pub atlas: Vec<u8>,
    /// Frames in link order.
    pub frames: Vec<Frame>,
}

/// Terrain smoothing σ of the HIL tile, metres: that of the tiles the flyer carries (InSAR
/// tiles, [`ground_sim::reference::INSAR_SMOOTHING_M`], 50 m), so every terrain frame pays for
/// the Gaussian the navigator applies to match it; `UMBRA_HIL_SMOOTHING_M` overrides it for
/// measuring (0: no smoothing, the set before session 28).
pub fn tile_smoothing_m() -> f64 {
    std::env::var("UMBRA_HIL_SMOOTHING_M")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(ground_sim::reference::INSAR_SMOOTHING_M)
}

/// Deterministic xorshift-multiply generator for the stress frames.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn bilinear(z: &[f32], n: usize, u: f64, v: f64) -> f32 {
    let u = u.clamp(0.0, (n - 1) as f64);
    let v = v.clamp(0.0, (n - 1) as f64);
    let (x0, y0) = (
        (u.floor() as usize).min(n - 2),
        (v.floor() as usize).min(n - 2),
    );
    let (fx, fy) = (u - x0 as f64, v - y0 as f64);
    let at = |x: usize, y: usize| z[y * n + x] as f64;
    let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
    let bot = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
    (top * (1.0 - fy) + bot * fy) as f32
}

/// Cut a frame from the 10 m DEM at centre `(cu, cv)` (DEM pixels) and `heading_rad`.
fn cut(dem: &[f32], cu: f64, cv: f64, heading_rad: f64) -> Vec<f32> {
    let (s, c) = heading_rad.sin_cos();
    let half = (FRAME_SIDE as f64 - 1.0) / 2.0;
    let mut out = Vec::with_capacity(FRAME_SIDE * FRAME_SIDE);
    for row in 0..FRAME_SIDE {
        for col in 0..FRAME_SIDE {
            let (x, y) = (col as f64 - half, row as f64 - half);
            out.push(bilinear(
                dem,
                TERRAIN_SIDE,
                cu + c * x - s * y,
                cv + s * x + c * y,
            ));
        }
    }
    out
}

/// Unit-RMS height noise over an `n × n` frame, correlated over about `radius` pixels: white
/// noise through three box passes per axis, then scaled to RMS 1.
fn correlated_noise(rng: &mut Rng, n: usize, radius: usize) -> Vec<f32> {
    let mut v: Vec<f64> = (0..n * n).map(|_| rng.unit() - 0.5).collect();
    let r = radius as isize;
    for _ in 0..3 {
        for axis in 0..2 {
            let src = v.clone();
            for y in 0..n as isize {
                for x in 0..n as isize {
                    let mut acc = 0.0;
                    let mut cnt = 0.0;
                    for d in -r..=r {
                        let (xx, yy) = if axis == 0 { (x + d, y) } else { (x, y + d) };
                        if (0..n as isize).contains(&xx) && (0..n as isize).contains(&yy) {
                            acc += src[yy as usize * n + xx as usize];
                            cnt += 1.0;
                        }
                    }
                    v[y as usize * n + x as usize] = acc / cnt;
                }
            }
        }
    }
    let rms = (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt();
    v.iter().map(|e| (e / rms.max(1e-12)) as f32).collect()
}

/// The prior of a filter in cruise: 50 m and 2° (1σ), drawn off the truth by about 1σ.
fn cruise_prior(truth: &Truth) -> crate::msg::WirePrior {
    crate::msg::WirePrior {
        center_tile_px: [
            truth.center_tile_px[0] as f32 - 2.0,
            truth.center_tile_px[1] as f32 + 1.5,
        ],
        sigma_px: 2.5,
        heading_rad: truth.heading_rad as f32 - 0.03,
        heading_sigma_rad: 0.035,
        scale: 0.5,
        scale_sigma: 0.01,
    }
}

fn stress(kind: FrameKind, seed: u64) -> Vec<f32> {
    let n = FRAME_SIDE;
    let mut rng = Rng(seed);
    let mut z = vec![0.0f32; n * n];
    match kind {
        FrameKind::Flat => z.fill(-1234.5),
        FrameKind::Noise => z.iter_mut().for_each(|v| *v = (rng.unit() * 40.0) as f32),
        FrameKind::Checkerboard => {
            for (i, v) in z.iter_mut().enumerate() {
                let (x, y) = (i % n / 8, i / n / 8);
                *v = if (x + y) % 2 == 0 { 0.0 } else { 25.0 };
            }
        }
        FrameKind::Textured => {
            let waves: Vec<(f64, f64, f64, f64)> = (0..12)
                .map(|k| {
                    let wl = 6.0 * 1.35f64.powi(k);
                    let dir = rng.unit() * std::f64::consts::TAU;
                    let kk = std::f64::consts::TAU / wl;
                    (kk * dir.cos(), kk * dir.sin(), rng.unit() * 6.3, 0.4 * wl)
                })
                .collect();
            for (i, v) in z.iter_mut().enumerate() {
                let (x, y) = ((i % n) as f64, (i / n) as f64);
                *v = waves
                    .iter()
                    .map(|(kx, ky, ph, a)| a * (kx * x + ky * y + ph).sin())
                    .sum::<f64>() as f32;
            }
        }
        FrameKind::MaxKeypoints => {
            // Gaussian pits and bumps, σ 3–9 px, every ~9 px: far more blobs than the budget.
            for _ in 0..700 {
                let (cx, cy) = (rng.unit() * n as f64, rng.unit() * n as f64);
                let sigma = 3.0 + 6.0 * rng.unit();
                let amp = (rng.unit() - 0.5) * 60.0;
                let r = (3.0 * sigma).ceil() as isize;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (x, y) = (cx as isize + dx, cy as isize + dy);
                        if x < 0 || y < 0 || x >= n as isize || y >= n as isize {
                            continue;
                        }
                        let (fx, fy) = (x as f64 - cx, y as f64 - cy);
                        let g = (-(fx * fx + fy * fy) / (2.0 * sigma * sigma)).exp();
                        z[y as usize * n + x as usize] += (amp * g) as f32;
                    }
                }
            }
        }
        _ => {}
    }
    z
}

/// The synthetic terrain a frame set is cut from: the recorded set CI runs is
/// [`SetTerrain::DEFAULT`] (a Shoemaker-like floor); others check the firmware's counts, and the
/// work model's calibration, on other ground (`hil-bridge run --terrain plains`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetTerrain {
    /// Terrain preset.
    pub preset: Preset,
    /// Window in the preset's host crater.
    pub window: Window,
    /// Terrain seed.
    pub seed: u64,
}

impl SetTerrain {
    /// The recorded set's terrain.
    pub const DEFAULT: Self = Self {
        preset: Preset::Shoemaker,
        window: Window::Floor,
        seed: TERRAIN_SEED,
    };

    /// `PRESET[:WINDOW[:SEED]]`, e.g. `plains`, `fresh:rim`, `shackleton:wall:2` (window `floor`
    /// and seed [`TERRAIN_SEED`] by default).
    pub fn parse(s: &str) -> Result<Self> {
        use clap::ValueEnum;
        let mut parts = s.split(':');
        let preset = parts.next().unwrap_or_default();
        let preset = Preset::from_str(preset, true).map_err(|_| {
            anyhow::anyhow!(
                "unknown terrain preset {preset:?}: one of {}",
                value_names(Preset::value_variants())
            )
        })?;
        let window = match parts.next() {
            None => Window::Floor,
            Some(w) => Window::from_str(w, true).map_err(|_| {
                anyhow::anyhow!(
                    "unknown window {w:?}: one of {}",
                    value_names(Window::value_variants())
                )
            })?,
        };
        // Presets without a host crater are the same scene for every window: one set, one name.
        let window = match preset {
            Preset::Lola | Preset::Plains => Window::Floor,
            _ => window,
        };
        let seed = match parts.next() {
            None => TERRAIN_SEED,
            Some(v) => v
                .parse()
                .with_context(|| format!("terrain seed {v:?} is not an unsigned integer"))?,
        };
        if let Some(extra) = parts.next() {
            bail!("terrain {s:?}: unexpected {extra:?} after PRESET:WINDOW:SEED");
        }
        Ok(Self {
            preset,
            window,
            seed,
        })
    }

    /// Short name, e.g. `plains-floor-8` (the set's folder and the tile's projection note).
    pub fn label(&self) -> String {
        format!(
            "{}-{}-{}",
            value_name(&self.preset),
            value_name(&self.window),
            self.seed
        )
    }
}

/// A terrain enum's values as the command line spells them, comma-separated.
fn value_names<T: clap::ValueEnum>(all: &[T]) -> String {
    all.iter().map(value_name).collect::<Vec<_>>().join(", ")
}

/// A terrain enum's name as the command line spells it.
fn value_name<T: clap::ValueEnum>(v: &T) -> String {
    v.to_possible_value()
        .map(|p| p.get_name().to_string())
        .unwrap_or_default()
}

/// Generate the recorded set on the default terrain ([`SetTerrain::DEFAULT`]); see
/// [`generate_set_on`].
pub fn generate_set(terrain_frames: usize) -> Result<FrameSet> {
    generate_set_on(SetTerrain::DEFAULT, terrain_frames)
}

/// Generate the set on `terrain`: `terrain_frames` terrain frames (headings 0–345°, every sixth
/// with a prior, one with holes), [`GENTLE_FRAMES`] gentle frames with a prior, the noisy frames,
/// the five stress frames, two stress frames with a prior, the atlas sequence and the final
/// phase.
pub fn generate_set_on(terrain: SetTerrain, terrain_frames: usize) -> Result<FrameSet> {
    let params = TerrainParams {
        preset: terrain.preset,
        window: terrain.window,
        seed: terrain.seed,
        size_m: TERRAIN_SIDE as f64 * FRAME_PIXEL_M as f64,
        pixel_m: FRAME_PIXEL_M as f64,
    };
    let (dem, _) = generate(&params, &indicatif::ProgressBar::hidden())
        .map_err(|e| anyhow::anyhow!("terrain: {e}"))?;
    if dem.width() != TERRAIN_SIDE || dem.height() != TERRAIN_SIDE {
        bail!("terrain is {}x{}", dem.width(), dem.height());
    }
    let z = dem.heights_m();
    // 20 m reference: 2 × 2 block means, then nav-core's own slope and SURF.
    let t = TERRAIN_SIDE / 2;
    let mut coarse = vec![0.0f32; t * t];
    for r in 0..t {
        for c in 0..t {
            let at = |x: usize, y: usize| z[y * TERRAIN_SIDE + x];
            coarse[r * t + c] = 0.25
                * (at(2 * c, 2 * r)
                    + at(2 * c + 1, 2 * r)
                    + at(2 * c, 2 * r + 1)
                    + at(2 * c + 1, 2 * r + 1));
        }
    }
    let patch = nav_core::DemPatch::new_checked(&coarse, t, t, TILE_PIXEL_M as f32)?;
    let mut slope = vec![SLOPE_NODATA; t * t];
    // The flight tiles' smoothing (sessions 1–27 ran this set unsmoothed, which left out the
    // frames' Gaussian stage: 10 M instructions a frame at 50 m before session 28's rewrite).
    let smoothing_m = tile_smoothing_m();
    let img: SlopeImage<'_> = nav_core::slope::slope_into_binned_smoothed::<1024>(
        &patch,
        1,
        (smoothing_m / TILE_PIXEL_M) as f32,
        &mut slope,
        false,
    )?;
    let grid = GeoGrid {
        origin_x_m: -0.5 * (TERRAIN_SIDE as f64 * FRAME_PIXEL_M as f64) + 0.5 * TILE_PIXEL_M,
        origin_y_m: 0.5 * (TERRAIN_SIDE as f64 * FRAME_PIXEL_M as f64) - 0.5 * TILE_PIXEL_M,
        pixel_x_m: TILE_PIXEL_M,
        pixel_y_m: -TILE_PIXEL_M,
        projection: if terrain == SetTerrain::DEFAULT {
            "local metric grid, Shoemaker floor synthetic scene (hil-bridge)".into()
        } else {
            format!(
                "local metric grid, synthetic scene {} (hil-bridge)",
                terrain.label()
            )
        },
    };
    let tile = build_tile(
        &img,
        &grid,
        &SurfConfig::default(),
        MAX_TILE_FEATURES,
        smoothing_m,
        ground_sim::reference::reference_sigma_m(0.0, 1.0),
        0.0,
        None,
    )
    .context("reference tile")?;

    let mut frames = Vec::new();
    let mut rng = Rng(0xF2A3E5);
    let margin = 150.0;
    for k in 0..terrain_frames {
        let heading = (k as f64 * 45.0 + 15.0 * (k / 8) as f64)
            .rem_euclid(360.0)
            .to_radians();
        let cu = margin + rng.unit() * (TERRAIN_SIDE as f64 - 2.0 * margin);
        let cv = margin + rng.unit() * (TERRAIN_SIDE as f64 - 2.0 * margin);
        let mut heights = cut(z, cu, cv, heading);
        let truth = Truth {
            center_tile_px: [(cu - 0.5) / 2.0, (cv - 0.5) / 2.0],
            heading_rad: heading,
            scale: FRAME_PIXEL_M as f64 / TILE_PIXEL_M,
        };
        let kind = if k % 6 == 5 {
            FrameKind::TerrainWithPrior
        } else if k % 6 == 3 {
            FrameKind::TerrainHoles
        } else {
            FrameKind::Terrain
        };
        if kind == FrameKind::TerrainHoles {
            for (i, h) in heights.iter_mut().enumerate() {
                let (x, y) = ((i % FRAME_SIDE) as i64, (i / FRAME_SIDE) as i64);
                if (x - 60).pow(2) + (y - 140).pow(2) < 400 || (20..40).contains(&x) {
                    *h = f32::NAN;
                }
            }
        }
        let prior = (kind == FrameKind::TerrainWithPrior).then(|| crate::msg::WirePrior {
            center_tile_px: [
                truth.center_tile_px[0] as f32 + 4.0,
                truth.center_tile_px[1] as f32 - 3.0,
            ],
            sigma_px: 8.0,
            heading_rad: heading as f32 + 0.05,
            heading_sigma_rad: 0.1,
            scale: 0.5,
            scale_sigma: 0.02,
        });
        frames.push(Frame {
            meta: FrameMeta {
                id: frames.len() as u32,
                name: format!(
                    "terrain-{k:02}-{:03}deg",
                    heading.to_degrees().round() as i64
                ),
                kind,
                width: FRAME_SIDE as u16,
                height: FRAME_SIDE as u16,
                pixel_m: FRAME_PIXEL_M,
                truth: Some(truth),
                prior,
                job: FrameJob::Locate,
                truth_offset_m: None,
            },
            heights_m: heights,
        });
    }
    for k in 0..GENTLE_FRAMES {
        let heading = (40.0 + 110.0 * k as f64).to_radians();
        let cu = margin + rng.unit() * (TERRAIN_SIDE as f64 - 2.0 * margin);
        let cv = margin + rng.unit() * (TERRAIN_SIDE as f64 - 2.0 * margin);
        let mut heights = cut(z, cu, cv, heading);
        let mean = heights.iter().map(|&h| h as f64).sum::<f64>() / heights.len() as f64;
        for h in &mut heights {
            *h = (mean + (*h as f64 - mean) * GENTLE_RELIEF as f64) as f32;
        }
        let truth = Truth {
            center_tile_px: [(cu - 0.5) / 2.0, (cv - 0.5) / 2.0],
            heading_rad: heading,
            scale: FRAME_PIXEL_M as f64 / TILE_PIXEL_M,
        };
        let prior = cruise_prior(&truth);
        frames.push(Frame {
            meta: FrameMeta {
                id: frames.len() as u32,
                name: format!(
                    "gentle-{k:02}-{:03}deg",
                    heading.to_degrees().round() as i64
                ),
                kind: FrameKind::GentleWithPrior,
                width: FRAME_SIDE as u16,
                height: FRAME_SIDE as u16,
                pixel_m: FRAME_PIXEL_M,
                truth: Some(truth),
                prior: Some(prior),
                job: FrameJob::Locate,
                truth_offset_m: None,
            },
            heights_m: heights,
        });
    }
    for (k, &rms) in NOISY_RMS_M.iter().enumerate() {
        let heading = (20.0 + 125.0 * k as f64).to_radians();
        let cu = margin + rng.unit() * (TERRAIN_SIDE as f64 - 2.0 * margin);
        let cv = margin + rng.unit() * (TERRAIN_SIDE as f64 - 2.0 * margin);
        let mut heights = cut(z, cu, cv, heading);
        let noise = correlated_noise(&mut rng, FRAME_SIDE, NOISY_BOX_RADIUS_PX);
        for (h, e) in heights.iter_mut().zip(&noise) {
            *h += rms * e;
        }
        let truth = Truth {
            center_tile_px: [(cu - 0.5) / 2.0, (cv - 0.5) / 2.0],
            heading_rad: heading,
            scale: FRAME_PIXEL_M as f64 / TILE_PIXEL_M,
        };
        frames.push(Frame {
            meta: FrameMeta {
                id: frames.len() as u32,
                name: format!("noisy-{k:02}-{rms:.0}m"),
                kind: FrameKind::NoisyWithPrior,
                width: FRAME_SIDE as u16,
                height: FRAME_SIDE as u16,
                pixel_m: FRAME_PIXEL_M,
                truth: Some(truth),
                prior: Some(cruise_prior(&truth)),
                job: FrameJob::Locate,
                truth_offset_m: None,
            },
            heights_m: heights,
        });
    }
    // The search's widest window (every cap reached) over frames where features fail.
    let wide_prior = crate::msg::WirePrior {
        center_tile_px: [0.5 * t as f32, 0.5 * t as f32],
        sigma_px: 8.0,
        heading_rad: 0.3,
        heading_sigma_rad: 0.1,
        scale: 0.5,
        scale_sigma: 0.03,
    };
    // (kind, seed offset, prior): the prior frames reuse their plain twin's heights.
    for (kind, i, prior) in [
        (FrameKind::MaxKeypoints, 0, None),
        (FrameKind::Noise, 1, None),
        (FrameKind::Textured, 2, None),
        (FrameKind::Checkerboard, 3, None),
        (FrameKind::Flat, 4, None),
        (FrameKind::Noise, 1, Some(wide_prior)),
        (FrameKind::Textured, 2, Some(wide_prior)),
    ] {
        let name = format!(
            "stress-{}{}",
            serde_json::to_string(&kind)?.trim_matches('"'),
            if prior.is_some() { "-prior" } else { "" }
        );
        frames.push(Frame {
            meta: FrameMeta {
                id: frames.len() as u32,
                name,
                kind: if prior.is_some() {
                    FrameKind::StressWithPrior
                } else {
                    kind
                },
                width: FRAME_SIDE as u16,
                height: FRAME_SIDE as u16,
                pixel_m: FRAME_PIXEL_M,
                truth: None,
                prior,
                job: FrameJob::Locate,
                truth_offset_m: None,
            },
            heights_m: stress(kind, 77 + i as u64),
        });
    }
    let (atlas, _) = ground_sim::reference::atlas::build_atlas(
        &tile,
        ground_sim::reference::atlas::AtlasLayout {
            core_px: ATLAS_CORE_PX,
            margin_px: ATLAS_MARGIN_PX,
        },
        MAX_TILE_FEATURES,
    )
    .context("atlas")?;
    atlas_frames(z, &mut frames);
    final_phase_frames(&dem, &mut frames)?;
    Ok(FrameSet {
        tile,
        atlas,
        frames,
    })
}

/// The atlas sequence: frames along a diagonal through the point where the four tiles meet
/// (tile pixels (85, 105) to (215, 195)), with the priors of a filter in cruise (σ 2.5 px =
/// 50 m, drawn about 1σ off), the gentle frames at the corner, a coast and two stress frames.
fn atlas_frames(z: &[f32], frames: &mut Vec<Frame>) {
    let prior = |x: f64, y: f64, sigma_px: f32, heading: f64| crate::msg::WirePrior {
        center_tile_px: [x as f32, y as f32],
        sigma_px,
        heading_rad: heading as f32 + 0.02,
        heading_sigma_rad: 0.035,
        scale: 0.5,
        scale_sigma: 0.01,
    };
    let truth = |x: f64, y: f64, heading: f64| Truth {
        center_tile_px: [x, y],
        heading_rad: heading,
        scale: FRAME_PIXEL_M as f64 / TILE_PIXEL_M,
    };
    for k in 0..ATLAS_FRAMES + ATLAS_GENTLE_FRAMES {
        let gentle = k >= ATLAS_FRAMES;
        let t = if gentle {
            0.5 + 0.03 * (k - ATLAS_FRAMES) as f64
        } else {
            k as f64 / (ATLAS_FRAMES - 1) as f64
        };
        let (x, y) = (85.0 + 130.0 * t, 105.0 + 90.0 * t);
        let heading = (20.0 + 37.0 * k as f64).rem_euclid(360.0).to_radians();
        let mut heights = cut(z, 2.0 * x + 0.5, 2.0 * y + 0.5, heading);
        if gentle {
            let mean = heights.iter().map(|&h| h as f64).sum::<f64>() / heights.len() as f64;
            for h in &mut heights {
                *h = (mean + (*h as f64 - mean) * GENTLE_RELIEF as f64) as f32;
            }
        }
        let (name, kind) = if gentle {
            ("gentle-", FrameKind::AtlasGentle)
        } else {
            ("", FrameKind::AtlasCrossing)
        };
        push_atlas_frame(
            frames,
            format!(
                "atlas-{name}{k:02}-{:03}deg",
                heading.to_degrees().round() as i64
            ),
            kind,
            heights,
            Some(truth(x, y, heading)),
            prior(x + 2.0, y - 1.5, 2.5, heading),
        );
    }
    // The coast: truth at (240, 120), prior at (140, 121) with σ 30 px.
    let heading = 75f64.to_radians();
    push_atlas_frame(
        frames,
        "atlas-retry-coast".into(),
        FrameKind::AtlasRetry,
        cut(z, 480.5, 240.5, heading),
        Some(truth(240.0, 120.0, heading)),
        prior(140.0, 121.0, 30.0, heading),
    );
    // Stress frames at the corner: every neighbour within the budget is tried.
    for (kind, seed) in [(FrameKind::Textured, 79), (FrameKind::MaxKeypoints, 80)] {
        let name = serde_json::to_string(&kind).unwrap_or_default();
        push_atlas_frame(
            frames,
            format!("atlas-stress-{}", name.trim_matches('"')),
            FrameKind::AtlasStress,
            stress(kind, seed),
            None,
            crate::msg::WirePrior {
                heading_rad: 0.3,
                heading_sigma_rad: 0.1,
                scale_sigma: 0.03,
                ..prior(150.0, 150.0, 8.0, 0.0)
            },
        );
    }
}

fn push_atlas_frame(
    frames: &mut Vec<Frame>,
    name: String,
    kind: FrameKind,
    heights_m: Vec<f32>,
    truth: Option<Truth>,
    prior: crate::msg::WirePrior,
) {
    frames.push(Frame {
        meta: FrameMeta {
            id: frames.len() as u32,
            name,
            kind,
            width: FRAME_SIDE as u16,
            height: FRAME_SIDE as u16,
            pixel_m: FRAME_PIXEL_M,
            truth,
            prior: Some(prior),
            job: FrameJob::AtlasLocate,
            truth_offset_m: None,
        },
        heights_m,
    });
}

/// Seed of the final phase's landing zone and frame noise.
pub const FINAL_PHASE_SEED: u64 = 18;

/// The final phase of a descent as the target sees it: keyframes and odometry frames from 4 m
/// down to 0.6 m pixels, the hazard map on a 0.4 m frame, and the worst cases of odometry and of
/// the map. Frames come from the descent's own sensor model ([`SensorModel::default`]: range
/// noise shrinking with range, dropouts) over the HIL terrain with a landing zone (rocks and
/// small craters, [`LandingZoneConfig::default`]) at its centre.
fn final_phase_frames(dem: &Dem, frames: &mut Vec<Frame>) -> Result<()> {
    let (x0, y0, x1, y1) = dem.extent_m();
    let centre = [(x0 + x1) / 2.0, (y0 + y1) / 2.0];
    let zone = landing_zone(dem, centre, &LandingZoneConfig::default(), FINAL_PHASE_SEED)
        .map_err(|e| anyhow::anyhow!("landing zone: {e}"))?;
    let terrain = Terrain {
        map: dem,
        zone: Some(&zone),
    };
    let sensor = SensorModel::default();
    let side = FRAME_SIDE as f32;
    // The filter's state as the descent hands it over: heading known to ~0.3° (1σ 0.5°), the
    // pixel to 1e-3, the displacement predicted about 1σ off with σ 4 m.
    let heading_err = 0.3f64.to_radians();
    let heading_sigma = 0.5f64.to_radians();
    let rel_sigma = 1e-3;
    // (name, kind, pixel m, frame centre from the landing-zone centre [east, north] m, heading
    // deg)
    let plan: [(&str, FrameKind, f64, [f64; 2], f64); 11] = [
        (
            "final-key-4.0m",
            FrameKind::Keyframe,
            4.0,
            [-60.0, 40.0],
            20.0,
        ),
        (
            "final-odo-2.6m",
            FrameKind::Odometry,
            2.6,
            [-25.0, 18.0],
            21.5,
        ),
        (
            "final-key-1.5m",
            FrameKind::Keyframe,
            1.5,
            [-12.0, 9.0],
            22.0,
        ),
        (
            "final-odo-1.0m",
            FrameKind::Odometry,
            1.0,
            [-4.0, 3.0],
            23.0,
        ),
        (
            "final-key-0.6m",
            FrameKind::Keyframe,
            0.6,
            [-1.0, 1.5],
            23.5,
        ),
        (
            "final-hazard-0.4m",
            FrameKind::Hazard,
            0.4,
            [1.0, -0.5],
            24.0,
        ),
        (
            "final-odo-0.4m",
            FrameKind::Odometry,
            0.4,
            [2.0, -1.0],
            24.0,
        ),
        (
            "final-confirm-0.25m",
            FrameKind::Confirm,
            0.25,
            [1.5, -0.5],
            24.0,
        ),
        (
            "stress-odometry",
            FrameKind::StressOdometry,
            0.4,
            [2.0, -1.0],
            24.0,
        ),
        (
            "stress-hazard",
            FrameKind::StressHazard,
            0.4,
            [2.0, -1.0],
            24.0,
        ),
        (
            "stress-confirm",
            FrameKind::StressConfirm,
            0.25,
            [2.0, -1.0],
            24.0,
        ),
    ];
    let mut key: Option<FramePose> = None;
    for (k, (name, kind, pixel_m, off, heading_deg)) in plan.into_iter().enumerate() {
        let pose = FramePose {
            x_m: centre[0] + off[0],
            y_m: centre[1] + off[1],
            heading_rad: heading_deg.to_radians(),
            pixel_m,
        };
        let mut heights = synth_frame_on(&terrain, &pose, &sensor, FINAL_PHASE_SEED + k as u64)
            .map_err(|e| anyhow::anyhow!("{name}: {e}"))?
            .heights_m;
        let mut truth_offset_m = None;
        let job = match kind {
            FrameKind::Keyframe => {
                key = Some(pose);
                FrameJob::Keyframe(WireKeyframePose {
                    heading_rad: pose.heading_rad + heading_err,
                    heading_sigma_rad: heading_sigma,
                    pixel_rel_sigma: rel_sigma,
                })
            }
            FrameKind::Hazard
            | FrameKind::StressHazard
            | FrameKind::Confirm
            | FrameKind::StressConfirm => {
                // The target 25 px right of and 15 px below the frame centre (frame axes), the
                // aim still on it: the map keeps it or moves it. The stress confirmation's aim
                // sits at the centre, so its window is whole (the most sites it can have).
                let target = if matches!(kind, FrameKind::StressConfirm) {
                    [side / 2.0; 2]
                } else {
                    [side / 2.0 + 25.0, side / 2.0 + 15.0]
                };
                if matches!(kind, FrameKind::StressHazard | FrameKind::StressConfirm) {
                    // Gentle swell a few centimetres high and one 0.8 m boulder on the aim: the
                    // choice then scans the whole lattice. A lost return every 8 cells each way
                    // (isolated, so each is filled) puts 0–2 in each 0.4 m footprint (81 cells,
                    // 2 allowed) and 2–5 in each 0.25 m one (197 cells, 6 allowed): every site
                    // stays safe, reads both passes and fills its lost cells, the map's
                    // costliest path (every 7 cells, 3 fell in some 0.4 m footprints, which
                    // then skipped their relief pass).
                    let tex = stress(FrameKind::Textured, 93);
                    heights = tex.iter().map(|&t| t * 0.001).collect();
                    for (i, h) in heights.iter_mut().enumerate() {
                        let (col, row) = (i % FRAME_SIDE, i / FRAME_SIDE);
                        let (x, y) = (col as f32, row as f32);
                        if (x - target[0]).hypot(y - target[1]) < 2.5 {
                            *h += 0.8;
                        }
                        if col % 8 == 3 && row % 8 == 3 {
                            *h = f32::NAN;
                        }
                    }
                }
                if matches!(kind, FrameKind::Confirm | FrameKind::StressConfirm) {
                    FrameJob::Confirm(target)
                } else {
                    FrameJob::Hazard(WireAim {
                        aim_px: target,
                        target_px: target,
                    })
                }
            }
            _ => {
                let Some(kp) = key else {
                    bail!("{name}: an odometry frame before any keyframe");
                };
                let truth = [pose.x_m - kp.x_m, pose.y_m - kp.y_m];
                let is_stress = kind == FrameKind::StressOdometry;
                if is_stress {
                    // Relief a few decimetres over 2–40 m: texture the matcher cannot place.
                    let tex = stress(FrameKind::Textured, 91);
                    heights = tex.iter().map(|&t| t * 0.02).collect();
                } else {
                    truth_offset_m = Some(truth);
                }
                // A fixed error of about one σ, not drawn: the recorded set stays the same.
                let sigma_m: f64 = if is_stress { 12.0 } else { 4.0 };
                FrameJob::Odometry(WireOdometryPrior {
                    offset_m: [truth[0] + 0.8 * sigma_m, truth[1] - 0.6 * sigma_m],
                    offset_cov_m2: [sigma_m * sigma_m, 0.0, 0.0, sigma_m * sigma_m],
                    heading_rad: pose.heading_rad - heading_err,
                    heading_sigma_rad: if is_stress {
                        6.0f64.to_radians()
                    } else {
                        heading_sigma
                    },
                    pixel_rel_sigma: if is_stress { 0.03 } else { rel_sigma },
                })
            }
        };
        frames.push(Frame {
            meta: FrameMeta {
                id: frames.len() as u32,
                name: name.into(),
                kind,
                width: FRAME_SIDE as u16,
                height: FRAME_SIDE as u16,
                pixel_m: pixel_m as f32,
                truth: None,
                prior: None,
                job,
                truth_offset_m,
            },
            heights_m: heights,
        });
    }
    Ok(())
}

impl FrameSet {
    /// Write `tile.bin`, `frames.bin` (heights, `f32` LE, frame after frame) and `frames.json`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        fs::create_dir_all(dir)?;
        fs::write(dir.join("tile.bin"), &self.tile)?;
        fs::write(dir.join("atlas.bin"), &self.atlas)?;
        let mut bin = Vec::new();
        bin.extend_from_slice(b"UMBRAFRM");
        bin.extend_from_slice(&FRAMES_FORMAT_VERSION.to_le_bytes());
        for f in &self.frames {
            for h in &f.heights_m {
                bin.extend_from_slice(&h.to_le_bytes());
            }
        }
        fs::write(dir.join("frames.bin"), bin)?;
        let metas: Vec<&FrameMeta> = self.frames.iter().map(|f| &f.meta).collect();
        fs::write(
            dir.join("frames.json"),
            serde_json::to_string_pretty(&metas)?,
        )?;
        Ok(())
    }

    /// Read a set written by [`FrameSet::write`].
    pub fn read(dir: &Path) -> Result<Self> {
        let tile = fs::read(dir.join("tile.bin")).context("tile.bin")?;
        let atlas = fs::read(dir.join("atlas.bin")).context("atlas.bin")?;
        let metas: Vec<FrameMeta> =
            serde_json::from_slice(&fs::read(dir.join("frames.json")).context("frames.json")?)?;
        let bin = fs::read(dir.join("frames.bin")).context("frames.bin")?;
        if bin.get(..8) != Some(b"UMBRAFRM")
            || bin.get(8..12) != Some(&FRAMES_FORMAT_VERSION.to_le_bytes()[..])
        {
            bail!("frames.bin: not a version-{FRAMES_FORMAT_VERSION} frame file");
        }
        let mut at = 12;
        let mut frames = Vec::with_capacity(metas.len());
        for meta in metas {
            let n = meta.width as usize * meta.height as usize * 4;
            let bytes = bin.get(at..at + n).context("frames.bin truncated")?;
            at += n;
            let heights_m = bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            frames.push(Frame { meta, heights_m });
        }
        Ok(Self {
            tile,
            atlas,
            frames,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terrains_parse_with_defaults_and_refuse_typos() {
        assert_eq!(SetTerrain::parse("shoemaker").unwrap(), SetTerrain::DEFAULT);
        let t = SetTerrain::parse("fresh:rim:3").unwrap();
        assert_eq!(
            (t.preset, t.window, t.seed),
            (Preset::Fresh, Window::Rim, 3)
        );
        assert_eq!(t.label(), "fresh-rim-3");
        assert_eq!(SetTerrain::DEFAULT.label(), "shoemaker-floor-8");
        // No host crater, no window: `plains:rim` is the plains' one scene.
        assert_eq!(
            SetTerrain::parse("plains:rim").unwrap().label(),
            "plains-floor-8"
        );
        for bad in [
            "",
            "mars",
            "plains:ridge",
            "plains:floor:x",
            "plains:floor:1:2",
        ] {
            assert!(SetTerrain::parse(bad).is_err(), "{bad:?}");
        }
    }
}
