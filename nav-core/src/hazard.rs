//! Hazard map and safe-site choice from one of the flyer's own DEM frames near the ground.
//!
//! A **site** is a lattice point of the frame (every `step` frame pixels, about
//! [`HazardConfig::site_step_m`] apart). Each site is judged over the lander's footprint: the
//! frame cells whose centres lie within half [`HazardConfig::footprint_m`] of it get a
//! least-squares plane; the site is **safe** when that plane's tilt is at most
//! [`HazardConfig::max_slope_deg`] and no cell lies farther than [`HazardConfig::max_relief_m`]
//! above or below it (a rock the belly or a leg would strike, a hole a leg would drop into). A
//! footprint over a hole in the data is unsafe: what the flyer cannot see, it does not land on.
//! Scattered lost returns are no hole: a NaN cell whose four edge neighbours returned enters the
//! plane's fit as their mean and the relief test is left to the cells that returned, up to one
//! lost cell in [`LOST_CELLS_PER`] of the footprint. The descent's sensor loses 0.5 % of its
//! cells at random, so a 0.25 m footprint of ~200 cells held one in 63 % of sites, and the map
//! refused those whatever the ground (session 36, docs/registration.md "Lost returns in the
//! hazard map"). A lost cell can hide a rock's top only where its neighbours are off the rock;
//! the calibration (`ground-sim hazard-calibrate`) scores the map against the truth with it.
//! A no-data sentinel ([`DemPatch::nodata_m`]) marks ground outside the data and stays a hole.
//! This is the same test the ground scores touchdowns with (`ground-sim`'s `site_safety`), on
//! the flyer's noisy frame instead of the truth.
//!
//! The **clearance** of a safe site is its distance to the nearest unsafe site or to the edge of
//! the mapped lattice (beyond it nothing is known): a two-pass 3-4 chamfer distance transform,
//! integer and exact on every target, within 8 % of the Euclidean distance. The chosen site is
//! the safe site within [`HazardConfig::max_reach_m`] of the target nearest to it among those
//! with [`HazardConfig::preferred_clearance_m`] of clearance, else among those with
//! [`HazardConfig::clearance_m`], else the one with the most clearance (ties: nearer, then
//! lattice order), so the lander's own dispersion around the site stays on safe ground.
//!
//! Units and axes: frame pixels (x = column, y = row, centres at integers) and metres on the
//! ground; the caller turns the site's frame position into east/north with the frame's heading.
//! Bounds: at most `N` sites (const generic; [`MAX_FOOTPRINT_PX`] footprint side); work per
//! frame is sites × footprint cells, twice, plus two lattice sweeps. No allocation, no panic.

use crate::frame::DemPatch;
use core::fmt;

/// Largest footprint side in frame pixels: a finer frame is judged on a 2× coarser grid of its
/// cells would be the remedy; refused instead, the caller takes the next frame.
pub const MAX_FOOTPRINT_PX: usize = 33;
/// Smallest footprint side in frame pixels: fewer cells cannot show a rock inside the footprint.
pub const MIN_FOOTPRINT_PX: usize = 5;
/// Chamfer weights (orthogonal, diagonal) of the clearance distance transform, in thirds of a
/// lattice step.
const CHAMFER: (u16, u16) = (3, 4);
/// Clearance of a site that is itself unsafe.
const BLOCKED: u16 = 0;
/// A footprint may hold one lost return per this many cells (the descent's sensor loses one in
/// 200); more is a hole.
pub const LOST_CELLS_PER: usize = 32;
/// Most lost returns one footprint may hold: a [`MAX_FOOTPRINT_PX`]² square's cells over
/// [`LOST_CELLS_PER`].
pub const MAX_LOST_CELLS: usize = MAX_FOOTPRINT_PX * MAX_FOOTPRINT_PX / LOST_CELLS_PER;

