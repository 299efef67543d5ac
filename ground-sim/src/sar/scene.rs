//! Triangle meshes of the DEM (eq 1) with their radar geometry, shadow and layover flags, and
//! the scatterers (position + scattering amplitude per channel) fed to the echo simulator.
//!
//! Cell `(r, c)` with nodes `p00 = (r, c)`, `p01 = (r, c+1)`, `p10 = (r+1, c)`, `p11 =
//! (r+1, c+1)` gives triangles `(p00, p01, p11)` and `(p00, p11, p10)`, facets `2·(r·(W−1)+c)`
//! and `+1`. All radar angles are taken at zero Doppler from antenna A1 (the look direction
//! changes by ±0.35° over the aperture and by 7·10⁻⁵ rad between antennas, both negligible for
//! the reflectivity); the same reflectivity serves both antennas.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::config::{Polarisation, SarConfig};
use super::geometry::{Antenna, Geometry, SarDem};
use super::scattering::{TwoScaleModel, complex_gaussian};
use super::{C32, MAX_POLARISATIONS, SarError, SarResult};

/// Facet flag: occluded along the line of sight by nearer terrain (radar shadow).
pub const FLAG_SHADOW: u8 = 1;
/// Facet flag: slant range decreases with ground range across the facet (layover: the facet's
/// slope towards the radar exceeds the incidence angle).
pub const FLAG_LAYOVER: u8 = 2;
/// Facet flag: faces away from the radar (local incidence ≥ 90°, self-shadowed).
pub const FLAG_BACK_FACING: u8 = 4;

/// Radar-relevant properties of every triangle (structure of arrays, facet index order).
#[derive(Debug, Clone, Default)]
pub struct Facets {
    /// Centroid in the local frame, m.
    pub centroid_m: Vec<[f64; 3]>,
    /// Area A_n, m².
    pub area_m2: Vec<f64>,
    /// Upward unit normal.
    pub normal: Vec<[f64; 3]>,
    /// Local incidence angle between the normal and the direction to antenna A1, rad.
    pub local_incidence_rad: Vec<f64>,
    /// Rotation Δ from the radar H/V basis to the facet's local basis (eqs 2–3), rad.
    pub pol_rotation_rad: Vec<f64>,
    /// Bitwise OR of `FLAG_*`.
    pub flags: Vec<u8>,
}

/// Counts of flagged facets.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneStats {
    /// Facets in the mesh.
    pub facets: usize,
    /// Facets in radar shadow (occluded or back-facing).
    pub shadowed: usize,
    /// Facets in layover.
    pub layover: usize,
    /// Facets using the Kirchhoff model for HH.
    pub kirchhoff_hh: usize,
    /// Mean local incidence of lit facets, degrees.
    pub mean_local_incidence_deg: f64,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Angle from nadir at which antenna A1's track sees point `p` in its zero-Doppler plane, rad.
/// Larger means farther/higher along the line of sight; used for the shadow sweep.
fn look_angle(geom: &Geometry, p: [f64; 3]) -> f64 {
    let [ya, za] = geom.antenna_yz(Antenna::A1);
    (p[1] - ya).atan2(za - p[2])
}

