//! DEM statistics: slope (through nav-core), elevation and slope summaries, closed depressions
//! (a crater proxy that works the same on real and synthetic DEMs) and the main crater's
//! depth/diameter.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use nav_core::frame::{DemPatch, SLOPE_NODATA, slope_to_deg};
use nav_core::slope::slope_into;

use crate::dem::{Dem, DemError};

/// Slope in degrees of every pixel, computed by nav-core's Horn operator (the flight code path)
/// and converted from its fixed-point pixels; `NaN` on the border and next to nodata.
pub fn slope_deg(dem: &Dem) -> Result<Vec<f32>, DemError> {
    let pixel_m = dem.pixel_m()? as f32;
    let patch = DemPatch::new_checked(dem.heights_m(), dem.width(), dem.height(), pixel_m)
        .map_err(|e| DemError::Invalid(format!("nav-core refused the DEM: {e}")))?;
    let mut px = vec![SLOPE_NODATA; dem.width() * dem.height()];
    let img = slope_into(&patch, &mut px)
        .map_err(|e| DemError::Invalid(format!("nav-core slope failed: {e}")))?;
    Ok(img
        .pixels()
        .iter()
        .map(|&p| slope_to_deg(p).unwrap_or(f32::NAN))
        .collect())
}

/// Summary of a DEM: the JSON of `ground-sim info`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DemStats {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Pixel size, metres.
    pub pixel_m: f64,
    /// Upper-left corner of the grid in map coordinates, metres (GDAL's "origin").
    pub origin_x_m: f64,
    /// Upper-left corner y, metres.
    pub origin_y_m: f64,
    /// Extent `[x_min, y_min, x_max, y_max]`, metres.
    pub extent_m: [f64; 4],
    /// Nodata sample count.
    pub nodata_count: usize,
    /// Lowest height, metres.
    pub elev_min_m: f64,
    /// Highest height, metres.
    pub elev_max_m: f64,
    /// Mean height, metres.
    pub elev_mean_m: f64,
    /// Standard deviation of heights, metres.
    pub elev_std_m: f64,
    /// Mean slope, degrees.
    pub slope_mean_deg: f64,
    /// Slope percentiles (50, 90, 99, 99.9), degrees.
    pub slope_p50_deg: f64,
    /// 90th percentile slope, degrees.
    pub slope_p90_deg: f64,
    /// 99th percentile slope, degrees.
    pub slope_p99_deg: f64,
    /// 99.9th percentile slope, degrees.
    pub slope_p999_deg: f64,
    /// Largest slope, degrees.
    pub slope_max_deg: f64,
    /// Fraction of valid slope pixels below 30°.
    pub slope_lt30_frac: f64,
    /// Fraction of valid slope pixels below 35°.
    pub slope_lt35_frac: f64,
    /// Slope CDF at 5° steps: fraction below 5°, 10°, …, 45°.
    pub slope_cdf_5deg: Vec<f64>,
    /// Closed depressions (crater proxy) per diameter bin.
    pub depressions: Vec<DepressionBin>,
    /// Main crater depth/diameter, if a rim is found inside the DEM.
    pub main_crater: Option<MainCrater>,
}

/// Count of closed depressions in a diameter bin.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DepressionBin {
    /// Lower equivalent diameter, metres.
    pub d_min_m: f64,
    /// Upper equivalent diameter, metres.
    pub d_max_m: f64,
    /// Count.
    pub count: usize,
    /// Count per km² of the DEM.
    pub per_km2: f64,
}

fn percentile(sorted: &[f32], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    f64::from(sorted[i.min(sorted.len() - 1)])
}

