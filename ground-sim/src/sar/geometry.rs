//! Input DEM, flat-Moon acquisition geometry, pulse grid and echo window.
//!
//! Frame: `x` along track (= increasing DEM row), `y` ground range (= increasing DEM column,
//! the look direction), `z` up, all in metres. The platform flies along `+x` at height
//! `z_ref + H` (where `z_ref` is the DEM's mean height) on the line `y = y_c − H·tan θ0`, so the
//! scene centre `(x_c, y_c, z_ref)` is seen at incidence θ0. Antenna A1 is on that line; A2 is
//! offset by `B_L·(0, cos α, sin α)` (towards the look direction and up). Each antenna transmits
//! and receives its own pulses (ping-pong), so the interferometric phase of `A1·conj(A2)` is
//! `−4π(R1 − R2)/λ`.

use serde::{Deserialize, Serialize};

use super::config::{Derived, SarConfig};
use super::kernel::KERNEL_TAPS;
use super::{SPEED_OF_LIGHT_M_S, SarError, SarResult};

/// Largest DEM side accepted, nodes (keeps allocations bounded: 8192² nodes ≈ 134 M facets).
pub const MAX_DEM_SIDE: usize = 8192;
/// Largest echo window or pulse count accepted (samples or pulses per axis).
pub const MAX_AXIS_SAMPLES: usize = 1 << 17;
/// Extra slant-range gates kept on each side of the scene in the SLC crop and the echo window.
pub const RANGE_MARGIN_GATES: usize = 8;

/// A height grid in the local SAR frame: row `r`, column `c` is at
/// `x = origin_m[0] + r·pixel_m`, `y = origin_m[1] + c·pixel_m`, height `heights_m[r·width + c]`.
/// Node (pixel-centre) registration: pixel centres are at integer coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct SarDem {
    /// Columns (ground-range direction).
    pub width: usize,
    /// Rows (azimuth direction).
    pub height: usize,
    /// Node spacing on both axes, m.
    pub pixel_m: f64,
    /// Row-major heights, m.
    pub heights_m: Vec<f32>,
    /// Local `(x, y)` of node (0, 0), m.
    pub origin_m: [f64; 2],
}

impl SarDem {
    /// Validate and wrap a grid: at least 2×2 nodes, at most [`MAX_DEM_SIDE`] per side, positive
    /// finite spacing, finite heights.
    pub fn new_checked(
        width: usize,
        height: usize,
        pixel_m: f64,
        heights_m: Vec<f32>,
        origin_m: [f64; 2],
    ) -> SarResult<Self> {
        if width < 2 || height < 2 || width > MAX_DEM_SIDE || height > MAX_DEM_SIDE {
            return Err(SarError::Dem(format!(
                "size {width}×{height} outside 2..={MAX_DEM_SIDE}"
            )));
        }
        if heights_m.len() != width * height {
            return Err(SarError::Dem(format!(
                "{} heights for {width}×{height} nodes",
                heights_m.len()
            )));
        }
        if !(pixel_m.is_finite() && pixel_m > 0.0) {
            return Err(SarError::Dem(format!("pixel_m must be > 0, got {pixel_m}")));
        }
        if !origin_m.iter().all(|v| v.is_finite()) {
            return Err(SarError::Dem("origin must be finite".into()));
        }
        if let Some(i) = heights_m.iter().position(|h| !h.is_finite()) {
            return Err(SarError::Dem(format!("non-finite height at index {i}")));
        }
        Ok(Self {
            width,
            height,
            pixel_m,
            heights_m,
            origin_m,
        })
    }

