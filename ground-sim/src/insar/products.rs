//! What `ground-sim insar` writes into its folder: the reference folder of
//! [`crate::reference`] (tile.bin, slope.tif, reference-dem.tif = the InSAR DEM, tile.json),
//! further GeoTIFFs (coherence, mask codes of [`super::label`], height bound, height error), the paper's Fig. 5 and 6
//! pictures and `report.json`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::Serialize;

use super::accuracy::{Accuracy, compare};
use super::geometry::PairGeometry;
use super::pipeline::{
    CoregReport, InsarConfig, InsarProduct, MaskFractions, TruthOnGrid, UnwrapReport,
};
use crate::dem::stats::slope_deg;
use crate::dem::{Dem, SampleKind, write_geotiff};
use crate::pictures::render::{ColourMap, RasterStyle, raster_image};
use crate::reference::tile::MAX_TILE_FEATURES;
use crate::reference::{Smoothing, TileSummary, write_reference};
use crate::sar::pipeline::{InsarPair, Timings};
use crate::sar::{Derived, SarConfig};

/// Coherence GeoTIFF.
pub const COHERENCE_FILE: &str = "coherence.tif";
/// Mask GeoTIFF (uint16 codes of [`super::label`]).
pub const MASK_FILE: &str = "mask.tif";
/// Per-pixel Cramér–Rao height bound GeoTIFF, m.
pub const CRLB_FILE: &str = "height-crlb.tif";
/// InSAR minus truth GeoTIFF, m.
pub const ERROR_FILE: &str = "height-error.tif";
/// The truth on the output grid (block mean), m.
pub const TRUTH_FILE: &str = "truth-dem.tif";
/// The truth averaged over the multilook window's footprint, m.
pub const TRUTH_WINDOW_FILE: &str = "truth-window-dem.tif";
/// Report file.
pub const REPORT_FILE: &str = "report.json";

/// The SAR part of the report (when the chain simulated the radar itself).
#[derive(Debug, Clone, Serialize)]
pub struct SarSummary {
    /// Radar configuration.
    pub config: SarConfig,
    /// Derived radar values.
    pub derived: Derived,
    /// SAR stage timings, s.
    pub timings: Timings,
    /// Facets in the mesh / shadowed / layover (the simulator's own geometric flags).
    pub facets: [usize; 3],
}

impl SarSummary {
    /// Summary of a simulated pair.
    pub fn of(pair: &InsarPair) -> Self {
        Self {
            config: pair.config.clone(),
            derived: pair.derived.clone(),
            timings: pair.timings.clone(),
            facets: [pair.stats.facets, pair.stats.shadowed, pair.stats.layover],
        }
    }
}

