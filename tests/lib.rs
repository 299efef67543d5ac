//! Shared helpers for Umbra's end-to-end tests and benchmarks: an analytic, seeded lunar-like
//! terrain that can be sampled at any position, pixel size and heading without resampling error,
//! and frame rendering on top of nav-core.

use nav_core::frame::{DemPatch, SlopePx};
use nav_core::slope::slope_into;

/// Small deterministic PRNG (SplitMix64) so test scenes need no external crate and never change.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// Seeded generator.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u = self.unit().max(1e-300);
        let v = self.unit();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// One bowl crater with a raised rim and ejecta falloff.
#[derive(Debug, Clone, Copy)]
pub struct Crater {
    /// Centre, metres (scene frame: x east, y south, matching image columns and rows).
    pub x_m: f64,
    /// Centre, metres.
    pub y_m: f64,
    /// Rim radius, metres.
    pub radius_m: f64,
    /// Floor depth below the rim crest, metres.
    pub depth_m: f64,
    /// Rim height above the surroundings, metres.
    pub rim_m: f64,
}

/// Analytic crater field: craters from a power-law size distribution on rolling terrain.
#[derive(Debug, Clone)]
pub struct CraterField {
    craters: Vec<Crater>,
    /// Bucket grid (cell side `cell_m`) listing the craters whose influence disc touches a cell.
    grid: Vec<Vec<u32>>,
    cell_m: f64,
    grid_n: usize,
    origin_m: f64,
    /// Rolling background: (kx, ky rad/m, phase rad, amplitude m).
    waves: Vec<(f64, f64, f64, f64)>,
}

impl CraterField {
    /// A field covering `[-extent_m/2, extent_m/2]²` with `count` craters of radius
    /// `r_min_m..r_max_m` drawn from a cumulative N(>r) ∝ r⁻² distribution, depth/diameter 0.1–0.2.
    pub fn new(seed: u64, extent_m: f64, count: usize, r_min_m: f64, r_max_m: f64) -> Self {
        let mut rng = SplitMix64::new(seed);
        let mut craters = Vec::with_capacity(count);
        for _ in 0..count {
            // Inverse-CDF sampling of a truncated r⁻² cumulative power law.
            let u = rng.unit();
            let a = r_min_m.powi(-2);
            let b = r_max_m.powi(-2);
            let r = (a - u * (a - b)).powf(-0.5);
            let dd = rng.range(0.1, 0.2);
            craters.push(Crater {
                x_m: rng.range(-0.5, 0.5) * extent_m,
                y_m: rng.range(-0.5, 0.5) * extent_m,
                radius_m: r,
                depth_m: dd * 2.0 * r,
                rim_m: 0.04 * 2.0 * r,
            });
        }
        let mut waves = Vec::new();
        for k in 0..24 {
            // Fractal-ish background: amplitude ∝ wavelength.
            let wl = 2000.0 * 0.8f64.powi(k);
            let dir = rng.range(0.0, std::f64::consts::TAU);
            let kk = std::f64::consts::TAU / wl;
            waves.push((
                kk * dir.cos(),
                kk * dir.sin(),
                rng.range(0.0, 6.3),
                0.015 * wl,
            ));
        }
        // Influence radius is 6 crater radii (ejecta term cut-off below).
        let cell_m = 250.0;
        let margin = 6.0 * r_max_m;
        let origin_m = -0.5 * extent_m - margin;
        let grid_n = ((extent_m + 2.0 * margin) / cell_m).ceil() as usize;
        let mut grid = vec![Vec::new(); grid_n * grid_n];
        for (k, c) in craters.iter().enumerate() {
            let reach = 6.0 * c.radius_m;
            let cell =
                |v: f64| (((v - origin_m) / cell_m).floor().max(0.0) as usize).min(grid_n - 1);
            for gy in cell(c.y_m - reach)..=cell(c.y_m + reach) {
                for gx in cell(c.x_m - reach)..=cell(c.x_m + reach) {
                    grid[gy * grid_n + gx].push(k as u32);
                }
            }
        }
        Self {
            craters,
            grid,
            cell_m,
            grid_n,
            origin_m,
            waves,
        }
    }

    /// The craters.
    pub fn craters(&self) -> &[Crater] {
        &self.craters
    }

    /// Height in metres at scene position `(x_m, y_m)`.
    pub fn height_m(&self, x_m: f64, y_m: f64) -> f64 {
        let mut h = 0.0;
        for &(kx, ky, ph, amp) in &self.waves {
            h += amp * (kx * x_m + ky * y_m + ph).sin();
        }
        let cell = |v: f64| ((v - self.origin_m) / self.cell_m).floor();
        let (gx, gy) = (cell(x_m), cell(y_m));
        let n = self.grid_n as f64;
        if !(0.0..n).contains(&gx) || !(0.0..n).contains(&gy) {
            return h;
        }
        for &k in &self.grid[gy as usize * self.grid_n + gx as usize] {
            let c = &self.craters[k as usize];
            let dx = x_m - c.x_m;
            let dy = y_m - c.y_m;
            let r2 = (dx * dx + dy * dy) / (c.radius_m * c.radius_m);
            if r2 > 36.0 {
                continue;
            }
            h += if r2 < 1.0 {
                // Parabolic bowl meeting the rim crest at r = 1.
                c.rim_m - c.depth_m * (1.0 - r2)
            } else {
                c.rim_m * r2.powf(-1.5)
            };
        }
        h
    }
}

