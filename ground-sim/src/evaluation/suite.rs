//! The terrain suite: every figure Umbra publishes is measured on these scenes. Each scene is
//! named, seeded and reproducible; each is flown against a tile built from the truth DEM and
//! against the InSAR product's tile, with and without a prior, as `eval` campaigns; the
//! navigability map of each tile is scored against the same frames.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, anyhow};
use image::{Rgb, RgbImage};
use indicatif::ProgressBar;
use nav_core::{NavConfig, Tile};
use serde::Serialize;

use crate::dem::{Dem, Interpolation, read_geotiff, resample_to_pixel, write_geotiff};
use crate::evaluation::campaign::{
    CampaignSpec, EvalSummary, PriorSpec, percentile, run_campaign, summarize, write_csv,
};
use crate::evaluation::navmap::{
    GO_SUCCESS_BAR, NavMap, NavmapScore, NavmapThresholds, agreement_ceiling,
};
use crate::evaluation::rehearsal::{ErrorModel, Rehearsal, RehearsalSpec, rehearse};
use crate::flyer::frames::SensorModel;
use crate::flyer::onboard::Budget;
use crate::insar::InsarConfig;
use crate::insar::pipeline::{LookDirections, run_from_dem_looks};
use crate::insar::products::{RunContext, SarSummary, write_outputs};
use crate::pictures::render::{GLYPH, draw_text};
use crate::reference::noise_floor::FrameNoise;
use crate::reference::tile::MAX_TILE_FEATURES;
use crate::reference::{
    DEFAULT_SMOOTHING_M, Smoothing, reference_dem, surf_config_for, write_reference,
};
use crate::sar::{Polarisation, SarConfig};
use crate::terrain::{Preset, TerrainParams, Window, generate};

/// Where a scene's DEM comes from.
#[derive(Debug, Clone, Serialize)]
pub enum SceneSource {
    /// A built-in synthetic preset (its parameters, seed included).
    Synthetic(TerrainParams),
    /// A real DEM file, its centre cropped to `size_m` and resampled to `pixel_m` (bicubic).
    File {
        /// The GeoTIFF.
        path: PathBuf,
        /// Side of the centred square crop, metres.
        size_m: f64,
        /// Pixel of the scene, metres.
        pixel_m: f64,
    },
}

/// One scene of the suite.
#[derive(Debug, Clone, Serialize)]
pub struct Scene {
    /// Short name (folder name and table row).
    pub name: String,
    /// What the scene stands for.
    pub what: String,
    /// Its DEM.
    pub source: SceneSource,
}

/// Where the real DEMs that may join the suite live, relative to the repository root (the
/// working directory the commands are run from).
pub const SHARED_DATA_DIR: &str = "../shared/data";

/// The suite's scenes at `size_m` × `size_m` and 5 m, terrain seed `seed`. `shared` is the
/// folder of real DEMs (`../shared/data`); its large-enough files join when it exists.
pub fn default_scenes(seed: u64, size_m: f64, shared: Option<&Path>) -> Vec<Scene> {
    let syn = |name: &str, what: &str, preset: Preset, window: Window| Scene {
        name: name.into(),
        what: what.into(),
        source: SceneSource::Synthetic(TerrainParams {
            preset,
            window,
            seed,
            size_m,
            pixel_m: 5.0,
        }),
    };
    let mut v = vec![
        syn(
            "plains",
            "smooth young plains, slope median ≤ 2° (the weak case)",
            Preset::Plains,
            Window::Floor,
        ),
        syn(
            "lola",
            "cratered plain calibrated on the real LOLA 5 m tile",
            Preset::Lola,
            Window::Floor,
        ),
        syn(
            "shoemaker",
            "dense old floor (the project's first preset)",
            Preset::Shoemaker,
            Window::Floor,
        ),
        syn(
            "shackleton-floor",
            "Shackleton floor (dense)",
            Preset::Shackleton,
            Window::Floor,
        ),
        syn(
            "fresh-floor",
            "fresh 2.3 km simple crater, d/D 0.2, 30–35° walls: the whole bowl",
            Preset::Fresh,
            Window::Floor,
        ),
        syn(
            "fresh-rim",
            "the same fresh crater's rim crest",
            Preset::Fresh,
            Window::Rim,
        ),
        syn(
            "shackleton-wall",
            "Shackleton wall, 30–35° (layover for the radar)",
            Preset::Shackleton,
            Window::Wall,
        ),
        syn(
            "shackleton-rim",
            "Shackleton rim crest",
            Preset::Shackleton,
            Window::Rim,
        ),
    ];
    if let Some(dir) = shared {
        // The 10 km ridge zoom is the only real DEM large enough for 2 km frames (the LOLA 5 m
        // tile is 1.28 km, the overview's 200 m pixels are coarser than the frames).
        let p = dir.join("shackleton-ridge-zoom-40m-256.tif");
        if p.exists() {
            v.push(Scene {
                name: "real-ridge".into(),
                what: "real LOLA ridge by Shackleton (40 m, median-blurred), resampled to 5 m"
                    .into(),
                source: SceneSource::File {
                    path: p,
                    size_m,
                    pixel_m: 5.0,
                },
            });
        }
    }
    v
}