/// `report.json`: the accuracy figures at the top level, then the details.
#[derive(Debug, Clone, Serialize)]
pub struct InsarReport {
    /// Height, slope, validity, coherence and CRLB figures.
    #[serde(flatten)]
    pub accuracy: Accuracy,
    /// SURF features in the reference tile.
    pub tile_features: usize,
    /// How many of those a tile built the same way from the truth on the same grid holds too
    /// ([`features_on_truth`]): the map's blobs that are ground, not noise. A simulation-only
    /// diagnostic (it reads the truth).
    pub tile_features_on_truth: usize,
    /// The reference tile summary.
    pub tile: TileSummary,
    /// Equivalent independent looks of one multilook window, times the stacked passes (the
    /// receiver noise's; the surface's decorrelation keeps one pass's).
    pub effective_looks: f64,
    /// Factor, 0–1, by which the DEM filter shrank the height CRLB of cells away from holes
    /// and edges (the looks' overlap keeps their noise correlated;
    /// `pipeline::dem_filter_noise_factor`; cells by a hole or the edge have their own,
    /// mostly larger).
    pub crlb_filter_factor: f64,
    /// Correlation length of the height noise after the quadratic DEM filter, m: σ of the
    /// Gaussian blur of white noise with its neighbour correlation (`pipeline::error_blur_m`;
    /// the rehearsal's error model reads it). Absent under the default mean, whose noise the
    /// DEM's own blur in tile.json describes (22.4 m: 0.82 at 20 m, the suite's error maps
    /// 0.81–0.83), which keeps the default products and the rehearsal as they were.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_blur_m: Option<f64>,
    /// Height of ambiguity at the scene centre, m per 2π.
    pub height_of_ambiguity_m: f64,
    /// Mean coherence of every multilooked radar pixel (masked ones included).
    pub coherence_mean_radar: f64,
    /// Coregistration figures.
    pub coregistration: CoregReport,
    /// Unwrapping figures.
    pub unwrap: UnwrapReport,
    /// Fractions of the output grid per mask code.
    pub mask: MaskFractions,
    /// With two look directions (`--looks both`): each pass's mask and how they were fused.
    pub looks: Option<crate::insar::pipeline::LookFusion>,
    /// With a long baseline (`--long-baseline-m`): how it entered the map, per look (east
    /// first).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub baselines: Vec<crate::insar::baselines::BaselineFusion>,
    /// Pixels removed by the eq 20 test on the generated DEM.
    pub eq20_removed_pixels: usize,
    /// Pixels removed by the ray-traced shadow and layover of the generated DEM.
    pub geometry_removed_pixels: usize,
    /// Output grid size and pixel.
    pub grid: [f64; 3],
    /// Pair geometry.
    pub geometry: PairGeometry,
    /// Processing configuration.
    pub config: InsarConfig,
    /// Radar simulation, if run by this command.
    pub sar: Option<SarSummary>,
    /// Input DEM file, if any.
    pub input_dem: Option<String>,
    /// Nodata heights filled before the radar simulation.
    pub filled_nodata: usize,
    /// InSAR processing time, s.
    pub insar_s: f64,
    /// Time to write the products, s.
    pub products_s: f64,
    /// Files written (relative to the folder).
    pub files: Vec<String>,
    /// The map was made in blocks (`insar --block-cells`): layout, seams, per-block figures.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blocks: Option<crate::insar::blocks::MosaicReport>,
}

/// Context of the run for the report.
#[derive(Debug, Clone, Default)]
pub struct RunContext {
    /// Radar simulation summary.
    pub sar: Option<SarSummary>,
    /// Input DEM path.
    pub input_dem: Option<PathBuf>,
    /// Nodata heights filled before the radar simulation.
    pub filled_nodata: usize,
    /// The map was made in blocks: how they joined.
    pub blocks: Option<crate::insar::blocks::MosaicReport>,
}

fn save(img: &image::RgbImage, path: &Path) -> anyhow::Result<()> {
    img.save(path)
        .with_context(|| format!("writing {}", path.display()))
}

/// The height noise the tile claims, metres: the root mean square of the height Cramér–Rao
/// bound over the map's valid cells, undone for the DEM filter (÷ `crlb_filter_factor`): a
/// filter lowers each cell's σ by averaging neighbours but not the noise's power per unit
/// area, which is what registration at the tile's coarser smoothing sees. 0 when no cell is
/// valid. From the radar's own coherence, not the truth, so a real mission has it too.
/// A lower bound on that power: the multilook windows overlap (size 8, step 4), so even
/// before the DEM filter neighbouring cells' noise correlates (the filter's factor, 0.55–0.57,
/// is above white noise's 0.33), and correlated noise carries more power per unit area than
/// its per-cell σ² × cell area. The map share it feeds (`nav_core::filter::map_noise_share`,
/// 0.98 on the default radar's maps) would only move towards 1 with the true power.
pub fn white_noise_m(p: &InsarProduct) -> f64 {
    let (sum, n) = p
        .dem
        .heights_m()
        .iter()
        .zip(p.crlb_m.heights_m())
        .filter(|(z, c)| z.is_finite() && c.is_finite())
        .fold((0.0f64, 0usize), |(s, n), (_, c)| {
            (s + f64::from(*c).powi(2), n + 1)
        });
    let f = p.crlb_filter_factor;
    if n == 0 || !(f.is_finite() && f > 0.0) {
        0.0
    } else {
        (sum / n as f64).sqrt() / f.min(1.0)
    }
}