/// Compute all statistics of a DEM.
pub fn dem_stats(dem: &Dem) -> Result<DemStats, DemError> {
    let pixel_m = dem.pixel_m()?;
    let valid: Vec<f64> = dem
        .heights_m()
        .iter()
        .filter(|h| h.is_finite())
        .map(|&h| f64::from(h))
        .collect();
    if valid.is_empty() {
        return Err(DemError::Invalid("the DEM has no valid height".into()));
    }
    let n = valid.len() as f64;
    let mean = valid.iter().sum::<f64>() / n;
    let std = (valid.iter().map(|h| (h - mean).powi(2)).sum::<f64>() / n).sqrt();
    let (mn, mx) = valid
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        });

    let mut s: Vec<f32> = slope_deg(dem)?
        .into_iter()
        .filter(|v| v.is_finite())
        .collect();
    s.sort_by(f32::total_cmp);
    let ns = s.len().max(1) as f64;
    let frac_lt = |t: f32| s.partition_point(|&v| v < t) as f64 / ns;
    let (x0, y0) = dem.origin_m();
    let e = dem.extent_m();
    Ok(DemStats {
        width: dem.width(),
        height: dem.height(),
        pixel_m,
        origin_x_m: x0,
        origin_y_m: y0,
        extent_m: [e.0, e.1, e.2, e.3],
        nodata_count: dem.nodata_count(),
        elev_min_m: mn,
        elev_max_m: mx,
        elev_mean_m: mean,
        elev_std_m: std,
        slope_mean_deg: s.iter().map(|&v| f64::from(v)).sum::<f64>() / ns,
        slope_p50_deg: percentile(&s, 0.5),
        slope_p90_deg: percentile(&s, 0.9),
        slope_p99_deg: percentile(&s, 0.99),
        slope_p999_deg: percentile(&s, 0.999),
        slope_max_deg: s.last().map_or(f64::NAN, |&v| f64::from(v)),
        slope_lt30_frac: frac_lt(30.0),
        slope_lt35_frac: frac_lt(35.0),
        slope_cdf_5deg: (1..=9).map(|k| frac_lt(5.0 * k as f32)).collect(),
        depressions: depression_bins(dem, pixel_m),
        main_crater: main_crater(dem, pixel_m),
    })
}

/// Minimum depth of a closed depression, in metres, for it to count (below it, roughness pits).
pub const DEPRESSION_MIN_DEPTH_M: f64 = 0.5;
/// Minimum depth/diameter of a depression to count as crater-like.
pub const DEPRESSION_MIN_D_OVER_D: f64 = 0.02;

/// Closed depressions found by priority-flood filling (Barnes et al. 2014): connected pixels
/// whose filled level exceeds the DEM, returned as `(equivalent diameter m, max depth m)`.
/// A depression touching nodata or the border is open and not counted.
pub fn depressions(dem: &Dem, pixel_m: f64) -> Vec<(f64, f64)> {
    let (w, h) = (dem.width(), dem.height());
    let z = dem.heights_m();
    let mut filled: Vec<f32> = z.to_vec();
    let mut done = vec![false; w * h];
    let mut heap: BinaryHeap<Reverse<(u32, usize)>> = BinaryHeap::new();
    // Order f32 heights through a monotone u32 key.
    let key = |v: f32| -> u32 {
        let b = v.to_bits();
        if b & 0x8000_0000 != 0 {
            !b
        } else {
            b | 0x8000_0000
        }
    };
    for i in 0..w * h {
        let (r, c) = (i / w, i % w);
        let edge = r == 0 || c == 0 || r + 1 == h || c + 1 == w;
        if edge || !z[i].is_finite() {
            done[i] = true;
            if z[i].is_finite() {
                heap.push(Reverse((key(z[i]), i)));
            } else {
                // Nodata drains like the border.
                filled[i] = f32::NEG_INFINITY;
                heap.push(Reverse((key(f32::NEG_INFINITY), i)));
            }
        }
    }
    while let Some(Reverse((_, i))) = heap.pop() {
        let (r, c) = (i / w, i % w);
        let level = filled[i];
        for (dr, dc) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (rr, cc) = (r as i64 + dr, c as i64 + dc);
            if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                continue;
            }
            let j = rr as usize * w + cc as usize;
            if done[j] {
                continue;
            }
            done[j] = true;
            filled[j] = filled[j].max(level);
            heap.push(Reverse((key(filled[j]), j)));
        }
    }
    // Connected components of filled > z.
    let mut seen = vec![false; w * h];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if seen[start] || filled[start] - z[start] <= 0.0 || z[start].is_nan() {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut area, mut depth) = (0usize, 0.0f64);
        while let Some(i) = stack.pop() {
            area += 1;
            depth = depth.max(f64::from(filled[i] - z[i]));
            let (r, c) = (i / w, i % w);
            for (dr, dc) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                    continue;
                }
                let j = rr as usize * w + cc as usize;
                if !seen[j] && filled[j] - z[j] > 0.0 {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        let d = 2.0 * (area as f64 * pixel_m * pixel_m / std::f64::consts::PI).sqrt();
        out.push((d, depth));
    }
    out
}

