//! Pictures of DEMs: hillshade, colour-mapped elevation and slope with labelled colour bars
//! (the paper's Fig. 4a, b, d, e). Text uses the `font8x8` bitmap glyphs, so no system font is
//! needed and the output is identical everywhere.
//!
//! Image axes follow the DEM: column → right (east), row → down (south for north-up grids).

use std::path::Path;

use image::{Rgb, RgbImage};

use crate::dem::stats::slope_deg;
use crate::dem::{Dem, DemError};

/// Glyph scale: 8×8 font glyphs drawn as 16×16 pixels.
const FONT_SCALE: u32 = 2;
/// Character cell of [`draw_text`] in output pixels.
pub const GLYPH: u32 = 8 * FONT_SCALE;
/// Largest picture side; bigger DEMs are decimated for display.
pub const MAX_PICTURE_SIDE: usize = 2048;
/// Colour-bar width in pixels.
const BAR_W: u32 = 24;
/// Fixed slope colour range, degrees (so that slope pictures of different scenes compare).
pub const SLOPE_RANGE_DEG: (f64, f64) = (0.0, 40.0);
/// Colour of nodata pixels.
const NODATA_RGB: [u8; 3] = [96, 96, 96];

/// Sun for hillshades: azimuth clockwise from north and elevation, degrees.
#[derive(Debug, Clone, Copy)]
pub struct Sun {
    /// Azimuth from north, clockwise, degrees.
    pub azimuth_deg: f64,
    /// Elevation above the horizon, degrees.
    pub elevation_deg: f64,
}

impl Default for Sun {
    /// The cartographic convention (light from the north-west, 35° high), which reads relief
    /// best; the real polar sun is within ~1.5° of the horizon and would leave PSRs black.
    fn default() -> Self {
        Self {
            azimuth_deg: 315.0,
            elevation_deg: 35.0,
        }
    }
}

/// Viridis-like perceptually ordered map (9 stops) for elevation.
const ELEV_STOPS: [[u8; 3]; 9] = [
    [68, 1, 84],
    [71, 44, 122],
    [59, 81, 139],
    [44, 113, 142],
    [33, 144, 141],
    [39, 173, 129],
    [92, 200, 99],
    [170, 220, 50],
    [253, 231, 37],
];

/// Magma-like map (8 stops) for slope: dark = flat, bright = steep.
const SLOPE_STOPS: [[u8; 3]; 8] = [
    [0, 0, 4],
    [28, 16, 68],
    [79, 18, 123],
    [129, 37, 129],
    [181, 54, 122],
    [229, 80, 100],
    [251, 135, 97],
    [252, 253, 191],
];

fn colormap(stops: &[[u8; 3]], t: f64) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (stops.len() - 1) as f64;
    let i = (x as usize).min(stops.len() - 2);
    let f = x - i as f64;
    let (a, b) = (stops[i], stops[i + 1]);
    std::array::from_fn(|k| {
        (f64::from(a[k]) + f * (f64::from(b[k]) - f64::from(a[k]))).round() as u8
    })
}

/// Decimation stride so that the picture fits [`MAX_PICTURE_SIDE`].
fn stride(dem: &Dem) -> usize {
    dem.width()
        .max(dem.height())
        .div_ceil(MAX_PICTURE_SIDE)
        .max(1)
}

