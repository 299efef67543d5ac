//! `ground-sim hazard-calibrate`: how often the onboard hazard map calls a site safe that the
//! truth DEM calls unsafe, for a range of the map's relief thresholds.
//!
//! For each preset and seed: a coarse scene (2 km at 10 m; or a real DEM with `--dem`), a
//! landing zone on it (rocks, small craters, sub-metre roughness: [`landing_zone`]), frames of the descent's sensor at the
//! hazard map's pixel ([`SensorModel::default`], noise and dropouts included) at random places
//! and headings in the zone, the flight hazard map ([`HazardMap::build`]) with each relief
//! threshold, and every site it judges scored with the truth ([`site_safety`], the lander's
//! 10° and 0.3 m). Sites with room around them (the clearance guidance asks for) are counted
//! apart: they are the ones a lander is sent to.
//!
//! Writes a table to stdout, the figures as JSON and the trade-off as a PNG.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use ground_sim::dem::Dem;
use ground_sim::flyer::frames::{FramePose, SensorModel, Terrain, synth_frame_on};
use ground_sim::pictures::plot::{PALETTE, Plot, Series, Style};
use ground_sim::terrain::landing::{
    LandingZoneConfig, SafetyThresholds, landing_zone, site_safety,
};
use ground_sim::terrain::{Preset, TerrainParams, Window, generate};
use nav_core::hazard::HazardConfig;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

/// Arguments of `ground-sim hazard-calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Presets of the coarse scenes.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Preset::Lola, Preset::Shoemaker, Preset::Plains])]
    pub presets: Vec<Preset>,
    /// First seed (scene, zone and frames); seeds `seed .. seed + zones` are used.
    #[arg(long, default_value_t = 101)]
    pub seed: u64,
    /// Landing zones per scene.
    #[arg(long, default_value_t = 6)]
    pub zones: u64,
    /// Frames per zone.
    #[arg(long, default_value_t = 4)]
    pub frames: usize,
    /// Frame pixel, metres (the descent maps at 0.4 m).
    #[arg(long, default_value_t = 0.4)]
    pub pixel_m: f64,
    /// Relief thresholds of the map to try, metres.
    #[arg(long, value_delimiter = ',', default_values_t = [0.30, 0.25, 0.20, 0.17, 0.15])]
    pub relief_m: Vec<f32>,
    /// Also calibrate over this north-up GeoTIFF DEM (e.g. the real LOLA tile in
    /// `../shared/data`): `--zones` landing zones at seed-drawn places on it, labelled with the
    /// file's name.
    #[arg(long)]
    pub dem: Option<PathBuf>,
    /// Figures as JSON.
    #[arg(long)]
    pub json: PathBuf,
    /// Trade-off picture (misses against safe ground refused, one curve per scene); default:
    /// the JSON's path with `.png`.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Counts for one relief threshold.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Counts {
    /// Sites judged by the map and by the truth.
    pub sites: usize,
    /// Sites the truth calls safe.
    pub truth_safe: usize,
    /// Sites the map calls safe.
    pub judged_safe: usize,
    /// Of those, unsafe by the truth (misses).
    pub missed: usize,
    /// Sites the map calls safe with at least the guidance's 2 m of clearance.
    pub judged_safe_2m: usize,
    /// Of those, unsafe by the truth.
    pub missed_2m: usize,
    /// Sites with the preferred 4 m of clearance.
    pub judged_safe_4m: usize,
    /// Of those, unsafe by the truth.
    pub missed_4m: usize,
}

impl Counts {
    fn add(&mut self, o: &Counts) {
        self.sites += o.sites;
        self.truth_safe += o.truth_safe;
        self.judged_safe += o.judged_safe;
        self.missed += o.missed;
        self.judged_safe_2m += o.judged_safe_2m;
        self.missed_2m += o.missed_2m;
        self.judged_safe_4m += o.judged_safe_4m;
        self.missed_4m += o.missed_4m;
    }
}

