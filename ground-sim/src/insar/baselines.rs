//! A second, longer baseline fused into the map (`insar --long-baseline-m B`).
//!
//! Why: the height noise of an interferogram scales with its height of ambiguity, so a boom four
//! times longer gives heights four times less noisy where the ground stays coherent, which is
//! what gentle ground lacks most (its relief is as small as the 32 m boom's noise: the seed-2
//! plains fix on 19 % of frames lost in space). But a long baseline decorrelates on slopes and
//! packs its cycles four times closer, so alone it loses steep ground (docs/insar.md, "The boom
//! re-measured on the whole suite"). Flown together, the short interferogram decides, and the
//! long one refines:
//!
//! - the long pair's whole cycles are chosen against the short pair's map ([`super::cycles`]
//!   with that map as the prior, the coarse prior where it has no height);
//! - per cell, the long height replaces the short one only where both are valid, the long one
//!   claims the smaller bound, their difference is within [`BASELINE_CONSISTENCY_SIGMAS`]
//!   combined bounds, and that tolerance is below half the long pair's height of ambiguity (so
//!   a wrong cycle cannot pass); everywhere else the short map stays as it was.
//!
//! The cell takes the long height and its own bound (with the chain's noise-free error added,
//! [`long_bound_m`]) rather than a weighted mean of the two: the
//! pairs share antenna A1 (its receiver noise and its speckle), so their errors are correlated
//! and a mean that assumed them independent would claim too small a bound.
//!
//! The simulation flies the long pair over the same ground with the same radar seed (the same
//! speckle; A2 sits at the long baseline along the same tilt) and draws the receiver noise of
//! both its antennas anew: a second satellite in formation, as TanDEM-X flies. A third antenna
//! on the boom would share A1's noise with the short pair, which makes the two errors more
//! alike and the consistency check a little weaker; not modelled. Its SAR time is reported with
//! the run's.

use serde::{Deserialize, Serialize};

use super::geocode::label;
use super::pipeline::{
    FUSE_MIN_BOUND_M, InsarConfig, InsarProduct, MaskFractions, cycle_height_m, process_stack,
};
use crate::sar::{SarConfig, Slc};

/// Combined bounds within which the long pair's height must agree with the short pair's to
/// replace it. The short map's error runs up to 1.4–1.5× its bound on the dense floors
/// (docs/insar.md), so four bounds keep nearly every good cell, while a wrong cycle of the
/// long pair (46 m at 128 m) is far outside wherever the check is allowed to decide.
pub const BASELINE_CONSISTENCY_SIGMAS: f64 = 4.0;

/// How the long baseline entered a map ([`fuse_baselines`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BaselineFusion {
    /// The long baseline, m.
    pub long_baseline_m: f64,
    /// Its height of ambiguity at the scene centre, m.
    pub long_ambiguity_height_m: f64,
    /// Mask fractions of the long pair's own map.
    pub long_mask: MaskFractions,
    /// Share of the map's valid cells whose height is now the long pair's.
    pub long_share: f64,
    /// Share of the valid cells where both were valid and disagreed (the short kept).
    pub inconsistent: f64,
    /// Share of the valid cells where both were valid but the check could not rule out a
    /// wrong cycle of the long pair (the short kept).
    pub unverifiable: f64,
    /// Median bound of the cells taken from the long pair ([`long_bound_m`]), m, and of the
    /// same cells before; `None` when it gave no cell.
    pub median_bound_m: Option<[f64; 2]>,
    /// σ, output pixels, of the long pair's DEM filter ([`long_config`]); `None` in records
    /// written before it was recorded (the short pair's then).
    #[serde(default)]
    pub long_filter_sigma_px: Option<f64>,
    /// The long pair's [`InsarProduct::crlb_filter_factor`] (no unit, 0–1: the DEM filter's
    /// shrinking of the height noise's σ); `None` as above.
    #[serde(default)]
    pub long_crlb_filter_factor: Option<f64>,
}

