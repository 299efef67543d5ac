//! Keyframe odometry: navigation below the reference tile's reach.
//!
//! Below about 2 km above the terrain the flyer's frames are finer than 5 m and no longer match
//! a 20 m reference tile. The flyer then makes its own reference: a **keyframe**, one of its own
//! frames turned into a tile in RAM (slope binned by [`KEYFRAME_BIN`], its SURF features and
//! that slope as the tile's raster, written by [`crate::tile::write_tile_with_raster`]). Later
//! frames are located on the keyframe with the very same [`Navigator`] (features, MSAC, dense
//! refinement and, with the filter's prior, the area search), and the fix becomes the flyer's
//! horizontal displacement since the keyframe ([`OffsetFix`]), which the filter takes as a
//! relative measurement against its cloned keyframe position
//! ([`crate::filter::NavFilter::update_offset`]).
//!
//! When the frames have become [`KEYFRAME_REFRESH_SCALE`] times finer than the keyframe's, the
//! caller captures a new keyframe ([`Keyframe::needs_refresh`]). Descending from 2 km to 20 m
//! takes about seven keyframes; each registration is against a frame at most twice as coarse,
//! so the chain's error is dominated by its first (coarsest) link.
//!
//! Axes: a keyframe tile's "geo" coordinates are metres along the keyframe's own pixel axes
//! (x = column, y = row, origin at pixel (0, 0)); [`Keyframe::offset`] turns them into east and
//! north with the keyframe's heading (frame +x clockwise from east, as
//! [`crate::navigator::Prior::heading_rad`] on a north-up tile).
//!
//! Memory: a [`Keyframe`] holds one tile blob of [`keyframe_bytes`] bytes (for the flight
//! budget, 200 × 200 px frames and [`crate::flight::MAX_KEYPOINTS`] keypoints: see
//! `docs/bounds.md`). No allocation, no
//! panic, bounded work: capture is one binned slope, one SURF extraction and one tile write.

use crate::frame::{DemPatch, FrameError};
use crate::navigator::{NavWorkspace, Navigator, Prior};
use crate::pose::Fix;
use crate::surf::{SurfConfig, SurfError, extract};
use crate::tile::{MAX_HEADER_LEN, Tile, TileError, TileHeader, tile_len_with_raster};
use core::fmt;

/// Binning of a keyframe's slope raster, frame pixels per keyframe pixel: a later frame, finer
/// than the keyframe's, is binned by 2–3 to meet it (as TRN frames are binned to the tile).
pub const KEYFRAME_BIN: usize = 2;
/// A new keyframe is due once the frame pixel is this fraction of the keyframe's frame pixel
/// or less: frames then bin by ≥ 4 onto the keyframe raster and cover a quarter of it.
pub const KEYFRAME_REFRESH_SCALE: f64 = 0.55;
/// The keyframe tile's projection note.
pub const KEYFRAME_PROJECTION: &str = "keyframe: metres along the keyframe's pixel axes";

/// Bytes of a keyframe tile for frames of at most `max_frame_px` pixels and `max_features`
/// keypoints (header at its largest, binned raster, CRC).
pub const fn keyframe_bytes(max_frame_px: usize, max_features: usize) -> usize {
    tile_len_with_raster(
        MAX_HEADER_LEN,
        max_features,
        max_frame_px / (KEYFRAME_BIN * KEYFRAME_BIN),
    )
}

/// Why a keyframe could not be captured or used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OdometryError {
    /// The frame was malformed or too large.
    Frame(FrameError),
    /// SURF refused the frame or configuration.
    Surf(SurfError),
    /// The keyframe tile could not be written or read back.
    Tile(TileError),
    /// No keyframe has been captured.
    NoKeyframe,
    /// A pose input (heading, pixel size, sigma) was not finite or out of range.
    BadPose,
}

impl fmt::Display for OdometryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Frame(e) => write!(f, "keyframe: {e}"),
            Self::Surf(e) => write!(f, "keyframe: {e}"),
            Self::Tile(e) => write!(f, "keyframe tile: {e}"),
            Self::NoKeyframe => f.write_str("no keyframe captured"),
            Self::BadPose => f.write_str("keyframe pose not finite or out of range"),
        }
    }
}
impl core::error::Error for OdometryError {}