/// Largest distance, tile pixels, at which a map feature counts as the truth's
/// ([`features_on_truth`]): within a blob's own size under the tile's 50 m smoothing (2.5 px
/// at 20 m), so a blob the map's noise moved a little still counts, one a blob away does not.
pub const ON_TRUTH_RADIUS_PX: f32 = 2.0;
/// Scale ratio band within which a map feature counts as the same blob as a truth feature.
pub const ON_TRUTH_SCALE_BAND: (f32, f32) = (0.7, 1.4);

/// How many features of the tile `tile_bytes` a tile built from `truth` (the truth on the
/// map's grid) with the same SURF settings `surf` and the full terrain smoothing
/// `smoothing_m` (metres; the truth carries no blur of its own) holds too: a truth feature
/// within [`ON_TRUTH_RADIUS_PX`], with the same sign of the Laplacian and a scale ratio in
/// [`ON_TRUTH_SCALE_BAND`]. What it tells: on gentle ground under radar noise many of a map's
/// blobs are its noise (session 37: 110 of 281 on the seed-1 plains at the 32 m boom), and a
/// frame's features can only match the ones that are ground.
pub fn features_on_truth(
    tile_bytes: &[u8],
    truth: &Dem,
    surf: &nav_core::SurfConfig,
    smoothing_m: f64,
) -> anyhow::Result<usize> {
    let tile = nav_core::Tile::parse(tile_bytes)
        .map_err(|e| anyhow::anyhow!("reading the map's tile: {e:?}"))?;
    let px = crate::reference::reference_slope_px(truth, smoothing_m)?;
    let img = nav_core::SlopeImage::new_checked(
        &px,
        truth.width(),
        truth.height(),
        truth.pixel_m()? as f32,
    )
    .map_err(|e| anyhow::anyhow!("truth slope: {e}"))?;
    let truth_feats = crate::reference::tile::tile_features(&img, surf)?;
    let truth_kp: Vec<(f32, f32, f32, bool)> = truth_feats
        .as_slice()
        .iter()
        .map(|f| {
            let k = &f.keypoint;
            (k.x_px, k.y_px, k.scale_px, k.laplacian_positive)
        })
        .collect();
    let r2 = ON_TRUTH_RADIUS_PX * ON_TRUTH_RADIUS_PX;
    let (lo, hi) = ON_TRUTH_SCALE_BAND;
    Ok((0..tile.len())
        .filter(|&i| {
            let k = tile.keypoint(i);
            truth_kp.iter().any(|&(x, y, sc, lap)| {
                let ratio = sc / k.scale_px;
                lap == k.laplacian_positive
                    && (lo..=hi).contains(&ratio)
                    && (x - k.x_px).powi(2) + (y - k.y_px).powi(2) <= r2
            })
        })
        .count())
}