/// Lambertian hillshade in [0, 1] per pixel (`NaN` where the gradient is unknown).
pub fn hillshade(dem: &Dem, sun: Sun) -> Result<Vec<f32>, DemError> {
    let px = dem.pixel_m()?;
    let (w, h) = (dem.width(), dem.height());
    let az = sun.azimuth_deg.to_radians();
    let el = sun.elevation_deg.to_radians();
    // Unit vector to the sun in (east, north, up).
    let (sx, sy, sz) = (el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
    let mut out = vec![f32::NAN; w * h];
    for r in 0..h {
        for c in 0..w {
            let at = |cc: usize, rr: usize| dem.get(cc, rr).map(f64::from);
            let (cl, cr) = (c.saturating_sub(1), (c + 1).min(w - 1));
            let (ru, rd) = (r.saturating_sub(1), (r + 1).min(h - 1));
            let (Some(zl), Some(zr), Some(zu), Some(zd)) =
                (at(cl, r), at(cr, r), at(c, ru), at(c, rd))
            else {
                continue;
            };
            let dzdx = (zr - zl) / ((cr - cl).max(1) as f64 * px);
            // Rows grow southwards: north gradient is (up − down).
            let dzdy = (zu - zd) / ((rd - ru).max(1) as f64 * px);
            let norm = (dzdx * dzdx + dzdy * dzdy + 1.0).sqrt();
            let v = (-dzdx * sx - dzdy * sy + sz) / norm;
            out[r * w + c] = v.max(0.0) as f32;
        }
    }
    Ok(out)
}

/// "Nice" tick values covering `[lo, hi]` (steps of 1, 2 or 5 × 10^k, about 4–8 ticks).
pub fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return vec![lo];
    }
    let raw = (hi - lo) / 7.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() * step;
    let mut v = Vec::new();
    let mut t = first;
    while t <= hi + 1e-9 * step {
        v.push(if t.abs() < 1e-9 * step { 0.0 } else { t });
        t += step;
    }
    v
}

/// Format a tick value with as many decimals as its step needs.
pub fn fmt_tick(v: f64, step: f64) -> String {
    if step >= 1.0 {
        format!("{v:.0}")
    } else {
        let decimals = (-step.log10()).ceil() as usize;
        format!("{v:.decimals$}")
    }
}

/// Draw `text` with its top-left corner at `(x, y)` (8×8 glyphs scaled by the picture font
/// scale; [`GLYPH`] pixels per character).
pub fn draw_text(img: &mut RgbImage, x: u32, y: u32, text: &str, colour: [u8; 3]) {
    for (k, ch) in text.chars().enumerate() {
        let glyph = font8x8::legacy::BASIC_LEGACY
            .get(ch as usize)
            .copied()
            .unwrap_or([0; 8]);
        let gx = x + k as u32 * GLYPH;
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8u32 {
                if bits & (1 << col) == 0 {
                    continue;
                }
                for dy in 0..FONT_SCALE {
                    for dx in 0..FONT_SCALE {
                        let (px, py) =
                            (gx + col * FONT_SCALE + dx, y + row as u32 * FONT_SCALE + dy);
                        if px < img.width() && py < img.height() {
                            img.put_pixel(px, py, Rgb(colour));
                        }
                    }
                }
            }
        }
    }
}

/// A map panel: `rgb` for each (decimated) DEM pixel, plus title, colour bar and scale bar.
struct Panel {
    w: u32,
    h: u32,
    rgb: Vec<[u8; 3]>,
}

const TOP: u32 = 8 + GLYPH + 8;
const LEFT: u32 = 8;
const BOTTOM: u32 = 8;

fn compose(
    panel: &Panel,
    title: &str,
    bar: Option<(&[[u8; 3]], f64, f64, &str)>,
    pixel_m: f64,
) -> RgbImage {
    let label_w = 9 * GLYPH;
    let right = if bar.is_some() {
        16 + BAR_W + 8 + label_w
    } else {
        8
    };
    let title_w = LEFT + title.chars().count() as u32 * GLYPH + 8;
    let (w, h) = (
        (LEFT + panel.w + right).max(title_w),
        TOP + panel.h.max(160) + BOTTOM,
    );
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    for y in 0..panel.h {
        for x in 0..panel.w {
            let c = panel.rgb[(y * panel.w + x) as usize];
            img.put_pixel(LEFT + x, TOP + y, Rgb(c));
        }
    }
    draw_text(&mut img, LEFT, 8, title, [0, 0, 0]);
    scale_bar(&mut img, panel, pixel_m);
    if let Some((stops, lo, hi, unit)) = bar {
        let bx = LEFT + panel.w + 16;
        let (by, bh) = (TOP, panel.h.max(160));
        for y in 0..bh {
            let t = 1.0 - f64::from(y) / f64::from(bh - 1);
            let c = colormap(stops, t);
            for x in 0..BAR_W {
                img.put_pixel(bx + x, by + y, Rgb(c));
            }
        }
        let tk = ticks(lo, hi);
        let step = if tk.len() > 1 { tk[1] - tk[0] } else { 1.0 };
        for v in tk {
            let t = if hi > lo { (v - lo) / (hi - lo) } else { 0.5 };
            let y = by + ((1.0 - t) * f64::from(bh - 1)).round() as u32;
            for x in 0..6 {
                img.put_pixel(bx + BAR_W + x, y, Rgb([0, 0, 0]));
            }
            let text = format!("{} {unit}", fmt_tick(v, step));
            let ty = y
                .saturating_sub(GLYPH / 2)
                .clamp(TOP.saturating_sub(4), h - GLYPH);
            draw_text(&mut img, bx + BAR_W + 8, ty, &text, [0, 0, 0]);
        }
    }
    img
}