/// Build all facets of `dem` with their geometry and flags.
pub fn build_facets(dem: &SarDem, geom: &Geometry) -> SarResult<Facets> {
    let (w, h) = (dem.width, dem.height);
    // Shadow horizon: for every node, the largest look angle of any node at or nearer in range on
    // the same row (the line of sight lies in the row's zero-Doppler plane).
    let horizon: Vec<f64> = (0..h)
        .into_par_iter()
        .flat_map_iter(|r| {
            let mut run = f64::NEG_INFINITY;
            (0..w)
                .map(|c| {
                    run = run.max(look_angle(geom, dem.node(r, c)));
                    run
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let [ya, za] = geom.antenna_yz(Antenna::A1);
    let cells = (w - 1) * (h - 1);
    let per_cell: Vec<[(Facet, u8); 2]> = (0..cells)
        .into_par_iter()
        .map(|cell| {
            let (r, c) = (cell / (w - 1), cell % (w - 1));
            let p00 = dem.node(r, c);
            let p01 = dem.node(r, c + 1);
            let p10 = dem.node(r + 1, c);
            let p11 = dem.node(r + 1, c + 1);
            let hz = 0.5 * (horizon[r * w + c] + horizon[(r + 1) * w + c]);
            [
                facet(p00, p01, p11, ya, za, hz, geom),
                facet(p00, p11, p10, ya, za, hz, geom),
            ]
        })
        .collect();
    let n = 2 * cells;
    let mut out = Facets {
        centroid_m: Vec::with_capacity(n),
        area_m2: Vec::with_capacity(n),
        normal: Vec::with_capacity(n),
        local_incidence_rad: Vec::with_capacity(n),
        pol_rotation_rad: Vec::with_capacity(n),
        flags: Vec::with_capacity(n),
    };
    for pair in per_cell {
        for (f, flags) in pair {
            out.centroid_m.push(f.centroid);
            out.area_m2.push(f.area);
            out.normal.push(f.normal);
            out.local_incidence_rad.push(f.incidence);
            out.pol_rotation_rad.push(f.delta);
            out.flags.push(flags);
        }
    }
    if out.area_m2.iter().any(|a| !(a.is_finite() && *a > 0.0)) {
        return Err(SarError::Dem("degenerate triangle (zero area)".into()));
    }
    Ok(out)
}

struct Facet {
    centroid: [f64; 3],
    area: f64,
    normal: [f64; 3],
    incidence: f64,
    delta: f64,
}

fn facet(
    a: [f64; 3],
    b: [f64; 3],
    c: [f64; 3],
    ya: f64,
    za: f64,
    horizon: f64,
    geom: &Geometry,
) -> (Facet, u8) {
    let centroid = scale(
        [a[0] + b[0] + c[0], a[1] + b[1] + c[1], a[2] + b[2] + c[2]],
        1.0 / 3.0,
    );
    let mut nrm = cross(sub(b, a), sub(c, a));
    if nrm[2] < 0.0 {
        nrm = scale(nrm, -1.0);
    }
    let len = norm(nrm);
    let area = 0.5 * len;
    let normal = scale(nrm, 1.0 / len.max(f64::MIN_POSITIVE));
    // Incident direction k̂ from the antenna (zero Doppler: same x) to the centroid.
    let k = [0.0, centroid[1] - ya, centroid[2] - za];
    let k = scale(k, 1.0 / norm(k));
    let cos_inc = -dot(k, normal);
    let incidence = cos_inc.clamp(-1.0, 1.0).acos();
    // Radar basis: ĥ = k̂×ẑ/|k̂×ẑ|, v̂ = ĥ×k̂. Local basis: ĥ_l = k̂×n̂/|k̂×n̂|. Δ from ĥ to ĥ_l.
    let h = cross(k, [0.0, 0.0, 1.0]);
    let h = scale(h, 1.0 / norm(h));
    let v = cross(h, k);
    let hl = cross(k, normal);
    let hl_len = norm(hl);
    let delta = if hl_len < 1e-12 {
        0.0
    } else {
        let hl = scale(hl, 1.0 / hl_len);
        dot(hl, v).atan2(dot(hl, h))
    };
    let mut flags = 0u8;
    if cos_inc <= 0.0 {
        flags |= FLAG_BACK_FACING | FLAG_SHADOW;
    }
    if look_angle(geom, centroid) < horizon - 1e-9 {
        flags |= FLAG_SHADOW;
    }
    // Layover: the slant range R(x, y) over the triangle, fitted as R = r0 + gx·x + gy·y
    // through the three vertices, decreases with ground range (gy < 0).
    let rr = |p: [f64; 3]| ((p[1] - ya).powi(2) + (p[2] - za).powi(2)).sqrt();
    let (ra, rb, rc) = (rr(a), rr(b), rr(c));
    let (dx1, dy1, dr1) = (b[0] - a[0], b[1] - a[1], rb - ra);
    let (dx2, dy2, dr2) = (c[0] - a[0], c[1] - a[1], rc - ra);
    let det = dx1 * dy2 - dx2 * dy1;
    if det.abs() > 1e-12 {
        let gy = (dx1 * dr2 - dx2 * dr1) / det;
        if gy < 0.0 {
            flags |= FLAG_LAYOVER;
        }
    }
    (
        Facet {
            centroid,
            area,
            normal,
            incidence,
            delta,
        },
        flags,
    )
}

/// Point scatterers given to the echo simulator, sorted by along-track position `x`.
#[derive(Debug, Clone, Default)]
pub struct Scatterers {
    /// Polarisation of each amplitude column.
    pub polarisations: Vec<Polarisation>,
    /// Along-track position, m (ascending).
    pub x_m: Vec<f64>,
    /// Ground-range position, m.
    pub y_m: Vec<f64>,
    /// Height, m.
    pub z_m: Vec<f64>,
    /// Half azimuth footprint L_s/2 = λR/(2L_A), R the zero-Doppler range from A1, m.
    pub half_footprint_m: Vec<f64>,
    /// Scattering amplitudes S_pq (eq 1), one per polarisation; unused slots are zero.
    pub amplitude: Vec<[C32; MAX_POLARISATIONS]>,
}

impl Scatterers {
    /// Number of scatterers.
    pub fn len(&self) -> usize {
        self.x_m.len()
    }
    /// True when there is none.
    pub fn is_empty(&self) -> bool {
        self.x_m.is_empty()
    }
    /// Largest half footprint, m.
    pub fn max_half_footprint_m(&self) -> f64 {
        self.half_footprint_m
            .iter()
            .fold(0.0, |m: f64, &v| m.max(v))
    }

    /// Append one scatterer (call [`Scatterers::sort_by_azimuth`] afterwards).
    pub fn push(&mut self, geom: &Geometry, p: [f64; 3], amplitude: [C32; MAX_POLARISATIONS]) {
        self.x_m.push(p[0]);
        self.y_m.push(p[1]);
        self.z_m.push(p[2]);
        self.half_footprint_m
            .push(geom.half_footprint_m(geom.zero_doppler_range(Antenna::A1, p)));
        self.amplitude.push(amplitude);
    }

    /// Sort by `x` so each pulse finds its footprint with two binary searches.
    pub fn sort_by_azimuth(&mut self) {
        let mut idx: Vec<usize> = (0..self.len()).collect();
        idx.sort_by(|&a, &b| self.x_m[a].total_cmp(&self.x_m[b]));
        let pick = |v: &Vec<f64>| idx.iter().map(|&i| v[i]).collect::<Vec<_>>();
        self.x_m = pick(&self.x_m);
        self.y_m = pick(&self.y_m);
        self.z_m = pick(&self.z_m);
        self.half_footprint_m = pick(&self.half_footprint_m);
        self.amplitude = idx.iter().map(|&i| self.amplitude[i]).collect();
    }
}

/// Facet scattering amplitudes `S = γ·sqrt(A/4π)` (eq 1) for the configured channels. Shadowed
/// facets are dropped; `clutter_scale` multiplies every amplitude (1 for the physical scene,
/// 0 for an isolated point target).
#[allow(
    clippy::needless_range_loop,
    reason = "one index walks parallel SoA arrays"
)]
pub fn facet_scatterers(
    facets: &Facets,
    geom: &Geometry,
    cfg: &SarConfig,
    clutter_scale: f64,
) -> (Scatterers, SceneStats) {
    facet_scatterers_indexed(facets, geom, cfg, clutter_scale, &|i| i as u64)
}

/// [`facet_scatterers`] with facet `i`'s speckle drawn as the scene's facet `index(i)` (a block
/// of a larger scene numbers its facets as the scene does, so overlapping blocks agree).
#[allow(
    clippy::needless_range_loop,
    reason = "one index walks parallel SoA arrays"
)]
pub fn facet_scatterers_indexed(
    facets: &Facets,
    geom: &Geometry,
    cfg: &SarConfig,
    clutter_scale: f64,
    index: &(dyn Fn(usize) -> u64 + Sync),
) -> (Scatterers, SceneStats) {
    let ev = TwoScaleModel::from_config(cfg).facet_evaluator();
    let n = facets.area_m2.len();
    let amps: Vec<Option<[C32; MAX_POLARISATIONS]>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if facets.flags[i] & FLAG_SHADOW != 0 || clutter_scale == 0.0 {
                return None;
            }
            let g = complex_gaussian(cfg.seed, 0, index(i));
            let gam = ev.reflectivity(facets.local_incidence_rad[i], facets.pol_rotation_rad[i], g);
            let s = clutter_scale * (facets.area_m2[i] / (4.0 * std::f64::consts::PI)).sqrt();
            let mut out = [C32::new(0.0, 0.0); MAX_POLARISATIONS];
            for (slot, pol) in out.iter_mut().zip(&cfg.polarisations) {
                let v = match pol {
                    Polarisation::HH => gam[0],
                    Polarisation::VV => gam[1],
                } * s;
                *slot = C32::new(v.re as f32, v.im as f32);
            }
            Some(out)
        })
        .collect();
    let mut sc = Scatterers {
        polarisations: cfg.polarisations.clone(),
        ..Default::default()
    };
    let mut stats = SceneStats {
        facets: n,
        ..Default::default()
    };
    let mut inc_sum = 0.0;
    let mut lit = 0usize;
    for i in 0..n {
        let f = facets.flags[i];
        if f & FLAG_SHADOW != 0 {
            stats.shadowed += 1;
        } else {
            lit += 1;
            inc_sum += facets.local_incidence_rad[i];
            if ev.regime(Polarisation::HH, facets.local_incidence_rad[i])
                == super::scattering::Regime::Kirchhoff
            {
                stats.kirchhoff_hh += 1;
            }
        }
        if f & FLAG_LAYOVER != 0 {
            stats.layover += 1;
        }
        if let Some(a) = amps[i] {
            sc.push(geom, facets.centroid_m[i], a);
        }
    }
    stats.mean_local_incidence_deg = if lit > 0 {
        (inc_sum / lit as f64).to_degrees()
    } else {
        0.0
    };
    sc.sort_by_azimuth();
    (sc, stats)
}