/// The lander's tolerances and the choice's limits.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HazardConfig {
    /// Diameter of the disc judged around a site, m: the lander's leg span.
    pub footprint_m: f32,
    /// Largest tilt of the fitted plane, degrees (judged on the flyer's frame: the lander's
    /// tolerance less a sensing margin).
    pub max_slope_deg: f32,
    /// Largest height of a cell above or below the plane, m.
    pub max_relief_m: f32,
    /// Spacing of the site lattice, m (rounded to whole frame pixels, at least one).
    pub site_step_m: f32,
    /// Smallest clearance of the chosen site, m: an aim with less is moved.
    pub clearance_m: f32,
    /// Clearance sought first, m: the nearest site with this much is taken when there is one
    /// (a roomy site stays safe from one map to the next as the frames sharpen).
    pub preferred_clearance_m: f32,
    /// Farthest the chosen site may be from the target, m (the fuel and time left).
    pub max_reach_m: f32,
}

impl Default for HazardConfig {
    fn default() -> Self {
        Self {
            footprint_m: 4.0,
            // The lander tolerates 10° and 0.3 m; the frame misreads both (a 0.4 m pixel
            // averages a rock's top away, 4 cm of range noise tilts a 4 m plane by ~1°), so the
            // map judges with a margin. The relief margin is measured (`ground-sim
            // hazard-calibrate`, lola/shoemaker/plains zones, seeds 101–106, 0.4 m frames): of
            // the sites judged safe with 2 m of clearance, 5.7 % are truly unsafe at 0.25 m,
            // 2.3 % at 0.20 m, 0.7 % at 0.17 m (which still offers 43 % of the truly safe
            // ground; 0.15 m: 0.4 %, 33 %). Since lost cells are filled (session 36) 0.17 m
            // offers 66 % and misses 1.0 % (0.15 m: 50 %, 0.6 %); the confirmation judges the
            // chosen site again on a finer frame.
            max_slope_deg: 8.0,
            max_relief_m: 0.17,
            site_step_m: 1.0,
            // About twice the relative drift between the hazard frame and touchdown.
            clearance_m: 2.0,
            preferred_clearance_m: 4.0,
            max_reach_m: 30.0,
        }
    }
}

impl HazardConfig {
    /// The confirmation map's settings ([`HazardMap::build_around`] on a frame of
    /// [`CONFIRM_MAX_PIXEL_M`] or finer, over [`CONFIRM_HALF_WINDOW_M`] around the aim, then
    /// [`HazardMap::decide`] with the aim as its own target). The first map (0.4 m) chooses
    /// among much ground but calls 2.5 % of its safe sites safe that are not (a 0.4 m pixel
    /// averages a small rock's top away); a 0.25 m frame misreads less. Relief 0.17 m, measured
    /// with `ground-sim hazard-calibrate --pixel-m 0.25` (lola/shoemaker/plains zones, seeds
    /// 101–106: 0.26 % of its safe sites truly unsafe, 23 % of the safe ground offered; with
    /// lost cells filled, session 36: 0.31 % and 60 %, and 0.02 % of those with 2 m of
    /// clearance, 15 % of the safe ground offered with it against 1.2 % before) and in
    /// descents (at 0.20 m, 0.76 % and 28 %, two of 540 touchdowns were unsafe; the one
    /// examined sat on a site the confirmation had passed). The aim moves at most 16 m (the
    /// flyer is about 95 m up, 20 s above touchdown): at 0.17 m this map passes few roomy
    /// sites, and with a 10 m reach half the runs over InSAR maps found none with 2 m of
    /// clearance and took one with about 1 m, which a 0.3 m landing dispersion could leave
    /// (session 34, 18 InSAR campaigns: 4 unsafe touchdowns in 480 open-ground runs at 10 m,
    /// none at 16 m; in the 8 of them re-flown to count, aims with under 1.5 m of clearance
    /// fell from 48 % to 24 % of the runs).
    pub fn confirmation() -> Self {
        Self {
            max_relief_m: 0.17,
            clearance_m: 2.0,
            preferred_clearance_m: 3.0,
            max_reach_m: 16.0,
            ..Self::default()
        }
    }
}