/// Which reference the frames are flown against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum TileKind {
    /// Built straight from the truth DEM ("perfect InSAR").
    Truth,
    /// The InSAR product's tile (radar simulated over the truth, the whole chain).
    Insar,
}

impl TileKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Truth => "truth",
            Self::Insar => "insar",
        }
    }
}

/// What a suite run does.
#[derive(Debug, Clone, Serialize)]
pub struct SuiteSpec {
    /// Frames per campaign.
    pub trials: usize,
    /// Campaign seed (the terrain seed is in each scene).
    pub seed: u64,
    /// Frame pixel range, metres.
    pub pixel_range_m: [f64; 2],
    /// The flyer's sensor.
    pub sensor: SensorModel,
    /// Tile kinds flown.
    pub kinds: Vec<TileKind>,
    /// Prior modes flown (`None`: lost in space).
    pub priors: Vec<Option<PriorSpec>>,
    /// Reference pixel, metres.
    pub reference_pixel_m: f64,
    /// Radar of the InSAR tiles.
    pub radar: SarConfig,
    /// Its InSAR channel.
    pub polarisation: Polarisation,
    /// Look directions of the InSAR tiles.
    pub looks: LookDirections,
    /// Passes of one track stacked per look ([`crate::insar::InsarConfig::passes`]; 1 = one).
    pub passes: usize,
    /// A second, longer baseline of the InSAR tiles, m ([`crate::insar::InsarConfig::long_baseline_m`];
    /// 0 = none).
    pub long_baseline_m: f64,
    /// σ of the long pair's DEM filter, output pixels
    /// ([`crate::insar::InsarConfig::long_filter_sigma_px`]; `None`: the short pair's).
    pub long_filter_sigma_px: Option<f64>,
    /// Kernel of the InSAR chain's DEM filter, at its default σ
    /// ([`crate::insar::pipeline::DemFilterKind::default_sigma_px`]).
    pub dem_filter: crate::insar::pipeline::DemFilterKind,
    /// InSAR tiles' features from their DEM with small holes filled
    /// ([`crate::insar::InsarConfig::fill_tile_holes`]).
    pub fill_tile_holes: bool,
    /// Navigability-map thresholds (the footprint rule).
    pub navmap: NavmapThresholds,
    /// The navigability map by rehearsal, per campaign's prior mode (`None`: not flown).
    pub rehearsal: Option<RehearsalSpec>,
    /// A simulation-only diagnostic: the rehearsal flies its frames from the scene's true
    /// terrain (at the scene's own 5 m pixel) instead of a draw from the map and its reported
    /// error. What it gains over the normal rehearsal is what the map's error model misses;
    /// what it still gets wrong is the go rule's own limit (docs/navmap.md). No flyer has this;
    /// its files are named `rehearsal-on-truth-*` and suite.md says so above the table.
    pub rehearse_on_truth: bool,
    /// Navigator budget (flight unless asked otherwise).
    pub budget: Budget,
}