/// Simple analytic surfaces for tests, benchmarks and the CLI's `--synthetic` option.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
pub enum AnalyticSurface {
    /// Flat plane at height 0.
    Flat,
    /// Gaussian hill, height 0.1·side, σ = side/6.
    Hill,
    /// Crater-like bowl: parabolic floor, raised rim, depth 0.1·side.
    Bowl,
}

/// An `n × n` node grid of an analytic surface at `pixel_m` spacing, origin at `(0, 0)`.
pub fn analytic_dem(surface: AnalyticSurface, n: usize, pixel_m: f64) -> SarResult<SarDem> {
    let side = (n.max(2) - 1) as f64 * pixel_m;
    let c = 0.5 * side;
    let mut z = Vec::with_capacity(n * n);
    for r in 0..n {
        for col in 0..n {
            let (dx, dy) = (r as f64 * pixel_m - c, col as f64 * pixel_m - c);
            let rho = (dx * dx + dy * dy).sqrt();
            let v = match surface {
                AnalyticSurface::Flat => 0.0,
                AnalyticSurface::Hill => {
                    let s = side / 6.0;
                    0.1 * side * (-(rho * rho) / (2.0 * s * s)).exp()
                }
                AnalyticSurface::Bowl => {
                    let rim = 0.35 * side;
                    let depth = 0.1 * side;
                    if rho < rim {
                        depth * ((rho / rim).powi(2) - 1.0) + 0.02 * side
                    } else {
                        0.02 * side * (-(rho - rim) / (0.08 * side)).exp()
                    }
                }
            };
            z.push(v as f32);
        }
    }
    SarDem::new_checked(n, n, pixel_m, z, [0.0, 0.0])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup(dem: &SarDem) -> Geometry {
        let cfg = SarConfig::default();
        Geometry::new(dem, &cfg, &cfg.derived().unwrap()).unwrap()
    }

    #[test]
    fn flat_facets_have_flat_incidence_and_no_flags() {
        let dem = analytic_dem(AnalyticSurface::Flat, 9, 5.0).unwrap();
        let g = setup(&dem);
        let f = build_facets(&dem, &g).unwrap();
        assert_eq!(f.area_m2.len(), 2 * 8 * 8);
        for i in 0..f.area_m2.len() {
            assert!((f.area_m2[i] - 12.5).abs() < 1e-9);
            let r0 = g.zero_doppler_range(Antenna::A1, f.centroid_m[i]);
            assert!((f.local_incidence_rad[i] - g.flat_incidence_rad(r0)).abs() < 1e-9);
            assert!(f.pol_rotation_rad[i].abs() < 1e-9);
            assert_eq!(f.flags[i], 0);
        }
    }

    /// A ridge across the swath: a 50° slope facing the radar (layover at 26° incidence)
    /// followed by a 70° drop facing away (steeper than 90° − 26°: shadow behind it).
    #[test]
    fn steep_ridge_gives_layover_then_shadow() {
        let (n, px) = (60, 5.0);
        let top = 100.0 * 50f64.to_radians().tan();
        let mut z = vec![0.0f32; n * n];
        for r in 0..n {
            for c in 0..n {
                let y = c as f64 * px;
                let v = if (50.0..150.0).contains(&y) {
                    (y - 50.0) * 50f64.to_radians().tan()
                } else if y >= 150.0 {
                    (top - (y - 150.0) * 70f64.to_radians().tan()).max(0.0)
                } else {
                    0.0
                };
                z[r * n + c] = v as f32;
            }
        }
        let dem = SarDem::new_checked(n, n, px, z, [0.0, 0.0]).unwrap();
        let g = setup(&dem);
        let f = build_facets(&dem, &g).unwrap();
        let row = 20;
        let flag_at = |c: usize| f.flags[2 * (row * (n - 1) + c)];
        assert_eq!(
            flag_at(5) & (FLAG_LAYOVER | FLAG_SHADOW),
            0,
            "flat ground before the ridge"
        );
        assert_ne!(flag_at(20) & FLAG_LAYOVER, 0, "front slope in layover");
        assert_ne!(flag_at(32) & FLAG_SHADOW, 0, "back slope shadowed");
        // Flat ground behind the ridge foot (y ≈ 193 m) lies in its shadow up to y ≈ 208 m.
        assert_ne!(flag_at(39) & FLAG_SHADOW, 0, "ground behind ridge shadowed");
        assert_eq!(
            flag_at(50) & FLAG_SHADOW,
            0,
            "ground far behind is lit again"
        );
    }

    #[test]
    fn tilted_facet_rotates_the_polarisation_basis() {
        // A plane tilted along azimuth rotates the local plane of incidence: Δ ≠ 0 and equal to
        // the analytic angle for a small tilt.
        let n = 5;
        let slope = 0.2_f64;
        let z: Vec<f32> = (0..n * n)
            .map(|i| (slope * 5.0 * (i / n) as f64) as f32)
            .collect();
        let dem = SarDem::new_checked(n, n, 5.0, z, [0.0, 0.0]).unwrap();
        let g = setup(&dem);
        let f = build_facets(&dem, &g).unwrap();
        let d = f.pol_rotation_rad[0];
        assert!(d.abs() > 0.1 && d.abs() < 0.6, "Δ = {d}");
        assert!(f.pol_rotation_rad.iter().all(|v| (v - d).abs() < 1e-3));
    }
}