/// One row of the result: a scene (preset or DEM; or all) and a threshold.
#[derive(Debug, Serialize)]
struct Row {
    scene: String,
    relief_m: f32,
    counts: Counts,
    /// `missed / judged_safe`.
    miss_rate: f64,
    /// `missed_2m / judged_safe_2m`.
    miss_rate_2m: f64,
    /// `missed_4m / judged_safe_4m`.
    miss_rate_4m: f64,
    /// `(judged_safe − missed) / truth_safe`: how much of the truly safe ground the map still
    /// offers.
    offered: f64,
    /// The same for the sites with 2 m of clearance (where guidance sends a lander).
    offered_2m: f64,
    /// Zones (scene × seed) with at least one miss among the 2 m-clearance sites, of all zones:
    /// sites 1.2 m apart share most of their footprint, so misses come in clusters and the
    /// zone count is the sturdier figure.
    zones_missed_2m: (usize, usize),
}

#[derive(Debug, Serialize)]
struct Report {
    presets: Vec<String>,
    seeds: (u64, u64),
    frames_per_zone: usize,
    pixel_m: f64,
    sensor: SensorModel,
    landing_zone: LandingZoneConfig,
    truth_thresholds: SafetyThresholds,
    map_slope_deg: f32,
    rows: Vec<Row>,
    seconds: f64,
}

/// Score every site of the maps of one zone, for every threshold.
/// The coarse scene of zone `seed`: a preset generated at 2 km × 10 m (zone at its centre), or
/// the given DEM (zone at a seed-drawn place at least 300 m inside its edges).
fn scene(source: &Source, seed: u64) -> anyhow::Result<(std::sync::Arc<Dem>, [f64; 2])> {
    match source {
        Source::Preset(preset) => {
            let params = TerrainParams {
                preset: *preset,
                window: Window::Floor,
                seed,
                size_m: 2000.0,
                pixel_m: 10.0,
            };
            let (map, _) = generate(&params, &indicatif::ProgressBar::hidden())
                .map_err(|e| anyhow::anyhow!("scene: {e}"))?;
            let (x0, y0, x1, y1) = map.extent_m();
            Ok((map.into(), [(x0 + x1) / 2.0, (y0 + y1) / 2.0]))
        }
        Source::Dem(_, map) => {
            let (x0, y0, x1, y1) = map.extent_m();
            let m = 300.0;
            anyhow::ensure!(
                x1 - x0 > 2.0 * m && y1 - y0 > 2.0 * m,
                "the DEM is smaller than a landing zone and its frames ({} m)",
                2.0 * m
            );
            let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
            let u: f64 = rng.random();
            let v: f64 = rng.random();
            Ok((
                map.clone(),
                [
                    x0 + m + u * (x1 - x0 - 2.0 * m),
                    y0 + m + v * (y1 - y0 - 2.0 * m),
                ],
            ))
        }
    }
}

/// Where the coarse scenes come from.
enum Source {
    /// A synthetic preset.
    Preset(Preset),
    /// A DEM read from a file: its label and heights.
    Dem(String, std::sync::Arc<Dem>),
}

impl Source {
    fn name(&self) -> String {
        match self {
            Self::Preset(p) => format!("{p:?}").to_lowercase(),
            Self::Dem(n, _) => n.clone(),
        }
    }
}