/// One campaign of the suite.
#[derive(Debug, Clone, Serialize)]
pub struct SuiteRow {
    /// Scene name.
    pub scene: String,
    /// Tile kind.
    pub kind: TileKind,
    /// Features in the tile.
    pub tile_features: usize,
    /// Of those, the ones a truth-built tile on the same grid holds too (InSAR tiles only,
    /// `insar::products::features_on_truth`): the map's blobs that are ground, not noise.
    pub tile_features_on_truth: Option<usize>,
    /// The campaign's summary (the prior is in it).
    pub summary: EvalSummary,
    /// The navigability map (footprint rule) against the campaign's outcomes.
    pub navmap: NavmapScore,
    /// Fraction of the tile's in-map cells the footprint rule predicted "go".
    pub navmap_go_fraction: f64,
    /// The navigability map by rehearsal (in the campaign's prior mode) against the outcomes.
    pub rehearsal: Option<NavmapScore>,
    /// Fraction of rehearsal sites predicted "go".
    pub rehearsal_go_fraction: Option<f64>,
    /// Rehearsal frames flown for this campaign's map.
    pub rehearsal_frames: Option<usize>,
    /// The rehearsal's predicted chance of a fix, averaged over the campaign's frame centres
    /// on its sites: its forecast of the campaign's success rate.
    pub rehearsal_predicted_success: Option<f64>,
    /// The best agreement any go/no-go map could reach on this campaign's frames (on the
    /// rehearsal's sites) while its "go" frames fix at [`GO_SUCCESS_BAR`], if the rehearsal's
    /// chances are right ([`agreement_ceiling`]): where it is below the agreement bar, the
    /// outcomes are too random for any map of cells to meet both bars on this campaign.
    pub rehearsal_agreement_ceiling: Option<f64>,
}

/// What one scene gave beyond its campaigns.
#[derive(Debug, Clone, Serialize)]
pub struct SceneReport {
    /// The scene.
    pub scene: Scene,
    /// Slope median of the scene DEM, degrees.
    pub slope_p50_deg: f64,
    /// InSAR height RMSE against the truth on the product grid, m (when InSAR was run).
    pub insar_height_rmse_m: Option<f64>,
    /// InSAR slope RMSE, degrees.
    pub insar_slope_rmse_deg: Option<f64>,
    /// Valid fraction of the InSAR product.
    pub insar_valid_frac: Option<f64>,
    /// RMS per-pixel Cramér–Rao height bound the InSAR product reported, m.
    pub insar_crlb_height_m: Option<f64>,
    /// Wall time of the scene (terrain, tiles, campaigns), s.
    pub seconds: f64,
}

/// The suite's result (`suite.json`).
#[derive(Debug, Clone, Serialize)]
pub struct SuiteReport {
    /// What was run.
    pub spec: SuiteSpec,
    /// Per scene.
    pub scenes: Vec<SceneReport>,
    /// Per campaign.
    pub rows: Vec<SuiteRow>,
    /// Wall time of the whole suite, s.
    pub seconds: f64,
}

/// Make the scene's DEM.
pub fn scene_dem(scene: &Scene) -> anyhow::Result<Dem> {
    match &scene.source {
        SceneSource::Synthetic(p) => Ok(generate(p, &ProgressBar::hidden())?.0),
        SceneSource::File {
            path,
            size_m,
            pixel_m,
        } => {
            let dem = read_geotiff(path).with_context(|| format!("reading {}", path.display()))?;
            let (x0, y0, x1, y1) = dem.extent_m();
            let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
            let half = 0.5 * size_m;
            let crop = dem.crop_geo(cx - half, cy - half, cx + half, cy + half)?;
            Ok(resample_to_pixel(&crop, *pixel_m, Interpolation::Bicubic)?)
        }
    }
}

