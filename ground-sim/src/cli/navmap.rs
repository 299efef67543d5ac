//! `ground-sim navmap`: the navigability map of a reference folder — where a frame centred on a
//! map cell is predicted to get a fix — as GeoTIFFs and a PNG, from the reference folder alone.
//! By default it rehearses the flight code against the reference
//! ([`ground_sim::evaluation::rehearsal`]); `--method footprint` applies the older rule on feature
//! count, valid fraction and slope texture under the frame.

use std::path::PathBuf;

use anyhow::anyhow;
use ground_sim::dem::read_geotiff;
use ground_sim::evaluation::campaign::{CampaignSpec, PriorSpec};
use ground_sim::evaluation::navmap::{
    NAVMAP_MIN_FEATURES, NAVMAP_MIN_TEXTURE_DEG, NAVMAP_MIN_VALID_FRAC, NavMap, NavmapThresholds,
};
use ground_sim::evaluation::rehearsal::{
    ErrorModel, REHEARSAL_FRAMES, REHEARSAL_MIN_SUCCESS, REHEARSAL_STEP_M, RehearsalSpec, rehearse,
};
use ground_sim::evaluation::suite::{write_navmap, write_rehearsal};
use ground_sim::reference::load;
use nav_core::{NavConfig, Tile};

/// How the map decides "go".
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
pub enum Method {
    /// Fly the flight code against the reference with frames from a draw of the terrain given
    /// its own DEM and its reported error (needs reference-dem.tif; uses height-crlb.tif when
    /// the folder has one).
    Rehearsal,
    /// Thresholds on tile features, valid fraction and slope texture under the frame.
    Footprint,
}

/// Arguments of `ground-sim navmap`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder: tile.bin with its slope raster, slope.tif for the georeference; the
    /// rehearsal also reads reference-dem.tif, tile.json and, when present, height-crlb.tif.
    #[arg(long)]
    pub tile: PathBuf,
    /// Output folder: navmap.tif (1 go, 0 no-go, NaN where a frame would leave the map),
    /// navmap.png, navmap.json; with the rehearsal navmap-success.tif (predicted success
    /// fraction) and navmap-sites.json, with the footprint rule navmap-features.tif and
    /// navmap-texture.tif.
    #[arg(long)]
    pub out: PathBuf,
    /// How "go" is decided.
    #[arg(long, value_enum, default_value_t = Method::Rehearsal)]
    pub method: Method,
    /// The flyer's ranging sensor (rehearsal frames).
    #[command(flatten)]
    pub sensor: super::SensorArgs,
    /// Smallest frame pixel, metres (rehearsal frames draw it uniformly up to the largest).
    #[arg(long, default_value_t = 9.0)]
    pub pixel_min_m: f64,
    /// Largest frame pixel, metres.
    #[arg(long, default_value_t = 11.0)]
    pub pixel_max_m: f64,
    /// Position σ of the prior the flyer will have, metres (0: lost in space, no prior).
    #[arg(long, default_value_t = 0.0)]
    pub prior_sigma_m: f64,
    /// Heading σ of that prior, degrees.
    #[arg(long, default_value_t = 2.0)]
    pub prior_heading_sigma_deg: f64,
    /// Relative scale σ of that prior (the altimeter's).
    #[arg(long, default_value_t = 0.02)]
    pub prior_scale_sigma: f64,
    /// Spacing of the rehearsal sites, metres.
    #[arg(long, default_value_t = REHEARSAL_STEP_M)]
    pub step_m: f64,
    /// Rehearsal frames per site.
    #[arg(long, default_value_t = REHEARSAL_FRAMES)]
    pub frames_per_site: usize,
    /// Smallest predicted success fraction for "go".
    #[arg(long, default_value_t = REHEARSAL_MIN_SUCCESS)]
    pub min_success: f64,
    /// Seed of the rehearsal (error draw, frames, priors).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The navigator budget.
    #[command(flatten)]
    pub budget: super::BudgetArgs,
    /// Footprint rule: side of the flyer's frame on the ground, metres (200 px at 9 m: 1 800).
    #[arg(long, default_value_t = 1800.0)]
    pub frame_side_m: f64,
    /// Footprint rule: fewest tile features under a frame for "go".
    #[arg(long, default_value_t = NAVMAP_MIN_FEATURES)]
    pub min_features: f64,
    /// Footprint rule: smallest valid fraction of the reference under a frame for "go".
    #[arg(long, default_value_t = NAVMAP_MIN_VALID_FRAC)]
    pub min_valid_frac: f64,
    /// Footprint rule: smallest slope standard deviation under a frame for "go", degrees.
    #[arg(long, default_value_t = NAVMAP_MIN_TEXTURE_DEG)]
    pub min_texture_deg: f64,
}

/// What `navmap` reports (`navmap.json`).
#[derive(Debug, serde::Serialize)]
struct Summary {
    tile: PathBuf,
    method: Method,
    width_px: usize,
    height_px: usize,
    /// Footprint rule: its disk radius and thresholds.
    footprint_radius_px: Option<f64>,
    thresholds: Option<NavmapThresholds>,
    /// Rehearsal: how it flew, the prior it assumed, the sites and frames.
    rehearsal: Option<RehearsalSpec>,
    prior: Option<PriorSpec>,
    height_sigma_map: Option<PathBuf>,
    /// Correlation of the map's error (Gaussian σ, metres), from tile.json.
    error_blur_m: Option<f64>,
    sites: Option<usize>,
    frames: Option<usize>,
    /// Fraction of in-map cells (footprint) or of sites (rehearsal) predicted "go".
    go_fraction: f64,
    /// Rehearsal: the sites' mean chance of a fix, a forecast of the success rate of frames
    /// centred uniformly over the map's box (the suite averages the same prediction over its
    /// campaign frames: within 2.4 points of the flown rate on truth-built tiles,
    /// docs/navmap.md).
    mean_predicted_success: Option<f64>,
    seconds: f64,
    files: Vec<PathBuf>,
}