/// Score every site of the maps of one zone, for every threshold.
fn zone_counts(source: &Source, seed: u64, a: &Args) -> anyhow::Result<Vec<Counts>> {
    let (map, centre) = scene(source, seed)?;
    let zone: Dem = landing_zone(&map, centre, &LandingZoneConfig::default(), seed)
        .map_err(|e| anyhow::anyhow!("landing zone: {e}"))?;
    let terrain = Terrain {
        map: &map,
        zone: Some(&zone),
    };
    let sensor = SensorModel::default();
    let truth = SafetyThresholds::default();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x4A2A_D0C5);
    let mut out = vec![Counts::default(); a.relief_m.len()];
    let mut hazards = Box::new(nav_core::flight::HazardMap::new());
    for _ in 0..a.frames {
        // Anywhere the frame stays inside the zone's untapered part.
        let pose = FramePose {
            x_m: centre[0] + (rng.random::<f64>() - 0.5) * 300.0,
            y_m: centre[1] + (rng.random::<f64>() - 0.5) * 300.0,
            heading_rad: rng.random::<f64>() * std::f64::consts::TAU,
            pixel_m: a.pixel_m,
        };
        let frame = synth_frame_on(&terrain, &pose, &sensor, rng.random::<u64>())
            .map_err(|e| anyhow::anyhow!("frame: {e}"))?;
        let dem = nav_core::DemPatch::new_checked(
            &frame.heights_m,
            frame.width,
            frame.height,
            a.pixel_m as f32,
        )?;
        // The truth of every lattice site (the lattice is the same for every threshold).
        let mut verdicts = Vec::new();
        for (k, &relief) in a.relief_m.iter().enumerate() {
            let cfg = HazardConfig {
                max_relief_m: relief,
                ..HazardConfig::default()
            };
            hazards
                .build(&dem, &cfg)
                .map_err(|e| anyhow::anyhow!("hazard map: {e}"))?;
            let (cols, rows) = hazards.size();
            if verdicts.is_empty() {
                for j in 0..rows {
                    for i in 0..cols {
                        let p = hazards.site_px(i, j);
                        let (x, y) =
                            pose.frame_to_geo(p[0] as f64, p[1] as f64, frame.width, frame.height);
                        verdicts.push(site_safety(&zone, x, y, &truth).map(|s| s.safe));
                    }
                }
            }
            let c = &mut out[k];
            for j in 0..rows {
                for i in 0..cols {
                    let Some(Some(safe)) = verdicts.get(j * cols + i).copied() else {
                        continue;
                    };
                    let clear = hazards.clearance_m(i, j);
                    c.sites += 1;
                    c.truth_safe += usize::from(safe);
                    if clear > 0.0 {
                        c.judged_safe += 1;
                        c.missed += usize::from(!safe);
                    }
                    if clear >= cfg.clearance_m {
                        c.judged_safe_2m += 1;
                        c.missed_2m += usize::from(!safe);
                    }
                    if clear >= cfg.preferred_clearance_m {
                        c.judged_safe_4m += 1;
                        c.missed_4m += usize::from(!safe);
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Misses among the 2 m-clearance sites against the truly safe ground refused, one curve per
/// scene (and all), each point one threshold (stricter to the right).
fn picture(rows: &[Row]) -> Plot {
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        if !names.contains(&r.scene.as_str()) {
            names.push(&r.scene);
        }
    }
    let mut series = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let mut pts: Vec<(f64, f64, f32)> = rows
            .iter()
            .filter(|r| r.scene == *name)
            .map(|r| {
                (
                    100.0 * (1.0 - r.offered),
                    100.0 * r.miss_rate_2m,
                    r.relief_m,
                )
            })
            .collect();
        pts.sort_by(|a, b| b.2.total_cmp(&a.2));
        let colour = if *name == "all" {
            [0, 0, 0]
        } else {
            PALETTE[k % PALETTE.len()]
        };
        let points: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, p.1)).collect();
        series.push(Series {
            label: (*name).to_string(),
            colour,
            points: points.clone(),
            style: Style::Line,
        });
        series.push(Series {
            label: String::new(),
            colour,
            points,
            style: Style::Dots(3),
        });
    }
    let all: Vec<String> = rows
        .iter()
        .filter(|r| r.scene == "all")
        .map(|r| format!("{:.2}", r.relief_m))
        .collect();
    Plot {
        width: 1000,
        height: 560,
        title: format!(
            "map relief {} .. {} m, left to right",
            all.first().map_or("?", |v| v.as_str()),
            all.last().map_or("?", |v| v.as_str())
        ),
        x_label: "truly safe ground the map refuses, %".into(),
        y_label: "sites with 2 m clearance truly unsafe, %".into(),
        series,
        equal_axes: false,
    }
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        f64::NAN
    } else {
        a as f64 / b as f64
    }
}

