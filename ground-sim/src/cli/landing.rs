//! `ground-sim landing-zone`: a fine truth DEM around a landing target (rocks, small craters,
//! sub-metre roughness) over a coarse scene, with its truth safety map.
//!
//! Writes `landing_zone.tif` (GeoTIFF, the coarse DEM's CRS), `landing_zone.png` (hillshade with
//! the unsafe sites tinted) and `landing_zone.json` (configuration, seed, counts against the
//! models, safe fraction, timing) into `--out`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use ground_sim::dem::stats::slope_deg;
use ground_sim::dem::{
    Dem, DemError, GeoRef, GeoTransform, SampleKind, read_geotiff, write_geotiff,
};
use ground_sim::pictures::render::{GLYPH, Sun, draw_text, hillshade, scale_bar_length};
use ground_sim::terrain::landing::{
    DEFAULT_ROCK_K, DEFAULT_TAPER_M, LandingZoneConfig, LandingZoneReport, SafetyMap,
    SafetyThresholds, landing_zone_with_report, safety_map,
};
use ground_sim::terrain::roughness::rms_lag1;
use ground_sim::terrain::{Preset, TerrainParams, Window, generate};
use image::{Rgb, RgbImage};

/// Arguments of `ground-sim landing-zone`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("coarse").required(true).args(["preset", "dem"])))]
pub struct Args {
    /// Coarse scene: a synthetic preset, generated as `terrain` does (with `--seed`,
    /// `--window`, `--scene-size-m`, `--scene-pixel-m`). The zone's roughness continues the
    /// preset's (its H and ν5).
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// Coarse scene: a north-up GeoTIFF DEM instead of a preset.
    #[arg(long)]
    pub dem: Option<PathBuf>,
    /// Window placement of the preset scene in its host crater.
    #[arg(long, value_enum, default_value = "floor")]
    pub window: Window,
    /// PRNG seed of the coarse scene and of the zone (same seed → bit-identical outputs).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Side of the preset scene, metres (default: the descent campaigns' 16 km maps).
    #[arg(long, default_value_t = 16_000.0)]
    pub scene_size_m: f64,
    /// Pixel of the preset scene, metres (default: the descent campaigns' 10 m).
    #[arg(long, default_value_t = 10.0)]
    pub scene_pixel_m: f64,
    /// Zone centre in the coarse DEM's map frame, metres, as X,Y (x east, y north); default:
    /// the centre of the coarse DEM.
    #[arg(long, value_name = "X,Y", value_parser = parse_xy, allow_hyphen_values = true)]
    pub centre_m: Option<[f64; 2]>,
    /// Side of the square zone, metres.
    #[arg(long, default_value_t = 512.0)]
    pub side_m: f64,
    /// Pixel of the zone, metres.
    #[arg(long, default_value_t = 0.25)]
    pub pixel_m: f64,
    /// Border band over which the added detail fades out, metres.
    #[arg(long, default_value_t = DEFAULT_TAPER_M)]
    pub taper_m: f64,
    /// Rock abundance k of the Golombek & Rapp model (0: no rocks).
    #[arg(long, default_value_t = DEFAULT_ROCK_K)]
    pub rock_k: f64,
    /// Step of the lattice of touchdown sites judged for the safe fraction and the picture,
    /// metres.
    #[arg(long, default_value_t = 1.0)]
    pub step_m: f64,
    /// Largest side of the PNG map, pixels (the zone is box-averaged to fit).
    #[arg(long, default_value_t = 1024)]
    pub png_px: usize,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
}

/// Parse `X,Y` (metres).
fn parse_xy(s: &str) -> Result<[f64; 2], String> {
    let num = |v: &str| v.trim().parse::<f64>().ok().filter(|f| f.is_finite());
    match s.split(',').collect::<Vec<_>>().as_slice() {
        [x, y] => match (num(x), num(y)) {
            (Some(x), Some(y)) => Ok([x, y]),
            _ => Err(format!("'{s}': X and Y must be finite numbers (metres)")),
        },
        _ => Err(format!("'{s}': expected X,Y in metres, e.g. 250,-1200")),
    }
}

/// Where the coarse DEM came from.
#[derive(Debug, serde::Serialize)]
struct CoarseInfo {
    /// Preset and window, or the GeoTIFF path.
    source: String,
    /// Seed of a preset scene.
    seed: Option<u64>,
    /// Pixel, metres.
    pixel_m: f64,
    /// Extent (x_min, y_min, x_max, y_max), metres.
    extent_m: (f64, f64, f64, f64),
}