/// Run `ground-sim navmap`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let t0 = std::time::Instant::now();
    let reference = load(&a.tile)?;
    let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
    std::fs::create_dir_all(&a.out)?;
    let stem = a.out.join("navmap");
    let h = tile.header();
    let mut s = Summary {
        tile: a.tile.clone(),
        method: a.method,
        width_px: h.width_px as usize,
        height_px: h.height_px as usize,
        footprint_radius_px: None,
        thresholds: None,
        rehearsal: None,
        prior: None,
        height_sigma_map: None,
        error_blur_m: None,
        sites: None,
        frames: None,
        go_fraction: f64::NAN,
        mean_predicted_success: None,
        seconds: 0.0,
        files: Vec::new(),
    };
    match a.method {
        Method::Footprint => {
            let thresholds = NavmapThresholds {
                min_features: a.min_features,
                min_valid_frac: a.min_valid_frac,
                min_texture_deg: a.min_texture_deg,
            };
            let m = NavMap::build(&tile, 0.5 * a.frame_side_m, thresholds)?;
            write_navmap(&m, reference.slope.as_ref(), &stem)?;
            s.footprint_radius_px = Some(m.radius_px);
            s.thresholds = Some(thresholds);
            s.go_fraction = m.go_fraction();
            s.files = [
                "navmap.tif",
                "navmap-features.tif",
                "navmap-texture.tif",
                "navmap.png",
            ]
            .iter()
            .map(|f| a.out.join(f))
            .collect();
        }
        Method::Rehearsal => {
            let dem_path = a.tile.join(ground_sim::reference::DEM_FILE);
            if !dem_path.exists() {
                anyhow::bail!(
                    "{} is missing: the rehearsal flies frames from the reference DEM \
                     (`--method footprint` needs only the tile)",
                    dem_path.display()
                );
            }
            // Checked before flying: the pictures need the tile's grid.
            if !reference.slope.as_ref().is_some_and(|g| {
                g.width() == h.width_px as usize && g.height() == h.height_px as usize
            }) {
                anyhow::bail!("{} has no slope.tif on the tile's grid", a.tile.display());
            }
            let dem = read_geotiff(&dem_path)?;
            let error = ErrorModel::load(&a.tile)?;
            let prior = (a.prior_sigma_m > 0.0).then_some(PriorSpec {
                sigma_m: a.prior_sigma_m,
                heading_sigma_deg: a.prior_heading_sigma_deg,
                scale_sigma: a.prior_scale_sigma,
            });
            let campaign = CampaignSpec {
                trials: 1,
                seed: a.seed,
                pixel_min_m: a.pixel_min_m,
                pixel_max_m: a.pixel_max_m,
                sensor: a.sensor.model(),
                prior,
                budget: a.budget.budget,
                host_time: false,
            };
            let spec = RehearsalSpec {
                step_m: a.step_m,
                frames_per_site: a.frames_per_site,
                min_success: a.min_success,
                seed: a.seed,
            };
            let pb = super::progress(0, "rehearsal");
            let r = rehearse(
                tile,
                NavConfig::default(),
                &dem,
                &error,
                &campaign,
                &spec,
                &pb,
            )?;
            pb.finish_and_clear();
            write_rehearsal(&r, &tile, reference.slope.as_ref(), &stem)?;
            s.rehearsal = Some(spec);
            s.prior = prior;
            s.height_sigma_map = error
                .sigma
                .is_some()
                .then(|| a.tile.join(ground_sim::insar::products::CRLB_FILE));
            s.error_blur_m = Some(error.blur_m);
            s.sites = Some(r.nx * r.ny);
            s.frames = Some(r.frames);
            s.go_fraction = r.go_fraction();
            s.mean_predicted_success = Some(
                r.success.iter().map(|&p| f64::from(p)).sum::<f64>()
                    / r.success.len().max(1) as f64,
            );
            s.files = [
                "navmap.tif",
                "navmap-success.tif",
                "navmap.png",
                "navmap-sites.json",
            ]
            .iter()
            .map(|f| a.out.join(f))
            .collect();
        }
    }
    s.seconds = t0.elapsed().as_secs_f64();
    match a.method {
        Method::Footprint => println!(
            "navmap     footprint rule, {}x{} cells: go on {:.1} % of the cells a frame fits",
            s.width_px,
            s.height_px,
            100.0 * s.go_fraction
        ),
        Method::Rehearsal => println!(
            "navmap     rehearsal ({}), {} sites, {} frames in {:.1} s: go on {:.1} % of the sites, \
             mean chance of a fix {:.1} %",
            s.prior.map_or("no prior".to_string(), |p| format!(
                "prior {} m, {}°",
                p.sigma_m, p.heading_sigma_deg
            )),
            s.sites.unwrap_or(0),
            s.frames.unwrap_or(0),
            s.seconds,
            100.0 * s.go_fraction,
            100.0 * s.mean_predicted_success.unwrap_or(f64::NAN)
        ),
    }
    for f in &s.files {
        println!("  {}", f.display());
    }
    super::write_json(&a.out.join("navmap.json"), &s)?;
    Ok(())
}