/// Pose of a frame over the scene: its centre pixel lands on `(x_m, y_m)`, its columns point along
/// `heading_rad` (0 = scene +x, positive towards scene +y), pixels are `pixel_m` apart.
#[derive(Debug, Clone, Copy)]
pub struct FramePose {
    /// Scene x of the frame centre, metres.
    pub x_m: f64,
    /// Scene y of the frame centre, metres.
    pub y_m: f64,
    /// Rotation of the frame axes relative to the scene axes, radians.
    pub heading_rad: f64,
    /// Ground sample distance, metres per pixel.
    pub pixel_m: f64,
}

impl FramePose {
    /// Scene position (metres) of frame pixel `(col, row)` in a `w × h` frame.
    pub fn to_scene(&self, col: f64, row: f64, w: usize, h: usize) -> (f64, f64) {
        let u = (col - (w as f64 - 1.0) / 2.0) * self.pixel_m;
        let v = (row - (h as f64 - 1.0) / 2.0) * self.pixel_m;
        let (s, c) = self.heading_rad.sin_cos();
        (self.x_m + c * u - s * v, self.y_m + s * u + c * v)
    }
    /// Frame pixel coordinates of scene position `(x_m, y_m)` in a `w × h` frame.
    pub fn to_frame(&self, x_m: f64, y_m: f64, w: usize, h: usize) -> (f64, f64) {
        let (dx, dy) = (x_m - self.x_m, y_m - self.y_m);
        let (s, c) = self.heading_rad.sin_cos();
        let u = c * dx + s * dy;
        let v = -s * dx + c * dy;
        (
            u / self.pixel_m + (w as f64 - 1.0) / 2.0,
            v / self.pixel_m + (h as f64 - 1.0) / 2.0,
        )
    }
}

/// Sub-samples per pixel side when rendering: each DEM pixel is the mean height over its
/// footprint, as a real sensor or a multilooked InSAR product averages, instead of a point sample
/// that would alias craters smaller than a pixel.
pub const RENDER_SUBSAMPLES: usize = 2;

/// Render a `w × h` DEM (metres, row-major) of `field` at `pose`, each pixel the mean over its
/// footprint.
pub fn render_dem(field: &CraterField, pose: &FramePose, w: usize, h: usize) -> Vec<f32> {
    let n = RENDER_SUBSAMPLES;
    let mut z = vec![0.0f32; w * h];
    for row in 0..h {
        for col in 0..w {
            let mut acc = 0.0;
            for j in 0..n {
                for i in 0..n {
                    let (di, dj) = (
                        (i as f64 + 0.5) / n as f64 - 0.5,
                        (j as f64 + 0.5) / n as f64 - 0.5,
                    );
                    let (x, y) = pose.to_scene(col as f64 + di, row as f64 + dj, w, h);
                    acc += field.height_m(x, y);
                }
            }
            z[row * w + col] = (acc / (n * n) as f64) as f32;
        }
    }
    z
}

/// Slope image (nav-core's implementation) of a DEM rendered at `pose`.
pub fn render_slope(field: &CraterField, pose: &FramePose, w: usize, h: usize) -> Vec<SlopePx> {
    let z = render_dem(field, pose, w, h);
    let mut out = vec![nav_core::SLOPE_NODATA; w * h];
    if let Ok(dem) = DemPatch::new_checked(&z, w, h, pose.pixel_m as f32) {
        let _ = slope_into(&dem, &mut out);
    }
    out
}

/// Bilinear resampling of a slope image: output pixel `(col, row)` takes the source value at
/// `map(col, row)` (source pixel coordinates). No data where any of the four neighbours is no data
/// or the point falls outside the source.
pub fn resample_slope(
    src: &[SlopePx],
    sw: usize,
    sh: usize,
    ow: usize,
    oh: usize,
    map: impl Fn(f64, f64) -> (f64, f64),
) -> Vec<SlopePx> {
    use nav_core::frame::{slope_from_deg, slope_to_deg};
    let mut out = vec![nav_core::SLOPE_NODATA; ow * oh];
    for row in 0..oh {
        for col in 0..ow {
            let (x, y) = map(col as f64, row as f64);
            if !(x >= 0.0 && y >= 0.0 && x <= (sw - 1) as f64 && y <= (sh - 1) as f64) {
                continue;
            }
            let (x0, y0) = (
                (x.floor() as usize).min(sw - 2),
                (y.floor() as usize).min(sh - 2),
            );
            let (fx, fy) = (x - x0 as f64, y - y0 as f64);
            let v = |c: usize, r: usize| slope_to_deg(src[r * sw + c]);
            if let (Some(a), Some(b), Some(c), Some(d)) =
                (v(x0, y0), v(x0 + 1, y0), v(x0, y0 + 1), v(x0 + 1, y0 + 1))
            {
                let top = a as f64 * (1.0 - fx) + b as f64 * fx;
                let bot = c as f64 * (1.0 - fx) + d as f64 * fx;
                out[row * ow + col] = slope_from_deg((top * (1.0 - fy) + bot * fy) as f32);
            }
        }
    }
    out
}

/// Add zero-mean Gaussian noise of `sigma_deg` to every valid slope pixel (sensor noise).
pub fn add_slope_noise(px: &mut [SlopePx], sigma_deg: f64, rng: &mut SplitMix64) {
    use nav_core::frame::{slope_from_deg, slope_to_deg};
    for p in px.iter_mut() {
        if let Some(d) = slope_to_deg(*p) {
            *p = slope_from_deg((d as f64 + sigma_deg * rng.normal()) as f32);
        }
    }
}