    /// The radar's view of a georeferenced [`Dem`](crate::dem::Dem): node `(row, col)` = DEM
    /// pixel `(col, row)`, origin `(0, 0)` (so `x` = rows southwards on a north-up map, the
    /// flight direction, and `y` = columns eastwards, the look direction), spacing = the DEM's
    /// square pixel. NaN (nodata) heights are filled from their valid neighbours (repeated
    /// 4-neighbour means growing inwards); returns the DEM and how many heights were filled.
    pub fn from_dem(dem: &crate::dem::Dem) -> SarResult<(Self, usize)> {
        let pixel_m = dem.pixel_m().map_err(|e| SarError::Dem(format!("{e}")))?;
        let (w, h) = (dem.width(), dem.height());
        let mut z = dem.heights_m().to_vec();
        let filled = fill_nodata(&mut z, w, h)?;
        Ok((Self::new_checked(w, h, pixel_m, z, [0.0, 0.0])?, filled))
    }

    /// Height of node (`row`, `col`), m. Indices must be in range (callers iterate the grid).
    #[inline]
    pub fn at(&self, row: usize, col: usize) -> f64 {
        f64::from(self.heights_m[row * self.width + col])
    }

    /// Local position of node (`row`, `col`), m.
    #[inline]
    pub fn node(&self, row: usize, col: usize) -> [f64; 3] {
        [
            self.origin_m[0] + row as f64 * self.pixel_m,
            self.origin_m[1] + col as f64 * self.pixel_m,
            self.at(row, col),
        ]
    }

    /// The `w × h` nodes from `(row0, col0)` as a DEM of their own, placed where they lie in
    /// this one (origin moved by the offset).
    pub fn crop(&self, row0: usize, col0: usize, w: usize, h: usize) -> SarResult<SarDem> {
        if row0 + h > self.height || col0 + w > self.width {
            return Err(SarError::Dem(format!(
                "crop {w}×{h} from ({row0}, {col0}) outside {}×{}",
                self.width, self.height
            )));
        }
        let mut heights = Vec::with_capacity(w * h);
        for r in row0..row0 + h {
            let start = r * self.width + col0;
            heights.extend_from_slice(&self.heights_m[start..start + w]);
        }
        let origin = [
            self.origin_m[0] + row0 as f64 * self.pixel_m,
            self.origin_m[1] + col0 as f64 * self.pixel_m,
        ];
        SarDem::new_checked(w, h, self.pixel_m, heights, origin)
    }

    /// Mean height, m.
    pub fn mean_height_m(&self) -> f64 {
        self.heights_m.iter().map(|&h| f64::from(h)).sum::<f64>() / self.heights_m.len() as f64
    }

    /// Bilinear resampling to `pixel_m` over the same extent (the paper interpolates its 10 m
    /// LOLA grid to 5 m meshes). Returns a copy when the spacing already matches.
    pub fn resampled(&self, pixel_m: f64) -> SarResult<SarDem> {
        if !(pixel_m.is_finite() && pixel_m > 0.0) {
            return Err(SarError::Dem(format!("resample spacing {pixel_m} invalid")));
        }
        if (pixel_m - self.pixel_m).abs() < 1e-9 * self.pixel_m {
            return Ok(self.clone());
        }
        let scale = self.pixel_m / pixel_m;
        let w = ((self.width - 1) as f64 * scale + 1e-9).floor() as usize + 1;
        let h = ((self.height - 1) as f64 * scale + 1e-9).floor() as usize + 1;
        if w > MAX_DEM_SIDE || h > MAX_DEM_SIDE {
            return Err(SarError::Dem(format!("resampled size {w}×{h} too large")));
        }
        let mut out = Vec::with_capacity(w * h);
        for r in 0..h {
            let fr = (r as f64 / scale).min((self.height - 1) as f64);
            let r0 = (fr.floor() as usize).min(self.height - 2);
            let ar = fr - r0 as f64;
            for c in 0..w {
                let fc = (c as f64 / scale).min((self.width - 1) as f64);
                let c0 = (fc.floor() as usize).min(self.width - 2);
                let ac = fc - c0 as f64;
                let v = (1.0 - ar) * ((1.0 - ac) * self.at(r0, c0) + ac * self.at(r0, c0 + 1))
                    + ar * ((1.0 - ac) * self.at(r0 + 1, c0) + ac * self.at(r0 + 1, c0 + 1));
                out.push(v as f32);
            }
        }
        SarDem::new_checked(w, h, pixel_m, out, self.origin_m)
    }
}

