//! The flight code as the ground segment runs it: nav-core's `Navigator` with a fixed-capacity
//! workspace, plus what the ground side wants back from a frame (timing, matched pairs).

use std::time::Instant;

use nav_core::frame::SlopePx;
use nav_core::{DemPatch, FrameReport, NavError, NavWorkspace, Navigator, Prior, SlopeImage};

/// Largest frame side the ground-side workspace holds, pixels.
pub const MAX_FRAME_SIDE: usize = 512;
/// Frame keypoint budget (as on the flyer).
pub const FRAME_KEYPOINTS: usize = 256;
/// Match list capacity.
pub const MAX_MATCHES: usize = 256;
/// Stack a thread needs to build a [`Workspace`] in place, bytes.
pub const WORKSPACE_STACK: usize = 64 << 20;

/// The onboard workspace (a few MiB of fixed arrays; build it on a thread with
/// [`WORKSPACE_STACK`] of stack).
pub type Workspace =
    NavWorkspace<{ MAX_FRAME_SIDE * MAX_FRAME_SIDE }, MAX_FRAME_SIDE, FRAME_KEYPOINTS, MAX_MATCHES>;

/// A fresh boxed workspace.
pub fn new_workspace() -> Box<Workspace> {
    Box::new(Workspace::new())
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