/// The flyer's displacement since the keyframe, from a fix on the keyframe tile.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OffsetFix {
    /// East displacement of the frame centre from the keyframe's centre, m.
    pub east_m: f64,
    /// North displacement, m.
    pub north_m: f64,
    /// Covariance of (east, north), m²: the fix's own, rotated, plus the keyframe heading's and
    /// pixel size's share.
    pub cov_m2: [[f64; 2]; 2],
    /// Side of the frame's footprint on the ground, m.
    pub footprint_m: f64,
    /// Heading of the frame relative to the keyframe, radians (frame +x from keyframe +x towards
    /// keyframe +y).
    pub rotation_rad: f64,
    /// Frame pixel over keyframe raster pixel.
    pub scale: f64,
}

/// The keyframe's pose as the flyer knew it at capture.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct KeyframePose {
    /// Frame +x axis, clockwise from east, radians.
    pub heading_rad: f64,
    /// 1σ of the heading, radians.
    pub heading_sigma_rad: f64,
    /// Frame ground pixel, m (height above terrain × angular pixel).
    pub pixel_m: f64,
    /// Relative 1σ of the pixel size (the ranging sensor's height error over the height).
    pub pixel_rel_sigma: f64,
}

/// A keyframe: a tile blob of at most `BYTES` bytes built from one frame, and its pose.
pub struct Keyframe<const BYTES: usize> {
    buf: [u8; BYTES],
    len: usize,
    pose: Option<KeyframePose>,
    /// Frame size at capture, pixels.
    frame_w: usize,
    frame_h: usize,
}

impl<const BYTES: usize> Default for Keyframe<BYTES> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const BYTES: usize> Keyframe<BYTES> {
    /// No keyframe yet (`const`, so it can be a `static`).
    pub const fn new() -> Self {
        Self {
            buf: [0; BYTES],
            len: 0,
            pose: None,
            frame_w: 0,
            frame_h: 0,
        }
    }

    /// Size in bytes.
    pub const fn footprint_bytes() -> usize {
        core::mem::size_of::<Self>()
    }

    /// Forget the keyframe.
    pub fn clear(&mut self) {
        self.len = 0;
        self.pose = None;
    }

    /// The keyframe's pose at capture, if one was captured.
    pub fn pose(&self) -> Option<&KeyframePose> {
        self.pose.as_ref()
    }

    /// Whether a frame of `frame_pixel_m` should replace the keyframe (none yet, or the frame
    /// is [`KEYFRAME_REFRESH_SCALE`] times finer or more).
    pub fn needs_refresh(&self, frame_pixel_m: f64) -> bool {
        match &self.pose {
            None => true,
            Some(p) => !(frame_pixel_m > KEYFRAME_REFRESH_SCALE * p.pixel_m),
        }
    }

    /// Turn `dem` (this frame, at `pose`) into the keyframe: its slope binned by
    /// [`KEYFRAME_BIN`], SURF features by `surf` (the reference tile's settings; its minimum
    /// scale is dropped, the keyframe's own detail is what later frames see), written as a tile
    /// with the slope as raster. Uses `ws` as scratch (its previous contents are lost). On error
    /// the keyframe is cleared.
    pub fn capture<const P: usize, const W: usize, const K: usize, const M: usize>(
        &mut self,
        ws: &mut NavWorkspace<P, W, K, M>,
        dem: &DemPatch<'_>,
        pose: &KeyframePose,
        surf: &SurfConfig,
    ) -> Result<(), OdometryError> {
        self.clear();
        let ok = |v: f64| v.is_finite();
        if !(ok(pose.heading_rad)
            && ok(pose.heading_sigma_rad)
            && pose.heading_sigma_rad >= 0.0
            && ok(pose.pixel_rel_sigma)
            && pose.pixel_rel_sigma >= 0.0
            && ok(pose.pixel_m)
            && pose.pixel_m > 0.0)
        {
            return Err(OdometryError::BadPose);
        }
        let (slope, surf_ws, features) = ws.parts_mut();
        let img = slope
            .compute_binned_smoothed::<W>(dem, KEYFRAME_BIN, 0.0, true)
            .map_err(OdometryError::Frame)?;
        let mut cfg = *surf;
        cfg.detector.min_scale_px = 0.0;
        extract(&img, &cfg, surf_ws.scratch(), features).map_err(OdometryError::Surf)?;
        let px = img.pixel_m() as f64;
        let header = TileHeader {
            width_px: img.width() as u32,
            height_px: img.height() as u32,
            origin_x_m: 0.0,
            origin_y_m: 0.0,
            pixel_x_m: px,
            pixel_y_m: px,
            projection: KEYFRAME_PROJECTION,
            feature_count: features.len() as u32,
            octaves: cfg.detector.octaves,
            layers: cfg.detector.layers,
            threshold: cfg.detector.threshold,
            min_scale_px: cfg.detector.min_scale_px,
            upright: cfg.upright,
            smoothing_m: 0.0,
            // The keyframe's own position error is the filter's cloned state, not the tile's.
            reference_sigma_m: [0.0; 2],
            // The keyframe's noise is a frame's; offsets carry the filter's default share.
            height_noise_m: 0.0,
        };
        let len = crate::tile::write_tile_with_raster(
            &header,
            features.as_slice(),
            Some(img.pixels()),
            &mut self.buf,
        )
        .map_err(OdometryError::Tile)?;
        self.len = len;
        self.pose = Some(*pose);
        self.frame_w = dem.width();
        self.frame_h = dem.height();
        Ok(())
    }