/// Fill non-finite heights in place from their finite 4-neighbours, layer by layer (each pass
/// gives every hole touching filled pixels the mean of those neighbours). Returns the count
/// filled; an all-nodata grid is an error.
pub(crate) fn fill_nodata(z: &mut [f32], w: usize, h: usize) -> SarResult<usize> {
    let holes = z.iter().filter(|v| !v.is_finite()).count();
    if holes == 0 {
        return Ok(0);
    }
    if holes == z.len() {
        return Err(SarError::Dem("every height is nodata".into()));
    }
    let mut left = holes;
    while left > 0 {
        let prev = z.to_vec();
        let mut changed = 0;
        for r in 0..h {
            for c in 0..w {
                let i = r * w + c;
                if prev[i].is_finite() {
                    continue;
                }
                let mut acc = 0.0f64;
                let mut n = 0;
                let mut take = |j: usize| {
                    if prev[j].is_finite() {
                        acc += f64::from(prev[j]);
                        n += 1;
                    }
                };
                if c > 0 {
                    take(i - 1);
                }
                if c + 1 < w {
                    take(i + 1);
                }
                if r > 0 {
                    take(i - w);
                }
                if r + 1 < h {
                    take(i + w);
                }
                if n > 0 {
                    z[i] = (acc / f64::from(n)) as f32;
                    changed += 1;
                }
            }
        }
        if changed == 0 {
            return Err(SarError::Dem("nodata fill made no progress".into()));
        }
        left -= changed;
    }
    Ok(holes)
}

/// One of the two interferometric antennas.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Antenna {
    /// Reference antenna on the nominal track.
    A1,
    /// Second antenna, offset by the tilted baseline.
    A2,
}

impl Antenna {
    /// Both antennas in order.
    pub const BOTH: [Antenna; 2] = [Antenna::A1, Antenna::A2];
    /// 0 for A1, 1 for A2.
    pub fn index(self) -> usize {
        match self {
            Antenna::A1 => 0,
            Antenna::A2 => 1,
        }
    }
    /// Number stored in file headers and names (1 or 2).
    pub fn number(self) -> u8 {
        self.index() as u8 + 1
    }
}

/// Platform track and antenna positions in the local frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Geometry {
    /// Scene centre on the reference datum `(x_c, y_c, z_ref)`, m.
    pub scene_centre_m: [f64; 3],
    /// Reference datum height `z_ref` (DEM mean), m.
    pub reference_height_m: f64,
    /// Cross-track position of antenna A1's track, m.
    pub track_y_m: f64,
    /// Height of antenna A1's track, m.
    pub track_z_m: f64,
    /// `(y, z)` offset of each antenna from the A1 track, m (A1: zero).
    pub antenna_offset_m: [[f64; 2]; 2],
    /// Platform speed along `+x`, m/s.
    pub velocity_m_s: f64,
    /// Wavelength, m (kept here so phase helpers need nothing else).
    pub wavelength_m: f64,
    /// Antenna length L_A, m (azimuth footprint λR/L_A).
    pub antenna_length_m: f64,
}

impl Geometry {
    /// Place the track so the DEM centre is seen at θ0 from `H` above the DEM mean height.
    pub fn new(dem: &SarDem, cfg: &SarConfig, derived: &Derived) -> SarResult<Self> {
        let xc = dem.origin_m[0] + 0.5 * (dem.height - 1) as f64 * dem.pixel_m;
        let yc = dem.origin_m[1] + 0.5 * (dem.width - 1) as f64 * dem.pixel_m;
        let zref = dem.mean_height_m();
        Self::in_scene(dem, cfg, derived, [xc, yc, zref])
    }

