//! Onboard slope from a DEM patch: Horn's 3×3 gradient, in degrees.
//!
//! The same function serves the ground segment (reference tile) and the flight segment
//! (real-time frames), so both sides quantise slope identically.

use crate::frame::{DemPatch, FrameError, SLOPE_NODATA, SlopeImage, SlopePx, slope_from_deg};

/// Degrees per radian.
const DEG_PER_RAD: f32 = 180.0 / core::f32::consts::PI;

/// Compute the slope of every DEM pixel into `out[..width × height]` and return it as an image.
///
/// Horn (1981): with the 3×3 neighbourhood `a b c / d e f / g h i`,
/// `∂z/∂x = ((c + 2f + i) − (a + 2d + g)) / (8·pixel)`,
/// `∂z/∂y = ((g + 2h + i) − (a + 2b + c)) / (8·pixel)`, slope = atan(|∇z|).
/// Border pixels and pixels with any masked (nodata or non-finite) neighbour are
/// [`SLOPE_NODATA`], so missing heights can never create slope edges.
///
/// Errors: `out` shorter than the frame gives [`FrameError::TooLarge`].
pub fn slope_into<'b>(
    dem: &DemPatch<'_>,
    out: &'b mut [SlopePx],
) -> Result<SlopeImage<'b>, FrameError> {
    slope_into_with(dem, out, false)
}

/// Fewest valid neighbours (of 8) for a missing height to be filled by their mean.
pub const FILL_MIN_NEIGHBOURS: usize = 5;

/// [`slope_into`], optionally filling isolated dropouts first: a missing height with at least
/// [`FILL_MIN_NEIGHBOURS`] valid 8-neighbours takes their mean, so a sensor's scattered lost
/// returns do not blank out 3 × 3 blocks of slope (and every feature footprint that touches
/// one). Larger holes stay masked. The reference tile is built without filling.
pub fn slope_into_with<'b>(
    dem: &DemPatch<'_>,
    out: &'b mut [SlopePx],
    fill_isolated: bool,
) -> Result<SlopeImage<'b>, FrameError> {
    let (w, h) = (dem.width(), dem.height());
    let at = |c: usize, r: usize| dem.height_at(c, r);
    if fill_isolated {
        slope_grid(w, h, dem.pixel_m(), |c, r| filled(&at, w, h, c, r), out)
    } else {
        slope_grid(w, h, dem.pixel_m(), at, out)
    }
}

/// Largest binning factor [`slope_into_binned`] accepts.
pub const MAX_BIN: usize = 8;

/// Slope of the DEM after averaging `k × k` blocks of heights (a block with fewer than half its
/// heights valid is no data), into `out[..(w/k) × (h/k)]`; pixel size `k × pixel_m`. Lets the
/// flyer bring a frame finer than the reference to the reference's ground sample distance
/// before SURF, so both images' slopes come from the same scale of terrain, at a quarter of the
/// pixels for k = 2. Isolated missing blocks are filled as in [`slope_into_with`] when asked.
/// Binned frames are at most [`BIN_ROW_CAP`] pixels wide.
pub fn slope_into_binned<'b>(
    dem: &DemPatch<'_>,
    k: usize,
    out: &'b mut [SlopePx],
    fill_isolated: bool,
) -> Result<SlopeImage<'b>, FrameError> {
    slope_into_binned_smoothed::<BIN_ROW_CAP>(dem, k, 0.0, out, fill_isolated)
}

/// Largest Gaussian radius, binned pixels, of [`slope_into_binned_smoothed`].
pub const MAX_SMOOTH_RADIUS: usize = 9;
/// Rows of filled heights the vertical Gaussian pass keeps.
const SMOOTH_RING: usize = 2 * MAX_SMOOTH_RADIUS + 1;

/// Radius `R = min(⌈3σ⌉, MAX_SMOOTH_RADIUS)` of the Gaussian [`slope_into_binned_smoothed`]
/// applies for `sigma_px` (0 for σ ≤ 0 or not finite), binned pixels.
///
/// Near the image border the Gaussian is cut and renormalised over the heights that exist, so
/// a smoothed height there is the average of ground farther in: on a slope its height, and the
/// slope between such heights, are biased (at the edge the slope of a plane comes out at about
/// a third of its value, at 2σ in still 11 % low). Slope pixels closer than `R + 1` to the
/// border carry that bias; [`crate::refine`] leaves them out.
pub fn smoothing_radius(sigma_px: f32) -> usize {
    if sigma_px > 0.0 && sigma_px.is_finite() {
        libm::ceilf(3.0 * sigma_px).min(MAX_SMOOTH_RADIUS as f32) as usize
    } else {
        0
    }
}

