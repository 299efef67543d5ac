//! The flight code as the ground segment runs it: nav-core's `Navigator` with a fixed-capacity
//! workspace, plus what the ground side wants back from a frame (timing, matched pairs).
//!
//! Two budgets: [`Budget::Flight`], the firmware's own ([`nav_core::flight`]: 200 × 200 px
//! frames, [`nav_core::flight::MAX_KEYPOINTS`] keypoints, 128 matches), which every campaign uses unless told otherwise, and
//! [`Budget::Host`], a bigger one for frames up to 512 px and image registration on the ground
//! (and no per-frame work budget, `NavConfig::work_budget`),
//! only ever chosen explicitly and labelled in every output.

use std::time::Instant;

use nav_core::frame::SlopePx;
use nav_core::odometry::{
    Keyframe, KeyframePose, OdometryError, OdometryReport, keyframe_bytes, locate_on_keyframe,
};
use nav_core::surf::SurfConfig;
use nav_core::{
    DemPatch, FrameReport, NavConfig, NavError, NavWorkspace, Navigator, Prior, SlopeImage,
};

/// Largest frame side the host-budget workspace holds, pixels.
pub const MAX_FRAME_SIDE: usize = 512;
/// Frame keypoint budget of the host budget (the flight budget keeps
/// [`nav_core::flight::MAX_KEYPOINTS`]).
pub const HOST_KEYPOINTS: usize = 256;
/// Match list capacity of the host budget.
pub const HOST_MATCHES: usize = 256;
/// Stack a thread needs to build a [`Workspace`] in place, bytes.
pub const WORKSPACE_STACK: usize = 64 << 20;

/// Which navigator budget a ground run uses.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Budget {
    /// The firmware's: [`nav_core::flight`] (200 × 200 px frames, [`nav_core::flight::MAX_KEYPOINTS`]
    /// keypoints, 128 matches).
    #[default]
    Flight,
    /// Bigger than what flies: 512 × 512 px frames, 256 keypoints, 256 matches.
    Host,
}

impl Budget {
    /// A label for outputs, with the budget's figures.
    pub fn label(self) -> String {
        match self {
            Self::Flight => format!(
                "flight ({} keypoints, {} matches)",
                nav_core::flight::MAX_KEYPOINTS,
                nav_core::flight::MAX_MATCHES
            ),
            Self::Host => format!(
                "host, bigger than what flies ({HOST_KEYPOINTS} keypoints, {HOST_MATCHES} matches, no work budget)"
            ),
        }
    }
}

/// The host budget's workspace.
pub type HostWorkspace =
    NavWorkspace<{ MAX_FRAME_SIDE * MAX_FRAME_SIDE }, MAX_FRAME_SIDE, HOST_KEYPOINTS, HOST_MATCHES>;

/// The onboard workspace of either budget (fixed arrays, up to a few MiB: build it on a thread
/// with [`WORKSPACE_STACK`] of stack).
pub enum Workspace {
    /// [`Budget::Flight`].
    Flight(Box<nav_core::flight::Workspace>),
    /// [`Budget::Host`].
    Host(Box<HostWorkspace>),
}

/// A fresh workspace of `budget`.
pub fn new_workspace(budget: Budget) -> Workspace {
    match budget {
        Budget::Flight => Workspace::Flight(Box::new(nav_core::flight::Workspace::new())),
        Budget::Host => Workspace::Host(Box::new(HostWorkspace::new())),
    }
}

/// A keyframe buffer large enough for either budget's frames and keypoints (its capacity only
/// bounds the blob; the keyframe itself is what the frame and budget make of it).
pub type GroundKeyframe =
    Keyframe<{ keyframe_bytes(MAX_FRAME_SIDE * MAX_FRAME_SIDE, HOST_KEYPOINTS) }>;

/// Capture `heights` (a `w × h` DEM frame of `pixel_m` metres) as the keyframe, with `ws` as
/// scratch: [`nav_core::odometry::Keyframe::capture`].
pub fn capture_keyframe(
    ws: &mut Workspace,
    key: &mut GroundKeyframe,
    frame: (&[f32], usize, usize, f64),
    pose: &KeyframePose,
    surf: &SurfConfig,
) -> Result<(), OdometryError> {
    let (z, w, h, px) = frame;
    let dem = DemPatch::new_checked(z, w, h, px as f32).map_err(OdometryError::Frame)?;
    match ws {
        Workspace::Flight(ws) => key.capture(ws.as_mut(), &dem, pose, surf),
        Workspace::Host(ws) => key.capture(ws.as_mut(), &dem, pose, surf),
    }
}