    /// Place the track for `scene_centre_m` (a whole scene's centre on its mean height, seen at
    /// θ0 from `H` above it) while `dem` is only part of that scene, e.g. one block of a map
    /// processed in blocks: every block is then seen from the one track of the whole pass. The
    /// processing datum (flat phase, focusing height) is `dem`'s own mean height, as a processor
    /// with a coarse prior DEM would take it block by block.
    pub fn in_scene(
        dem: &SarDem,
        cfg: &SarConfig,
        derived: &Derived,
        scene_centre_m: [f64; 3],
    ) -> SarResult<Self> {
        let theta = cfg.incidence_centre_deg.to_radians();
        let [xc, yc, scene_z] = scene_centre_m;
        let zref = dem.mean_height_m();
        let track_y_m = yc - cfg.altitude_m * theta.tan();
        let track_z_m = scene_z + cfg.altitude_m;
        let alpha = cfg.baseline_tilt_deg.to_radians();
        let zmax = dem
            .heights_m
            .iter()
            .fold(f64::NEG_INFINITY, |m, &h| m.max(f64::from(h)));
        if zmax > track_z_m - 0.5 * cfg.altitude_m {
            return Err(SarError::Geometry(format!(
                "terrain reaches {zmax:.0} m, too close to the platform at {track_z_m:.0} m"
            )));
        }
        if dem.origin_m[1] <= track_y_m {
            return Err(SarError::Geometry(
                "scene extends under the platform track (nadir in swath)".into(),
            ));
        }
        Ok(Self {
            scene_centre_m: [xc, yc, zref],
            reference_height_m: zref,
            track_y_m,
            track_z_m,
            antenna_offset_m: [
                [0.0, 0.0],
                [cfg.baseline_m * alpha.cos(), cfg.baseline_m * alpha.sin()],
            ],
            velocity_m_s: cfg.velocity_m_s,
            wavelength_m: derived.wavelength_m,
            antenna_length_m: derived.antenna_length_m,
        })
    }

    /// `(y, z)` of an antenna's track, m.
    #[inline]
    pub fn antenna_yz(&self, antenna: Antenna) -> [f64; 2] {
        let o = self.antenna_offset_m[antenna.index()];
        [self.track_y_m + o[0], self.track_z_m + o[1]]
    }

    /// Antenna phase centre when the platform is at along-track position `x_m`.
    pub fn antenna_position(&self, antenna: Antenna, x_m: f64) -> [f64; 3] {
        let [y, z] = self.antenna_yz(antenna);
        [x_m, y, z]
    }

    /// Closest-approach (zero-Doppler) slant range from an antenna's track to `p`, m.
    #[inline]
    pub fn zero_doppler_range(&self, antenna: Antenna, p: [f64; 3]) -> f64 {
        let [y, z] = self.antenna_yz(antenna);
        ((p[1] - y).powi(2) + (p[2] - z).powi(2)).sqrt()
    }

    /// Half of the azimuth footprint λR/L_A for a scatterer at zero-Doppler range `r0` from A1, m.
    #[inline]
    pub fn half_footprint_m(&self, r0: f64) -> f64 {
        0.5 * self.wavelength_m * r0 / self.antenna_length_m
    }

    /// Incidence angle on the flat datum at zero-Doppler slant range `r0` from A1, radians.
    pub fn flat_incidence_rad(&self, r0: f64) -> f64 {
        let h = self.track_z_m - self.reference_height_m;
        (h / r0).clamp(-1.0, 1.0).acos()
    }
}

/// Azimuth positions of the transmitted pulses: pulse `n` at `x = first_x_m + n·spacing_m`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PulseGrid {
    /// Along-track platform position of pulse 0, m.
    pub first_x_m: f64,
    /// Along-track spacing v/PRF, m.
    pub spacing_m: f64,
    /// Number of pulses.
    pub count: usize,
}

impl PulseGrid {
    /// Platform position of pulse `n`, m.
    #[inline]
    pub fn x(&self, n: usize) -> f64 {
        self.first_x_m + n as f64 * self.spacing_m
    }
}

/// Fast-time sampling of every echo: sample `k` is at two-way delay `2·(first_range_m +
/// k·spacing_m)/c`. The same window serves both antennas so their SLCs share range axes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EchoWindow {
    /// Slant range of sample 0, m.
    pub first_range_m: f64,
    /// Slant-range spacing c/(2fs), m.
    pub spacing_m: f64,
    /// Samples per pulse.
    pub samples: usize,
}

