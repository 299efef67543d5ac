//! `ground-sim trn`: one synthetic frame from the truth DEM against a reference tile, scored.

use std::path::PathBuf;

use anyhow::{Context, anyhow};
use ground_sim::dem::read_geotiff;
use ground_sim::evaluation::trn::check_frame;
use ground_sim::flyer::frames::FramePose;
use ground_sim::reference::load;
use nav_core::Tile;

/// Arguments of `ground-sim trn`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder (tile.bin, slope.tif) from `ground-sim tile` or `ground-sim insar`.
    #[arg(long)]
    pub tile: PathBuf,
    /// Truth DEM the flyer's frame is synthesised from (GeoTIFF).
    #[arg(long)]
    pub dem: PathBuf,
    /// Frame heading: its +x axis, clockwise from east, degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub heading_deg: f64,
    /// Frame centre east, metres (default: the tile centre).
    #[arg(long, allow_negative_numbers = true)]
    pub x_m: Option<f64>,
    /// Frame centre north, metres (default: the tile centre).
    #[arg(long, allow_negative_numbers = true)]
    pub y_m: Option<f64>,
    /// Frame pixel size, metres (the paper: 10).
    #[arg(long, default_value_t = 10.0)]
    pub pixel_m: f64,
    /// The flyer's ranging sensor.
    #[command(flatten)]
    pub sensor: super::SensorArgs,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Picture of the matches (frame left, reference right), like the paper's Fig. 7.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also export the frame and reference slope images (16-bit PNG, degrees × 512) and the true
    /// frame → reference affine (`truth.json`) into this folder, for other registration tools.
    #[arg(long)]
    pub export: Option<PathBuf>,
    /// The navigator budget.
    #[command(flatten)]
    pub budget: super::BudgetArgs,
}

/// Run `ground-sim trn`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let reference = load(&a.tile)?;
    let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
    let dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let h = tile.header();
    let (cx, cy) = h.pixel_to_geo(
        (h.width_px as f64 - 1.0) / 2.0,
        (h.height_px as f64 - 1.0) / 2.0,
    );
    let pose = FramePose {
        x_m: a.x_m.unwrap_or(cx),
        y_m: a.y_m.unwrap_or(cy),
        heading_rad: a.heading_deg.to_radians(),
        pixel_m: a.pixel_m,
    };
    let sensor = a.sensor.model();
    let check = check_frame(&dem, &tile, &pose, &sensor, a.seed, a.budget.budget)?;
    let (frame, run, s) = (&check.frame, &check.run, &check.score);
    println!(
        "frame      {}x{} px at {} m, heading {:.1}°, centre ({:.1}, {:.1}) m",
        frame.width, frame.height, a.pixel_m, a.heading_deg, pose.x_m, pose.y_m
    );
    println!(
        "features   {} frame, {} tile; matches {}, inliers {}",
        s.features,
        tile.len(),
        s.matches,
        s.inliers
    );
    let d = run.report.detect_stats;
    println!(
        "detector   {} responses above the threshold, {} maxima: {} on no data, {} refused by refinement, {} below the tile's scale",
        d.candidates, d.maxima, d.rejected_nodata, d.rejected_refine, d.rejected_scale
    );
    match (s.rotation_deg, s.heading_err_deg, s.scale, s.pos_err_m) {
        (Some(r), Some(he), Some(sc), Some(pe)) => {
            println!(
                "rotation   {r:.3}° (error {he:+.3}°), scale {sc:.4} (truth {:.4})",
                s.scale_truth
            );
            println!(
                "position   error {pe:.2} m = {:.3} ref px; registration error mean {:.3} / max {:.3} ref px{}",
                s.center_err_px.unwrap_or(f64::NAN),
                s.pos_err_mean_px.unwrap_or(f64::NAN),
                s.pos_err_max_px.unwrap_or(f64::NAN),
                if s.false_fix { "  FALSE FIX" } else { "" }
            );
        }
        _ => println!("no fix     {}", s.no_fix_reason.as_deref().unwrap_or("?")),
    }
    println!("time       {:.2} ms", s.time_ms);
    if let Some(j) = &a.json {
        super::write_json(j, s)?;
        println!("json       {}", j.display());
    }
    if let Some(dir) = &a.export {
        export(dir, frame, reference.slope.as_ref(), tile.header(), &pose)?;
        println!("export     {}", dir.display());
    }
    if let Some(p) = &a.png {
        let ref_slope = reference
            .slope
            .as_ref()
            .ok_or_else(|| anyhow!("{} has no slope.tif for the picture", a.tile.display()))?;
        let img = check.picture(ref_slope);
        super::ensure_parent(p)?;
        img.save(p)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("picture    {}", p.display());
    }
    Ok(())
}

/// Write `frame_slope.png`, `reference_slope.png` (16-bit grey, raw nav-core slope: degrees × 512,
/// 65535 = no data) and `truth.json` (the true frame → reference pixel affine).
fn export(
    dir: &std::path::Path,
    frame: &ground_sim::flyer::frames::Frame,
    ref_slope: Option<&ground_sim::dem::Dem>,
    h: &nav_core::TileHeader<'_>,
    pose: &ground_sim::flyer::frames::FramePose,
) -> anyhow::Result<()> {
    use nav_core::frame::slope_from_deg;
    std::fs::create_dir_all(dir)?;
    let png16 =
        |vals: &[f32], w: usize, hh: usize, path: std::path::PathBuf| -> anyhow::Result<()> {
            let raw: Vec<u16> = vals.iter().map(|&d| slope_from_deg(d).to_bits()).collect();
            let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
                w as u32, hh as u32, raw,
            )
            .ok_or_else(|| anyhow!("image size"))?;
            img.save(&path)
                .with_context(|| format!("writing {}", path.display()))?;
            Ok(())
        };
    png16(
        // As the flyer sees it: smoothed by the tile's terrain σ (at the frame's own pixel).
        &ground_sim::flyer::frames::frame_slope_deg(frame, f64::from(h.smoothing_m)),
        frame.width,
        frame.height,
        dir.join("frame_slope.png"),
    )?;
    let rs = ref_slope.ok_or_else(|| anyhow!("the reference folder has no slope.tif to export"))?;
    png16(
        rs.heights_m(),
        rs.width(),
        rs.height(),
        dir.join("reference_slope.png"),
    )?;
    let t = |x: f64, y: f64| {
        ground_sim::evaluation::trn::truth_to_tile(h, pose, frame.width, frame.height, x, y)
    };
    let (o, ex, ey) = (t(0.0, 0.0), t(1.0, 0.0), t(0.0, 1.0));
    let truth = serde_json::json!({
        "frame_width": frame.width,
        "frame_height": frame.height,
        "affine": [ex.0 - o.0, ey.0 - o.0, o.0, ex.1 - o.1, ey.1 - o.1, o.1],
        "heading_deg": pose.heading_rad.to_degrees(),
        "scale": pose.pixel_m / h.pixel_m(),
        "reference_pixel_m": h.pixel_m(),
        "note": "affine maps frame pixel (x = column, y = row, first pixel centre at 0,0) to reference pixels: X = m1 x + n1 y + p1, Y = m2 x + n2 y + p2",
    });
    std::fs::write(
        dir.join("truth.json"),
        serde_json::to_string_pretty(&truth)? + "\n",
    )?;
    Ok(())
}