    /// The keyframe tile blob (empty without a keyframe); its last four bytes are the tile's
    /// CRC-32, a digest of the whole keyframe.
    pub fn as_bytes(&self) -> &[u8] {
        if self.pose.is_none() {
            return &[];
        }
        self.buf.get(..self.len).unwrap_or(&[])
    }

    /// The keyframe as a tile (CRC checked), to build a [`Navigator`] on.
    pub fn tile(&self) -> Result<Tile<'_>, OdometryError> {
        if self.pose.is_none() {
            return Err(OdometryError::NoKeyframe);
        }
        let bytes = self.buf.get(..self.len).ok_or(OdometryError::NoKeyframe)?;
        Tile::parse(bytes).map_err(OdometryError::Tile)
    }

    /// The keyframe's frame centre in its raster pixels (the origin of [`OffsetFix`]).
    fn centre_px(&self) -> [f64; 2] {
        let k = KEYFRAME_BIN as f64;
        [
            self.frame_w as f64 / (2.0 * k) - 0.5,
            self.frame_h as f64 / (2.0 * k) - 0.5,
        ]
    }

    /// The keyframe raster's pixel, m.
    fn raster_pixel_m(&self) -> Option<f64> {
        self.pose.map(|p| p.pixel_m * KEYFRAME_BIN as f64)
    }

    /// A navigator prior for a frame predicted `offset_m` (east, north, m) from the keyframe
    /// with covariance `offset_cov_m2` (the filter's [`crate::filter::NavFilter::offset_cov_m2`]),
    /// heading `heading_rad` ± `heading_sigma_rad` (frame +x clockwise from east) and pixel
    /// `frame_pixel_m` (relative 1σ `pixel_rel_sigma`).
    pub fn prior(
        &self,
        offset_m: [f64; 2],
        offset_cov_m2: [[f64; 2]; 2],
        heading_rad: f64,
        heading_sigma_rad: f64,
        frame_pixel_m: f64,
        pixel_rel_sigma: f64,
    ) -> Result<Prior, OdometryError> {
        let (Some(kp), Some(rp)) = (self.pose, self.raster_pixel_m()) else {
            return Err(OdometryError::NoKeyframe);
        };
        let vals = [
            offset_m[0],
            offset_m[1],
            offset_cov_m2[0][0],
            offset_cov_m2[1][1],
            heading_rad,
            heading_sigma_rad,
            frame_pixel_m,
            pixel_rel_sigma,
        ];
        if !(vals.iter().all(|v| v.is_finite()) && frame_pixel_m > 0.0) {
            return Err(OdometryError::BadPose);
        }
        let (s, c) = libm::sincos(kp.heading_rad);
        // East/north → keyframe axes (the map is its own inverse: see `offset`).
        let du = c * offset_m[0] - s * offset_m[1];
        let dv = -s * offset_m[0] - c * offset_m[1];
        let [cx, cy] = self.centre_px();
        let var = offset_cov_m2[0][0].max(offset_cov_m2[1][1]).max(0.0);
        Ok(Prior {
            center_tile_px: [(cx + du / rp) as f32, (cy + dv / rp) as f32],
            sigma_px: (libm::sqrt(var) / rp) as f32,
            heading_rad: libm::remainder(heading_rad - kp.heading_rad, core::f64::consts::TAU)
                as f32,
            heading_sigma_rad: libm::hypot(heading_sigma_rad, kp.heading_sigma_rad) as f32,
            scale: (frame_pixel_m / rp) as f32,
            scale_sigma: (libm::hypot(pixel_rel_sigma, kp.pixel_rel_sigma) * frame_pixel_m / rp)
                as f32,
        })
    }

    /// The displacement a fix on this keyframe's tile says, for a frame of `frame_w` ×
    /// `frame_h` pixels of `frame_pixel_m` metres.
    pub fn offset(
        &self,
        fix: &Fix,
        frame_w: usize,
        frame_h: usize,
        frame_pixel_m: f64,
    ) -> Result<OffsetFix, OdometryError> {
        let (Some(kp), Some(rp)) = (self.pose, self.raster_pixel_m()) else {
            return Err(OdometryError::NoKeyframe);
        };
        let [cx, cy] = self.centre_px();
        let du = (fix.center_tile_px[0] - cx) * rp;
        let dv = (fix.center_tile_px[1] - cy) * rp;
        let (s, c) = libm::sincos(kp.heading_rad);
        // Keyframe +x = (cos H, −sin H) and +y = (−sin H, −cos H) in (east, north); the map
        // J = [[c, −s], [−s, −c]] is symmetric and J² = I.
        let east = c * du - s * dv;
        let north = -s * du - c * dv;
        let t = fix.center_cov_tile_px2;
        let r2 = rp * rp;
        let j = [[c, -s], [-s, -c]];
        let mut cov = [[0.0f64; 2]; 2];
        for (a, row) in cov.iter_mut().enumerate() {
            for (b, v) in row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (p, tp) in t.iter().enumerate() {
                    for (q, tpq) in tp.iter().enumerate() {
                        let ja = j.get(a).and_then(|r| r.get(p)).copied().unwrap_or(0.0);
                        let jb = j.get(b).and_then(|r| r.get(q)).copied().unwrap_or(0.0);
                        acc += ja * tpq * jb;
                    }
                }
                *v = acc * r2;
            }
        }
        // The keyframe's heading error turns the displacement (across it); its pixel-size error
        // stretches it (along it).
        let (hs, ps) = (kp.heading_sigma_rad, kp.pixel_rel_sigma);
        let (ex, ny) = (east, north);
        cov[0][0] += hs * hs * ny * ny + ps * ps * ex * ex;
        cov[1][1] += hs * hs * ex * ex + ps * ps * ny * ny;
        let cross = (ps * ps - hs * hs) * ex * ny;
        cov[0][1] += cross;
        cov[1][0] += cross;
        Ok(OffsetFix {
            east_m: east,
            north_m: north,
            cov_m2: cov,
            footprint_m: frame_w.max(frame_h) as f64 * frame_pixel_m,
            rotation_rad: fix.similarity.rotation_rad,
            scale: fix.similarity.scale,
        })
    }
}

