//! Register one frame image against a reference image with nav-core's full onboard chain:
//! the reference becomes a tile (SURF by nav-core on the host), the frame goes through
//! `Navigator` exactly as on the flyer.
//!
//! Inputs are single-band GeoTIFF or PNG rasters holding slope in degrees, or heights in metres
//! (`RasterKind::Dem`, slope computed by nav-core first). PNG conventions: 16-bit grey slope is
//! nav-core's raw fixed point (degrees × 512, the lossless form `ground-sim` writes), 8-bit grey
//! slope is `value × 90 / 255` degrees, grey DEM values are metres × `png_z_scale`.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use nav_core::frame::{DemPatch, SLOPE_NODATA, SlopePx, slope_from_deg};
use nav_core::msac::Model;
use nav_core::slope::slope_into;
use nav_core::{NavConfig, Navigator, SlopeImage, SurfConfig, Tile};
use serde::Serialize;

use crate::dem::read_geotiff;
use crate::reference::tile::{GeoGrid, MAX_TILE_FEATURES, build_tile};

use crate::flyer::onboard::{
    Budget, FrameInput, MAX_FRAME_SIDE, new_workspace, run_frame, with_big_stack,
};

/// What the raster values are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RasterKind {
    /// Slope in degrees.
    Slope,
    /// Heights in metres.
    Dem,
}

/// A single-band raster with its pixel size and (if known) geo-reference.
#[derive(Debug, Clone)]
pub struct Raster {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row-major values (degrees or metres), `NaN` = no data.
    pub values: Vec<f32>,
    /// Square pixel size, metres.
    pub pixel_m: f64,
    /// Geo x, y of the centre of pixel (0, 0) and the steps per column and row, metres; a local
    /// grid starting at 0 when the file has none (PNG).
    pub grid: GeoGrid,
}

/// Read a GeoTIFF or PNG raster. `pixel_m` is required for PNG (it has no geo-reference) and
/// overrides nothing for GeoTIFF (whose own pixel size is used; a disagreeing value is an error).
pub fn read_raster(
    path: &Path,
    kind: RasterKind,
    pixel_m: Option<f64>,
    png_z_scale: f64,
) -> Result<Raster> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match ext.as_str() {
        "tif" | "tiff" => {
            let dem = read_geotiff(path)?;
            let px = dem.pixel_m()?;
            if let Some(p) = pixel_m
                && ((p - px) / px).abs() > 1e-6
            {
                bail!(
                    "{}: --pixel-m {p} disagrees with the file's {px} m",
                    path.display()
                );
            }
            let t = dem.geo.transform.0;
            let grid = GeoGrid {
                origin_x_m: t[0] + 0.5 * t[1],
                origin_y_m: t[3] + 0.5 * t[5],
                pixel_x_m: t[1],
                pixel_y_m: t[5],
                projection: dem
                    .geo
                    .keys
                    .as_ref()
                    .and_then(|k| k.ascii.clone())
                    .unwrap_or_else(|| "unknown (GeoTIFF without citation)".into())
                    .chars()
                    .take(nav_core::tile::MAX_PROJECTION_LEN)
                    .collect(),
            };
            Ok(Raster {
                width: dem.width(),
                height: dem.height(),
                values: dem.heights_m().to_vec(),
                pixel_m: px,
                grid,
            })
        }
        "png" => {
            let px = pixel_m
                .ok_or_else(|| anyhow!("{}: a PNG has no pixel size; pass it", path.display()))?;
            if !(px.is_finite() && px > 0.0) {
                bail!("pixel size must be > 0 m, got {px}");
            }
            let img = image::open(path).with_context(|| format!("reading {}", path.display()))?;
            let (w, h) = (img.width() as usize, img.height() as usize);
            let values: Vec<f32> = match (&img, kind) {
                (image::DynamicImage::ImageLuma16(b), RasterKind::Slope) => b
                    .as_raw()
                    .iter()
                    .map(|&v| {
                        if v > nav_core::frame::SLOPE_MAX_RAW {
                            f32::NAN
                        } else {
                            v as f32 / 512.0
                        }
                    })
                    .collect(),
                (image::DynamicImage::ImageLuma8(b), RasterKind::Slope) => b
                    .as_raw()
                    .iter()
                    .map(|&v| v as f32 * 90.0 / 255.0)
                    .collect(),
                (image::DynamicImage::ImageLuma16(b), RasterKind::Dem) => b
                    .as_raw()
                    .iter()
                    .map(|&v| (v as f64 * png_z_scale) as f32)
                    .collect(),
                (image::DynamicImage::ImageLuma8(b), RasterKind::Dem) => b
                    .as_raw()
                    .iter()
                    .map(|&v| (v as f64 * png_z_scale) as f32)
                    .collect(),
                (other, _) => bail!(
                    "{}: only single-band grey PNGs are supported, this one is {:?}",
                    path.display(),
                    other.color()
                ),
            };
            Ok(Raster {
                width: w,
                height: h,
                values,
                pixel_m: px,
                grid: GeoGrid {
                    origin_x_m: 0.0,
                    origin_y_m: 0.0,
                    pixel_x_m: px,
                    pixel_y_m: px,
                    projection: "local image grid (PNG)".into(),
                },
            })
        }
        _ => bail!(
            "{}: expected a .tif/.tiff GeoTIFF or a .png",
            path.display()
        ),
    }
}