fn depression_bins(dem: &Dem, pixel_m: f64) -> Vec<DepressionBin> {
    let deps: Vec<(f64, f64)> = depressions(dem, pixel_m)
        .into_iter()
        .filter(|&(d, depth)| {
            depth >= DEPRESSION_MIN_DEPTH_M && depth / d >= DEPRESSION_MIN_D_OVER_D
        })
        .collect();
    let area_km2 = dem.width() as f64 * dem.height() as f64 * pixel_m * pixel_m / 1e6;
    let edges = [10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0, 1280.0, 2560.0];
    edges
        .windows(2)
        .map(|e| {
            let count = deps.iter().filter(|(d, _)| *d >= e[0] && *d < e[1]).count();
            DepressionBin {
                d_min_m: e[0],
                d_max_m: e[1],
                count,
                per_km2: count as f64 / area_km2,
            }
        })
        .collect()
}

/// Depth and diameter of the largest crater in the DEM, from its azimuthally averaged profile.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct MainCrater {
    /// Centre column (pixels).
    pub centre_col: f64,
    /// Centre row (pixels).
    pub centre_row: f64,
    /// Rim-crest diameter (twice the median crest radius), metres.
    pub diameter_m: f64,
    /// Median rim-crest height minus the floor (lowest ring mean), metres.
    pub depth_m: f64,
    /// depth / diameter.
    pub d_over_d: f64,
}