/// Gaussian weights `exp(−d²/2σ²)` for `d = 0..=R`, `R = min(⌈3σ⌉, MAX_SMOOTH_RADIUS)`
/// (`R = 0`, no smoothing, for σ ≤ 0 or not finite). `libm`, so host and target agree bit for bit.
fn gauss_weights(sigma_px: f32) -> ([f32; MAX_SMOOTH_RADIUS + 1], usize) {
    let mut wt = [0.0f32; MAX_SMOOTH_RADIUS + 1];
    wt[0] = 1.0;
    if !(sigma_px > 0.0 && sigma_px.is_finite()) {
        return (wt, 0);
    }
    let r = smoothing_radius(sigma_px);
    let inv = -0.5 / (sigma_px * sigma_px);
    for (d, w) in wt.iter_mut().enumerate().take(r + 1) {
        let x = d as f32;
        *w = libm::expf(x * x * inv);
    }
    (wt, r)
}

/// [`slope_into_binned`] with the binned heights smoothed by a Gaussian of `sigma_px` binned
/// pixels first (cut at [`MAX_SMOOTH_RADIUS`]; 0 = none), so a frame sees terrain at the same
/// resolution as a reference tile whose DEM was smoothed by the same σ in metres (see
/// `TileHeader::smoothing_m`). Smoothing is normalised over valid heights and never fills:
/// a missing height stays missing. `CAP` is the widest binned row the stack rings hold
/// (`(5 + 2·MAX_SMOOTH_RADIUS + 1 + 3 + 4) · CAP · 4` bytes of stack: 124 KiB for 1024, 24 KiB
/// for the flight frame's 200).
pub fn slope_into_binned_smoothed<'b, const CAP: usize>(
    dem: &DemPatch<'_>,
    k: usize,
    sigma_px: f32,
    out: &'b mut [SlopePx],
    fill_isolated: bool,
) -> Result<SlopeImage<'b>, FrameError> {
    slope_into_binned_smoothed_counted::<CAP>(dem, k, sigma_px, out, fill_isolated)
        .map(|(img, _)| img)
}