/// Write every product of `p` into `dir` (compared with `truth`), return the report.
pub fn write_outputs(
    dir: &Path,
    p: &InsarProduct,
    truth: &TruthOnGrid,
    ctx: &RunContext,
) -> anyhow::Result<InsarReport> {
    let t = std::time::Instant::now();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let truth_grid = &truth.grid;
    let accuracy = compare(p, truth_grid, Some(&truth.window))?;
    let surf = crate::reference::surf_config_for(
        &crate::reference::noise_floor::FrameNoise::default_sensor(),
        p.dem.pixel_m()?,
        crate::reference::INSAR_SMOOTHING_M,
    )?;
    let tile = write_reference(
        &p.dem,
        dir,
        &surf,
        MAX_TILE_FEATURES,
        Smoothing {
            target_m: crate::reference::INSAR_SMOOTHING_M,
            inherent_m: p.inherent_smoothing_m(),
            one_look_share: p.look_fusion.map_or(1.0, |f| f.one_look_share_for_frames()),
            height_noise_m: white_noise_m(p),
            fill_holes: p.config.fill_tile_holes,
        },
    )
    .context("building the reference tile")?;
    let mut files: Vec<String> = [
        crate::reference::TILE_FILE,
        crate::reference::SLOPE_FILE,
        crate::reference::DEM_FILE,
        crate::reference::META_FILE,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let tif = |dem: &Dem, name: &str, kind: SampleKind, files: &mut Vec<String>| {
        let path = dir.join(name);
        write_geotiff(dem, &path, Some(kind)).with_context(|| format!("writing {name}"))?;
        files.push(name.to_string());
        anyhow::Ok(())
    };
    tif(&p.coherence, COHERENCE_FILE, SampleKind::F32, &mut files)?;
    tif(&p.crlb_m, CRLB_FILE, SampleKind::F32, &mut files)?;
    let mask = p
        .grid
        .raster(p.labels.iter().map(|&l| f32::from(l)).collect())?;
    tif(&mask, MASK_FILE, SampleKind::U16, &mut files)?;
    let err: Vec<f32> = p
        .dem
        .heights_m()
        .iter()
        .zip(truth_grid.heights_m())
        .map(|(a, b)| a - b)
        .collect();
    let err_dem = p.grid.raster(err.clone())?;
    tif(&err_dem, ERROR_FILE, SampleKind::F32, &mut files)?;
    tif(truth_grid, TRUTH_FILE, SampleKind::F32, &mut files)?;
    tif(
        &truth.window,
        TRUTH_WINDOW_FILE,
        SampleKind::F32,
        &mut files,
    )?;

    // Pictures. Radar geometry: rows = azimuth, columns = slant range (near range left), one
    // pixel per multilook window (≈ 20 m × 20 m on the ground).
    let r = &p.radar;
    let pi = std::f64::consts::PI;
    let mut png = |img: image::RgbImage, name: &str| -> anyhow::Result<()> {
        save(&img, &dir.join(name))?;
        files.push(name.to_string());
        Ok(())
    };
    let radar_px = r.line_spacing_m;
    // A map made in blocks has no radar geometry of its own (each block has its own).
    let radar_pictures = r.lines > 0 && r.cols > 0;
    if radar_pictures {
        png(
            raster_image(
                &r.phase_with_flat_rad,
                r.cols,
                r.lines,
                radar_px,
                &RasterStyle {
                    title: "Fig 5a: phase with flat-Moon term",
                    map: ColourMap::Phase,
                    range: (-pi, pi),
                    unit: "rad",
                },
            ),
            "fig5a-phase-with-flat.png",
        )?;
        png(
            raster_image(
                &r.phase_rad,
                r.cols,
                r.lines,
                radar_px,
                &RasterStyle {
                    title: "Fig 5b: phase, flat-Moon term removed",
                    map: ColourMap::Phase,
                    range: (-pi, pi),
                    unit: "rad",
                },
            ),
            "fig5b-phase-flat-removed.png",
        )?;
        png(
            raster_image(
                &r.coherence,
                r.cols,
                r.lines,
                radar_px,
                &RasterStyle {
                    title: "coherence (radar geometry)",
                    map: ColourMap::Grey,
                    range: (0.0, 1.0),
                    unit: "",
                },
            ),
            "coherence-radar.png",
        )?;
    }
    let (w, h) = (p.grid.width, p.grid.height);
    let (zlo, zhi) = truth_grid
        .heights_m()
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(f64::from(v)), b.max(f64::from(v)))
        });
    let zr = if zhi > zlo {
        (zlo, zhi)
    } else {
        (zlo - 1.0, zlo + 1.0)
    };
    let slope_range = crate::pictures::render::SLOPE_RANGE_DEG;
    for (dem, name, what) in [
        (&p.dem, "fig6a-insar-dem.png", "Fig 6a: InSAR DEM"),
        (truth_grid, "truth-dem.png", "truth DEM at the same grid"),
    ] {
        png(
            raster_image(
                dem.heights_m(),
                w,
                h,
                p.grid.pixel_m,
                &RasterStyle {
                    title: what,
                    map: ColourMap::Elevation,
                    range: zr,
                    unit: "m",
                },
            ),
            name,
        )?;
    }
    for (dem, name, what) in [
        (&p.dem, "fig6b-insar-slope.png", "Fig 6b: InSAR slope"),
        (
            truth_grid,
            "truth-slope.png",
            "truth slope at the same grid",
        ),
    ] {
        png(
            raster_image(
                &slope_deg(dem)?,
                w,
                h,
                p.grid.pixel_m,
                &RasterStyle {
                    title: what,
                    map: ColourMap::Slope,
                    range: slope_range,
                    unit: "deg",
                },
            ),
            name,
        )?;
    }
    let lim = (3.0 * accuracy.height_rmse_m).max(1.0);
    png(
        raster_image(
            &err,
            w,
            h,
            p.grid.pixel_m,
            &RasterStyle {
                title: "InSAR - truth",
                map: ColourMap::Diverging,
                range: (-lim, lim),
                unit: "m",
            },
        ),
        "height-error.png",
    )?;
    let labels: Vec<f32> = p.labels.iter().map(|&l| f32::from(l)).collect();
    png(
        raster_image(
            &labels,
            w,
            h,
            p.grid.pixel_m,
            &RasterStyle {
                title: "mask: 0 ok 1 layover 2 shadow 3 low coh 4 out",
                map: ColourMap::Mask,
                range: (0.0, 4.0),
                unit: "",
            },
        ),
        "mask.png",
    )?;
    let on_truth = features_on_truth(
        &std::fs::read(dir.join(crate::reference::TILE_FILE)).context("reading the tile back")?,
        truth_grid,
        &surf,
        crate::reference::INSAR_SMOOTHING_M,
    )
    .context("the tile's features on the truth")?;
    let products_s = t.elapsed().as_secs_f64();
    let report = InsarReport {
        accuracy,
        tile_features: tile.features,
        tile_features_on_truth: on_truth,
        tile,
        effective_looks: p.effective_looks,
        crlb_filter_factor: p.crlb_filter_factor,
        error_blur_m: (p.config.dem_filter == crate::insar::pipeline::DemFilterKind::Quadratic)
            .then_some(p.error_blur_m),
        height_of_ambiguity_m: p.unwrap.ambiguity_height_m,
        coherence_mean_radar: p.coherence_mean_radar,
        coregistration: p.coreg,
        unwrap: p.unwrap,
        looks: p.look_fusion,
        baselines: p.baseline_fusion.clone(),
        mask: p.mask,
        eq20_removed_pixels: p.eq20_removed,
        geometry_removed_pixels: p.geometry_removed,
        grid: [w as f64, h as f64, p.grid.pixel_m],
        geometry: p.geometry,
        config: p.config,
        sar: ctx.sar.clone(),
        input_dem: ctx.input_dem.as_ref().map(|p| p.display().to_string()),
        filled_nodata: ctx.filled_nodata,
        insar_s: p.seconds,
        products_s,
        files: {
            let mut f = files;
            f.push(REPORT_FILE.to_string());
            f
        },
        blocks: ctx.blocks.clone(),
    };
    let text = serde_json::to_string_pretty(&report)? + "\n";
    std::fs::write(dir.join(REPORT_FILE), text)
        .with_context(|| format!("writing {}", dir.join(REPORT_FILE).display()))?;
    Ok(report)
}