/// The truth safety figures of the zone.
#[derive(Debug, serde::Serialize)]
struct SafetySummary {
    /// Thresholds (the defaults).
    thresholds: SafetyThresholds,
    /// Lattice step, metres.
    step_m: f64,
    /// Border excluded (the taper band), metres.
    margin_m: f64,
    /// Sites judged.
    sites: usize,
    /// Safe sites.
    safe: usize,
    /// Sites whose plane is too steep.
    too_steep: usize,
    /// Sites with too much relief.
    too_rough: usize,
    /// `safe / sites`.
    safe_fraction: f64,
}

/// Wall-clock times, seconds.
#[derive(Debug, serde::Serialize)]
struct Timing {
    coarse_s: f64,
    zone_s: f64,
    safety_s: f64,
    write_s: f64,
    total_s: f64,
}

/// `landing_zone.json`.
#[derive(Debug, serde::Serialize)]
struct Output {
    coarse: CoarseInfo,
    /// Generation report: configuration, seed, counts against the models.
    zone: LandingZoneReport,
    /// RMS slope between neighbouring zone pixels, degrees (`atan(rms Δz / pixel)`).
    rms_slope_pixel_deg: f64,
    /// Slope percentiles of the zone (nav-core's Horn 3×3 at the zone pixel), degrees: p50, p90,
    /// p99.
    slope_p50_p90_p99_deg: [f64; 3],
    safety: SafetySummary,
    timing: Timing,
    files: Vec<PathBuf>,
}