/// nav-core slope pixels of a raster (slope degrees quantised, or slope of heights).
pub fn slope_pixels(r: &Raster, kind: RasterKind) -> Result<Vec<SlopePx>> {
    match kind {
        RasterKind::Slope => Ok(r.values.iter().map(|&v| slope_from_deg(v)).collect()),
        RasterKind::Dem => {
            let patch = DemPatch::new_checked(&r.values, r.width, r.height, r.pixel_m as f32)
                .map_err(|e| anyhow!("DEM refused: {e}"))?;
            let mut out = vec![SLOPE_NODATA; r.width * r.height];
            slope_into(&patch, &mut out).map_err(|e| anyhow!("slope: {e}"))?;
            Ok(out)
        }
    }
}

/// Registration options.
#[derive(Debug, Clone, Copy)]
pub struct RegisterOptions {
    /// Transform model fitted by MSAC.
    pub model: Model,
    /// MSAC seed.
    pub seed: u64,
    /// Detector threshold for both images, (degrees of slope)².
    pub threshold: f32,
}

impl Default for RegisterOptions {
    fn default() -> Self {
        Self {
            model: Model::Similarity,
            seed: nav_core::MsacConfig::default().seed,
            threshold: nav_core::DetectorConfig::default().threshold,
        }
    }
}

/// The JSON report of `ground-sim register`.
#[derive(Debug, Clone, Serialize)]
pub struct RegisterReport {
    /// Whether the gate accepted a fix.
    pub fix: bool,
    /// Why not, when `fix` is false.
    pub no_fix_reason: Option<String>,
    /// Reference features in the tile.
    pub reference_features: usize,
    /// Frame features.
    pub frame_features: u16,
    /// Putative matches (after guided matching when it ran).
    pub matches: u16,
    /// MSAC inliers.
    pub inliers: u16,
    /// Rotation φ of eq 19, degrees: frame +x axis in reference pixel axes.
    pub rotation_deg: Option<f64>,
    /// Scale s of eq 19: reference pixels per frame pixel.
    pub scale: Option<f64>,
    /// `[m1, n1, p1, m2, n2, p2]` of eq 18: frame pixel (x = column, y = row, first pixel's
    /// centre at (0, 0)) → reference pixel.
    pub affine: Option<[f64; 6]>,
    /// Departure of the least-squares affine from a similarity (0 = pure similarity).
    pub non_similar: Option<f64>,
    /// Frame centre in reference pixels `[x, y]`.
    pub frame_center_in_reference_px: Option<[f64; 2]>,
    /// Frame centre in the reference's geo coordinates, metres.
    pub frame_center_geo_m: Option<[f64; 2]>,
    /// 1σ of the frame centre, reference pixels.
    pub center_sigma_px: Option<f64>,
    /// 1σ of the heading, degrees.
    pub heading_sigma_deg: Option<f64>,
    /// RMS transfer error of the inliers, reference pixels.
    pub residual_rms_px: Option<f64>,
    /// Whether the fix was refined densely over the frame's pixels (`nav_core::refine`).
    pub refined: bool,
    /// Normalised cross-correlation of frame and reference slope under the refined transform.
    pub refined_ncc: Option<f32>,
    /// Why the refinement was not applied, when it was not.
    pub refine_note: Option<String>,
    /// Time of the onboard part (slope, SURF, matching, MSAC, gate) on this host, ms.
    pub time_ms: f64,
    /// Time to build the reference tile, ms.
    pub tile_build_ms: f64,
    /// Matched keypoint pairs `[frame x, frame y, reference x, reference y, inlier]` (pictures).
    #[serde(skip)]
    pub pairs: Vec<(f32, f32, f32, f32, bool)>,
}