/// Run one scene: DEM, tiles, campaigns. Writes into `dir`: `dem.tif`, `truth/` and `insar/`
/// (reference folders), `<kind>-<prior>.json/.csv` per campaign with `<kind>-<prior>-navmap.csv`
/// (both maps' predictions at every frame), `navmap-<kind>.tif/.png` (the footprint rule) and,
/// with a rehearsal, `rehearsal-<kind>-<prior>.tif/.png`, `-success.tif` and `-sites.json`.
pub fn run_scene(
    scene: &Scene,
    spec: &SuiteSpec,
    dir: &Path,
    progress: &ProgressBar,
) -> anyhow::Result<(SceneReport, Vec<SuiteRow>)> {
    let t0 = Instant::now();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    progress.set_message(format!("{}: terrain", scene.name));
    let dem = scene_dem(scene)?;
    write_geotiff(&dem, &dir.join("dem.tif"), None)?;
    let mut slope: Vec<f64> = crate::dem::stats::slope_deg(&dem)?
        .into_iter()
        .filter(|v| v.is_finite())
        .map(f64::from)
        .collect();
    let mut report = SceneReport {
        scene: scene.clone(),
        slope_p50_deg: percentile(&mut slope, 0.5),
        insar_height_rmse_m: None,
        insar_slope_rmse_deg: None,
        insar_valid_frac: None,
        insar_crlb_height_m: None,
        seconds: 0.0,
    };
    let mut rows = Vec::new();
    for &kind in &spec.kinds {
        let tdir = dir.join(kind.name());
        progress.set_message(format!("{}: {} tile", scene.name, kind.name()));
        let (features, on_truth) = match kind {
            TileKind::Truth => {
                let r = reference_dem(&dem, spec.reference_pixel_m)?;
                let surf = surf_config_for(
                    &FrameNoise::default_sensor(),
                    spec.reference_pixel_m,
                    DEFAULT_SMOOTHING_M,
                )?;
                let n = write_reference(
                    &r,
                    &tdir,
                    &surf,
                    MAX_TILE_FEATURES,
                    Smoothing::default_for_truth(),
                )?
                .features;
                (n, None)
            }
            TileKind::Insar => {
                let cfg = InsarConfig {
                    pixel_m: spec.reference_pixel_m,
                    passes: spec.passes,
                    long_baseline_m: spec.long_baseline_m,
                    long_filter_sigma_px: spec.long_filter_sigma_px,
                    dem_filter: spec.dem_filter,
                    dem_filter_sigma_px: spec.dem_filter.default_sigma_px(),
                    fill_tile_holes: spec.fill_tile_holes,
                    ..InsarConfig::default()
                };
                let run = run_from_dem_looks(
                    &dem,
                    &spec.radar,
                    spec.polarisation,
                    &cfg,
                    false,
                    spec.looks,
                )?;
                let ctx = RunContext {
                    sar: Some(SarSummary::of(&run.pair)),
                    input_dem: Some(dir.join("dem.tif")),
                    filled_nodata: run.filled_nodata,
                    blocks: None,
                };
                let r = write_outputs(&tdir, &run.product, &run.truth, &ctx)?;
                report.insar_height_rmse_m = Some(r.accuracy.height_rmse_m);
                report.insar_slope_rmse_deg = Some(r.accuracy.slope_rmse_deg);
                report.insar_valid_frac = Some(r.accuracy.valid_fraction);
                report.insar_crlb_height_m = Some(r.accuracy.crlb_height_m);
                (r.tile_features, Some(r.tile_features_on_truth))
            }
        };
        let reference = crate::reference::load(&tdir)?;
        let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
        // The disk every frame covers whatever its heading: half the side of the smallest frame.
        let radius_m =
            0.5 * spec.sensor.width_px.min(spec.sensor.height_px) as f64 * spec.pixel_range_m[0];
        let navmap = NavMap::build(&tile, radius_m, spec.navmap)?;
        write_navmap(
            &navmap,
            reference.slope.as_ref(),
            &dir.join(format!("navmap-{}", kind.name())),
        )?;
        // Read once per tile: every prior mode rehearses from the same reference DEM and error.
        let rehearsal_input = spec
            .rehearsal
            .map(|r| -> anyhow::Result<_> {
                if spec.rehearse_on_truth {
                    // The truth claims no error: its DEM is flown as it is.
                    return Ok((r, dem.clone(), ErrorModel::none()));
                }
                Ok((
                    r,
                    read_geotiff(&tdir.join(crate::reference::DEM_FILE))?,
                    ErrorModel::load(&tdir)?,
                ))
            })
            .transpose()?;
        for prior in &spec.priors {
            let cspec = CampaignSpec {
                trials: spec.trials,
                seed: spec.seed,
                pixel_min_m: spec.pixel_range_m[0],
                pixel_max_m: spec.pixel_range_m[1],
                sensor: spec.sensor,
                prior: *prior,
                budget: spec.budget,
                host_time: true,
            };
            let tag = format!("{}-{}", kind.name(), prior_tag(prior.as_ref()));
            progress.set_message(format!("{}: {tag}", scene.name));
            let scores = run_campaign(
                tile,
                NavConfig::default(),
                &dem,
                &cspec,
                &ProgressBar::hidden(),
            )?;
            let summary = summarize(&scores, &cspec);
            write_csv(&dir.join(format!("{tag}.csv")), &scores)?;
            crate::write_json(&dir.join(format!("{tag}.json")), &summary)?;
            // The rehearsal flies the campaign's own mode (sensor, pixels, prior, budget) from
            // the reference folder alone: its DEM and, for an InSAR map, its height error.
            let rehearsal = match &rehearsal_input {
                Some((r, rdem, error)) => {
                    progress.set_message(format!("{}: {tag} rehearsal", scene.name));
                    let reh = rehearse(
                        tile,
                        NavConfig::default(),
                        rdem,
                        error,
                        &cspec,
                        r,
                        &ProgressBar::hidden(),
                    )?;
                    write_rehearsal(
                        &reh,
                        &tile,
                        reference.slope.as_ref(),
                        // A diagnostic rehearsal's files say so in their names.
                        &dir.join(if spec.rehearse_on_truth {
                            format!("rehearsal-on-truth-{tag}")
                        } else {
                            format!("rehearsal-{tag}")
                        }),
                    )?;
                    Some(reh)
                }
                None => None,
            };
            let h = tile.header();
            let mut nm = NavmapScore::default();
            let mut rm = NavmapScore::default();
            let mut predicted = Vec::new();
            // Per frame: what the maps read at the true centre, what they predicted, what
            // happened.
            let mut csv = String::from(
                "trial,features,valid_frac,texture_deg,go,rehearsal_success,rehearsal_go,success\n",
            );
            for (i, s) in scores.iter().enumerate() {
                let Some(t) = s.truth else { continue };
                let x = (t.x_m - h.origin_x_m) / h.pixel_x_m;
                let y = (t.y_m - h.origin_y_m) / h.pixel_y_m;
                let (go, ok) = (navmap.go_at(x, y), s.fix && !s.false_fix);
                nm.add(go, ok);
                let (rp, rgo) = rehearsal.as_ref().map_or((f64::NAN, false), |r| {
                    (r.success_at(t.x_m, t.y_m), r.go_at(t.x_m, t.y_m))
                });
                if rehearsal.is_some() {
                    // A centre off the rehearsal's sites (NaN) is "no-go": a frame there would
                    // leave the map; it does not enter the forecast's mean.
                    rm.add(rgo, ok);
                    if rp.is_finite() {
                        predicted.push(rp);
                    }
                }
                if let Some(c) = navmap.cell_at(x, y) {
                    csv += &format!(
                        "{i},{},{:.4},{:.3},{go},{rp:.3},{rgo},{ok}\n",
                        navmap.features[c], navmap.valid_frac[c], navmap.texture_deg[c]
                    );
                }
            }
            let p = dir.join(format!("{tag}-navmap.csv"));
            std::fs::write(&p, csv).with_context(|| format!("writing {}", p.display()))?;
            rows.push(SuiteRow {
                scene: scene.name.clone(),
                kind,
                tile_features: features,
                tile_features_on_truth: on_truth,
                summary,
                navmap: nm,
                navmap_go_fraction: navmap.go_fraction(),
                rehearsal: rehearsal.as_ref().map(|_| rm),
                rehearsal_go_fraction: rehearsal.as_ref().map(Rehearsal::go_fraction),
                rehearsal_frames: rehearsal.as_ref().map(|r| r.frames),
                rehearsal_predicted_success: (!predicted.is_empty())
                    .then(|| predicted.iter().sum::<f64>() / predicted.len() as f64),
                rehearsal_agreement_ceiling: (!predicted.is_empty())
                    .then(|| agreement_ceiling(&predicted, GO_SUCCESS_BAR)),
            });
            progress.inc(1);
        }
    }
    report.seconds = t0.elapsed().as_secs_f64();
    Ok((report, rows))
}