/// What one odometry frame gave: the navigator's report on the keyframe tile, and the
/// displacement if it found a fix.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OdometryReport {
    /// The navigator's report (its fix, if any, is in keyframe raster pixels).
    pub report: crate::navigator::FrameReport,
    /// The displacement since the keyframe, when the report holds a fix.
    pub offset: Option<OffsetFix>,
}

/// Locate a frame on the keyframe: `nav_cfg` is the flight navigator's configuration (the same
/// as for TRN), `prior` from [`Keyframe::prior`].
pub fn locate_on_keyframe<
    const BYTES: usize,
    const P: usize,
    const W: usize,
    const K: usize,
    const M: usize,
>(
    key: &Keyframe<BYTES>,
    nav_cfg: &crate::navigator::NavConfig,
    ws: &mut NavWorkspace<P, W, K, M>,
    dem: &DemPatch<'_>,
    prior: &Prior,
) -> Result<OdometryReport, OdometryError> {
    let tile = key.tile()?;
    let nav = Navigator::new(tile, *nav_cfg);
    let report = nav.locate_dem(ws, dem, Some(prior)).map_err(|e| match e {
        crate::navigator::NavError::Frame(f) => OdometryError::Frame(f),
        crate::navigator::NavError::Surf(s) => OdometryError::Surf(s),
    })?;
    let offset = match &report.outcome {
        Ok(fix) => Some(key.offset(fix, dem.width(), dem.height(), dem.pixel_m() as f64)?),
        Err(_) => None,
    };
    Ok(OdometryReport { report, offset })
}