/// A round scale-bar length (1, 2 or 5 × a power of ten) at most `target`, in the same unit.
pub fn scale_bar_length(target: f64) -> f64 {
    let mag = 10f64.powf(target.log10().floor());
    [5.0, 2.0, 1.0]
        .iter()
        .map(|m| m * mag)
        .find(|l| *l <= target)
        .unwrap_or(mag)
}

/// A white scale bar with a black outline and its length, bottom-left of the map.
fn scale_bar(img: &mut RgbImage, panel: &Panel, pixel_m: f64) {
    let map_w_m = f64::from(panel.w) * pixel_m;
    let len_m = scale_bar_length(map_w_m / 4.0);
    let len_px = (len_m / pixel_m).round() as u32;
    if len_px < 4 || panel.h < 3 * GLYPH {
        return;
    }
    let (x0, y0) = (LEFT + 8, TOP + panel.h - 12);
    for x in x0.saturating_sub(1)..=x0 + len_px + 1 {
        for y in y0 - 1..=y0 + 5 {
            let edge = x < x0 || x > x0 + len_px || y < y0 || y > y0 + 4;
            img.put_pixel(x, y, Rgb(if edge { [0, 0, 0] } else { [255, 255, 255] }));
        }
    }
    let text = if len_m >= 1000.0 {
        format!("{} km", len_m / 1000.0)
    } else {
        format!("{len_m} m")
    };
    let ty = y0 - 4 - GLYPH;
    // Outline the label so it reads on any background.
    for (dx, dy) in [(0i32, 1i32), (2, 1), (1, 0), (1, 2)] {
        draw_text(
            img,
            (x0 as i32 + dx - 1) as u32,
            (ty as i32 + dy - 1) as u32,
            &text,
            [0, 0, 0],
        );
    }
    draw_text(img, x0, ty, &text, [255, 255, 255]);
}

fn decimated<T: Copy>(v: &[T], w: usize, h: usize, s: usize) -> (u32, u32, Vec<T>) {
    let (dw, dh) = (w.div_ceil(s), h.div_ceil(s));
    let mut out = Vec::with_capacity(dw * dh);
    for r in (0..h).step_by(s) {
        for c in (0..w).step_by(s) {
            out.push(v[r * w + c]);
        }
    }
    (dw as u32, dh as u32, out)
}

/// Grey hillshade picture with title and scale bar.
pub fn hillshade_image(dem: &Dem, sun: Sun) -> Result<RgbImage, DemError> {
    let hs = hillshade(dem, sun)?;
    let s = stride(dem);
    let (w, h, v) = decimated(&hs, dem.width(), dem.height(), s);
    let rgb = v
        .into_iter()
        .map(|x| {
            if x.is_finite() {
                let g = (x * 255.0).round() as u8;
                [g, g, g]
            } else {
                NODATA_RGB
            }
        })
        .collect();
    let title = format!(
        "hillshade (sun az {:.0}, el {:.0} deg)",
        sun.azimuth_deg, sun.elevation_deg
    );
    Ok(compose(
        &Panel { w, h, rgb },
        &title,
        None,
        dem.pixel_m()? * s as f64,
    ))
}