/// `noprior` or `prior50m2deg`: the prior's file tag.
pub fn prior_tag(p: Option<&PriorSpec>) -> String {
    p.map_or("noprior".into(), |p| {
        format!("prior{}m{}deg", p.sigma_m, p.heading_sigma_deg)
    })
}

/// Write the navigability map's layers as GeoTIFFs on the tile's grid (`<stem>.tif`: 1 go,
/// 0 no-go, NaN where a frame leaves the map; `<stem>-features.tif`, `<stem>-texture.tif`) and
/// `<stem>.png` (the reference slope with go cells tinted green, no-go red), when the tile's
/// slope map `grid` is at hand for the georeference.
pub fn write_navmap(m: &NavMap, grid: Option<&Dem>, stem: &Path) -> anyhow::Result<()> {
    let Some(grid) = grid.filter(|g| g.width() == m.width && g.height() == m.height) else {
        anyhow::bail!("the reference folder has no slope.tif on the tile's grid");
    };
    let with = |v: Vec<f32>| -> anyhow::Result<Dem> {
        let mut d = grid.clone();
        d.heights_m_mut().copy_from_slice(&v);
        Ok(d)
    };
    let name = |suffix: &str| {
        let mut s = stem.as_os_str().to_owned();
        s.push(suffix);
        PathBuf::from(s)
    };
    write_geotiff(&with(m.go_layer())?, &name(".tif"), None)?;
    write_geotiff(&with(m.features.clone())?, &name("-features.tif"), None)?;
    write_geotiff(&with(m.texture_deg.clone())?, &name("-texture.tif"), None)?;
    navmap_picture(m, grid.heights_m())
        .save(name(".png"))
        .with_context(|| format!("writing {}", name(".png").display()))?;
    Ok(())
}

