//! Exhaustive SSD matching of frame features against tile features (the paper's method), gated
//! by the Laplacian sign, with a distance threshold, Lowe's ratio test and an optional mutual
//! check. The match list is bounded.

use crate::describe::DESCRIPTOR_LEN;
use crate::surf::Feature;
use crate::tile::Tile;

/// Matching settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MatchConfig {
    /// Largest accepted sum of squared differences between unit descriptors (range 0–4).
    pub max_ssd: f32,
    /// Lowe's ratio on distances: best distance < `ratio` × second-best distance (SSD compared
    /// against `ratio²`). 1 disables the test.
    pub ratio: f32,
    /// Keep a match only if the frame feature is also the tile feature's best match.
    pub mutual: bool,
}

impl Default for MatchConfig {
    fn default() -> Self {
        Self {
            max_ssd: 0.8,
            ratio: 0.9,
            mutual: true,
        }
    }
}

/// One putative correspondence.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Match {
    /// Index into the frame's features.
    pub frame: u16,
    /// Index into the tile's features.
    pub tile: u16,
    /// Sum of squared descriptor differences.
    pub ssd: f32,
}

/// Counters from one matching run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MatchStats {
    /// Tile features considered (inside the prior footprint, if any).
    pub tile_candidates: u32,
    /// Descriptor comparisons started.
    pub comparisons: u32,
    /// Matches refused by the ratio test.
    pub rejected_ratio: u32,
    /// Matches refused by the mutual check.
    pub rejected_mutual: u32,
    /// Matches not kept because the list was full (the worst by SSD go).
    pub dropped: u32,
}

/// SSD between a frame descriptor and tile descriptor `j`, abandoning once it exceeds `bound`
/// (the result is then some value > `bound`; exact otherwise). Same order of additions always.
/// SSD between a frame descriptor and tile descriptor `j`; once the running sum exceeds
/// `bound` the scan stops and returns a value above `bound`.
#[inline]
pub fn ssd_to_tile(a: &[f32; DESCRIPTOR_LEN], tile: &Tile<'_>, j: usize, bound: f32) -> f32 {
    ssd_bounded(a, tile, j, bound)
}

#[inline]
fn ssd_bounded(a: &[f32; DESCRIPTOR_LEN], tile: &Tile<'_>, j: usize, bound: f32) -> f32 {
    let (b, _) = tile.descriptor_bytes(j).as_chunks::<4>();
    let mut acc = 0.0f32;
    // Check the bound every 8 components: early exit without changing the order of additions.
    // The running sum never decreases, so exiting at any granularity returns some value above
    // `bound` exactly when the full sum would be above it; callers only compare the result with
    // `bound` or smaller values, so the granularity changes no decision.
    for (av, bb) in a.chunks_exact(8).zip(b.chunks_exact(8)) {
        for (x, yb) in av.iter().zip(bb) {
            let d = x - f32::from_le_bytes(*yb);
            acc += d * d;
        }
        if acc > bound {
            return acc;
        }
    }
    acc
}

/// Match `frame` features against the tile features for which `use_tile(j)` is true, writing at
/// most `M` matches (lowest SSD kept) into `out`, sorted by frame index.
pub fn match_features<const M: usize>(
    frame: &[Feature],
    tile: &Tile<'_>,
    cfg: &MatchConfig,
    use_tile: impl Fn(usize) -> bool,
    out: &mut heapless::Vec<Match, M>,
) -> MatchStats {
    out.clear();
    let mut stats = MatchStats::default();
    let n_tile = tile.len().min(u16::MAX as usize);
    let ratio2 = cfg.ratio * cfg.ratio;
    stats.tile_candidates = (0..n_tile).filter(|&j| use_tile(j)).count() as u32;
    for (i, f) in frame.iter().enumerate().take(u16::MAX as usize) {
        let lap = f.keypoint.laplacian_positive;
        let (mut best, mut best_j, mut second) = (f32::INFINITY, usize::MAX, f32::INFINITY);
        for j in 0..n_tile {
            if tile.laplacian_positive(j) != lap || !use_tile(j) {
                continue;
            }
            stats.comparisons += 1;
            let d = ssd_bounded(&f.descriptor, tile, j, second);
            if d < best {
                second = best;
                best = d;
                best_j = j;
            } else if d < second {
                second = d;
            }
        }
        if best_j == usize::MAX || best > cfg.max_ssd {
            continue;
        }
        if second.is_finite() && best >= ratio2 * second {
            stats.rejected_ratio += 1;
            continue;
        }
        if cfg.mutual && !is_mutual(frame, i, tile, best_j, best) {
            stats.rejected_mutual += 1;
            continue;
        }
        let m = Match {
            frame: i as u16,
            tile: best_j as u16,
            ssd: best,
        };
        if let Err(m) = out.push(m) {
            stats.dropped += 1;
            // Replace the worst kept match if this one is better (ties: keep the earlier).
            let worst =
                out.iter()
                    .enumerate()
                    .fold(None::<(usize, f32)>, |acc, (k, x)| match acc {
                        Some((_, s)) if s >= x.ssd => acc,
                        _ => Some((k, x.ssd)),
                    });
            if let Some((k, s)) = worst
                && m.ssd < s
                && let Some(slot) = out.get_mut(k)
            {
                *slot = m;
            }
        }
    }
    out.sort_unstable_by_key(|m| m.frame);
    stats
}

/// Whether frame feature `i` is tile feature `j`'s best frame match (ties go to the lower index).
fn is_mutual(frame: &[Feature], i: usize, tile: &Tile<'_>, j: usize, ssd_ij: f32) -> bool {
    let lap = tile.laplacian_positive(j);
    for (k, f) in frame.iter().enumerate() {
        if k == i || f.keypoint.laplacian_positive != lap {
            continue;
        }
        let d = ssd_bounded(&f.descriptor, tile, j, ssd_ij);
        if d < ssd_ij || (d == ssd_ij && k < i) {
            return false;
        }
    }
    true
}