/// The short map as the long pair's cycle prior: its heights where it has them, `coarse`
/// (the usual coarse prior, on the same grid) elsewhere.
pub fn cycle_prior_heights(short: &InsarProduct, coarse: Option<&[f32]>) -> Vec<f32> {
    let h = short.dem.heights_m();
    h.iter()
        .enumerate()
        .map(|(i, &v)| {
            if v.is_finite() {
                v
            } else {
                coarse.and_then(|c| c.get(i).copied()).unwrap_or(f32::NAN)
            }
        })
        .collect()
}

/// Process the long pair's passes (`(A1, A2)` per pass, [`process_stack`]) onto `short`'s grid
/// with `short`'s map as the cycle prior (`coarse` where it has no height), then fuse it in
/// ([`fuse_baselines`]).
pub fn add_long_baseline(
    short: &mut InsarProduct,
    long_pairs: &[(&Slc, &Slc)],
    coarse: Option<&[f32]>,
    cfg: &InsarConfig,
) -> anyhow::Result<BaselineFusion> {
    let prior = cycle_prior_heights(short, coarse);
    let grid = short.grid.clone();
    let long = process_stack(long_pairs, &grid, &long_config(cfg), Some(&prior))?;
    fuse_baselines(short, &long, cfg.long_baseline_m)
}

/// How the long pair is processed: as the short one, with its own width of the Gaussian mean
/// when [`InsarConfig::long_filter_sigma_px`] gives one (the quadratic fit keeps its own).
///
/// Why an option: the mean that halves the 32 m pair's noise flattens relief by `σ²/2·∇²h`,
/// and the long pair's noise is four times smaller, so on gentle cratered ground a narrower
/// mean makes a better DEM (at 0.5 px the dense floors' height RMSE −3 to −12 %, within 1.3×
/// the bound); but the tiles made from such maps navigate worse, so the default keeps the
/// short pair's width (docs/insar.md, "The error at the chain's own resolution, and the long
/// pair's filter").
pub fn long_config(cfg: &InsarConfig) -> InsarConfig {
    let mut long = *cfg;
    if let Some(s) = cfg.long_filter_sigma_px
        && cfg.dem_filter == super::demfilter::DemFilterKind::Gaussian
    {
        long.dem_filter_sigma_px = s;
    }
    long
}

/// Gaussian-equivalent σ, metres, of a map made with `cfg` whose looks took the long pair's
/// heights as `fusion` says ([`InsarConfig::inherent_smoothing_m`] per pair, the variances
/// mixed by the share of cells each gave, averaged over the looks). `cfg`'s own without a
/// long baseline, or where a record does not say its filter.
pub fn mixed_inherent_smoothing_m(cfg: &InsarConfig, fusion: &[BaselineFusion]) -> f64 {
    let short = cfg.inherent_smoothing_m();
    let mixed: Vec<f64> = fusion
        .iter()
        .map(|f| match f.long_filter_sigma_px {
            // One width: the short pair's, exactly (no mixing round-off).
            Some(s) if s != cfg.dem_filter_sigma_px => {
                let long = InsarConfig {
                    dem_filter_sigma_px: s,
                    ..*cfg
                }
                .inherent_smoothing_m();
                let share = f.long_share.clamp(0.0, 1.0);
                (1.0 - share) * short * short + share * long * long
            }
            _ => short * short,
        })
        .filter(|v| v.is_finite())
        .collect();
    if mixed.is_empty() {
        short
    } else {
        (mixed.iter().sum::<f64>() / mixed.len() as f64).sqrt()
    }
}

/// The radar of the long pair: `sar` with A2 at `long_baseline_m` (same tilt).
pub fn long_radar(sar: &SarConfig, long_baseline_m: f64) -> SarConfig {
    SarConfig {
        baseline_m: long_baseline_m,
        ..sar.clone()
    }
}

/// Receiver-noise seed of pass `k` of the long pair whose short pair's noise seed is `seed`:
/// its own receivers, independent of the short pair's; the ground (speckle) is the same.
pub fn long_noise_seed(seed: u64, k: usize) -> u64 {
    crate::sar::scattering::splitmix64(
        seed ^ LONG_SALT ^ crate::sar::scattering::splitmix64(k as u64),
    )
}

/// Salt of [`long_noise_seed`] ("long" in ASCII).
const LONG_SALT: u64 = 0x6c6f_6e67;