/// The navigability map over the reference slope (grey, 0–30°): go green, no-go red, cells
/// whose frame would leave the map left grey.
pub fn navmap_picture(m: &NavMap, slope_deg: &[f32]) -> RgbImage {
    go_picture(
        &m.go_layer(),
        m.width,
        m.height,
        slope_deg,
        &format!("navmap: go {:.0} %", 100.0 * m.go_fraction()),
    )
}

/// A go layer (1 go, 0 no-go, NaN off the map; `width` × `height`, row-major) over the
/// reference slope (grey, 0–30°): go tinted green, no-go red, off-map left grey; `title` under
/// it.
pub fn go_picture(
    go: &[f32],
    width: usize,
    height: usize,
    slope_deg: &[f32],
    title: &str,
) -> RgbImage {
    let mag = (600 / width.max(height).max(1)).max(1) as u32;
    let (w, h) = (width as u32 * mag, height as u32 * mag + 2 * GLYPH + 8);
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    for r in 0..height {
        for c in 0..width {
            let i = r * width + c;
            let s = slope_deg.get(i).copied().unwrap_or(f32::NAN);
            let g = if s.is_finite() {
                (s / 30.0).clamp(0.0, 1.0) * 200.0 + 40.0
            } else {
                20.0
            };
            let v = go.get(i).copied().unwrap_or(f32::NAN);
            // Tinted, not painted over: the terrain under a go or no-go cell stays visible.
            let px = if !v.is_finite() {
                [g as u8; 3]
            } else if v >= 0.5 {
                [(0.7 * g) as u8, (0.7 * g + 75.0) as u8, (0.7 * g) as u8]
            } else {
                [(0.7 * g + 75.0) as u8, (0.7 * g) as u8, (0.7 * g) as u8]
            };
            for dy in 0..mag {
                for dx in 0..mag {
                    img.put_pixel(c as u32 * mag + dx, r as u32 * mag + dy, Rgb(px));
                }
            }
        }
    }
    let y = height as u32 * mag + 4;
    draw_text(&mut img, 4, y, title, [0, 0, 0]);
    draw_text(
        &mut img,
        4,
        y + GLYPH + 2,
        "green go, red no-go, grey off map",
        [60, 60, 60],
    );
    img
}

/// Write a rehearsal on the tile's grid: `<stem>.tif` (1 go, 0 no-go, NaN where a frame leaves
/// the map), `<stem>-success.tif` (interpolated success fraction), `<stem>.png` (over the
/// reference slope `grid`, which gives the georeference) and `<stem>-sites.json` (the sites).
pub fn write_rehearsal(
    r: &Rehearsal,
    tile: &Tile<'_>,
    grid: Option<&Dem>,
    stem: &Path,
) -> anyhow::Result<()> {
    let h = tile.header();
    let (w, hh) = (h.width_px as usize, h.height_px as usize);
    let Some(grid) = grid.filter(|g| g.width() == w && g.height() == hh) else {
        anyhow::bail!("the reference folder has no slope.tif on the tile's grid");
    };
    let name = |suffix: &str| {
        let mut s = stem.as_os_str().to_owned();
        s.push(suffix);
        PathBuf::from(s)
    };
    let with = |v: Vec<f32>| {
        let mut d = grid.clone();
        d.heights_m_mut().copy_from_slice(&v);
        d
    };
    let go = r.go_layer(tile);
    write_geotiff(&with(go.clone()), &name(".tif"), None)?;
    write_geotiff(&with(r.success_layer(tile)), &name("-success.tif"), None)?;
    go_picture(
        &go,
        w,
        hh,
        grid.heights_m(),
        &format!(
            "rehearsal: go {:.0} % of {} sites",
            100.0 * r.go_fraction(),
            r.nx * r.ny
        ),
    )
    .save(name(".png"))
    .with_context(|| format!("writing {}", name(".png").display()))?;
    crate::write_json(&name("-sites.json"), r)?;
    Ok(())
}

