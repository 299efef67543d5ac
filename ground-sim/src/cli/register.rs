//! `ground-sim register`: one frame image against one reference image, through nav-core.

use std::path::PathBuf;

use anyhow::{Context, bail};
use ground_sim::evaluation::register::{
    RasterKind, RegisterOptions, read_raster, register, slope_pixels,
};
use ground_sim::pictures::matchplot::match_picture;
use nav_core::frame::slope_to_deg;
use nav_core::msac::Model;

/// Transform model for the robust fit.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum ModelArg {
    /// Rotation + uniform scale + translation (2-point samples).
    Similarity,
    /// Full affine, the paper's eq 18 (3-point samples).
    Affine,
}

/// Arguments of `ground-sim register`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference image (GeoTIFF or PNG): slope in degrees, or a DEM with --dem.
    #[arg(long)]
    pub reference: PathBuf,
    /// Frame image (GeoTIFF or PNG), same kind as the reference.
    #[arg(long)]
    pub frame: PathBuf,
    /// Both images are DEMs (heights in metres): slope is computed by nav-core first.
    #[arg(long)]
    pub dem: bool,
    /// Pixel size of a PNG reference, metres.
    #[arg(long)]
    pub reference_pixel_m: Option<f64>,
    /// Pixel size of a PNG frame, metres.
    #[arg(long)]
    pub frame_pixel_m: Option<f64>,
    /// Metres per grey level for PNG DEMs.
    #[arg(long, default_value_t = 1.0)]
    pub png_z_scale: f64,
    /// Transform model.
    #[arg(long, value_enum, default_value_t = ModelArg::Similarity)]
    pub model: ModelArg,
    /// MSAC seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Detector threshold, (degrees of slope)².
    #[arg(long)]
    pub threshold: Option<f32>,
    /// Write the figures as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a picture of the matches (frame left, reference right) here.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Run `ground-sim register`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let kind = if a.dem {
        RasterKind::Dem
    } else {
        RasterKind::Slope
    };
    let reference = read_raster(&a.reference, kind, a.reference_pixel_m, a.png_z_scale)
        .with_context(|| format!("reference {}", a.reference.display()))?;
    let frame = read_raster(&a.frame, kind, a.frame_pixel_m, a.png_z_scale)
        .with_context(|| format!("frame {}", a.frame.display()))?;
    let defaults = RegisterOptions::default();
    let opts = RegisterOptions {
        model: match a.model {
            ModelArg::Similarity => Model::Similarity,
            ModelArg::Affine => Model::Affine,
        },
        seed: a.seed.unwrap_or(defaults.seed),
        threshold: a.threshold.unwrap_or(defaults.threshold),
    };
    let r = register(&reference, &frame, kind, &opts)?;
    println!(
        "reference  {} ({}x{} px, {} m/px): {} features",
        a.reference.display(),
        reference.width,
        reference.height,
        reference.pixel_m,
        r.reference_features
    );
    println!(
        "frame      {} ({}x{} px, {} m/px): {} features",
        a.frame.display(),
        frame.width,
        frame.height,
        frame.pixel_m,
        r.frame_features
    );
    println!("matches    {}, inliers {}", r.matches, r.inliers);
    if let (Some(rot), Some(s), Some(c), Some(g)) = (
        r.rotation_deg,
        r.scale,
        r.frame_center_in_reference_px,
        r.frame_center_geo_m,
    ) {
        println!(
            "rotation   {rot:.3}° (±{:.3}°), scale {s:.4}",
            r.heading_sigma_deg.unwrap_or(f64::NAN)
        );
        println!(
            "centre     ({:.2}, {:.2}) reference px (±{:.2}), geo ({:.1}, {:.1}) m",
            c[0],
            c[1],
            r.center_sigma_px.unwrap_or(f64::NAN),
            g[0],
            g[1]
        );
        println!(
            "residual   {:.3} px RMS, non-similarity {:.4}",
            r.residual_rms_px.unwrap_or(f64::NAN),
            r.non_similar.unwrap_or(f64::NAN)
        );
        match (r.refined, r.refined_ncc, &r.refine_note) {
            (true, Some(ncc), _) => println!(
                "refined    over the frame's pixels against the reference slope (correlation {ncc:.3})"
            ),
            (_, _, Some(note)) => println!("refined    no: {note} (feature fix as is)"),
            _ => {}
        }
    }
    println!(
        "time       {:.2} ms onboard chain (+{:.1} ms building the tile)",
        r.time_ms, r.tile_build_ms
    );
    if let Some(j) = &a.json {
        super::write_json(j, &r)?;
        println!("json       {}", j.display());
    }
    if let Some(p) = &a.png {
        let deg = |px: Vec<nav_core::SlopePx>| {
            px.into_iter()
                .map(|p| slope_to_deg(p).unwrap_or(f32::NAN))
                .collect::<Vec<_>>()
        };
        let fs = deg(slope_pixels(&frame, kind)?);
        let rs = deg(slope_pixels(&reference, kind)?);
        let img = match_picture(
            (&fs, frame.width, frame.height),
            (&rs, reference.width, reference.height),
            &r.pairs,
        );
        super::ensure_parent(p)?;
        img.save(p)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("picture    {}", p.display());
    }
    if !r.fix {
        bail!(
            "no fix: {}",
            r.no_fix_reason.as_deref().unwrap_or("unknown")
        );
    }
    Ok(())
}
