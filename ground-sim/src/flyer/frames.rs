//! Synthetic flyer frames: the onboard DEM patch the flyer's ranging sensor would produce at a
//! pose, sampled from a truth DEM, with sensor noise.
//!
//! Pose convention: `(x_m, y_m)` is the geo position (metres, the DEM's projection) of the frame
//! centre; `heading_rad` is the direction of the frame's +x (column) axis measured **clockwise
//! from geo east** (from east towards south), i.e. the rotation from a north-up map's pixel axes
//! to the frame's axes. So for a north-up tile a perfect fix reports `rotation = heading`.
//! Frame pixel centres are at integer coordinates; the frame centre is `((w−1)/2, (h−1)/2)`.

use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::dem::{Dem, DemError};

/// The ranging sensor that produces onboard DEM patches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorModel {
    /// Frame width, pixels.
    pub width_px: usize,
    /// Frame height, pixels.
    pub height_px: usize,
    /// 1σ white range (height) noise per pixel, metres.
    pub range_noise_m: f64,
    /// Fraction of pixels lost (no return): no data in the frame.
    pub dropout_frac: f64,
    /// Samples per pixel side averaged over the footprint (a beam averages, a point sample
    /// would alias sub-pixel craters).
    pub subsamples: usize,
    /// Frame pixel, metres, at and above which the range noise is `range_noise_m`; on finer
    /// frames (closer to the ground) it shrinks in proportion to the pixel, i.e. to the range,
    /// down to `range_noise_floor_m`. An assumption, stated: a ranging sensor's echo gets
    /// stronger as it nears the ground, and a fixed 0.5 m would bury the 0.3 m relief that
    /// matters for landing under noise. 0 keeps the noise fixed at every range.
    #[serde(default)]
    pub range_noise_ref_pixel_m: f64,
    /// Smallest range noise 1σ, metres (the sensor's timing floor).
    #[serde(default)]
    pub range_noise_floor_m: f64,
}

impl SensorModel {
    /// Range noise 1σ, metres, of a frame of `pixel_m` metres per pixel.
    pub fn range_noise_at(&self, pixel_m: f64) -> f64 {
        if self.range_noise_ref_pixel_m > 0.0 && pixel_m < self.range_noise_ref_pixel_m {
            (self.range_noise_m * pixel_m / self.range_noise_ref_pixel_m)
                .max(self.range_noise_floor_m)
        } else {
            self.range_noise_m
        }
    }
}

impl Default for SensorModel {
    fn default() -> Self {
        Self {
            width_px: 200,
            height_px: 200,
            range_noise_m: 0.5,
            dropout_frac: 0.005,
            subsamples: 2,
            // At 5 m pixels and coarser (all TRN frames, 1.9 km and higher with the descent's
            // sensor) the noise stays 0.5 m; the floor is a lidar's few-centimetre class.
            range_noise_ref_pixel_m: 5.0,
            range_noise_floor_m: 0.02,
        }
    }
}

/// Where a frame is taken.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FramePose {
    /// Geo x (east) of the frame centre, metres.
    pub x_m: f64,
    /// Geo y (north) of the frame centre, metres.
    pub y_m: f64,
    /// Frame +x axis, clockwise from geo east, radians.
    pub heading_rad: f64,
    /// Ground sample distance of the frame, metres.
    pub pixel_m: f64,
}

impl FramePose {
    /// Geo position (metres) of frame pixel `(col, row)` in a `w × h` frame.
    pub fn frame_to_geo(&self, col: f64, row: f64, w: usize, h: usize) -> (f64, f64) {
        let u = (col - (w as f64 - 1.0) / 2.0) * self.pixel_m;
        let v = (row - (h as f64 - 1.0) / 2.0) * self.pixel_m;
        let (s, c) = self.heading_rad.sin_cos();
        // Frame +x = (cos H, −sin H) and frame +y = (−sin H, −cos H) in (east, north).
        (self.x_m + u * c - v * s, self.y_m - u * s - v * c)
    }
}

/// One synthetic frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Heights, metres, row-major; `NaN` = dropout.
    pub heights_m: Vec<f32>,
    /// Truth pose.
    pub pose: FramePose,
}

/// Bilinear height at geo `(x, y)` (NaN outside or next to no data).
pub fn height_at_geo(dem: &Dem, x: f64, y: f64) -> f32 {
    let t = dem.geo.transform.0;
    // Inverse of the north-up corner transform, to pixel-centre coordinates.
    let col = (x - t[0]) / t[1] - 0.5;
    let row = (y - t[3]) / t[5] - 0.5;
    let (w, h) = (dem.width(), dem.height());
    if !(col >= 0.0 && row >= 0.0 && col <= (w - 1) as f64 && row <= (h - 1) as f64) {
        return f32::NAN;
    }
    let (c0, r0) = (
        (col as usize).min(w.saturating_sub(2)),
        (row as usize).min(h.saturating_sub(2)),
    );
    let (fx, fy) = ((col - c0 as f64) as f32, (row - r0 as f64) as f32);
    let z = |c, r| dem.get(c, r).unwrap_or(f32::NAN);
    let top = z(c0, r0) * (1.0 - fx) + z(c0 + 1, r0) * fx;
    let bot = z(c0, r0 + 1) * (1.0 - fx) + z(c0 + 1, r0 + 1) * fx;
    top * (1.0 - fy) + bot * fy
}