/// A radar design in words for tables and reports: baseline, thermal noise, diffuse echo and
/// look directions (e.g. "32 m baseline, NESZ -25 dB, diffuse echo -17 dB, both looks fused").
pub fn radar_words(radar: &SarConfig, looks: LookDirections, passes: usize) -> String {
    let noise = radar.noise_equivalent_sigma0_db;
    let diffuse = radar.diffuse_sigma0_db;
    format!(
        "{} m baseline, {}, {}, {}{}",
        radar.baseline_m,
        if noise.is_finite() {
            format!("NESZ {noise} dB")
        } else {
            "no thermal noise".to_string()
        },
        if diffuse.is_finite() {
            format!("diffuse echo {diffuse} dB")
        } else {
            "no diffuse echo".to_string()
        },
        match looks {
            LookDirections::One => "one look (east)",
            LookDirections::Both => "both looks fused",
        },
        if passes > 1 {
            format!(", {passes} passes stacked per look")
        } else {
            String::new()
        }
    )
}

/// A navigability map's score as a table cell: "success of the go frames / agreement", and
/// when given, the best agreement a map of cells could reach ([`agreement_ceiling`]) in
/// brackets.
fn go_cell(score: Option<&NavmapScore>, ceiling: Option<f64>) -> String {
    let best = ceiling
        .filter(|c| c.is_finite())
        .map_or(String::new(), |c| format!(" (≤ {:.0} %)", 100.0 * c));
    match score {
        None => "–".into(),
        Some(m) if m.go_frames > 0 => format!(
            "{:.1} % of {} / {:.0} %{best}",
            100.0 * m.go_success_rate(),
            m.go_frames,
            100.0 * m.agreement()
        ),
        Some(m) => format!("no go frame / {:.0} %{best}", 100.0 * m.agreement()),
    }
}

