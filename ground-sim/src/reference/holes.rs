//! Small holes in a reference DEM, filled before the tile is built.
//!
//! An InSAR DEM loses scattered cells to its masks (layover, shadow, low coherence). Nav-core's
//! slope needs all nine heights of Horn's operator, so every missing height removes a 3 × 3
//! block of slope, and SURF refuses a keypoint whose descriptor window meets a missing slope:
//! 16 % of scattered missing heights on the Shackleton wall left 60 % of the tile's slope
//! missing and no feature at all. The tile smooths the terrain by a Gaussian of σ anyway
//! (`Smoothing::target_m`), so a hole whose every cell lies within σ of valid heights holds no
//! detail the tile could keep: such holes are filled from their rims. Larger holes, and holes
//! that touch the map's edge (where a fill would extrapolate), stay missing.

use anyhow::Result;

use crate::dem::Dem;

/// What [`fill_small_holes`] did, in cells of the DEM.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct HoleFill {
    /// Missing cells before the fill.
    pub missing_cells: usize,
    /// Of them, cells filled.
    pub filled_cells: usize,
}

/// Fill every hole (8-connected missing cells) of `dem` whose cells all lie within `radius_m`
/// metres of a valid cell (Euclidean, cell centre to cell centre) and that does not touch the
/// grid's edge. A filled cell takes the mean of its valid or already filled 8-neighbours, ring
/// by ring from the hole's rim inwards (deterministic: each ring reads only earlier rings).
/// `radius_m` ≤ 0 fills nothing. Returns the filled DEM and the counts.
pub fn fill_small_holes(dem: &Dem, radius_m: f64) -> Result<(Dem, HoleFill)> {
    let (w, h) = (dem.width(), dem.height());
    let z = dem.heights_m();
    let missing: Vec<bool> = z.iter().map(|v| !v.is_finite()).collect();
    let mut stats = HoleFill {
        missing_cells: missing.iter().filter(|&&m| m).count(),
        filled_cells: 0,
    };
    if !(radius_m.is_finite() && radius_m > 0.0) || stats.missing_cells == 0 {
        return Ok((dem.clone(), stats));
    }
    let r_px = radius_m / dem.pixel_m()?;
    let reach = r_px.floor() as isize;
    let r2 = r_px * r_px;
    let (wi, hi) = (w as isize, h as isize);
    let valid_at = |c: isize, r: isize| {
        c >= 0 && r >= 0 && c < wi && r < hi && !missing[(r * wi + c) as usize]
    };
    // Within reach of valid data: some valid cell inside the disc of radius r_px.
    let near_valid = |c: isize, r: isize| {
        (-reach..=reach).any(|dy| {
            (-reach..=reach)
                .any(|dx| ((dx * dx + dy * dy) as f64) <= r2 && valid_at(c + dx, r + dy))
        })
    };
    // Label holes and keep those that qualify.
    let mut fill = vec![false; w * h];
    let mut seen = vec![false; w * h];
    let mut stack = Vec::new();
    let mut cells = Vec::new();
    for start in 0..w * h {
        if !missing[start] || seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        cells.clear();
        let mut ok = true;
        while let Some(i) = stack.pop() {
            cells.push(i);
            let (c, r) = ((i % w) as isize, (i / w) as isize);
            if c == 0 || r == 0 || c + 1 == wi || r + 1 == hi || !near_valid(c, r) {
                ok = false;
            }
            for dy in -1..=1isize {
                for dx in -1..=1isize {
                    let (cc, rr) = (c + dx, r + dy);
                    if cc < 0 || rr < 0 || cc >= wi || rr >= hi {
                        continue;
                    }
                    let j = (rr * wi + cc) as usize;
                    if missing[j] && !seen[j] {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        if ok {
            for &i in &cells {
                fill[i] = true;
            }
        }
    }
    // Ring by ring: every cell to fill that touches known heights takes their mean.
    let mut out = z.to_vec();
    let mut known: Vec<bool> = missing.iter().map(|&m| !m).collect();
    let mut todo: Vec<usize> = (0..w * h).filter(|&i| fill[i]).collect();
    let mut ring = Vec::new();
    while !todo.is_empty() {
        ring.clear();
        for &i in &todo {
            let (c, r) = ((i % w) as isize, (i / w) as isize);
            let (mut sum, mut n) = (0.0f64, 0usize);
            for dy in -1..=1isize {
                for dx in -1..=1isize {
                    let (cc, rr) = (c + dx, r + dy);
                    if (dx, dy) == (0, 0) || cc < 0 || rr < 0 || cc >= wi || rr >= hi {
                        continue;
                    }
                    let j = (rr * wi + cc) as usize;
                    if known[j] {
                        sum += f64::from(out[j]);
                        n += 1;
                    }
                }
            }
            if n > 0 {
                ring.push((i, (sum / n as f64) as f32));
            }
        }
        if ring.is_empty() {
            // Cannot happen for a hole with valid cells in reach; stop rather than spin.
            break;
        }
        for &(i, v) in &ring {
            out[i] = v;
            known[i] = true;
        }
        stats.filled_cells += ring.len();
        todo.retain(|&i| !known[i]);
    }
    let mut filled = Dem::new(w, h, out, dem.geo.clone())?;
    filled.nodata = dem.nodata;
    filled.sample = dem.sample;
    Ok((filled, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dem::GeoRef;

    fn plane(w: usize, h: usize) -> Dem {
        let z = (0..w * h)
            .map(|i| (3.0 * (i % w) as f64 + 2.0 * (i / w) as f64) as f32)
            .collect();
        Dem::new(w, h, z, GeoRef::local(0.0, 0.0, 20.0, "test")).unwrap()
    }

    #[test]
    fn small_inner_holes_are_filled_and_large_or_edge_holes_are_not() {
        let mut d = plane(40, 30);
        let w = d.width();
        let z = d.heights_m_mut();
        // A 3 × 3 hole (every cell within 40 m of valid data), a 9 × 9 hole (centre 100 m from
        // valid data) and a single cell on the edge.
        for r in 5..8 {
            for c in 5..8 {
                z[r * w + c] = f32::NAN;
            }
        }
        for r in 12..21 {
            for c in 20..29 {
                z[r * w + c] = f32::NAN;
            }
        }
        z[10 * w] = f32::NAN;
        let (f, s) = fill_small_holes(&d, 50.0).unwrap();
        assert_eq!(s.missing_cells, 9 + 81 + 1);
        assert_eq!(s.filled_cells, 9);
        // The small hole: filled, within one cell's rise of the plane (3.6 m here): a rim cell
        // takes the mean of its known neighbours, which on a slope sit on one side of it.
        for r in 5..8 {
            for c in 5..8 {
                let v = f.get(c, r).expect("filled");
                let truth = 3.0 * c as f32 + 2.0 * r as f32;
                assert!((v - truth).abs() < 3.7, "({c}, {r}): {v} vs {truth}");
            }
        }
        assert!(f.get(24, 16).is_none(), "the large hole stays");
        assert!(
            f.get(20, 12).is_none(),
            "a large hole stays whole, rim included"
        );
        assert!(f.get(0, 10).is_none(), "an edge hole stays");
        // Valid heights are untouched, bit for bit.
        let untouched = f
            .heights_m()
            .iter()
            .zip(d.heights_m())
            .filter(|(_, b)| b.is_finite())
            .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(untouched);
        // No radius, no fill.
        let (_, none) = fill_small_holes(&d, 0.0).unwrap();
        assert_eq!(none.filled_cells, 0);
    }

    /// Scattered lost cells no longer empty a tile when it is asked to fill them: the builder
    /// keeps most of the hole-free tile's features, while the folder's DEM and the tile's slope
    /// raster keep the holes missing. Without the option the holes cost most features.
    #[test]
    fn scattered_holes_keep_the_tiles_features() {
        use crate::reference::noise_floor::FrameNoise;
        use crate::reference::{
            DEM_FILE, INSAR_SMOOTHING_M, Smoothing, TILE_FILE, reference_dem, surf_config_for,
            write_reference,
        };
        use crate::terrain::{Preset, TerrainParams, generate};
        let mut p = TerrainParams::new(Preset::Shoemaker);
        p.size_m = 2000.0;
        p.seed = 4;
        let (dem, _) = generate(&p, &indicatif::ProgressBar::hidden()).unwrap();
        let clean = reference_dem(&dem, 20.0).unwrap();
        let mut holed = clean.clone();
        // 12 % of the cells lost, one by one, at places a fixed LCG picks.
        let n = holed.heights_m().len();
        let mut x = 12345u64;
        let mut lost = 0;
        while lost < n * 12 / 100 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let i = (x >> 33) as usize % n;
            if holed.heights_m()[i].is_finite() {
                holed.heights_m_mut()[i] = f32::NAN;
                lost += 1;
            }
        }
        let surf = surf_config_for(&FrameNoise::default_sensor(), 20.0, INSAR_SMOOTHING_M).unwrap();
        let smoothing = Smoothing {
            target_m: INSAR_SMOOTHING_M,
            fill_holes: true,
            ..Smoothing::default_for_truth()
        };
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let full = write_reference(&clean, a.path(), &surf, 8192, smoothing).unwrap();
        let s = write_reference(&holed, b.path(), &surf, 8192, smoothing).unwrap();
        eprintln!(
            "hole-free {} features; 12 % lost: {} features, {} of {} cells filled",
            full.features, s.features, s.holes.filled_cells, s.holes.missing_cells
        );
        assert!(full.features >= 30, "too few features to test with");
        assert_eq!(s.holes.missing_cells, lost);
        // Only cells on the map's edge may stay missing.
        assert!(s.holes.filled_cells + 4 * 100 >= lost);
        assert!(
            10 * s.features >= 6 * full.features,
            "{} of {} features kept",
            s.features,
            full.features
        );
        let written = crate::dem::read_geotiff(&b.path().join(DEM_FILE)).unwrap();
        let missing = |d: &Dem| d.heights_m().iter().filter(|v| !v.is_finite()).count();
        assert_eq!(missing(&written), lost, "the folder's DEM keeps its holes");
        let bytes = std::fs::read(b.path().join(TILE_FILE)).unwrap();
        let tile = nav_core::Tile::parse(&bytes).unwrap();
        let raster = tile.slope_raster().unwrap();
        let nodata = (0..raster.height())
            .flat_map(|r| (0..raster.width()).map(move |c| (c, r)))
            .filter(|&(c, r)| !nav_core::frame::slope_is_valid(raster.get(c, r)))
            .count();
        assert!(
            nodata > lost,
            "the raster keeps the holes: {nodata} no-data pixels"
        );
        // Without the option the same holes cost most of the features.
        let c = tempfile::tempdir().unwrap();
        let plain = Smoothing {
            fill_holes: false,
            ..smoothing
        };
        let unfilled = write_reference(&holed, c.path(), &surf, 8192, plain).unwrap();
        eprintln!("without the fill: {} features", unfilled.features);
        assert_eq!(unfilled.holes.filled_cells, 0);
        assert!(unfilled.features < s.features);
    }
}