/// Colour-mapped elevation, shaded by the hillshade, with a colour bar in metres.
pub fn elevation_image(dem: &Dem) -> Result<RgbImage, DemError> {
    let hs = hillshade(dem, Sun::default())?;
    let (lo, hi) = dem
        .heights_m()
        .iter()
        .filter(|h| h.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(f64::from(h)), b.max(f64::from(h)))
        });
    if !lo.is_finite() {
        return Err(DemError::Invalid("the DEM has no valid height".into()));
    }
    let s = stride(dem);
    let (w, h, z) = decimated(dem.heights_m(), dem.width(), dem.height(), s);
    let (_, _, shade) = decimated(&hs, dem.width(), dem.height(), s);
    let span = (hi - lo).max(1e-6);
    let rgb = z
        .iter()
        .zip(&shade)
        .map(|(&v, &sh)| {
            if !v.is_finite() {
                return NODATA_RGB;
            }
            let c = colormap(&ELEV_STOPS, (f64::from(v) - lo) / span);
            // Blend 65 % colour with 35 % relief shading so both elevation and texture read.
            let k = if sh.is_finite() {
                0.65 + 0.35 * f64::from(sh) / 0.82
            } else {
                1.0
            };
            c.map(|x| (f64::from(x) * k).clamp(0.0, 255.0) as u8)
        })
        .collect();
    Ok(compose(
        &Panel { w, h, rgb },
        "elevation",
        Some((&ELEV_STOPS, lo, hi, "m")),
        dem.pixel_m()? * s as f64,
    ))
}

/// Slope (nav-core's Horn slope) colour-mapped over 0–40°, with a colour bar in degrees.
pub fn slope_image(dem: &Dem) -> Result<RgbImage, DemError> {
    let sl = slope_deg(dem)?;
    let s = stride(dem);
    let (w, h, v) = decimated(&sl, dem.width(), dem.height(), s);
    let (lo, hi) = SLOPE_RANGE_DEG;
    let rgb = v
        .into_iter()
        .map(|x| {
            if x.is_finite() {
                colormap(&SLOPE_STOPS, (f64::from(x) - lo) / (hi - lo))
            } else {
                NODATA_RGB
            }
        })
        .collect();
    Ok(compose(
        &Panel { w, h, rgb },
        "slope",
        Some((&SLOPE_STOPS, lo, hi, "deg")),
        dem.pixel_m()? * s as f64,
    ))
}

/// Cyclic map (red → yellow → green → cyan → blue → magenta → red) for wrapped phases.
const PHASE_STOPS: [[u8; 3]; 7] = [
    [220, 40, 40],
    [230, 200, 40],
    [60, 190, 60],
    [40, 200, 210],
    [50, 70, 220],
    [200, 50, 200],
    [220, 40, 40],
];

/// Black to white.
const GREY_STOPS: [[u8; 3]; 2] = [[0, 0, 0], [255, 255, 255]];

/// Diverging blue–white–red map for signed errors.
const DIVERGING_STOPS: [[u8; 3]; 5] = [
    [33, 102, 172],
    [146, 197, 222],
    [247, 247, 247],
    [244, 165, 130],
    [178, 24, 43],
];

/// Categorical colours for the InSAR mask codes 0–4 (valid, layover, shadow, low coherence,
/// outside); one stop per code so that integer values hit their colour exactly.
const MASK_STOPS: [[u8; 3]; 5] = [
    [235, 235, 235],
    [230, 120, 20],
    [30, 30, 120],
    [180, 40, 160],
    [120, 120, 120],
];

/// Colour maps offered by [`raster_image`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColourMap {
    /// Viridis-like elevation map.
    Elevation,
    /// Magma-like slope map.
    Slope,
    /// Cyclic map for wrapped phases (the two ends have one colour).
    Phase,
    /// Grey ramp (e.g. coherence).
    Grey,
    /// Blue–white–red for signed differences.
    Diverging,
    /// Five categorical colours for integer codes 0–4 over `lo = 0`, `hi = 4`.
    Mask,
}