/// Register `frame` against `reference`.
pub fn register(
    reference: &Raster,
    frame: &Raster,
    kind: RasterKind,
    opts: &RegisterOptions,
) -> Result<RegisterReport> {
    if frame.width > MAX_FRAME_SIDE || frame.height > MAX_FRAME_SIDE {
        bail!(
            "frame is {}x{} px; the onboard workspace holds at most {MAX_FRAME_SIDE}x{MAX_FRAME_SIDE} (crop or downsample it)",
            frame.width,
            frame.height
        );
    }
    let t0 = Instant::now();
    let ref_px = slope_pixels(reference, kind)?;
    let ref_img = SlopeImage::new_checked(
        &ref_px,
        reference.width,
        reference.height,
        reference.pixel_m as f32,
    )
    .map_err(|e| anyhow!("reference: {e}"))?;
    let detector = nav_core::DetectorConfig {
        threshold: opts.threshold,
        ..Default::default()
    };
    let tile_bytes = build_tile(
        &ref_img,
        &reference.grid,
        &SurfConfig {
            detector,
            upright: false,
        },
        MAX_TILE_FEATURES,
        // Images are registered as given: no terrain smoothing on either side, and the
        // reference image is the authority (no map error of its own).
        0.0,
        [0.0; 2],
        0.0,
        None,
    )?;
    let tile = Tile::parse(&tile_bytes).map_err(|e| anyhow!("tile: {e}"))?;
    let tile_build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let mut cfg = NavConfig::default();
    cfg.msac.model = opts.model;
    cfg.msac.seed = opts.seed;
    let nav = Navigator::new(tile, cfg);
    let frame_px = match kind {
        RasterKind::Dem => None,
        RasterKind::Slope => Some(slope_pixels(frame, kind)?),
    };
    let run = with_big_stack(|| {
        let mut ws = new_workspace(Budget::Host);
        let input = match &frame_px {
            None => FrameInput::Dem(&frame.values, frame.width, frame.height, frame.pixel_m),
            Some(px) => FrameInput::Slope(px, frame.width, frame.height, frame.pixel_m),
        };
        run_frame(&nav, &mut ws, input, None).map_err(|e| anyhow!("frame: {e}"))
    })?;
    let (report, pairs, time_ms) = (run.report, run.pairs, run.time_ms);
    let mut out = RegisterReport {
        fix: report.outcome.is_ok(),
        no_fix_reason: report.outcome.err().map(|e| e.to_string()),
        reference_features: tile_len_of(&tile_bytes),
        frame_features: report.features,
        matches: report.matches,
        inliers: report.inliers,
        rotation_deg: None,
        scale: None,
        affine: None,
        non_similar: None,
        frame_center_in_reference_px: None,
        frame_center_geo_m: None,
        center_sigma_px: None,
        heading_sigma_deg: None,
        residual_rms_px: None,
        refined: false,
        refined_ncc: None,
        refine_note: None,
        time_ms,
        tile_build_ms,
        pairs,
    };
    if let Ok(f) = report.outcome {
        out.rotation_deg = Some(f.similarity.rotation_rad.to_degrees());
        out.scale = Some(f.similarity.scale);
        out.affine = Some(f.affine.to_array());
        out.non_similar = Some(f.similarity.non_similar);
        out.frame_center_in_reference_px = Some(f.center_tile_px);
        out.frame_center_geo_m = Some(f.center_geo_m);
        out.center_sigma_px = Some(f.center_cov_tile_px2[0][0].sqrt());
        out.heading_sigma_deg = Some(f.heading_sigma_rad.to_degrees());
        out.residual_rms_px = Some(f.residual_rms_px);
        out.refined = f.refined;
    }
    match report.refine {
        Some(Ok(r)) => out.refined_ncc = Some(r.ncc_after),
        Some(Err(e)) => out.refine_note = Some(e.to_string()),
        None => {}
    }
    Ok(out)
}

fn tile_len_of(bytes: &[u8]) -> usize {
    Tile::parse(bytes).map(|t| t.len()).unwrap_or(0)
}