impl EchoWindow {
    /// Fast time of sample 0 (two-way delay), s.
    pub fn first_time_s(&self) -> f64 {
        2.0 * self.first_range_m / SPEED_OF_LIGHT_M_S
    }
}

/// Part of the focused image kept in the SLC: azimuth lines and range gates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SlcCrop {
    /// First kept pulse/line index.
    pub first_line: usize,
    /// Number of kept lines.
    pub lines: usize,
    /// First kept echo sample/gate index.
    pub first_gate: usize,
    /// Number of kept gates.
    pub gates: usize,
}

/// Everything fixed before simulating: geometry, pulses, echo window and SLC crop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AcquisitionPlan {
    /// Track and antennas.
    pub geometry: Geometry,
    /// Pulse positions.
    pub pulses: PulseGrid,
    /// Echo window (holds every facet's whole chirp for both antennas).
    pub window: EchoWindow,
    /// SLC crop: the DEM's azimuth extent and its slant-range extent plus margins.
    pub crop: SlcCrop,
}

impl AcquisitionPlan {
    /// Size the pulse grid and echo window so that every DEM point's whole synthetic aperture
    /// and whole chirp are recorded, for both antennas.
    pub fn new(
        dem: &SarDem,
        cfg: &SarConfig,
        derived: &Derived,
        geometry: Geometry,
    ) -> SarResult<Self> {
        let dr = derived.range_spacing_slant_m;
        let dx = derived.azimuth_spacing_m;
        let (mut r_lo, mut r_hi_zd, mut r_hi) = (f64::INFINITY, 0.0_f64, 0.0_f64);
        let mut half_max = 0.0_f64;
        for row in 0..dem.height {
            for col in 0..dem.width {
                let p = dem.node(row, col);
                let half = geometry.half_footprint_m(geometry.zero_doppler_range(Antenna::A1, p));
                half_max = half_max.max(half);
                for a in Antenna::BOTH {
                    let r0 = geometry.zero_doppler_range(a, p);
                    r_lo = r_lo.min(r0);
                    r_hi_zd = r_hi_zd.max(r0);
                    r_hi = r_hi.max((r0 * r0 + half * half).sqrt());
                }
            }
        }
        // Margins: the kernel's half-length plus a few gates for facet centroids that can lie
        // nearer than every node, and for the tails of the point response in the SLC.
        let margin_gates = (KERNEL_TAPS + RANGE_MARGIN_GATES) as f64;
        let half_chirp_m = 0.25 * SPEED_OF_LIGHT_M_S * cfg.pulse_width_s;
        let first_range_m = r_lo - half_chirp_m - margin_gates * dr;
        let samples =
            ((r_hi - r_lo + 2.0 * half_chirp_m) / dr + 2.0 * margin_gates).ceil() as usize;

        let x0 = dem.origin_m[0];
        let x1 = x0 + (dem.height - 1) as f64 * dem.pixel_m;
        let lead = (half_max / dx).ceil() as usize + 2;
        let first_x_m = x0 - lead as f64 * dx;
        let count = ((x1 + half_max - first_x_m) / dx).ceil() as usize + 3;
        if samples > MAX_AXIS_SAMPLES || count > MAX_AXIS_SAMPLES {
            return Err(SarError::Bound(format!(
                "echo needs {count} pulses × {samples} samples; limit {MAX_AXIS_SAMPLES} per axis"
            )));
        }
        let lines = ((x1 - x0) / dx + 1e-9).floor() as usize + 1;
        let m = RANGE_MARGIN_GATES as f64;
        let g0 = ((r_lo - first_range_m) / dr - m).floor().max(0.0) as usize;
        let g1 = (((r_hi_zd - first_range_m) / dr + m).ceil() as usize).min(samples - 1);
        Ok(Self {
            geometry,
            pulses: PulseGrid {
                first_x_m,
                spacing_m: dx,
                count,
            },
            window: EchoWindow {
                first_range_m,
                spacing_m: dr,
                samples,
            },
            crop: SlcCrop {
                first_line: lead,
                lines,
                first_gate: g0,
                gates: g1 + 1 - g0,
            },
        })
    }
}