/// Run `ground-sim landing-zone`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let t_all = Instant::now();
    if a.png_px < 16 {
        bail!("--png-px {} is too small (at least 16)", a.png_px);
    }
    // Coarse DEM.
    let t0 = Instant::now();
    let mut cfg = LandingZoneConfig {
        side_m: a.side_m,
        pixel_m: a.pixel_m,
        taper_m: a.taper_m,
        rock_k: a.rock_k,
        ..LandingZoneConfig::default()
    };
    let (coarse, source, scene_seed) = match (&a.preset, &a.dem) {
        (Some(preset), _) => {
            let params = TerrainParams {
                preset: *preset,
                window: a.window,
                seed: a.seed,
                size_m: a.scene_size_m,
                pixel_m: a.scene_pixel_m,
            };
            let pb = super::progress(4, "terrain");
            let (dem, _) = generate(&params, &pb).context("generating the coarse scene")?;
            pb.finish_and_clear();
            let r = preset.model().roughness;
            cfg.roughness.hurst = r.hurst;
            cfg.roughness.nu5_m = r.nu5_m;
            let source = format!(
                "preset {preset:?}, {:?} window, {} m at {} m",
                a.window, a.scene_size_m, a.scene_pixel_m
            )
            .to_lowercase();
            (dem, source, Some(a.seed))
        }
        (None, Some(path)) => {
            let dem = read_geotiff(path).with_context(|| format!("reading {}", path.display()))?;
            (dem, path.display().to_string(), None)
        }
        (None, None) => bail!("give the coarse scene with --preset or --dem"),
    };
    let coarse_s = t0.elapsed().as_secs_f64();
    let coarse_px = coarse.pixel_m().context("coarse DEM")?;
    let extent = coarse.extent_m();
    let centre = a
        .centre_m
        .unwrap_or([0.5 * (extent.0 + extent.2), 0.5 * (extent.1 + extent.3)]);

    // Zone.
    let t0 = Instant::now();
    let (zone, report) = landing_zone_with_report(&coarse, centre, &cfg, a.seed)
        .context("building the landing zone")?;
    let zone_s = t0.elapsed().as_secs_f64();

    // Safety.
    let t0 = Instant::now();
    let thresholds = SafetyThresholds::default();
    let map = safety_map(&zone, &thresholds, a.step_m, cfg.taper_m);
    if map.sites.is_empty() {
        bail!(
            "no touchdown site fits: the zone interior ({} m less a {} m taper each side) holds \
             no {} m lattice cell",
            report.side_m,
            cfg.taper_m,
            a.step_m
        );
    }
    let judged: Vec<_> = map.sites.iter().flatten().collect();
    let safety = SafetySummary {
        thresholds,
        step_m: a.step_m,
        margin_m: cfg.taper_m,
        sites: judged.len(),
        safe: judged.iter().filter(|s| s.safe).count(),
        too_steep: judged
            .iter()
            .filter(|s| !(s.slope_deg <= thresholds.max_slope_deg))
            .count(),
        too_rough: judged
            .iter()
            .filter(|s| !(s.relief_m <= thresholds.max_relief_m))
            .count(),
        safe_fraction: map.safe_fraction(),
    };
    let safety_s = t0.elapsed().as_secs_f64();

    // Outputs.
    let t0 = Instant::now();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let tif = a.out.join("landing_zone.tif");
    write_geotiff(&zone, &tif, Some(SampleKind::F32))
        .with_context(|| format!("writing {}", tif.display()))?;
    let what = match a.preset {
        Some(p) => format!("{p:?} seed {}", a.seed).to_lowercase(),
        None => format!("seed {}", a.seed),
    };
    let lines = [
        format!(
            "landing zone {} m at {} m, {what}",
            report.side_m, cfg.pixel_m
        ),
        format!(
            "red: unsafe {} m site (>{} deg, >{} m)",
            thresholds.footprint_m, thresholds.max_slope_deg, thresholds.max_relief_m
        ),
        format!(
            "safe {:.1} % of {}; dark: taper",
            100.0 * safety.safe_fraction,
            safety.sites
        ),
    ];
    let png = a.out.join("landing_zone.png");
    picture(&zone, &map, &lines, a.png_px)
        .context("drawing the picture")?
        .save(&png)
        .with_context(|| format!("writing {}", png.display()))?;
    let write_s = t0.elapsed().as_secs_f64();

    let slope_pct = {
        let mut v: Vec<f32> = slope_deg(&zone)
            .context("zone slope")?
            .into_iter()
            .filter(|s| s.is_finite())
            .collect();
        v.sort_by(f32::total_cmp);
        let at = |p: f64| {
            v.get(((v.len().saturating_sub(1)) as f64 * p).round() as usize)
                .map_or(f64::NAN, |&s| f64::from(s))
        };
        [at(0.5), at(0.9), at(0.99)]
    };
    let rms_slope_pixel_deg = (rms_lag1(zone.heights_m(), zone.width(), zone.height())
        / cfg.pixel_m)
        .atan()
        .to_degrees();
    let json = a.out.join("landing_zone.json");
    let out = Output {
        coarse: CoarseInfo {
            source,
            seed: scene_seed,
            pixel_m: coarse_px,
            extent_m: extent,
        },
        zone: report,
        rms_slope_pixel_deg,
        slope_p50_p90_p99_deg: slope_pct,
        safety,
        timing: Timing {
            coarse_s,
            zone_s,
            safety_s,
            write_s,
            total_s: t_all.elapsed().as_secs_f64(),
        },
        files: vec![tif.clone(), png.clone(), json.clone()],
    };
    super::write_json(&json, &out)?;
    let r = &out.zone;
    println!(
        "landing zone {} m at {} m ({} px) centred ({:.1}, {:.1}) m on {}: {} rocks ({} higher \
         than 0.3 m), {} craters {:.0}-{:.0} m, safe {:.1} % of {} sites ({} m disc, <= {} deg, \
         <= {} m); zone {:.2} s, safety {:.2} s",
        r.side_m,
        cfg.pixel_m,
        r.side_px,
        centre[0],
        centre[1],
        out.coarse.source,
        r.rocks_drawn,
        r.rocks_over_0_3m_high,
        r.craters_drawn,
        r.crater_range_m.0,
        r.crater_range_m.1,
        100.0 * out.safety.safe_fraction,
        out.safety.sites,
        thresholds.footprint_m,
        thresholds.max_slope_deg,
        thresholds.max_relief_m,
        zone_s,
        safety_s
    );
    for f in &out.files {
        println!("  {}", f.display());
    }
    Ok(())
}

/// Mean of `s × s` blocks (a NaN in a block gives NaN); the remainder rows/columns are dropped.
fn box_average(dem: &Dem, s: usize) -> Result<Dem, DemError> {
    let px = dem.pixel_m()?;
    if s <= 1 {
        return Ok(dem.clone());
    }
    let (w, h) = (dem.width() / s, dem.height() / s);
    let z = dem.heights_m();
    let src_w = dem.width();
    let out = (0..w * h)
        .map(|k| {
            let (c, r) = (k % w, k / w);
            let mut acc = 0.0f64;
            for rr in r * s..(r + 1) * s {
                for cc in c * s..(c + 1) * s {
                    acc += f64::from(z[rr * src_w + cc]);
                }
            }
            (acc / (s * s) as f64) as f32
        })
        .collect();
    let (ox, oy) = dem.origin_m();
    let geo = GeoRef {
        transform: GeoTransform::north_up(ox, oy, px * s as f64),
        ..dem.geo.clone()
    };
    Dem::new(w, h, out, geo)
}