/// The suite's table as Markdown: one row per campaign.
pub fn table_markdown(r: &SuiteReport) -> String {
    let mut s = format!(
        "{} frames per campaign, campaign seed {}, navigator budget {}; InSAR tiles: {}{}{}.\n\n",
        r.spec.trials,
        r.spec.seed,
        r.spec.budget.label(),
        radar_words(&r.spec.radar, r.spec.looks, r.spec.passes),
        if r.spec.long_baseline_m > 0.0 {
            format!(
                ", a second {} m baseline fused in{}",
                r.spec.long_baseline_m,
                r.spec
                    .long_filter_sigma_px
                    .map(|s| format!(" (its DEM filter {s} px)"))
                    .unwrap_or_default()
            )
        } else {
            String::new()
        },
        match r.spec.dem_filter {
            crate::insar::pipeline::DemFilterKind::Gaussian => String::new(),
            k => format!(", DEM filter {k:?} at {} px", k.default_sigma_px()).to_lowercase(),
        },
    );
    if r.spec.rehearse_on_truth {
        s += "**Diagnostic run: the rehearsal flew frames from the scenes' true terrain** \
              (`--rehearse-on-truth`), not from the maps; its column is not a prediction a \
              flyer could have.\n\n";
    }
    s += concat!(
        "| scene | tile | prior | success | false | no fix (reasons) | pos p50 / p95 m | heading p95 ° | in 3σ | NEES | ms/frame | M4 work p95 (frames over 20 M / budget cut) | navmap (footprint) go: success / agree | navmap (rehearsal) go: success / agree (≤ best any map) |\n",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for row in &r.rows {
        let e = &row.summary;
        let reasons: Vec<String> = e
            .no_fix_reasons
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        let f = |v: f64, d: usize| {
            if v.is_finite() {
                format!("{v:.d$}")
            } else {
                "–".into()
            }
        };
        s += &format!(
            "| {} | {} ({} feat.{}) | {} | {:.1} % | {} | {:.1} % {} | {} / {} | {} | {} | {} | {:.2} | {} | {} | {} |\n",
            row.scene,
            row.kind.name(),
            row.tile_features,
            row.tile_features_on_truth
                .map_or(String::new(), |n| format!(", {n} ground")),
            e.prior.map_or("none".into(), |p| format!(
                "{} m, {}°",
                p.sigma_m, p.heading_sigma_deg
            )),
            100.0 * e.success_rate,
            e.false_fixes,
            100.0 * e.no_fix_rate,
            if reasons.is_empty() {
                String::new()
            } else {
                format!("({})", reasons.join(", "))
            },
            f(e.pos_err_p50_m, 2),
            f(e.pos_err_p95_m, 2),
            f(e.heading_err_p95_deg, 3),
            if e.success_rate + e.false_fix_rate > 0.0 {
                format!("{:.1} %", 100.0 * e.within_3sigma_frac)
            } else {
                "–".into()
            },
            f(e.nees_mean, 2),
            e.time_ms_mean,
            if e.m4_instructions_p95.is_finite() {
                format!(
                    "{:.1} M ({:.0} % / {:.1} %)",
                    e.m4_instructions_p95 / 1e6,
                    100.0 * e.over_budget_frac,
                    100.0 * e.budget_cut_frac
                )
            } else {
                "–".into()
            },
            go_cell(Some(&row.navmap), None),
            go_cell(row.rehearsal.as_ref(), row.rehearsal_agreement_ceiling),
        );
    }
    s
}

/// One picture of the suite: success per scene (rows) and campaign (columns), red 0 % → green
/// 100 %, the figure written in each cell, false fixes flagged.
pub fn suite_picture(r: &SuiteReport) -> RgbImage {
    let mut cols: Vec<(TileKind, Option<PriorSpec>)> = Vec::new();
    for row in &r.rows {
        let key = (row.kind, row.summary.prior);
        if !cols.contains(&key) {
            cols.push(key);
        }
    }
    let names: Vec<&str> = r.scenes.iter().map(|s| s.scene.name.as_str()).collect();
    let label_w = names.iter().map(|n| n.len()).max().unwrap_or(8) as u32 * GLYPH + 16;
    let (cell_w, cell_h) = (12 * GLYPH, 2 * GLYPH + 8);
    let top = 4 * GLYPH + 12;
    let w = label_w + cell_w * cols.len() as u32 + 8;
    let h = top + cell_h * names.len() as u32 + GLYPH + 12;
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    draw_text(
        &mut img,
        4,
        4,
        &format!(
            "TRN success on the terrain suite ({} frames each)",
            r.spec.trials
        ),
        [0, 0, 0],
    );
    for (j, (k, p)) in cols.iter().enumerate() {
        let x = label_w + j as u32 * cell_w + 4;
        draw_text(&mut img, x, 2 * GLYPH + 4, k.name(), [0, 0, 0]);
        let pt = p.map_or("no prior".into(), |p| format!("prior {}m", p.sigma_m));
        draw_text(&mut img, x, 3 * GLYPH + 4, &pt, [60, 60, 60]);
    }
    for (i, n) in names.iter().enumerate() {
        let y = top + i as u32 * cell_h + 8;
        draw_text(&mut img, 4, y + GLYPH / 2, n, [0, 0, 0]);
        for (j, key) in cols.iter().enumerate() {
            let Some(row) = r
                .rows
                .iter()
                .find(|x| x.scene == *n && (x.kind, x.summary.prior) == *key)
            else {
                continue;
            };
            let s = row.summary.success_rate.clamp(0.0, 1.0);
            let col = if s >= 0.99 {
                [40, 170, 60]
            } else {
                let t = s as f32;
                [(230.0 - 120.0 * t) as u8, (60.0 + 150.0 * t) as u8, 50]
            };
            let x0 = label_w + j as u32 * cell_w;
            for yy in y - 4..y - 4 + cell_h - 4 {
                for xx in x0..x0 + cell_w - 4 {
                    img.put_pixel(xx, yy, Rgb(col));
                }
            }
            let mut text = format!("{:.1}%", 100.0 * s);
            if row.summary.false_fixes > 0 {
                text += &format!(" F{}", row.summary.false_fixes);
            }
            draw_text(&mut img, x0 + 6, y + GLYPH / 2, &text, [255, 255, 255]);
        }
    }
    draw_text(
        &mut img,
        4,
        h - GLYPH - 4,
        "green >= 99 %; F = false fixes",
        [60, 60, 60],
    );
    img
}