/// [`slope_into_binned_smoothed`], also returning the smoothing's missing-height work: how many
/// column sums (one binned row's window at one column) held a missing height and were summed
/// again term by term, with their normalisers. A frame without no-data has none; each no-data
/// binned pixel adds up to `2R + 1` (its column's windows), so the count grows with the no-data
/// area and, for scattered holes, with their number (the work model charges it,
/// [`crate::cost::slope_nodata`]).
pub fn slope_into_binned_smoothed_counted<'b, const CAP: usize>(
    dem: &DemPatch<'_>,
    k: usize,
    sigma_px: f32,
    out: &'b mut [SlopePx],
    fill_isolated: bool,
) -> Result<(SlopeImage<'b>, u32), FrameError> {
    if k == 0 || k > MAX_BIN {
        return Err(FrameError::TooLarge {
            needed: k,
            capacity: MAX_BIN,
        });
    }
    let (w, h) = (dem.width() / k, dem.height() / k);
    if w == 0 || h == 0 {
        return Err(FrameError::Empty);
    }
    if w > CAP {
        return Err(FrameError::TooLarge {
            needed: w,
            capacity: CAP,
        });
    }
    let n = w * h;
    let capacity = out.len();
    let out = out.get_mut(..n).ok_or(FrameError::TooLarge {
        needed: n,
        capacity,
    })?;
    let pixel_m = dem.pixel_m() * k as f32;
    let inv8 = 1.0 / (8.0 * pixel_m);
    let half = (k * k).div_ceil(2);
    // A block needs at least half its cells valid.
    let block_mean = |sum: f32, cnt: usize| {
        if cnt >= half {
            sum / cnt as f32
        } else {
            f32::NAN
        }
    };
    let (wt, rad) = gauss_weights(sigma_px);
    let ri = rad as isize;
    let ring = 2 * rad + 1;
    // Streaming over coarse rows: block means into a 5-row ring, filled heights into a
    // (2R + 1)-row ring, smoothed heights into a 3-row ring, slope written R + 1 rows behind.
    // `DemPatch::height_at`'s validity: finite and not the nodata value (none: NaN, which no
    // height equals).
    let (dem_w, heights) = (dem.width(), dem.heights_m());
    let nd = dem.nodata_m().unwrap_or(f32::NAN);
    let mut raw = [[f32::NAN; CAP]; 5];
    let mut fil = [[f32::NAN; CAP]; SMOOTH_RING];
    let mut smo = [[f32::NAN; CAP]; 3];
    let mut num = [0.0f32; CAP];
    let mut den = [0.0f32; CAP];
    // Missing-height columns among columns 0..=c of the row (prefix counts), the normalisers of
    // clean windows and the `drow` they were computed for, and the kernel as 2R + 1 taps.
    let mut nbad = [0u32; CAP];
    let mut dconst = [0.0f32; CAP];
    let mut dconst_for = f32::NAN;
    let mut wfull = [0.0f32; SMOOTH_RING];
    let mut nodata_sums = 0u32;
    for (i, v) in wfull.iter_mut().enumerate().take(ring) {
        *v = wt.get(i.abs_diff(rad)).copied().unwrap_or(0.0);
    }
    // A function, not a closure: the compiler inlines it into every caller, which keeps the
    // firmware's slope stage at the same cost whoever calls this (HIL profile, session 12).
    #[inline(always)]
    fn ring_get<const CAP: usize>(
        rows: &[[f32; CAP]],
        ring: usize,
        (r, c): (isize, isize),
        (w, h): (usize, usize),
    ) -> f32 {
        if r < 0 || c < 0 || r as usize >= h || c as usize >= w {
            return f32::NAN;
        }
        rows.get(r as usize % ring)
            .and_then(|row| row.get(c as usize))
            .copied()
            .unwrap_or(f32::NAN)
    }
    let get = |rows: &[[f32; CAP]], ring: usize, r: isize, c: isize| -> f32 {
        ring_get(rows, ring, (r, c), (w, h))
    };
    for r_in in 0..h + 2 + rad {
        if r_in < h
            && let Some(row) = raw.get_mut(r_in % 5)
        {
            // 2 × 2 blocks (10 m frames on 20 m tiles) from two row slices: the heights of
            // `DemPatch::height_at`, in its order, without its per-call checks.
            let (top, bot) = (2 * r_in * dem_w, (2 * r_in + 1) * dem_w);
            let pairs = (k == 2)
                .then(|| {
                    heights
                        .get(top..top + 2 * w)
                        .zip(heights.get(bot..bot + 2 * w))
                })
                .flatten();
            if let Some((top, bot)) = pairs {
                for ((slot, t), b) in row
                    .iter_mut()
                    .zip(top.chunks_exact(2))
                    .zip(bot.chunks_exact(2))
                {
                    let (mut sum, mut cnt) = (0.0f32, 0usize);
                    let (&[z0, z1], &[z2, z3]) = (t, b) else {
                        continue;
                    };
                    for z in [z0, z1, z2, z3] {
                        // Branch-free; adding +0 for a refused height leaves the sum's bits
                        // as they were (it starts at +0, so it is never −0).
                        let ok = z.is_finite() && z != nd;
                        sum += if ok { z } else { 0.0 };
                        cnt += usize::from(ok);
                    }
                    *slot = block_mean(sum, cnt);
                }
            } else {
                for (c, slot) in row.iter_mut().take(w).enumerate() {
                    let (mut sum, mut cnt) = (0.0f32, 0usize);
                    for j in 0..k {
                        for i in 0..k {
                            if let Some(z) = dem.height_at(c * k + i, r_in * k + j) {
                                sum += z;
                                cnt += 1;
                            }
                        }
                    }
                    *slot = block_mean(sum, cnt);
                }
            }
        }
        // Filled row F = r_in − 1 needs raw rows F − 1 ..= F + 1.
        let f = r_in as isize - 1;
        if f >= 0
            && (f as usize) < h
            && let Some(dst) = fil.get_mut(f as usize % ring)
        {
            let centre = raw.get(f as usize % 5);
            for (c, slot) in dst.iter_mut().take(w).enumerate() {
                let ci = c as isize;
                let v = centre
                    .and_then(|row| row.get(c))
                    .copied()
                    .unwrap_or(f32::NAN);
                *slot = if !v.is_nan() || !fill_isolated {
                    v
                } else {
                    let (mut sum, mut cnt) = (0.0f32, 0usize);
                    for dr in -1..=1isize {
                        for dc in -1..=1isize {
                            let z = get(&raw, 5, f + dr, ci + dc);
                            if (dr, dc) != (0, 0) && !z.is_nan() {
                                sum += z;
                                cnt += 1;
                            }
                        }
                    }
                    if cnt >= FILL_MIN_NEIGHBOURS {
                        sum / cnt as f32
                    } else {
                        f32::NAN
                    }
                };
            }
        }
        // Smoothed row G = r_in − 1 − R needs filled rows G − R ..= G + R. Separable and
        // normalised over valid heights: vertical sums per column, then along the row.
        //
        // The sums are those of the plain normalised convolution, term for term and in the
        // same order (so host, target and earlier results agree bit for bit), but the common
        // case is cheap: a column with no missing height in its window has the row's weight
        // sum `drow` as its normaliser, and a window of such columns has a normaliser fixed
        // per column position (`dconst`). Only windows touching a missing height sum the
        // normalisers term by term (HIL: the smoothing cost ≈ 1 000 instructions a binned
        // pixel before, session 28).
        let g = r_in as isize - 1 - ri;
        if g >= 0
            && (g as usize) < h
            && let (Some(centre_row), Some(dst)) =
                (fil.get(g as usize % ring), smo.get_mut(g as usize % 3))
        {
            if rad == 0 {
                *dst = *centre_row;
            } else {
                let (lo_d, hi_d) = ((-ri).max(-g), ri.min(h as isize - 1 - g));
                let mut drow = 0.0f32;
                for d in lo_d..=hi_d {
                    drow += wt.get(d.unsigned_abs()).copied().unwrap_or(0.0);
                }
                num.iter_mut().take(w).for_each(|v| *v = 0.0);
                // Unconditional: a missing height turns the column's sum into NaN, and the
                // column is summed again below, skipping it. Four rows a sweep (one load and
                // store of each column's sum per four terms), terms still in row order.
                let wrow = |d: isize| {
                    let wd = wt.get(d.unsigned_abs()).copied().unwrap_or(0.0);
                    fil.get((g + d) as usize % ring).map(|r| (wd, r))
                };
                let mut d = lo_d;
                while d + 3 <= hi_d {
                    if let (Some((w0, r0)), Some((w1, r1)), Some((w2, r2)), Some((w3, r3))) =
                        (wrow(d), wrow(d + 1), wrow(d + 2), wrow(d + 3))
                    {
                        let rows = r0.iter().zip(r1).zip(r2).zip(r3);
                        for (a, (((&z0, &z1), &z2), &z3)) in num.iter_mut().zip(rows).take(w) {
                            let mut v = *a;
                            v += w0 * z0;
                            v += w1 * z1;
                            v += w2 * z2;
                            v += w3 * z3;
                            *a = v;
                        }
                    }
                    d += 4;
                }
                while d <= hi_d {
                    if let Some((wd, src)) = wrow(d) {
                        for (a, &z) in num.iter_mut().zip(src.iter()).take(w) {
                            *a += wd * z;
                        }
                    }
                    d += 1;
                }
                let mut bad_run = 0u32;
                for c in 0..w {
                    let (Some(a), Some(b), Some(nb)) =
                        (num.get_mut(c), den.get_mut(c), nbad.get_mut(c))
                    else {
                        continue;
                    };
                    if a.is_nan() {
                        let (mut sa, mut sb) = (0.0f32, 0.0f32);
                        for d in lo_d..=hi_d {
                            let wd = wt.get(d.unsigned_abs()).copied().unwrap_or(0.0);
                            let z = fil
                                .get((g + d) as usize % ring)
                                .and_then(|row| row.get(c))
                                .copied()
                                .unwrap_or(f32::NAN);
                            if !z.is_nan() {
                                sa += wd * z;
                                sb += wd;
                            }
                        }
                        (*a, *b) = (sa, sb);
                        bad_run += 1;
                    } else {
                        *b = drow;
                    }
                    *nb = bad_run;
                }
                nodata_sums = nodata_sums.saturating_add(bad_run);
                // Normalisers of clean windows depend on the row only through `drow`.
                if drow.to_bits() != dconst_for.to_bits() {
                    dconst_for = drow;
                    for (c, slot) in dconst.iter_mut().take(w).enumerate() {
                        let (lo, hi) = (c.saturating_sub(rad), (c + rad).min(w - 1));
                        let mut dv = 0.0f32;
                        for wd in wfull.get(lo + rad - c..=hi + rad - c).into_iter().flatten() {
                            dv += wd * drow;
                        }
                        *slot = dv;
                    }
                }
                for (c, (slot, &centre)) in
                    dst.iter_mut().zip(centre_row.iter()).take(w).enumerate()
                {
                    *slot = if centre.is_nan() {
                        centre
                    } else {
                        let (lo, hi) = (c.saturating_sub(rad), (c + rad).min(w - 1));
                        let ws = wfull.get(lo + rad - c..=hi + rad - c).unwrap_or(&[]);
                        let taps = num.get(lo..=hi).unwrap_or(&[]);
                        // Four terms a step (fewer loop instructions), still one running sum
                        // in index order.
                        let (w4, wrest) = ws.as_chunks::<4>();
                        let (t4, trest) = taps.as_chunks::<4>();
                        let mut nv = 0.0f32;
                        for ([w0, w1, w2, w3], [t0, t1, t2, t3]) in w4.iter().zip(t4) {
                            nv += w0 * t0;
                            nv += w1 * t1;
                            nv += w2 * t2;
                            nv += w3 * t3;
                        }
                        for (&wd, &a) in wrest.iter().zip(trest) {
                            nv += wd * a;
                        }
                        let before = match lo {
                            0 => 0,
                            _ => nbad.get(lo - 1).copied().unwrap_or(0),
                        };
                        let clean = nbad.get(hi).copied().unwrap_or(u32::MAX) == before;
                        let dv = if clean {
                            dconst.get(c).copied().unwrap_or(0.0)
                        } else {
                            let mut dv = 0.0f32;
                            for (&wd, &b) in ws.iter().zip(den.get(lo..=hi).unwrap_or(&[])) {
                                dv += wd * b;
                            }
                            dv
                        };
                        if dv > 0.0 { nv / dv } else { f32::NAN }
                    };
                }
            }
        }
        // Slope row S = r_in − 2 − R needs smoothed rows S − 1 ..= S + 1.
        let srow = r_in as isize - 2 - ri;
        if srow < 0 || srow as usize >= h {
            continue;
        }
        let sr = srow as usize;
        // The three smoothed rows around S, looked up once per row; interior pixels read their
        // 3 × 3 neighbourhoods as windows of them.
        let rows3 = (
            smo.get((sr + 2) % 3).and_then(|r| r.get(..w)),
            smo.get(sr % 3).and_then(|r| r.get(..w)),
            smo.get((sr + 1) % 3).and_then(|r| r.get(..w)),
        );
        let Some(dst) = out.get_mut(sr * w..sr * w + w) else {
            continue;
        };
        dst.fill(SLOPE_NODATA);
        let (Some(up), Some(mid), Some(dn)) = rows3 else {
            continue;
        };
        if sr == 0 || sr + 1 >= h {
            continue;
        }
        let windows = up.windows(3).zip(mid.windows(3)).zip(dn.windows(3));
        for (o, ((u, m), d)) in dst.iter_mut().skip(1).zip(windows) {
            let (&[a, b, c], &[dd, e, f], &[g, hh, i]) = (u, m, d) else {
                continue;
            };
            if [a, b, c, dd, e, f, g, hh, i].iter().all(|v| !v.is_nan()) {
                *o = slope_from_deg(horn_deg([a, b, c, dd, f, g, hh, i], inv8));
            }
        }
    }
    Ok((SlopeImage::new_checked(out, w, h, pixel_m)?, nodata_sums))
}