/// Coarsest frame pixel of the confirmation map, m (95 m above the ground with the descent's
/// sensor): sixteen pixels across the 4 m footprint.
pub const CONFIRM_MAX_PIXEL_M: f32 = 0.25;

/// Half side of the confirmation map's window around the aim, m: the confirmation's 16 m reach,
/// its 3 m preferred clearance and one site to spare (the window's edge counts as a hazard).
/// It bounds the map's work: 41 × 41 sites at 0.25 m pixels against 64 × 64 for a whole
/// 0.4 m frame (docs/bounds.md); a 200-pixel frame at 0.25 m spans ±25 m.
pub const CONFIRM_HALF_WINDOW_M: f32 = 20.0;

/// Why no hazard map was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum HazardError {
    /// A setting is not finite or not positive.
    BadConfig,
    /// The frame's pixels are too coarse for the footprint (fewer than [`MIN_FOOTPRINT_PX`]).
    TooCoarse,
    /// The frame's pixels are too fine (more than [`MAX_FOOTPRINT_PX`] per footprint).
    TooFine,
    /// The frame is smaller than one footprint.
    TooSmall,
    /// The window of [`HazardMap::build_around`] holds no site of the frame (or is not
    /// finite).
    WindowOutside,
    /// More sites than the map holds.
    TooManySites {
        /// Sites the frame would need.
        needed: usize,
        /// Sites the map holds.
        capacity: usize,
    },
}

impl fmt::Display for HazardError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadConfig => f.write_str("hazard settings not finite or not positive"),
            Self::TooCoarse => f.write_str("frame too coarse for the lander's footprint"),
            Self::TooFine => f.write_str("frame too fine for the footprint window"),
            Self::TooSmall => f.write_str("frame smaller than one footprint"),
            Self::WindowOutside => f.write_str("map window holds no site of the frame"),
            Self::TooManySites { needed, capacity } => {
                write!(f, "{needed} sites needed, the map holds {capacity}")
            }
        }
    }
}
impl core::error::Error for HazardError {}

/// What one map found.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HazardStats {
    /// Sites judged.
    pub sites: u32,
    /// Of those, safe.
    pub safe: u32,
    /// Unsafe for their tilt (and possibly their relief too).
    pub too_steep: u32,
    /// Unsafe for their relief alone.
    pub too_rough: u32,
    /// Unsafe because their footprint touched a hole in the data: a lost cell beside another or
    /// on the frame's edge, more lost cells than [`LOST_CELLS_PER`] allows, or a no-data
    /// sentinel.
    pub no_data: u32,
}

/// The chosen site.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SafeSite {
    /// Position in frame pixels `[x, y]`.
    pub frame_px: [f32; 2],
    /// Clearance, m.
    pub clearance_m: f32,
    /// Distance from the target, m.
    pub from_target_m: f32,
}

/// What a hazard map decided for the aim ([`HazardMap::decide`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AimDecision {
    /// The aim's site is safe with enough clearance (m): keep it.
    Keep {
        /// Clearance of the aim's site, m.
        clearance_m: f32,
    },
    /// Fly to this site instead.
    Move(SafeSite),
    /// No site within reach qualifies; the aim stays.
    NoSite,
}

/// A hazard map of at most `N` sites.
pub struct HazardMap<const N: usize> {
    /// Clearance per site in thirds of a lattice step; 0 = unsafe.
    clearance: [u16; N],
    cols: usize,
    rows: usize,
    /// Frame pixels between sites.
    step_px: usize,
    /// Frame pixel `[x, y]` of site (0, 0).
    first_px: [usize; 2],
    pixel_m: f32,
}