/// Locate a DEM frame on the keyframe with the navigator configuration `cfg`:
/// [`nav_core::odometry::locate_on_keyframe`].
pub fn run_odometry(
    key: &GroundKeyframe,
    cfg: &NavConfig,
    ws: &mut Workspace,
    frame: (&[f32], usize, usize, f64),
    prior: &Prior,
) -> Result<OdometryReport, OdometryError> {
    let (z, w, h, px) = frame;
    let dem = DemPatch::new_checked(z, w, h, px as f32).map_err(OdometryError::Frame)?;
    match ws {
        Workspace::Flight(ws) => locate_on_keyframe(key, cfg, ws.as_mut(), &dem, prior),
        Workspace::Host(ws) => locate_on_keyframe(key, &unbounded(cfg), ws.as_mut(), &dem, prior),
    }
}

/// One frame's input.
#[derive(Debug, Clone, Copy)]
pub enum FrameInput<'a> {
    /// Heights in metres (NaN = no data), width, height, pixel size in metres.
    Dem(&'a [f32], usize, usize, f64),
    /// nav-core slope pixels, width, height, pixel size in metres.
    Slope(&'a [SlopePx], usize, usize, f64),
}

/// What one onboard call gave.
#[derive(Debug, Clone)]
pub struct FrameRun {
    /// nav-core's report.
    pub report: FrameReport,
    /// Host time of the call, ms.
    pub time_ms: f64,
    /// Matched keypoints `(frame x, frame y, tile x, tile y, inlier)`, pixels.
    pub pairs: Vec<(f32, f32, f32, f32, bool)>,
}

/// Run the Navigator on one frame.
pub fn run_frame(
    nav: &Navigator<'_>,
    ws: &mut Workspace,
    input: FrameInput<'_>,
    prior: Option<&Prior>,
) -> Result<FrameRun, NavError> {
    match ws {
        Workspace::Flight(w) => run_with(nav, w, input, prior),
        Workspace::Host(w) => {
            let host = Navigator::new(*nav.tile(), unbounded(nav.config()));
            run_with(&host, w, input, prior)
        }
    }
}

/// `cfg` without a per-frame work budget: the host budget's keypoints alone would cost more
/// than the flyer's 20 M (`nav_core::cost`), so that budget is not the flyer's in work either.
fn unbounded(cfg: &NavConfig) -> NavConfig {
    NavConfig {
        work_budget: u32::MAX,
        ..*cfg
    }
}

fn run_with<const P: usize, const W: usize, const K: usize, const M: usize>(
    nav: &Navigator<'_>,
    ws: &mut NavWorkspace<P, W, K, M>,
    input: FrameInput<'_>,
    prior: Option<&Prior>,
) -> Result<FrameRun, NavError> {
    let t = Instant::now();
    let report = match input {
        FrameInput::Dem(z, w, h, px) => {
            nav.locate_dem(ws, &DemPatch::new_checked(z, w, h, px as f32)?, prior)?
        }
        FrameInput::Slope(s, w, h, px) => {
            nav.locate_slope(ws, &SlopeImage::new_checked(s, w, h, px as f32)?, prior)?
        }
    };
    let time_ms = t.elapsed().as_secs_f64() * 1e3;
    let feats = ws.features().as_slice();
    let pairs = ws
        .matches()
        .iter()
        .zip(ws.inliers())
        .filter_map(|(m, &inl)| {
            let f = feats.get(m.frame as usize)?.keypoint;
            let t = nav.tile().keypoint(m.tile as usize);
            Some((f.x_px, f.y_px, t.x_px, t.y_px, inl))
        })
        .collect();
    Ok(FrameRun {
        report,
        time_ms,
        pairs,
    })
}

/// Run `f` on a thread with room to build a [`Workspace`] in place, and wait for it.
pub fn with_big_stack<T: Send>(f: impl FnOnce() -> anyhow::Result<T> + Send) -> anyhow::Result<T> {
    std::thread::scope(|scope| {
        std::thread::Builder::new()
            .stack_size(WORKSPACE_STACK)
            .spawn_scoped(scope, f)
            .map_err(|e| anyhow::anyhow!("starting a worker thread: {e}"))?
            .join()
            .map_err(|_| anyhow::anyhow!("worker thread panicked"))?
    })
}

/// Most tiles a ground run's [`nav_core::atlas::MappedAtlas`] holds (a 64 km corridor of 4 km
/// tiles; ≈ 0.2 KB of parsed handles each).
pub const GROUND_ATLAS_TILES: usize = 256;

/// The reference a closed-loop run navigates on: one tile, or an atlas of tiles.
#[derive(Debug, Clone, Copy)]
pub enum MapNav<'a> {
    /// One reference tile.
    Tile(&'a Navigator<'a>),
    /// A flight atlas, every tile parsed once, with the atlas navigator.
    Atlas(
        &'a nav_core::atlas::MappedAtlas<'a, GROUND_ATLAS_TILES>,
        &'a nav_core::atlas::AtlasNavigator,
    ),
}