/// Hillshade of the zone (box-averaged to at most `max_px` a side) with the unsafe lattice cells
/// tinted red and the excluded border darkened; `lines` of text above, a scale bar below.
fn picture(
    zone: &Dem,
    map: &SafetyMap,
    lines: &[String],
    max_px: usize,
) -> anyhow::Result<RgbImage> {
    let s = zone.width().max(zone.height()).div_ceil(max_px).max(1);
    let small = box_average(zone, s)?;
    let shade = hillshade(&small, Sun::default())?;
    let (w, h) = (small.width() as u32, small.height() as u32);
    let ppx = small.pixel_m()?;
    let (ox, oy) = small.origin_m();
    let pad = 8u32;
    let line_h = GLYPH + 4;
    let top = pad + lines.len() as u32 * line_h + 4;
    let text_w = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0) as u32 * GLYPH;
    let width = (2 * pad + w).max(2 * pad + text_w);
    let height = top + h + 12 + GLYPH + pad;
    let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    for (i, l) in lines.iter().enumerate() {
        draw_text(&mut img, pad, pad + i as u32 * line_h, l, [0, 0, 0]);
    }
    let (lx0, ly1) = (map.x_min_m, map.y_max_m);
    let (lx1, ly0) = (
        lx0 + map.nx as f64 * map.step_m,
        ly1 - map.ny as f64 * map.step_m,
    );
    for r in 0..h {
        for c in 0..w {
            let v = shade[(r * w + c) as usize];
            let g = if v.is_finite() {
                f64::from(v) * 255.0
            } else {
                96.0
            };
            let x = ox + (f64::from(c) + 0.5) * ppx;
            let y = oy - (f64::from(r) + 0.5) * ppx;
            let in_lattice = x >= lx0 && x < lx1 && y > ly0 && y <= ly1;
            let rgb = if !in_lattice {
                [g * 0.55; 3]
            } else if map.at(x, y).is_some_and(|s| !s.safe) {
                [
                    0.5 * g + 0.5 * 235.0,
                    0.5 * g + 0.5 * 30.0,
                    0.5 * g + 0.5 * 30.0,
                ]
            } else {
                [g; 3]
            };
            img.put_pixel(
                pad + c,
                top + r,
                Rgb(rgb.map(|v| v.clamp(0.0, 255.0) as u8)),
            );
        }
    }
    // Scale bar below the map: a round length near a quarter of its width.
    let len_m = scale_bar_length(f64::from(w) * ppx / 4.0);
    let len_px = (len_m / ppx).round() as u32;
    let y0 = top + h + 6;
    for x in pad..pad + len_px {
        for y in y0..y0 + 6 {
            img.put_pixel(x, y, Rgb([0, 0, 0]));
        }
    }
    draw_text(
        &mut img,
        pad + len_px + 8,
        y0 + 3 - GLYPH / 2 + 4,
        &format!("{len_m} m"),
        [0, 0, 0],
    );
    Ok(img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_parses_and_bad_values_are_refused() {
        assert_eq!(parse_xy("250,-1200"), Ok([250.0, -1200.0]));
        assert_eq!(parse_xy(" -3.5 , 4 "), Ok([-3.5, 4.0]));
        assert!(parse_xy("1").unwrap_err().contains("X,Y"));
        assert!(parse_xy("1,2,3").is_err());
        assert!(parse_xy("a,2").unwrap_err().contains("finite"));
        assert!(parse_xy("nan,2").is_err());
    }

    #[test]
    fn picture_tints_unsafe_cells() {
        // A 32 m flat zone with a 15° plane in its east half.
        let n = 128usize;
        let z = (0..n * n)
            .map(|i| {
                let x = ((i % n) as f64 + 0.5) * 0.25;
                if x > 16.0 {
                    ((x - 16.0) * 15f64.to_radians().tan()) as f32
                } else {
                    0.0
                }
            })
            .collect();
        let dem = Dem::new(n, n, z, GeoRef::local(0.0, 32.0, 0.25, "t")).unwrap();
        let map = safety_map(&dem, &SafetyThresholds::default(), 1.0, 2.0);
        let img = picture(&dem, &map, &["t".to_string()], 64).unwrap();
        // 64 px map (2×2 blocks), 8 px pad, one text line.
        let top = 8 + (GLYPH + 4) + 4;
        let px = |c: u32, r: u32| img.get_pixel(8 + c, top + r).0;
        let west = px(10, 32);
        let east = px(54, 32);
        assert_eq!(west[0], west[1], "west is grey: {west:?}");
        assert!(east[0] > east[1] + 40, "east is red: {east:?}");
    }
}