impl<const N: usize> Default for HazardMap<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> HazardMap<N> {
    /// An empty map (`const`, so it can be a `static`).
    pub const fn new() -> Self {
        Self {
            clearance: [BLOCKED; N],
            cols: 0,
            rows: 0,
            step_px: 1,
            first_px: [0, 0],
            pixel_m: 1.0,
        }
    }

    /// Size in bytes.
    pub const fn footprint_bytes() -> usize {
        core::mem::size_of::<Self>()
    }

    /// Lattice size `(columns, rows)` of the last map.
    pub fn size(&self) -> (usize, usize) {
        (self.cols, self.rows)
    }

    /// Frame pixel of lattice site `(i, j)`.
    pub fn site_px(&self, i: usize, j: usize) -> [f32; 2] {
        [
            (self.first_px[0] + i * self.step_px) as f32,
            (self.first_px[1] + j * self.step_px) as f32,
        ]
    }

    /// The lattice site nearest to frame pixel `q` (clamped to the lattice).
    pub fn nearest_site(&self, q: [f32; 2]) -> (usize, usize) {
        let idx = |v: f32, first: usize, n: usize| {
            let k = libm::roundf((v - first as f32) / self.step_px as f32);
            if k.is_finite() && k > 0.0 {
                (k as usize).min(n.saturating_sub(1))
            } else {
                0
            }
        };
        (
            idx(q[0], self.first_px[0], self.cols),
            idx(q[1], self.first_px[1], self.rows),
        )
    }

    /// Clearance of site `(i, j)`, m (0: unsafe or outside the lattice).
    pub fn clearance_m(&self, i: usize, j: usize) -> f32 {
        if i >= self.cols || j >= self.rows {
            return 0.0;
        }
        let c = self
            .clearance
            .get(j * self.cols + i)
            .copied()
            .unwrap_or(BLOCKED);
        c as f32 / CHAMFER.0 as f32 * self.step_px as f32 * self.pixel_m
    }

    /// Whether site `(i, j)` is safe.
    pub fn is_safe(&self, i: usize, j: usize) -> bool {
        self.clearance_m(i, j) > 0.0
    }

    /// Judge every site of `dem` under `cfg`.
    pub fn build(
        &mut self,
        dem: &DemPatch<'_>,
        cfg: &HazardConfig,
    ) -> Result<HazardStats, HazardError> {
        self.build_window(dem, cfg, None)
    }

    /// Judge only the sites within `half_window_m` (m, along each frame axis) of `center_px`
    /// (frame pixels `[x, y]`): a confirmation map around an aim already chosen, on a frame
    /// finer than the one that chose it. The window's edge counts as unsafe for the clearance,
    /// like the frame's. [`HazardError::WindowOutside`] when the window holds no site or its
    /// centre or size is not finite.
    pub fn build_around(
        &mut self,
        dem: &DemPatch<'_>,
        cfg: &HazardConfig,
        center_px: [f32; 2],
        half_window_m: f32,
    ) -> Result<HazardStats, HazardError> {
        self.build_window(dem, cfg, Some((center_px, half_window_m)))
    }