/// Smallest `n' ≥ n` of the form 2^a·3^b·5^c (fast for rustfft's mixed-radix plans).
pub fn fft_friendly_len(n: usize) -> usize {
    let mut m = n.max(1);
    loop {
        let mut k = m;
        for p in [2, 3, 5] {
            while k.is_multiple_of(p) {
                k /= p;
            }
        }
        if k == 1 {
            return m;
        }
        m += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_keeps_heights_and_place() {
        let heights: Vec<f32> = (0..20).map(|v| v as f32).collect();
        let dem = SarDem::new_checked(5, 4, 10.0, heights, [100.0, 200.0]).unwrap();
        let c = dem.crop(1, 2, 3, 2).unwrap();
        assert_eq!((c.width, c.height, c.pixel_m), (3, 2, 10.0));
        assert_eq!(c.heights_m, vec![7.0, 8.0, 9.0, 12.0, 13.0, 14.0]);
        assert_eq!(c.origin_m, [110.0, 220.0]);
        assert_eq!(c.node(1, 2), dem.node(2, 4));
        assert!(dem.crop(3, 0, 5, 2).is_err());
        assert!(dem.crop(0, 3, 3, 1).is_err());
    }

    #[test]
    fn resampling_keeps_a_plane_exact() {
        let (w, h) = (5, 4);
        let z: Vec<f32> = (0..w * h)
            .map(|i| (2.0 * (i % w) as f32) - 3.0 * (i / w) as f32)
            .collect();
        let dem = SarDem::new_checked(w, h, 10.0, z, [0.0, 0.0]).unwrap();
        let r = dem.resampled(5.0).unwrap();
        assert_eq!((r.width, r.height), (9, 7));
        for row in 0..r.height {
            for col in 0..r.width {
                let want = 2.0 * col as f64 / 2.0 - 3.0 * row as f64 / 2.0;
                assert!((r.at(row, col) - want).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn nodata_is_filled_from_neighbours() {
        let mut z = vec![
            1.0,
            f32::NAN,
            3.0,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            7.0,
            8.0,
            9.0,
        ];
        assert_eq!(fill_nodata(&mut z, 3, 3).unwrap(), 4);
        assert!(z.iter().all(|v| v.is_finite()));
        assert_eq!(z[1], 2.0);
        let mut all = vec![f32::NAN; 4];
        assert!(fill_nodata(&mut all, 2, 2).is_err());
    }

    #[test]
    fn bad_dems_are_rejected() {
        assert!(SarDem::new_checked(1, 5, 5.0, vec![0.0; 5], [0.0; 2]).is_err());
        assert!(SarDem::new_checked(2, 2, 0.0, vec![0.0; 4], [0.0; 2]).is_err());
        assert!(SarDem::new_checked(2, 2, 5.0, vec![0.0; 3], [0.0; 2]).is_err());
        assert!(SarDem::new_checked(2, 2, 5.0, vec![0.0, f32::NAN, 0.0, 0.0], [0.0; 2]).is_err());
    }

    #[test]
    fn centre_is_seen_at_the_configured_incidence() {
        let cfg = SarConfig::default();
        let d = cfg.derived().unwrap();
        let dem = SarDem::new_checked(11, 11, 5.0, vec![100.0; 121], [0.0, 0.0]).unwrap();
        let g = Geometry::new(&dem, &cfg, &d).unwrap();
        let r = g.zero_doppler_range(Antenna::A1, g.scene_centre_m);
        assert!((g.flat_incidence_rad(r).to_degrees() - 26.0).abs() < 1e-9);
        assert!((r - d.slant_range_centre_m).abs() < 1e-6);
    }

    #[test]
    fn fft_lengths_are_5_smooth() {
        assert_eq!(fft_friendly_len(1000), 1000);
        assert_eq!(fft_friendly_len(1001), 1024);
        assert_eq!(fft_friendly_len(1067), 1080);
    }
}