/// A frame located on a [`MapNav`]: the fix (or why none) and, over an atlas, which tile.
#[derive(Debug, Clone, Copy)]
pub struct MapFrame {
    /// The fix, or why none (`None` over an atlas when no tile reaches the prior).
    pub outcome: Option<Result<nav_core::Fix, nav_core::NoFix>>,
    /// Over an atlas: the tile the report comes from, and how many tiles were tried.
    pub atlas_tile: Option<(u16, u8)>,
}

impl MapNav<'_> {
    /// The map grid: geo of pixel (0, 0)'s centre and the steps per column and row, metres.
    pub fn grid(&self) -> (f64, f64, f64, f64) {
        match self {
            Self::Tile(n) => {
                let h = n.tile().header();
                (h.origin_x_m, h.origin_y_m, h.pixel_x_m, h.pixel_y_m)
            }
            Self::Atlas(a, _) => {
                use nav_core::atlas::TileSource;
                let h = a.atlas().header();
                (h.origin_x_m, h.origin_y_m, h.pixel_x_m, h.pixel_y_m)
            }
        }
    }
    /// Mean pixel size of the map grid, metres.
    pub fn pixel_m(&self) -> f64 {
        let (_, _, px, py) = self.grid();
        0.5 * (px.abs() + py.abs())
    }
    /// The SURF settings of the map's tiles.
    pub fn surf_config(&self) -> SurfConfig {
        match self {
            Self::Tile(n) => n.tile().header().surf_config(),
            Self::Atlas(a, _) => {
                use nav_core::atlas::TileSource;
                a.atlas().header().surf_config()
            }
        }
    }
    /// The navigator settings.
    pub fn nav_config(&self) -> &NavConfig {
        match self {
            Self::Tile(n) => n.config(),
            Self::Atlas(_, nav) => &nav.config().nav,
        }
    }
    /// Locate a DEM frame under `prior` (map grid pixels).
    pub fn locate(
        &self,
        ws: &mut Workspace,
        frame: (&[f32], usize, usize, f64),
        prior: &Prior,
    ) -> anyhow::Result<MapFrame> {
        match self {
            Self::Tile(n) => {
                let r = run_frame(
                    n,
                    ws,
                    FrameInput::Dem(frame.0, frame.1, frame.2, frame.3),
                    Some(prior),
                )
                .map_err(|e| anyhow::anyhow!("navigator: {e}"))?;
                Ok(MapFrame {
                    outcome: Some(r.report.outcome),
                    atlas_tile: None,
                })
            }
            Self::Atlas(atlas, nav) => {
                let (z, w, h, px) = frame;
                let dem = DemPatch::new_checked(z, w, h, px as f32)
                    .map_err(|e| anyhow::anyhow!("navigator: {e}"))?;
                let mut src = *atlas;
                let r = match ws {
                    Workspace::Flight(ws) => nav.locate_dem(&mut src, ws.as_mut(), &dem, prior),
                    Workspace::Host(ws) => {
                        let cfg = nav.config();
                        let host =
                            nav_core::atlas::AtlasNavigator::new(nav_core::atlas::AtlasConfig {
                                nav: unbounded(&cfg.nav),
                                ..*cfg
                            });
                        host.locate_dem(&mut src, ws.as_mut(), &dem, prior)
                    }
                }
                .map_err(|e| anyhow::anyhow!("atlas navigator: {e}"))?;
                Ok(MapFrame {
                    outcome: r.report.map(|r| r.outcome),
                    atlas_tile: r.tile.map(|t| (t, r.tried)),
                })
            }
        }
    }
}