/// Run `ground-sim hazard-calibrate`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        !a.presets.is_empty() || a.dem.is_some(),
        "--presets: give at least one preset (or a --dem)"
    );
    anyhow::ensure!(
        a.zones > 0 && a.frames > 0,
        "--zones and --frames must be positive"
    );
    anyhow::ensure!(
        a.relief_m.iter().all(|r| r.is_finite() && *r > 0.0),
        "--relief-m: thresholds must be finite and positive"
    );
    anyhow::ensure!(
        a.pixel_m.is_finite() && a.pixel_m > 0.0,
        "--pixel-m must be finite and positive"
    );
    let t0 = Instant::now();
    let mut sources: Vec<Source> = a.presets.iter().map(|&p| Source::Preset(p)).collect();
    if let Some(path) = &a.dem {
        let dem = ground_sim::dem::read_geotiff(path)
            .with_context(|| format!("reading {}", path.display()))?;
        let label = path
            .file_stem()
            .map_or("dem".into(), |s| s.to_string_lossy().into_owned());
        sources.push(Source::Dem(label, dem.into()));
    }
    let jobs: Vec<(usize, u64)> = (0..sources.len())
        .flat_map(|k| (a.seed..a.seed + a.zones).map(move |s| (k, s)))
        .collect();
    let bar = indicatif::ProgressBar::new(jobs.len() as u64).with_message("landing zones");
    let per_zone: Vec<(usize, Vec<Counts>)> = jobs
        .par_iter()
        .map(|&(k, s)| {
            let r = zone_counts(&sources[k], s, a)
                .with_context(|| format!("{} seed {s}", sources[k].name()));
            bar.inc(1);
            r.map(|c| (k, c))
        })
        .collect::<anyhow::Result<_>>()?;
    bar.finish_and_clear();
    let mut rows = Vec::new();
    let groups: Vec<Option<usize>> = (0..sources.len())
        .map(Some)
        .chain(std::iter::once(None))
        .collect();
    for g in groups {
        for (k, &relief) in a.relief_m.iter().enumerate() {
            let mut c = Counts::default();
            let mut zones = (0, 0);
            for (src, counts) in &per_zone {
                if g.is_none_or(|g| g == *src) {
                    c.add(&counts[k]);
                    zones.0 += usize::from(counts[k].missed_2m > 0);
                    zones.1 += 1;
                }
            }
            rows.push(Row {
                scene: g.map_or("all".into(), |g| sources[g].name()),
                relief_m: relief,
                counts: c,
                miss_rate: ratio(c.missed, c.judged_safe),
                miss_rate_2m: ratio(c.missed_2m, c.judged_safe_2m),
                miss_rate_4m: ratio(c.missed_4m, c.judged_safe_4m),
                offered: ratio(c.judged_safe - c.missed, c.truth_safe),
                offered_2m: ratio(c.judged_safe_2m - c.missed_2m, c.truth_safe),
                zones_missed_2m: zones,
            });
        }
    }
    let nw = rows.iter().map(|r| r.scene.len()).max().unwrap_or(5).max(5);
    println!(
        "map relief threshold vs truth (lander 10°, 0.3 m), {} zones × {} frames at {} m per scene, seeds {}..{}",
        a.zones,
        a.frames,
        a.pixel_m,
        a.seed,
        a.seed + a.zones - 1
    );
    println!(
        "{:<nw$} {:>7} {:>7} {:>8} {:>16} {:>8} {:>9} {:>11} {:>11}",
        "scene",
        "relief",
        "sites",
        "miss",
        "miss ≥2 m",
        "zones",
        "miss ≥4 m",
        "offered",
        "offered ≥2m"
    );
    for r in &rows {
        println!(
            "{:<nw$} {:>5.2} m {:>7} {:>7.2}% {:>6.2}% ({:>5}) {:>4}/{:<3} {:>8.2}% {:>10.1}% {:>10.1}%",
            r.scene,
            r.relief_m,
            r.counts.sites,
            100.0 * r.miss_rate,
            100.0 * r.miss_rate_2m,
            r.counts.missed_2m,
            r.zones_missed_2m.0,
            r.zones_missed_2m.1,
            100.0 * r.miss_rate_4m,
            100.0 * r.offered,
            100.0 * r.offered_2m
        );
    }
    let report = Report {
        presets: sources.iter().map(Source::name).collect(),
        seeds: (a.seed, a.seed + a.zones - 1),
        frames_per_zone: a.frames,
        pixel_m: a.pixel_m,
        sensor: SensorModel::default(),
        landing_zone: LandingZoneConfig::default(),
        truth_thresholds: SafetyThresholds::default(),
        map_slope_deg: HazardConfig::default().max_slope_deg,
        rows,
        seconds: t0.elapsed().as_secs_f64(),
    };
    if let Some(dir) = a.json.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let png = a
        .png
        .clone()
        .unwrap_or_else(|| a.json.with_extension("png"));
    picture(&report.rows)
        .render()
        .save(&png)
        .with_context(|| png.display().to_string())?;
    eprintln!("wrote {}", png.display());
    std::fs::write(&a.json, serde_json::to_string_pretty(&report)?)
        .with_context(|| a.json.display().to_string())?;
    eprintln!("wrote {} ({:.1} s)", a.json.display(), report.seconds);
    Ok(())
}