/// Widest binned frame (in binned pixels) [`slope_into_binned`] streams through its row rings.
pub const BIN_ROW_CAP: usize = 1024;

/// Horn's slope over a `w × h` grid of heights given by `z(col, row)` (`None` = no data).
fn slope_grid<'b>(
    w: usize,
    h: usize,
    pixel_m: f32,
    z: impl Fn(usize, usize) -> Option<f32>,
    out: &'b mut [SlopePx],
) -> Result<SlopeImage<'b>, FrameError> {
    let n = w * h;
    let capacity = out.len();
    let out = out.get_mut(..n).ok_or(FrameError::TooLarge {
        needed: n,
        capacity,
    })?;
    if !(pixel_m.is_finite() && pixel_m > 0.0) {
        return Err(FrameError::BadPixelSize);
    }
    let inv8 = 1.0 / (8.0 * pixel_m);
    for row in 0..h {
        for col in 0..w {
            let v = if row == 0 || col == 0 || row + 1 >= h || col + 1 >= w {
                SLOPE_NODATA
            } else {
                horn(&z, col, row, inv8).map_or(SLOPE_NODATA, slope_from_deg)
            };
            if let Some(o) = out.get_mut(row * w + col) {
                *o = v;
            }
        }
    }
    SlopeImage::new_checked(out, w, h, pixel_m)
}