/// The truth terrain a flyer sees: a map, optionally with a finer landing zone laid over part
/// of it (where the zone has data, its heights win).
#[derive(Debug, Clone, Copy)]
pub struct Terrain<'a> {
    /// The whole map.
    pub map: &'a Dem,
    /// A finer DEM over part of the map (e.g. rocks and small craters around a landing target).
    pub zone: Option<&'a Dem>,
}

impl<'a> Terrain<'a> {
    /// The map alone.
    pub fn map(map: &'a Dem) -> Self {
        Self { map, zone: None }
    }
    /// Bilinear height at geo `(x, y)`, metres: the zone's where it has one, else the map's (NaN
    /// outside both).
    pub fn height_at(&self, x: f64, y: f64) -> f32 {
        if let Some(z) = self.zone {
            let h = height_at_geo(z, x, y);
            if h.is_finite() {
                return h;
            }
        }
        height_at_geo(self.map, x, y)
    }
}

/// Synthesise the frame at `pose` from `dem`, with noise drawn from a PRNG seeded by `seed`.
/// Errors if the DEM is not north-up or the frame leaves it.
pub fn synth_frame(
    dem: &Dem,
    pose: &FramePose,
    sensor: &SensorModel,
    seed: u64,
) -> Result<Frame, DemError> {
    synth_frame_on(&Terrain::map(dem), pose, sensor, seed)
}

/// [`synth_frame`] over a [`Terrain`] (map plus landing zone).
pub fn synth_frame_on(
    terrain: &Terrain<'_>,
    pose: &FramePose,
    sensor: &SensorModel,
    seed: u64,
) -> Result<Frame, DemError> {
    let north_up = |d: &Dem| d.geo.transform.is_north_up();
    if !north_up(terrain.map) || !terrain.zone.is_none_or(north_up) {
        return Err(DemError::Unsupported(
            "frame synthesis needs a north-up DEM".into(),
        ));
    }
    if !(pose.pixel_m.is_finite() && pose.pixel_m > 0.0) {
        return Err(DemError::Invalid(format!(
            "frame pixel size {} m",
            pose.pixel_m
        )));
    }
    let (w, h, k) = (sensor.width_px, sensor.height_px, sensor.subsamples.max(1));
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let normal = |rng: &mut rand_pcg::Pcg64| {
        let u: f64 = rng.random::<f64>().max(1e-300);
        let v: f64 = rng.random::<f64>();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let sigma_m = sensor.range_noise_at(pose.pixel_m);
    let mut z = vec![0.0f32; w * h];
    for row in 0..h {
        for col in 0..w {
            let mut acc = 0.0f64;
            for j in 0..k {
                for i in 0..k {
                    let (di, dj) = (
                        (i as f64 + 0.5) / k as f64 - 0.5,
                        (j as f64 + 0.5) / k as f64 - 0.5,
                    );
                    let (x, y) = pose.frame_to_geo(col as f64 + di, row as f64 + dj, w, h);
                    acc += terrain.height_at(x, y) as f64;
                }
            }
            if acc.is_nan() {
                return Err(DemError::Invalid(format!(
                    "frame at ({:.0}, {:.0}) m, heading {:.1}°, {} m px leaves the DEM",
                    pose.x_m,
                    pose.y_m,
                    pose.heading_rad.to_degrees(),
                    pose.pixel_m
                )));
            }
            let noise = sigma_m * normal(&mut rng);
            let lost = rng.random::<f64>() < sensor.dropout_frac;
            z[row * w + col] = if lost {
                f32::NAN
            } else {
                (acc / (k * k) as f64 + noise) as f32
            };
        }
    }
    Ok(Frame {
        width: w,
        height: h,
        heights_m: z,
        pose: *pose,
    })
}

/// Geo extent of a DEM's pixel centres: `(x_min, x_max, y_min, y_max)`, metres.
pub fn centre_extent(dem: &Dem) -> (f64, f64, f64, f64) {
    let (x0, y0) = dem.pixel_centre_m(0.0, 0.0);
    let (x1, y1) = dem.pixel_centre_m((dem.width() - 1) as f64, (dem.height() - 1) as f64);
    (x0.min(x1), x0.max(x1), y0.min(y1), y0.max(y1))
}

/// Half the diagonal of a frame on the ground, metres: a frame centred farther than this from
/// every DEM edge fits whatever its heading.
pub fn frame_reach_m(sensor: &SensorModel, pixel_m: f64) -> f64 {
    0.5 * ((sensor.width_px as f64).hypot(sensor.height_px as f64) + 2.0) * pixel_m
}

/// Slope (degrees, NaN = no data) of a frame after a Gaussian of `smoothing_m` metres (0 = none;
/// a tile's terrain smoothing), by nav-core's onboard implementation, at the frame's own pixel.
pub fn frame_slope_deg(frame: &Frame, smoothing_m: f64) -> Vec<f32> {
    use nav_core::frame::{DemPatch, SLOPE_NODATA, slope_to_deg};
    let mut px = vec![SLOPE_NODATA; frame.width * frame.height];
    if let Ok(patch) = DemPatch::new_checked(
        &frame.heights_m,
        frame.width,
        frame.height,
        frame.pose.pixel_m as f32,
    ) {
        let sigma_px = (smoothing_m / frame.pose.pixel_m) as f32;
        let _ = nav_core::slope::slope_into_binned_smoothed::<
            { crate::flyer::onboard::MAX_FRAME_SIDE },
        >(&patch, 1, sigma_px, &mut px, false);
    }
    px.iter()
        .map(|&p| slope_to_deg(p).unwrap_or(f32::NAN))
        .collect()
}