/// Bound, m, a cell taken from the long pair carries: its CRLB `crlb_m` with the chain's
/// noise-free error ([`FUSE_MIN_BOUND_M`]) added in quadrature. (The choice compares the raw
/// CRLBs, the same order as with the floor on both; the short cells keep theirs without it.)
///
/// Why: the CRLB holds the receiver noise and the surface's decorrelation, not the error the
/// chain makes without them (window resolution, speckle centroids, the relief the window
/// averages; 0.59 m on a tilted plane). Under the 32 m pair's bound (0.9–1 m on gentle ground)
/// that floor is a small share, and the tiles' reference error was calibrated with it left
/// out; the 128 m pair's CRLB (0.35–0.5 m) is below it, so left out it would make the map
/// claim less than half its error (the 16 km plains: 0.58 m RMSE against 0.36 m, and descents
/// whose NEES left the 95 % band on 13–22 % of frames; docs/insar.md).
pub fn long_bound_m(crlb_m: f32) -> f32 {
    (f64::from(crlb_m).hypot(FUSE_MIN_BOUND_M)) as f32
}

/// What one cell of the map keeps ([`choose`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Choice {
    /// The long pair's height and bound.
    Long,
    /// The short pair's: the long one is missing or not better.
    Short,
    /// The short pair's: the two differ by more than [`BASELINE_CONSISTENCY_SIGMAS`] bounds.
    Inconsistent,
    /// The short pair's: the tolerance reaches half a cycle of the long pair, so a wrong
    /// cycle could pass.
    Unverifiable,
}

/// The choice for one cell valid in the short map, `(height m, bound m)`, given the long
/// pair's `(height, bound)` if valid and its height of ambiguity `cycle_m` there (bounds below
/// [`FUSE_MIN_BOUND_M`] count as that).
pub fn choose(short: (f32, f32), long: Option<(f32, f32)>, cycle_m: f64) -> Choice {
    let Some((hl, sl)) = long else {
        return Choice::Short;
    };
    let (hs, ss) = short;
    let floor = |s: f32| f64::from(s).max(FUSE_MIN_BOUND_M);
    let tol = BASELINE_CONSISTENCY_SIGMAS * floor(ss).hypot(floor(sl));
    if !(tol < 0.5 * cycle_m) {
        Choice::Unverifiable
    } else if !((f64::from(hl) - f64::from(hs)).abs() <= tol) {
        Choice::Inconsistent
    } else if sl < ss {
        Choice::Long
    } else {
        Choice::Short
    }
}