/// Height at `(col, row)` from `z`, or the mean of its valid 8-neighbours when it is missing and
/// at least [`FILL_MIN_NEIGHBOURS`] of them are valid (in a fixed order, so deterministic).
fn filled(
    z: &impl Fn(usize, usize) -> Option<f32>,
    w: usize,
    h: usize,
    col: usize,
    row: usize,
) -> Option<f32> {
    if let Some(v) = z(col, row) {
        return Some(v);
    }
    let (mut sum, mut n) = (0.0f32, 0usize);
    for dr in 0..3usize {
        for dc in 0..3usize {
            let (c, r) = (col + dc, row + dr);
            if (dc, dr) == (1, 1) || c == 0 || r == 0 || c > w || r > h {
                continue;
            }
            if let Some(v) = z(c - 1, r - 1) {
                sum += v;
                n += 1;
            }
        }
    }
    (n >= FILL_MIN_NEIGHBOURS).then(|| sum / n as f32)
}

/// Horn slope in degrees at an interior pixel; `None` if any of the 9 heights is masked.
#[inline]
fn horn(
    z: &impl Fn(usize, usize) -> Option<f32>,
    col: usize,
    row: usize,
    inv8: f32,
) -> Option<f32> {
    let z = |dc: usize, dr: usize| z(col + dc - 1, row + dr - 1);
    let (a, b, c) = (z(0, 0)?, z(1, 0)?, z(2, 0)?);
    let (d, f) = (z(0, 1)?, z(2, 1)?);
    let (g, hh, i) = (z(0, 2)?, z(1, 2)?, z(2, 2)?);
    // Centre height is not used by Horn's operator but a masked centre must still mask the pixel.
    z(1, 1)?;
    Some(horn_deg([a, b, c, d, f, g, hh, i], inv8))
}