/// Find the main crater: centre at the lowest point of a box-smoothed DEM, mid-wall at the
/// steepest rise of the ring-mean profile, rim crest on rays beyond it. `None` when fewer than
/// half of the rays find a crest inside the DEM or the crater is shallower than 1 % of its radius.
pub fn main_crater(dem: &Dem, pixel_m: f64) -> Option<MainCrater> {
    let (w, h) = (dem.width(), dem.height());
    let z = dem.heights_m();
    // Box smoothing over ~5 % of the size suppresses small pits when locating the centre, which
    // is searched away from the borders (a low corner is not a crater centre).
    let k = (w.min(h) / 20).max(1) as i64;
    let mut best = (f64::INFINITY, h / 2, w / 2);
    let step = ((k / 2) as usize).max(1);
    let (mw, mh) = (w / 8, h / 8);
    for r in (mh..h - mh).step_by(step) {
        for c in (mw..w - mw).step_by(step) {
            let (mut s, mut n) = (0.0, 0);
            for rr in (r as i64 - k).max(0)..=(r as i64 + k).min(h as i64 - 1) {
                for cc in (c as i64 - k).max(0)..=(c as i64 + k).min(w as i64 - 1) {
                    let v = z[rr as usize * w + cc as usize];
                    if v.is_finite() {
                        s += f64::from(v);
                        n += 1;
                    }
                }
            }
            if n > 0 && s / (n as f64) < best.0 {
                best = (s / n as f64, r, c);
            }
        }
    }
    let (_, r0, c0) = best;
    let r_max = ((w.max(h)) as f64 * std::f64::consts::SQRT_2) as usize;
    let mut sum = vec![0.0f64; r_max + 1];
    let mut cnt = vec![0usize; r_max + 1];
    for r in 0..h {
        for c in 0..w {
            let v = z[r * w + c];
            if !v.is_finite() {
                continue;
            }
            let d = ((r as f64 - r0 as f64).powi(2) + (c as f64 - c0 as f64).powi(2)).sqrt();
            let i = d.round() as usize;
            if i <= r_max {
                sum[i] += f64::from(v);
                cnt[i] += 1;
            }
        }
    }
    // Rings mostly inside the DEM: count ≥ 75 % of the ring's circumference in pixels.
    let mut prof = Vec::new();
    for i in 0..=r_max {
        let full = (std::f64::consts::TAU * i as f64).max(1.0);
        if (cnt[i] as f64) < 0.75 * full {
            break;
        }
        prof.push(sum[i] / cnt[i] as f64);
    }
    let zmin = prof.iter().copied().fold(f64::INFINITY, f64::min);
    // Mid-wall: the steepest rise of the mean profile. Then, along 72 rays, the rim crest is the
    // first local maximum beyond it (the global maximum would pick regional highs outside the
    // rim: Shackleton sits on a ridge). Diameter and rim height are medians over the rays.
    let i_wall = (1..prof.len())
        .max_by(|&a, &b| (prof[a] - prof[a - 1]).total_cmp(&(prof[b] - prof[b - 1])))?;
    let r_wall = i_wall as f64;
    let k = (r_wall / 10.0).max(2.0);
    let at = |x: f64, y: f64| -> Option<f64> {
        if x < 0.0 || y < 0.0 || x > (w - 1) as f64 || y > (h - 1) as f64 {
            return None;
        }
        let (c, r) = (x.floor() as usize, y.floor() as usize);
        let (c1, r1) = ((c + 1).min(w - 1), (r + 1).min(h - 1));
        let (tx, ty) = (x - c as f64, y - r as f64);
        let g = |cc: usize, rr: usize| f64::from(z[rr * w + cc]);
        let v = (1.0 - ty) * ((1.0 - tx) * g(c, r) + tx * g(c1, r))
            + ty * ((1.0 - tx) * g(c, r1) + tx * g(c1, r1));
        v.is_finite().then_some(v)
    };
    let mut radii = Vec::new();
    let mut rims = Vec::new();
    const RAYS: usize = 72;
    for a in 0..RAYS {
        let th = std::f64::consts::TAU * a as f64 / RAYS as f64;
        let ray: Vec<f64> = (0..)
            .map(|i| r_wall + 0.5 * i as f64)
            .take_while(|&r| r <= 3.0 * r_wall)
            .map_while(|r| at(c0 as f64 + r * th.cos(), r0 as f64 + r * th.sin()))
            .collect();
        let kk = (2.0 * k) as usize;
        let crest = (kk..ray.len().saturating_sub(kk))
            .find(|&i| (i - kk..=i + kk).all(|j| ray[j] <= ray[i]));
        if let Some(i) = crest {
            radii.push(r_wall + 0.5 * i as f64);
            rims.push(ray[i]);
        }
    }
    if radii.len() < RAYS / 2 {
        return None;
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let imax = median(&mut radii);
    let zmax = median(&mut rims);
    let diameter_m = 2.0 * imax * pixel_m;
    let depth_m = zmax - zmin;
    if depth_m < 0.01 * diameter_m / 2.0 {
        return None;
    }
    Some(MainCrater {
        centre_col: c0 as f64,
        centre_row: r0 as f64,
        diameter_m,
        depth_m,
        d_over_d: depth_m / diameter_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dem::GeoRef;

    #[test]
    fn plane_slope_matches_closed_form_and_depression_found() {
        // A 20° plane, plus a 2 m deep pit of radius 5 px.
        let (w, h, px) = (64usize, 64usize, 5.0f64);
        let t = 20f64.to_radians().tan();
        let mut z = Vec::new();
        for _row in 0..h {
            for c in 0..w {
                z.push((c as f64 * px * t) as f32);
            }
        }
        let dem = Dem::new(w, h, z.clone(), GeoRef::local(0.0, 0.0, px, "t")).unwrap();
        let s = slope_deg(&dem).unwrap();
        assert!(s[0].is_nan());
        assert!((s[w + 1] - 20.0).abs() < 0.01);
        let st = dem_stats(&dem).unwrap();
        assert_eq!(st.slope_lt30_frac, 1.0);
        assert!(st.slope_cdf_5deg[3] == 0.0 && st.slope_cdf_5deg[4] == 1.0);

        let mut flat = vec![0.0f32; w * h];
        for r in 0..h {
            for c in 0..w {
                let d2 = (r as f64 - 30.0).powi(2) + (c as f64 - 30.0).powi(2);
                if d2 < 25.0 {
                    flat[r * w + c] = -2.0 * (1.0 - d2 / 25.0) as f32;
                }
            }
        }
        let dem = Dem::new(w, h, flat, GeoRef::local(0.0, 0.0, px, "t")).unwrap();
        let d = depressions(&dem, px);
        assert_eq!(d.len(), 1);
        assert!(
            (d[0].0 - 50.0).abs() < 6.0 && (d[0].1 - 2.0).abs() < 1e-6,
            "{d:?}"
        );
    }
}

/// Flagged cells of a `w × h` grid (row-major) counted over any rectangle in O(1): a
/// summed-area table. Shared by the DEM filter's footprints and the one-look windows.
#[derive(Debug, Clone)]
pub struct CellCounts {
    /// `table[r·(w+1) + c]` = flagged cells in rows `< r`, columns `< c`.
    table: Vec<u32>,
    w: usize,
    h: usize,
}

impl CellCounts {
    /// Count the cells `i` (row-major index) for which `flag(i)` holds.
    pub fn new(w: usize, h: usize, flag: impl Fn(usize) -> bool) -> Self {
        let mut table = vec![0u32; (w + 1) * (h + 1)];
        for r in 0..h {
            let mut run = 0u32;
            for c in 0..w {
                run += u32::from(flag(r * w + c));
                table[(r + 1) * (w + 1) + c + 1] = table[r * (w + 1) + c + 1] + run;
            }
        }
        Self { table, w, h }
    }

    /// Flagged cells in rows `r0..r1`, columns `c0..c1` (clipped to the grid).
    pub fn count(&self, r0: usize, c0: usize, r1: usize, c1: usize) -> usize {
        let (r1, c1) = (r1.min(self.h), c1.min(self.w));
        if r0 >= r1 || c0 >= c1 {
            return 0;
        }
        let at = |r: usize, c: usize| i64::from(self.table[r * (self.w + 1) + c]);
        (at(r1, c1) - at(r0, c1) - at(r1, c0) + at(r0, c0)) as usize
    }
}

#[cfg(test)]
mod cell_count_tests {
    use super::CellCounts;

    #[test]
    fn rectangles_count_what_a_loop_counts() {
        let (w, h) = (7, 5);
        let flag = |i: usize| (i * 13) % 5 < 2;
        let t = CellCounts::new(w, h, flag);
        for (r0, c0, r1, c1) in [(0, 0, 5, 7), (1, 2, 4, 6), (3, 3, 3, 6), (2, 5, 9, 9)] {
            let mut n = 0;
            for r in r0..r1.min(h) {
                for c in c0..c1.min(w) {
                    n += usize::from(flag(r * w + c));
                }
            }
            assert_eq!(t.count(r0, c0, r1, c1), n, "{r0} {c0} {r1} {c1}");
        }
    }
}