/// Replace `short`'s heights by `long`'s where the long pair measures the same ground better
/// (module docs), in place (DEM, coherence and bound; labels and mask unchanged). `long` must
/// be on the same grid.
pub fn fuse_baselines(
    short: &mut InsarProduct,
    long: &InsarProduct,
    long_baseline_m: f64,
) -> anyhow::Result<BaselineFusion> {
    let n = short.labels.len();
    let w = short.grid.width;
    anyhow::ensure!(
        long.labels.len() == n && long.grid.width == w && long.grid.height == short.grid.height,
        "the two baselines' grids differ"
    );
    let mut dem = short.dem.heights_m().to_vec();
    let mut coh = short.coherence.heights_m().to_vec();
    let mut sig = short.crlb_m.heights_m().to_vec();
    let (ld, lc, ls) = (
        long.dem.heights_m(),
        long.coherence.heights_m(),
        long.crlb_m.heights_m(),
    );
    let (mut valid, mut taken, mut inconsistent, mut unverifiable) = (0usize, 0, 0, 0);
    let (mut before, mut after) = (Vec::new(), Vec::new());
    // Σ bound² and Σ (bound / its map's filter factor)² over the valid cells, for the fused
    // map's effective factor.
    let (fs, fl) = (short.crlb_filter_factor, long.crlb_filter_factor);
    let (mut bound2, mut white2) = (0.0f64, 0.0f64);
    for i in 0..n {
        let sv = short.labels[i] == label::VALID && dem[i].is_finite() && sig[i].is_finite();
        if !sv {
            continue;
        }
        valid += 1;
        let lv = long.labels[i] == label::VALID && ld[i].is_finite() && ls[i].is_finite();
        let cycle_m = cycle_height_m(long, i % w.max(1));
        let choice = choose((dem[i], sig[i]), lv.then_some((ld[i], ls[i])), cycle_m);
        let f = if choice == Choice::Long { fl } else { fs };
        match choice {
            Choice::Long => {
                taken += 1;
                let bound = long_bound_m(ls[i]);
                before.push(f64::from(sig[i]));
                after.push(f64::from(bound));
                dem[i] = ld[i];
                coh[i] = lc[i];
                sig[i] = bound;
            }
            Choice::Inconsistent => inconsistent += 1,
            Choice::Unverifiable => unverifiable += 1,
            Choice::Short => {}
        }
        let b = f64::from(sig[i]);
        bound2 += b * b;
        white2 += (b / f).powi(2);
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    short.dem = short.grid.raster(dem)?;
    short.coherence = short.grid.raster(coh)?;
    short.crlb_m = short.grid.raster(sig)?;
    // Undoing the filter must undo each cell's own (`products::white_noise_m`, the
    // rehearsal's draw): with another width for the long pair, the factor that maps the fused
    // bounds' power to their white power. (Under one width the two factors differ only by the
    // pairs' geometry, ~1e-5, and the short one's stays.)
    let effective = (bound2 / white2).sqrt();
    if long.config.dem_filter_sigma_px != short.config.dem_filter_sigma_px
        && effective.is_finite()
        && effective > 0.0
    {
        short.crlb_filter_factor = effective;
    }
    short.seconds += long.seconds;
    let share = |k: usize| k as f64 / valid.max(1) as f64;
    let fusion = BaselineFusion {
        long_baseline_m,
        long_ambiguity_height_m: long.unwrap.ambiguity_height_m,
        long_mask: MaskFractions::of(&long.labels),
        long_share: share(taken),
        inconsistent: share(inconsistent),
        unverifiable: share(unverifiable),
        median_bound_m: median(after).zip(median(before)).map(|(a, b)| [a, b]),
        long_filter_sigma_px: Some(long.config.dem_filter_sigma_px),
        long_crlb_filter_factor: Some(long.crlb_filter_factor),
    };
    short.baseline_fusion.push(fusion);
    Ok(fusion)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A long height replaces the short one only when it agrees, is better and its cycle is
    /// checked; a wrong cycle never passes.
    #[test]
    fn the_long_height_is_taken_only_where_it_is_checked_and_better() {
        let cycle = 46.0;
        // Agrees within 4 bounds and is better.
        assert_eq!(choose((10.0, 1.0), Some((10.8, 0.3)), cycle), Choice::Long);
        // Missing, or not better.
        assert_eq!(choose((10.0, 1.0), None, cycle), Choice::Short);
        assert_eq!(choose((10.0, 0.6), Some((10.2, 0.9)), cycle), Choice::Short);
        // One cycle off, or a few bounds too far.
        assert_eq!(
            choose((10.0, 1.0), Some((10.0 + 46.0, 0.3)), cycle),
            Choice::Inconsistent
        );
        assert_eq!(
            choose((10.0, 1.0), Some((15.0, 0.3)), cycle),
            Choice::Inconsistent
        );
        // Where the short bound allows half a cycle, a wrong cycle could pass: not taken,
        // even when the heights agree.
        assert_eq!(
            choose((10.0, 6.0), Some((10.5, 0.3)), cycle),
            Choice::Unverifiable
        );
        assert_eq!(
            choose((10.0, 6.0), Some((10.0 - 46.0, 0.3)), cycle),
            Choice::Unverifiable
        );
        // Non-finite inputs never take the long height.
        assert_ne!(
            choose((10.0, 1.0), Some((f32::NAN, 0.3)), cycle),
            Choice::Long
        );
        assert_ne!(
            choose((10.0, 1.0), Some((10.0, 0.3)), f64::NAN),
            Choice::Long
        );
    }
}

#[cfg(test)]
mod filter_tests {
    use super::*;
    use crate::insar::demfilter::DemFilterKind;

    fn fusion(share: f64, sigma: Option<f64>) -> BaselineFusion {
        BaselineFusion {
            long_baseline_m: 128.0,
            long_ambiguity_height_m: 46.0,
            long_mask: MaskFractions::default(),
            long_share: share,
            inconsistent: 0.0,
            unverifiable: 0.0,
            median_bound_m: None,
            long_filter_sigma_px: sigma,
            long_crlb_filter_factor: None,
        }
    }

    /// The long pair takes its own width of the Gaussian mean when given one, the short
    /// pair's otherwise; the quadratic fit keeps its own.
    #[test]
    fn the_long_pair_has_its_own_filter_width() {
        let same = InsarConfig {
            long_baseline_m: 128.0,
            ..InsarConfig::default()
        };
        assert_eq!(long_config(&same), same);
        let cfg = InsarConfig {
            long_filter_sigma_px: Some(0.5),
            ..same
        };
        assert!(cfg.validate().is_ok());
        assert_eq!(long_config(&cfg).dem_filter_sigma_px, 0.5);
        assert_eq!(long_config(&cfg).filter().kind, DemFilterKind::Gaussian);
        let quadratic = InsarConfig {
            dem_filter: DemFilterKind::Quadratic,
            dem_filter_sigma_px: 2.0,
            ..cfg
        };
        assert_eq!(long_config(&quadratic).dem_filter_sigma_px, 2.0);
        // Asked where it would do nothing (no long pair, or the quadratic fit): refused.
        assert!(quadratic.validate().is_err());
        let alone = InsarConfig {
            long_baseline_m: 0.0,
            ..cfg
        };
        assert!(alone.validate().is_err());
        // A width outside the filter's range is refused like the short pair's.
        let bad = InsarConfig {
            long_filter_sigma_px: Some(0.05),
            ..cfg
        };
        assert!(bad.validate().is_err());
    }

    /// The map's blur mixes the two pairs' variances by their shares of the cells.
    #[test]
    fn the_blur_of_a_map_mixes_the_pairs_by_their_cells() {
        let cfg = InsarConfig::default();
        // Window (40² − 20²)/12 = 100 m² plus the 1 px (20 m) mean's 400 m².
        let short = 500f64.sqrt();
        assert!((cfg.inherent_smoothing_m() - short).abs() < 1e-9);
        assert_eq!(mixed_inherent_smoothing_m(&cfg, &[]), short);
        // All cells long at 0.5 px: 100 + 100 m².
        let all = mixed_inherent_smoothing_m(&cfg, &[fusion(1.0, Some(0.5))]);
        assert!((all - 200f64.sqrt()).abs() < 1e-9, "{all}");
        // Half the cells, and two looks averaged.
        let half = mixed_inherent_smoothing_m(&cfg, &[fusion(0.5, Some(0.5))]);
        assert!((half - 350f64.sqrt()).abs() < 1e-9, "{half}");
        let looks = mixed_inherent_smoothing_m(&cfg, &[fusion(1.0, Some(0.5)), fusion(0.0, None)]);
        assert!((looks - 350f64.sqrt()).abs() < 1e-9, "{looks}");
        // A record that does not say its filter counts as the short pair's.
        assert!((mixed_inherent_smoothing_m(&cfg, &[fusion(1.0, None)]) - short).abs() < 1e-9);
    }
}

#[cfg(test)]
mod report_tests {
    use super::*;

    /// A block whose long pair gave no cell has no median bound, and its record reads back
    /// (a NaN would be written as `null` and refused on reading the block back).
    #[test]
    fn a_fusion_without_long_cells_reads_back() {
        let f = BaselineFusion {
            long_baseline_m: 128.0,
            long_ambiguity_height_m: 46.0,
            long_mask: MaskFractions::default(),
            long_share: 0.0,
            inconsistent: 0.0,
            unverifiable: 1.0,
            median_bound_m: None,
            long_filter_sigma_px: Some(0.5),
            long_crlb_filter_factor: Some(0.8),
        };
        let text = serde_json::to_string(&f).unwrap();
        let back: BaselineFusion = serde_json::from_str(&text).unwrap();
        assert_eq!(back, f);
    }
}