/// Horn's slope in degrees from the eight neighbours `[a, b, c, d, f, g, h, i]` (rows top to
/// bottom, left to right, centre left out) and `1 / (8 · pixel)`.
#[inline(always)]
fn horn_deg([a, b, c, d, f, g, hh, i]: [f32; 8], inv8: f32) -> f32 {
    let dzdx = ((c + 2.0 * f + i) - (a + 2.0 * d + g)) * inv8;
    let dzdy = ((g + 2.0 * hh + i) - (a + 2.0 * b + c)) * inv8;
    let grad = libm::sqrtf(dzdx * dzdx + dzdy * dzdy);
    // Overflowing gradients (huge heights) give +inf → atan = 90°, still a valid slope; NaN masks.
    libm::atanf(grad) * DEG_PER_RAD
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{SLOPE_LSB_DEG, slope_is_valid, slope_to_deg};

    fn plane(w: usize, h: usize, px: f32, gx: f32, gy: f32) -> [f32; 64] {
        let mut z = [0.0f32; 64];
        for r in 0..h {
            for c in 0..w {
                z[r * w + c] = gx * c as f32 * px + gy * r as f32 * px + 100.0;
            }
        }
        z
    }

    #[test]
    fn tilted_plane_gives_its_slope() {
        let (gx, gy) = (0.3f32, -0.4f32); // |∇z| = 0.5
        let z = plane(8, 8, 10.0, gx, gy);
        let dem = DemPatch::new_checked(&z, 8, 8, 10.0).unwrap();
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into(&dem, &mut out).unwrap();
        let expect = libm::atanf(0.5) * DEG_PER_RAD;
        for r in 1..7 {
            for c in 1..7 {
                let got = slope_to_deg(img.get(c, r)).unwrap();
                assert!((got - expect).abs() <= SLOPE_LSB_DEG, "{got} vs {expect}");
            }
        }
        // Borders are masked.
        assert!(!slope_is_valid(img.get(0, 3)));
        assert!(!slope_is_valid(img.get(7, 7)));
    }

    #[test]
    fn nodata_masks_its_neighbourhood() {
        let mut z = plane(8, 8, 5.0, 0.1, 0.0);
        z[3 * 8 + 3] = f32::NAN;
        z[5 * 8 + 6] = -9999.0;
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0)
            .unwrap()
            .with_nodata(-9999.0);
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into(&dem, &mut out).unwrap();
        for r in 1..7usize {
            for c in 1..7usize {
                let near_nan = r.abs_diff(3) <= 1 && c.abs_diff(3) <= 1;
                let near_nodata = r.abs_diff(5) <= 1 && c.abs_diff(6) <= 1;
                assert_eq!(slope_is_valid(img.get(c, r)), !(near_nan || near_nodata));
            }
        }
    }

    #[test]
    fn isolated_dropouts_are_filled_when_asked() {
        let mut z = plane(8, 8, 5.0, 0.1, 0.2);
        z[3 * 8 + 3] = f32::NAN;
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into_with(&dem, &mut out, true).unwrap();
        // The plane's slope everywhere inside, the hole filled by its neighbours' mean (exact on
        // a plane).
        let expect = libm::atanf(libm::sqrtf(0.01 + 0.04)) * DEG_PER_RAD;
        for r in 1..7 {
            for c in 1..7 {
                let got = slope_to_deg(img.get(c, r)).unwrap();
                assert!(
                    (got - expect).abs() <= 2.0 * SLOPE_LSB_DEG,
                    "{got} vs {expect}"
                );
            }
        }
        // A 3 × 3 hole is too large: its centre stays masked.
        let mut z = plane(8, 8, 5.0, 0.1, 0.2);
        for r in 2..5 {
            for c in 2..5 {
                z[r * 8 + c] = f32::NAN;
            }
        }
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let img = slope_into_with(&dem, &mut out, true).unwrap();
        assert!(!slope_is_valid(img.get(3, 3)));
    }

    #[test]
    fn binning_averages_blocks_and_keeps_the_slope_of_a_plane() {
        let z = plane(8, 8, 5.0, 0.3, -0.4);
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let mut out = [SLOPE_NODATA; 64];
        let img = slope_into_binned(&dem, 2, &mut out, false).unwrap();
        assert_eq!((img.width(), img.height(), img.pixel_m()), (4, 4, 10.0));
        let expect = libm::atanf(0.5) * DEG_PER_RAD;
        for r in 1..3 {
            for c in 1..3 {
                assert!((slope_to_deg(img.get(c, r)).unwrap() - expect).abs() <= SLOPE_LSB_DEG);
            }
        }
        assert!(slope_into_binned(&dem, 0, &mut out, false).is_err());
        assert!(slope_into_binned(&dem, 9, &mut out, false).is_err());
    }

    #[test]
    fn output_too_small_is_an_error() {
        let z = [0.0f32; 64];
        let dem = DemPatch::new_checked(&z, 8, 8, 5.0).unwrap();
        let mut out = [SLOPE_NODATA; 10];
        assert!(matches!(
            slope_into(&dem, &mut out),
            Err(FrameError::TooLarge {
                needed: 64,
                capacity: 10
            })
        ));
    }

    #[test]
    fn smoothing_keeps_planes_lowers_noise_and_never_fills() {
        const N: usize = 40;
        let mut z = [0.0f32; N * N];
        let mut noisy = [0.0f32; N * N];
        // Deterministic ±1 m checkerboard-ish roughness on a 0.2-gradient plane.
        for r in 0..N {
            for c in 0..N {
                let p = 0.2 * (c as f32) * 10.0 + 50.0;
                z[r * N + c] = p;
                let e = ((r * 7 + c * 13) % 5) as f32 * 0.5 - 1.0;
                noisy[r * N + c] = p + e;
            }
        }
        let expect = libm::atanf(0.2) * DEG_PER_RAD;
        let mut out = [SLOPE_NODATA; N * N];
        let dem = DemPatch::new_checked(&z, N, N, 10.0).unwrap();
        let img = slope_into_binned_smoothed::<N>(&dem, 1, 1.5, &mut out, false).unwrap();
        for r in 6..N - 6 {
            for c in 6..N - 6 {
                let got = slope_to_deg(img.get(c, r)).unwrap();
                assert!((got - expect).abs() <= SLOPE_LSB_DEG, "{got} vs {expect}");
            }
        }
        let spread = |sigma: f32| -> f32 {
            let mut out = [SLOPE_NODATA; N * N];
            let dem = DemPatch::new_checked(&noisy, N, N, 10.0).unwrap();
            let img = slope_into_binned_smoothed::<N>(&dem, 1, sigma, &mut out, false).unwrap();
            let mut worst = 0.0f32;
            for r in 6..N - 6 {
                for c in 6..N - 6 {
                    worst = worst.max((slope_to_deg(img.get(c, r)).unwrap() - expect).abs());
                }
            }
            worst
        };
        let (raw, smooth) = (spread(0.0), spread(1.5));
        assert!(smooth < 0.25 * raw, "{smooth} vs {raw}");
        // A hole stays a hole (and masks its 3 × 3 slope block), nothing else is lost.
        let mut holed = z;
        holed[20 * N + 20] = f32::NAN;
        let dem = DemPatch::new_checked(&holed, N, N, 10.0).unwrap();
        let img = slope_into_binned_smoothed::<N>(&dem, 1, 1.5, &mut out, false).unwrap();
        for r in 1..N - 1 {
            for c in 1..N - 1 {
                let near = r.abs_diff(20) <= 1 && c.abs_diff(20) <= 1;
                assert_eq!(slope_is_valid(img.get(c, r)), !near, "({c}, {r})");
            }
        }
        // The smoothing's missing-height work: none without a hole; one interior hole is held by
        // its column's window in each of the 2R + 1 rows that reach it (R = 5 for σ 1.5), one
        // at a frame edge by the R + 1 inside; no smoothing, no such work.
        let count = |z: &[f32], sigma: f32| {
            let mut out = [SLOPE_NODATA; N * N];
            let dem = DemPatch::new_checked(z, N, N, 10.0).unwrap();
            slope_into_binned_smoothed_counted::<N>(&dem, 1, sigma, &mut out, false)
                .unwrap()
                .1
        };
        assert_eq!(smoothing_radius(1.5), 5);
        assert_eq!(count(&z, 1.5), 0);
        assert_eq!(count(&holed, 1.5), 11);
        assert_eq!(count(&holed, 0.0), 0);
        let mut edge = z;
        edge[20] = f32::NAN;
        assert_eq!(count(&edge, 1.5), 6);
        let mut two = holed;
        two[20 * N + 21] = f32::NAN;
        assert_eq!(count(&two, 1.5), 22);
        // Bad σ means no smoothing, a row wider than CAP a typed error; never a panic.
        for bad in [f32::NAN, -1.0, f32::INFINITY] {
            assert!(slope_into_binned_smoothed::<N>(&dem, 1, bad, &mut out, false).is_ok());
        }
        assert!(slope_into_binned_smoothed::<{ N - 1 }>(&dem, 1, 1.0, &mut out, false).is_err());
        assert!(slope_into_binned_smoothed::<N>(&dem, 2, 100.0, &mut out, false).is_ok());
    }

    /// The plain normalised convolution, summed in the order the streaming code promises:
    /// per column over the window's rows, then along the row.
    fn plain_smoothed(z: &[f32], w: usize, h: usize, sigma: f32) -> [f32; 48 * 48] {
        let (wt, r) = gauss_weights(sigma);
        let ri = r as isize;
        let mut out = [f32::NAN; 48 * 48];
        let mut num = [0.0f32; 48 * 48];
        let mut den = [0.0f32; 48 * 48];
        for g in 0..h as isize {
            for c in 0..w {
                let (mut a, mut b) = (0.0f32, 0.0f32);
                for d in -ri..=ri {
                    let rr = g + d;
                    if rr < 0 || rr as usize >= h {
                        continue;
                    }
                    let v = z[rr as usize * w + c];
                    if !v.is_nan() {
                        a += wt[d.unsigned_abs()] * v;
                        b += wt[d.unsigned_abs()];
                    }
                }
                num[g as usize * w + c] = a;
                den[g as usize * w + c] = b;
            }
        }
        for g in 0..h {
            for c in 0..w {
                if z[g * w + c].is_nan() {
                    continue;
                }
                let (lo, hi) = (c.saturating_sub(r), (c + r).min(w - 1));
                let (mut nv, mut dv) = (0.0f32, 0.0f32);
                for j in lo..=hi {
                    nv += wt[j.abs_diff(c)] * num[g * w + j];
                    dv += wt[j.abs_diff(c)] * den[g * w + j];
                }
                out[g * w + c] = if dv > 0.0 { nv / dv } else { f32::NAN };
            }
        }
        out
    }

    #[test]
    fn streaming_smoothing_is_the_plain_convolution_bit_for_bit() {
        const N: usize = 48;
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut unit = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for (case, sigma) in [0.7f32, 1.5, 2.0, 2.5, 3.1, 20.0].into_iter().enumerate() {
            let mut z = [0.0f32; N * N];
            for (i, v) in z.iter_mut().enumerate() {
                let (x, y) = ((i % N) as f32, (i / N) as f32);
                *v = 30.0 * libm::sinf(0.21 * x + 0.1 * y) + 5.0 * unit() - 1700.0;
            }
            // Holes: scattered dropouts, a block, a border run, a whole row (the case index
            // moves them, so each σ sees its own pattern).
            for _ in 0..20 + 10 * case {
                let i = (unit() * (N * N) as f32) as usize % (N * N);
                z[i] = f32::NAN;
            }
            for r in 10 + case..16 + case {
                for c in 30..37 {
                    z[r * N + c] = f32::NAN;
                }
            }
            for r in 0..N / 2 {
                z[r * N + (N - 1 - case)] = f32::NAN;
            }
            for c in 0..N {
                z[(40 - case) * N + c] = f32::NAN;
            }
            let reference = plain_smoothed(&z, N, N, sigma);
            let (mut a, mut b) = ([SLOPE_NODATA; N * N], [SLOPE_NODATA; N * N]);
            let dem = DemPatch::new_checked(&z, N, N, 10.0).unwrap();
            let fast = slope_into_binned_smoothed::<N>(&dem, 1, sigma, &mut a, false).unwrap();
            let dem_ref = DemPatch::new_checked(&reference, N, N, 10.0).unwrap();
            let plain = slope_into_binned_smoothed::<N>(&dem_ref, 1, 0.0, &mut b, false).unwrap();
            let mut valid = 0;
            for r in 0..N {
                for c in 0..N {
                    assert_eq!(fast.get(c, r), plain.get(c, r), "σ {sigma} at ({c}, {r})");
                    valid += usize::from(slope_is_valid(fast.get(c, r)));
                }
            }
            assert!(valid > N * N / 2, "σ {sigma}: only {valid} valid slopes");
        }
    }

    #[test]
    fn binning_is_the_block_mean_of_valid_heights_bit_for_bit() {
        const N: usize = 96;
        let mut z = [0.0f32; N * N];
        for (i, v) in z.iter_mut().enumerate() {
            let (x, y) = ((i % N) as f32, (i / N) as f32);
            *v = 20.0 * libm::sinf(0.13 * x - 0.07 * y) + 0.37 * x + 1734.25;
            // Dropouts, infinities and the nodata value, some blocks losing most of their cells.
            match (i * 7919) % 97 {
                0 | 1 => *v = f32::NAN,
                2 => *v = f32::INFINITY,
                3 | 4 => *v = -9999.0,
                _ => {}
            }
        }
        for k in [2usize, 3] {
            let (w, h) = (N / k, N / k);
            let mut binned = [f32::NAN; N * N];
            for r in 0..h {
                for c in 0..w {
                    let (mut sum, mut cnt) = (0.0f32, 0usize);
                    for j in 0..k {
                        for i in 0..k {
                            let v = z[(r * k + j) * N + c * k + i];
                            if v.is_finite() && v != -9999.0 {
                                sum += v;
                                cnt += 1;
                            }
                        }
                    }
                    if cnt >= (k * k).div_ceil(2) {
                        binned[r * w + c] = sum / cnt as f32;
                    }
                }
            }
            let (mut a, mut b) = ([SLOPE_NODATA; N * N], [SLOPE_NODATA; N * N]);
            let dem = DemPatch::new_checked(&z, N, N, 10.0)
                .unwrap()
                .with_nodata(-9999.0);
            let fast = slope_into_binned_smoothed::<N>(&dem, k, 1.5, &mut a, false).unwrap();
            let dem_ref = DemPatch::new_checked(&binned[..w * h], w, h, 10.0 * k as f32).unwrap();
            let plain = slope_into_binned_smoothed::<N>(&dem_ref, 1, 1.5, &mut b, false).unwrap();
            assert_eq!((fast.width(), fast.height()), (w, h));
            assert!(fast.pixels().iter().filter(|p| slope_is_valid(**p)).count() > w * h / 2);
            assert_eq!(fast.pixels(), plain.pixels(), "k = {k}");
        }
    }
}