impl ColourMap {
    fn stops(self) -> &'static [[u8; 3]] {
        match self {
            Self::Elevation => &ELEV_STOPS,
            Self::Slope => &SLOPE_STOPS,
            Self::Phase => &PHASE_STOPS,
            Self::Grey => &GREY_STOPS,
            Self::Diverging => &DIVERGING_STOPS,
            Self::Mask => &MASK_STOPS,
        }
    }
}

/// Title, colours and value range of a [`raster_image`].
#[derive(Debug, Clone, Copy)]
pub struct RasterStyle<'a> {
    /// Title above the map.
    pub title: &'a str,
    /// Colour map.
    pub map: ColourMap,
    /// Values mapped to the two ends of the colour map.
    pub range: (f64, f64),
    /// Unit written after the colour-bar ticks.
    pub unit: &'a str,
}

/// Any raster (`w × h`, row-major, NaN = nodata in grey) colour-mapped over `[lo, hi]` with a
/// title, a colour bar labelled in `unit` and a scale bar for `pixel_m`. Rasters smaller than
/// 300 px a side are magnified by an integer factor (nearest neighbour) for legibility.
pub fn raster_image(
    values: &[f32],
    w: usize,
    h: usize,
    pixel_m: f64,
    style: &RasterStyle<'_>,
) -> RgbImage {
    let RasterStyle {
        title,
        map,
        range: (lo, hi),
        unit,
    } = *style;
    let side = w.max(h).max(1);
    let s = side.div_ceil(MAX_PICTURE_SIDE).max(1);
    let (dw, dh, v) = decimated(values, w, h, s);
    let mag = (600 / (dw.max(dh).max(1) as usize)).max(1) as u32;
    let (pw, ph) = (dw * mag, dh * mag);
    let stops = map.stops();
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut rgb = Vec::with_capacity((pw * ph) as usize);
    for y in 0..ph {
        for x in 0..pw {
            let val = v[((y / mag) * dw + x / mag) as usize];
            rgb.push(if val.is_finite() {
                colormap(stops, (f64::from(val) - lo) / span)
            } else {
                NODATA_RGB
            });
        }
    }
    compose(
        &Panel { w: pw, h: ph, rgb },
        title,
        Some((stops, lo, hi, unit)),
        pixel_m * s as f64 / f64::from(mag),
    )
}

/// Write the three pictures as `hillshade.png`, `elevation.png`, `slope.png` in `dir`; returns
/// the paths written.
pub fn write_pictures(dem: &Dem, dir: &Path) -> Result<Vec<std::path::PathBuf>, DemError> {
    std::fs::create_dir_all(dir).map_err(|source| DemError::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let mut out = Vec::new();
    for (name, img) in [
        ("hillshade.png", hillshade_image(dem, Sun::default())?),
        ("elevation.png", elevation_image(dem)?),
        ("slope.png", slope_image(dem)?),
    ] {
        let path = dir.join(name);
        img.save(&path).map_err(|e| DemError::Io {
            path: path.display().to_string(),
            source: std::io::Error::other(e.to_string()),
        })?;
        out.push(path);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        assert_eq!(ticks(0.0, 40.0), vec![0.0, 10.0, 20.0, 30.0, 40.0]);
        let t = ticks(468.3, 593.1);
        assert_eq!(t.first().copied(), Some(480.0));
        assert!(t.iter().all(|v| (468.3..=593.1).contains(v)));
        assert_eq!(fmt_tick(0.5, 0.1), "0.5");
    }

    #[test]
    fn colormap_ends_are_the_stops() {
        assert_eq!(colormap(&ELEV_STOPS, 0.0), ELEV_STOPS[0]);
        assert_eq!(colormap(&ELEV_STOPS, 1.0), ELEV_STOPS[8]);
        assert_eq!(colormap(&ELEV_STOPS, f64::NAN), ELEV_STOPS[0]);
    }
}