    fn build_window(
        &mut self,
        dem: &DemPatch<'_>,
        cfg: &HazardConfig,
        window: Option<([f32; 2], f32)>,
    ) -> Result<HazardStats, HazardError> {
        self.cols = 0;
        self.rows = 0;
        let vals = [
            cfg.footprint_m,
            cfg.max_slope_deg,
            cfg.max_relief_m,
            cfg.site_step_m,
            cfg.clearance_m,
            cfg.preferred_clearance_m,
            cfg.max_reach_m,
        ];
        if !vals.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(HazardError::BadConfig);
        }
        let px = dem.pixel_m();
        let side = libm::roundf(cfg.footprint_m / px);
        if side < MIN_FOOTPRINT_PX as f32 {
            return Err(HazardError::TooCoarse);
        }
        if side > MAX_FOOTPRINT_PX as f32 {
            return Err(HazardError::TooFine);
        }
        let half = (side as usize) / 2;
        let (w, h) = (dem.width(), dem.height());
        if w < 2 * half + 1 || h < 2 * half + 1 {
            return Err(HazardError::TooSmall);
        }
        let step = (libm::roundf(cfg.site_step_m / px) as usize).max(1);
        let all_cols = (w - 2 * half - 1) / step + 1;
        let all_rows = (h - 2 * half - 1) / step + 1;
        // Lattice index range `[first, last]` per axis: the whole lattice, or the sites whose
        // centres lie within the window.
        let range = |c: f32, hw_m: f32, n: usize| -> Option<(usize, usize)> {
            let (lo, hi) = (
                libm::ceilf((c - hw_m / px - half as f32) / step as f32),
                libm::floorf((c + hw_m / px - half as f32) / step as f32),
            );
            if !(lo.is_finite() && hi.is_finite() && hw_m >= 0.0) || hi < 0.0 || lo > hi {
                return None;
            }
            let first = if lo > 0.0 { lo as usize } else { 0 };
            let last = if hi > 0.0 { hi as usize } else { 0 }.min(n - 1);
            (first <= last).then_some((first, last))
        };
        let ((i0, i1), (j0, j1)) = match window {
            None => ((0, all_cols - 1), (0, all_rows - 1)),
            Some((c, hw)) => match (range(c[0], hw, all_cols), range(c[1], hw, all_rows)) {
                (Some(a), Some(b)) => (a, b),
                _ => return Err(HazardError::WindowOutside),
            },
        };
        let (cols, rows) = (i1 - i0 + 1, j1 - j0 + 1);
        let n = cols * rows;
        if n > N {
            return Err(HazardError::TooManySites {
                needed: n,
                capacity: N,
            });
        }
        // Disc offsets in pixels: |d| ≤ radius in metres.
        let r_px = cfg.footprint_m * 0.5 / px;
        let r2 = r_px * r_px;
        let h_i = half as isize;
        let in_disc = |dx: isize, dy: isize| ((dx * dx + dy * dy) as f32) <= r2;
        let (mut sxx, mut cells) = (0.0f32, 0u32);
        for dy in -h_i..=h_i {
            for dx in -h_i..=h_i {
                if in_disc(dx, dy) {
                    sxx += (dx * dx) as f32;
                    cells += 1;
                }
            }
        }
        // The disc is symmetric: Σx = Σy = Σxy = 0 and Σx² = Σy², so the plane's coefficients
        // are plain moments.
        let tan_max = libm::tanf(cfg.max_slope_deg.to_radians());
        let mut stats = HazardStats {
            sites: n as u32,
            safe: 0,
            too_steep: 0,
            too_rough: 0,
            no_data: 0,
        };
        // The disc row by row, empty rows left out: (dy, first dx, offset of the row's first
        // cell from the site's index, cells). Cells are visited in the order of the moment sums
        // above, so every sum is the same float.
        let mut spans = [(0.0f32, 0.0f32, 0isize, 0usize); MAX_FOOTPRINT_PX];
        let mut n_spans = 0;
        for k in 0..2 * half + 1 {
            let dy = k as isize - h_i;
            let Some(hw) = (0..=h_i).rev().find(|&dx| in_disc(dx, dy)) else {
                continue;
            };
            if let Some(sp) = spans.get_mut(n_spans) {
                *sp = (
                    dy as f32,
                    -hw as f32,
                    dy * w as isize - hw,
                    2 * hw as usize + 1,
                );
                n_spans += 1;
            }
        }
        let spans = spans.get(..n_spans).unwrap_or(&[]);
        let heights = dem.heights_m();
        let nodata = dem.nodata_m();
        let masked = |z: f32| !z.is_finite() || nodata == Some(z);
        // A footprint row of the site whose cell index is `at` (always inside the frame for a
        // lattice site; `None` would count as no data).
        let cells_of = |at: usize, off: isize, len: usize| -> Option<&[f32]> {
            let first = at.checked_add_signed(off)?;
            heights.get(first..first.checked_add(len)?)
        };
        // A lost return (NaN) whose four edge neighbours returned reads as their mean in the
        // plane's fit, which keeps the disc's moments symmetric; more than
        // `cells / LOST_CELLS_PER` of them in one footprint, one beside another or on the
        // frame's edge, or a no-data sentinel (ground outside the data, not a lost return) is a
        // hole. The relief test reads the cells that returned: a NaN compares false.
        let max_lost = (cells as usize / LOST_CELLS_PER).min(MAX_LOST_CELLS);
        let fill = |k: usize| -> Option<f32> {
            let (col, row) = (k % w, k / w);
            if col == 0 || row == 0 || col + 1 >= w || row + 1 >= h {
                return None;
            }
            let mut acc = 0.0f32;
            for n in [k - w, k - 1, k + 1, k + w] {
                let z = *heights.get(n)?;
                if masked(z) {
                    return None;
                }
                acc += z;
            }
            Some(acc * 0.25)
        };
        // (index, dx, dy) of a footprint's lost cells; each site overwrites what it reads.
        let mut lost = [(0usize, 0.0f32, 0.0f32); MAX_LOST_CELLS];
        for j in 0..rows {
            for i in 0..cols {
                let (cx, cy) = (half + (i0 + i) * step, half + (j0 + j) * step);
                let at = cy * w + cx;
                let z0 = match heights.get(at) {
                    Some(&z) if z.is_nan() => fill(at),
                    Some(&z) => Some(z),
                    None => None,
                };
                let (mut bad, z0) = (z0.is_none(), z0.unwrap_or(0.0));
                let (mut s, mut sx, mut sy) = (0.0f32, 0.0f32, 0.0f32);
                // Lost cells of this footprint in `lost[..n_lost]`: read after the sums.
                let mut n_lost = 0usize;
                'spans: for &(dy, dx0, off, len) in spans {
                    let Some(cells) = cells_of(at, off, len) else {
                        bad = true;
                        break;
                    };
                    if nodata.is_some() && cells.iter().any(|&z| nodata == Some(z)) {
                        bad = true;
                        break;
                    }
                    let first = at.wrapping_add_signed(off);
                    let mut dx = dx0;
                    for (k, &z) in cells.iter().enumerate() {
                        let d = z - z0;
                        if d.is_nan() {
                            match lost.get_mut(n_lost) {
                                Some(l) if n_lost < max_lost => *l = (first + k, dx, dy),
                                _ => {
                                    bad = true;
                                    break 'spans;
                                }
                            }
                            n_lost += 1;
                        } else {
                            s += d;
                            sx += dx * d;
                            sy += dy * d;
                        }
                        dx += 1.0;
                    }
                }
                for &(k, dx, dy) in lost.get(..n_lost).unwrap_or(&[]) {
                    let Some(z) = fill(k) else {
                        bad = true;
                        break;
                    };
                    let d = z - z0;
                    s += d;
                    sx += dx * d;
                    sy += dy * d;
                }
                // An infinite height leaves a sum that is not finite.
                bad |= !(s.is_finite() && sx.is_finite() && sy.is_finite());
                let safe = if bad || cells == 0 || sxx <= 0.0 {
                    stats.no_data += 1;
                    false
                } else {
                    let a = s / cells as f32;
                    let (b, c) = (sx / sxx, sy / sxx);
                    if libm::hypotf(b, c) / px > tan_max {
                        stats.too_steep += 1;
                        false
                    } else {
                        // Any cell off the plane by more than the limit settles it.
                        let mut rough = false;
                        for &(dy, dx0, off, len) in spans {
                            let Some(cells) = cells_of(at, off, len) else {
                                continue;
                            };
                            let cdy = c * dy;
                            let mut dx = dx0;
                            for &z in cells {
                                rough |=
                                    libm::fabsf(z - z0 - (a + b * dx + cdy)) > cfg.max_relief_m;
                                dx += 1.0;
                            }
                            if rough {
                                break;
                            }
                        }
                        if rough {
                            stats.too_rough += 1;
                            false
                        } else {
                            stats.safe += 1;
                            true
                        }
                    }
                };
                if let Some(c) = self.clearance.get_mut(j * cols + i) {
                    *c = if safe { u16::MAX } else { BLOCKED };
                }
            }
        }
        self.cols = cols;
        self.rows = rows;
        self.step_px = step;
        self.first_px = [half + i0 * step, half + j0 * step];
        self.pixel_m = px;
        self.distance_transform();
        Ok(stats)
    }

    /// Two-pass 3-4 chamfer distance to the nearest unsafe site, the lattice's outside counting
    /// as unsafe (one step beyond the edge).
    fn distance_transform(&mut self) {
        let (cols, rows) = (self.cols, self.rows);
        let (o, d) = CHAMFER;
        let get = |c: &[u16; N], i: isize, j: isize| -> u16 {
            if i < 0 || j < 0 || i >= cols as isize || j >= rows as isize {
                BLOCKED
            } else {
                c.get(j as usize * cols + i as usize)
                    .copied()
                    .unwrap_or(BLOCKED)
            }
        };
        for j in 0..rows as isize {
            for i in 0..cols as isize {
                let k = j as usize * cols + i as usize;
                let v = get(&self.clearance, i, j);
                if v == BLOCKED {
                    continue;
                }
                let best = [
                    get(&self.clearance, i - 1, j).saturating_add(o),
                    get(&self.clearance, i, j - 1).saturating_add(o),
                    get(&self.clearance, i - 1, j - 1).saturating_add(d),
                    get(&self.clearance, i + 1, j - 1).saturating_add(d),
                ]
                .into_iter()
                .fold(v, u16::min);
                if let Some(c) = self.clearance.get_mut(k) {
                    *c = best;
                }
            }
        }
        for j in (0..rows as isize).rev() {
            for i in (0..cols as isize).rev() {
                let k = j as usize * cols + i as usize;
                let v = get(&self.clearance, i, j);
                if v == BLOCKED {
                    continue;
                }
                let best = [
                    get(&self.clearance, i + 1, j).saturating_add(o),
                    get(&self.clearance, i, j + 1).saturating_add(o),
                    get(&self.clearance, i + 1, j + 1).saturating_add(d),
                    get(&self.clearance, i - 1, j + 1).saturating_add(d),
                ]
                .into_iter()
                .fold(v, u16::min);
                if let Some(c) = self.clearance.get_mut(k) {
                    *c = best;
                }
            }
        }
    }

    /// Confirm the chosen aim at `aim_px` (frame pixels) on a finer frame: map the window of
    /// [`CONFIRM_HALF_WINDOW_M`] around it under `cfg` (the flight uses
    /// [`HazardConfig::confirmation`]) and [`Self::decide`] with the aim as its own target, so a
    /// move stays within `cfg.max_reach_m` of it. The one definition the descent and the target
    /// both run.
    pub fn confirm(
        &mut self,
        dem: &DemPatch<'_>,
        cfg: &HazardConfig,
        aim_px: [f32; 2],
    ) -> Result<(HazardStats, AimDecision), HazardError> {
        let stats = self.build_around(dem, cfg, aim_px, CONFIRM_HALF_WINDOW_M)?;
        Ok((stats, self.decide(aim_px, aim_px, cfg)))
    }

    /// The one decision a map makes for guidance: keep the aim at `aim_px` (frame pixels) if
    /// its site has at least `cfg.clearance_m`; else move it: an aim that is safe but tight
    /// moves only to a site with that clearance ([`Self::nearest_with`] around `target_px`),
    /// an unsafe one to the best there is ([`Self::choose`]). [`AimDecision::NoSite`] when
    /// nothing within reach qualifies (the aim stays).
    pub fn decide(&self, aim_px: [f32; 2], target_px: [f32; 2], cfg: &HazardConfig) -> AimDecision {
        if !aim_px.iter().chain(&target_px).all(|v| v.is_finite()) {
            return AimDecision::NoSite;
        }
        let (i, j) = self.nearest_site(aim_px);
        let clear = self.clearance_m(i, j);
        if clear > 0.0 && clear >= cfg.clearance_m {
            return AimDecision::Keep { clearance_m: clear };
        }
        let pick = if clear > 0.0 {
            self.nearest_with(target_px, cfg.clearance_m, cfg)
        } else {
            self.choose(target_px, cfg)
        };
        pick.map_or(AimDecision::NoSite, AimDecision::Move)
    }

    /// The safe site nearest to `target_px` (frame pixels) with at least
    /// `cfg.preferred_clearance_m` of clearance, else with at least `cfg.clearance_m`, within
    /// `cfg.max_reach_m`; failing both, the safe site within reach with the largest clearance (a narrow safe spot beats certain hazard); `None` if no site within
    /// reach is safe.
    pub fn choose(&self, target_px: [f32; 2], cfg: &HazardConfig) -> Option<SafeSite> {
        if !(target_px[0].is_finite() && target_px[1].is_finite()) {
            return None;
        }
        self.nearest_with(target_px, cfg.preferred_clearance_m, cfg)
            .or_else(|| self.nearest_with(target_px, cfg.clearance_m, cfg))
            .or_else(|| self.widest_within_reach(target_px, cfg))
    }

    fn widest_within_reach(&self, target_px: [f32; 2], cfg: &HazardConfig) -> Option<SafeSite> {
        let mut best: Option<SafeSite> = None;
        for j in 0..self.rows {
            for i in 0..self.cols {
                let clear = self.clearance_m(i, j);
                if clear <= 0.0 {
                    continue;
                }
                let p = self.site_px(i, j);
                let dist = libm::hypotf(p[0] - target_px[0], p[1] - target_px[1]) * self.pixel_m;
                // NaN distances (a non-finite target) are out of reach too.
                if !(dist <= cfg.max_reach_m) {
                    continue;
                }
                let better = best.is_none_or(|b| {
                    clear > b.clearance_m || (clear == b.clearance_m && dist < b.from_target_m)
                });
                if better {
                    best = Some(SafeSite {
                        frame_px: p,
                        clearance_m: clear,
                        from_target_m: dist,
                    });
                }
            }
        }
        best
    }

    /// The safe site nearest to `target_px` with at least `min_clearance_m` of clearance within
    /// `cfg.max_reach_m` (no fallback).
    pub fn nearest_with(
        &self,
        target_px: [f32; 2],
        min_clearance_m: f32,
        cfg: &HazardConfig,
    ) -> Option<SafeSite> {
        let mut best: Option<(f32, f32, SafeSite)> = None;
        for j in 0..self.rows {
            for i in 0..self.cols {
                let clear = self.clearance_m(i, j);
                if clear <= 0.0 || clear < min_clearance_m {
                    continue;
                }
                let p = self.site_px(i, j);
                let dist = libm::hypotf(p[0] - target_px[0], p[1] - target_px[1]) * self.pixel_m;
                // NaN distances (a non-finite target) are out of reach too.
                if !(dist <= cfg.max_reach_m) {
                    continue;
                }
                let better = match &best {
                    None => true,
                    Some((bd, bc, _)) => dist < *bd || (dist == *bd && clear > *bc),
                };
                if better {
                    best = Some((
                        dist,
                        clear,
                        SafeSite {
                            frame_px: p,
                            clearance_m: clear,
                            from_target_m: dist,
                        },
                    ));
                }
            }
        }
        best.map(|b| b.2)
    }
}
