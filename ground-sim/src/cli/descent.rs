//! `ground-sim descent`: a campaign of closed-loop hops (dynamics, IMU, TRN frames, nav filter,
//! guidance) over the truth terrain against a reference tile. With `--shard I/N` it flies one
//! shard and writes a shard file for `ground-sim merge`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, anyhow, bail};
use ground_sim::dem::read_geotiff;
use ground_sim::evaluation::campaign::percentile;
use ground_sim::evaluation::descent::{
    DescentConfig, DescentRecord, HazardPicture, RunResult, fly,
};
use ground_sim::evaluation::shard::{
    CampaignInputs, SHARD_FORMAT, SHARD_VERSION, Shard, ShardFile,
};
use ground_sim::flyer::frames::{Terrain, centre_extent, frame_reach_m};
use ground_sim::flyer::onboard::{
    Budget, GROUND_ATLAS_TILES, MapNav, WORKSPACE_STACK, new_workspace,
};
use ground_sim::pictures::plot::{Plot, Series, Style};
use ground_sim::reference::load;
use ground_sim::terrain::landing::{LandingZoneConfig, landing_zone};
use nav_core::atlas::{AtlasConfig, AtlasNavigator, MappedAtlas};
use nav_core::{NavConfig, Navigator, Tile};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Arguments of `ground-sim descent`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder (tile.bin).
    #[arg(long, required_unless_present = "atlas", conflicts_with = "atlas")]
    pub tile: Option<PathBuf>,
    /// Fly over a flight atlas instead of one tile (`atlas.bin` from `ground-sim atlas`): each
    /// TRN frame is located on the tile under the filter's prior, and on a neighbour when it
    /// straddles a tile edge (`nav_core::atlas`).
    #[arg(long)]
    pub atlas: Option<PathBuf>,
    /// Truth DEM (GeoTIFF); it must be large enough for the hops.
    #[arg(long)]
    pub dem: PathBuf,
    /// Campaign seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of hops.
    #[arg(long, default_value_t = 1)]
    pub runs: usize,
    /// Shortest hop, m.
    #[arg(long, default_value_t = DescentConfig::default().hop_min_m)]
    pub hop_min_m: f64,
    /// Longest hop, m (clipped to what the DEM allows).
    #[arg(long, default_value_t = DescentConfig::default().hop_max_m)]
    pub hop_max_m: f64,
    /// TRN frames per second.
    #[arg(long, default_value_t = DescentConfig::default().frame_rate_hz)]
    pub frame_rate_hz: f64,
    /// Fly without the Doppler velocimeter (TRN, IMU, altimeter, star tracker only).
    #[arg(long)]
    pub no_velocimeter: bool,
    /// Fly without the star tracker.
    #[arg(long)]
    pub no_star_tracker: bool,
    /// Fly over the coarse map alone: no fine landing zone (rocks, small craters, sub-metre
    /// roughness; `ground-sim landing-zone`) laid around each target.
    #[arg(long)]
    pub no_landing_zone: bool,
    /// Stone cover of the landing zones: the Golombek & Rapp k (fraction of the ground covered
    /// by rocks of any size).
    #[arg(long, default_value_t = ground_sim::terrain::landing::DEFAULT_ROCK_K)]
    pub rock_k: f64,
    /// Land wherever guidance points: no hazard map of the final frames, no safe-site choice.
    #[arg(long)]
    pub no_hazard_avoidance: bool,
    /// Keep the first hazard map's choice: no confirmation of the chosen site on a finer frame
    /// (for comparison; the flight design confirms).
    #[arg(long)]
    pub no_hazard_confirmation: bool,
    /// No keyframe odometry below the TRN floor (2 km): the final phase flies on the IMU and
    /// whatever other aiding is on, as before odometry existed.
    #[arg(long)]
    pub no_odometry: bool,
    /// Summary JSON (with `--shard`: the shard file).
    #[arg(long)]
    pub json: PathBuf,
    /// Also write every run's history at the frame rate to this CSV (one row per frame: time,
    /// truth and estimate in the map frame, 1σ east/north, NEES, what aided the frame, the fix and
    /// its covariance, an odometry offset), for analysis beyond the summary. One process only
    /// (not with `--shard`, whose tasks would write the same file).
    #[arg(long, conflicts_with = "shard")]
    pub histories: Option<PathBuf>,
    /// Folder for the trajectory and error pictures of the first run (default: beside the JSON;
    /// none with `--shard`: `merge` draws them).
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// The navigator budget.
    #[command(flatten)]
    pub budget: super::BudgetArgs,
    /// Which shard of the campaign to fly.
    #[command(flatten)]
    pub shard: super::ShardArgs,
}

/// What decides a descent campaign's hops besides the tile and the DEM (a shard file's spec).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DescentSpec {
    /// Hops in the whole campaign.
    pub runs: usize,
    /// Campaign seed.
    pub seed: u64,
    /// The navigator budget.
    pub budget: Budget,
    /// Scenario and vehicle settings.
    pub config: DescentConfig,
    /// The landing zones laid around each target (`None`: the coarse map alone).
    #[serde(default)]
    pub landing_zone: Option<LandingZoneConfig>,
    /// What the frames were located on: `tile`, or `atlas of N tiles`.
    #[serde(default = "default_reference")]
    pub reference: String,
}

fn default_reference() -> String {
    "tile".into()
}

/// A shard file of `descent`: the campaign spec and one record per hop.
pub type DescentShard = ShardFile<DescentSpec, DescentRecord>;

/// `kind` of `descent` shard files.
pub const KIND: &str = "descent";

/// Campaign summary (the JSON of `ground-sim descent`).
#[derive(Debug, Serialize)]
pub struct DescentSummary {
    /// Hops flown.
    pub runs: usize,
    /// Campaign seed.
    pub seed: u64,
    /// The navigator budget the frames were flown with (`flight` is what flies).
    pub budget: String,
    /// What the frames were located on: `tile`, or `atlas of N tiles`.
    pub reference: String,
    /// Over an atlas: TRN frames located on more than one tile, all runs.
    pub atlas_retries: usize,
    /// Over an atlas: changes of the tile a frame's report came from, all runs.
    pub atlas_tile_switches: usize,
    /// Median landing error, m: distance from the touchdown to the spot aimed at (the spot the
    /// last hazard map judged, chosen or kept; the target without a map), truth.
    pub landing_err_p50_m: f64,
    /// 95th percentile landing error, m.
    pub landing_err_p95_m: f64,
    /// Largest landing error, m.
    pub landing_err_max_m: f64,
    /// 95th percentile of the horizontal navigation error at touchdown, m: how far the flyer
    /// believed itself from where it was, whatever it aimed at.
    pub nav_err_at_landing_p95_m: f64,
    /// RMS horizontal navigation error over all runs and frame times, m.
    pub nav_err_rms_m: f64,
    /// Fixes accepted by the filter (all runs).
    pub fixes: usize,
    /// Fixes rejected by the filter's gate.
    pub rejected_fixes: usize,
    /// Frames without a fix.
    pub no_fixes: usize,
    /// Odometry offsets accepted by the filter (all runs).
    pub odometry_fixes: usize,
    /// Odometry offsets rejected by the filter's gate.
    pub odometry_rejected: usize,
    /// Odometry frames without a fix on their keyframe.
    pub odometry_none: usize,
    /// Keyframes captured (all runs).
    pub keyframes: usize,
    /// Mean NEES of the odometry offsets against the truth displacement under their own
    /// covariance (2 if it is right; NaN without offsets).
    pub offset_nees_mean: f64,
    /// Fraction of the offsets with their NEES in the 95 % χ²(2) band.
    pub offsets_in_band_frac: f64,
    /// Runs whose touchdown spot could be judged on the truth landing zone.
    pub touchdowns_judged: usize,
    /// Of those, the fraction that touched down on a safe spot.
    pub safe_landing_frac: f64,
    /// Mean over runs of the safe fraction of the ground within 10 m of the target (truth).
    pub target_area_safe_frac: f64,
    /// Median and 95th percentile distance from the target to the spot finally aimed at (the
    /// chosen safe site), m.
    pub site_from_target_p50_m: f64,
    /// See `site_from_target_p50_m`.
    pub site_from_target_p95_m: f64,
    /// Hazard maps made (all runs).
    pub hazard_maps: usize,
    /// Runs whose aim moved to a safe site.
    pub runs_retargeted: usize,
    /// Confirmation maps made (all runs; finer frames, window around the chosen aim).
    pub confirm_maps: usize,
    /// Runs whose confirmation moved the aim.
    pub runs_moved_by_confirmation: usize,
    /// Runs whose final aim had less than the choice's clearance
    /// ([`nav_core::hazard::HazardConfig::clearance_m`]) on the flyer's last map of it: no roomier
    /// site was in reach, so the lander's dispersion may carry it onto a hazard the map saw.
    #[serde(default)]
    pub runs_on_narrow_site: usize,
    /// Runs whose aim no hazard map judged (no map made, or no avoidance).
    #[serde(default)]
    pub runs_aim_unjudged: usize,
    /// Runs whose ground within the site choice's reach (30 m) of the target is at least half
    /// safe by the truth: the landing zones the 99 % goal speaks of.
    pub open_zone_runs: usize,
    /// Of those, the fraction that touched down safely.
    pub open_zone_safe_frac: f64,
    /// Unsafe touchdowns whose chosen spot was itself unsafe by the truth (the map's misses).
    pub unsafe_on_unsafe_site: usize,
    /// Unsafe touchdowns whose chosen spot was safe (the lander's dispersion carried it off).
    pub unsafe_on_safe_site: usize,
    /// The landing zones' settings (`null`: none).
    pub landing_zone: Option<LandingZoneConfig>,
    /// Median height above terrain of each run's last accepted fix or offset, m.
    pub last_aid_agl_p50_m: f64,
    /// Median time from each run's last accepted fix or offset to touchdown, s.
    pub unaided_p50_s: f64,
    /// Fraction of frame times with with the horizontal NEES in the 95 % χ²(2) band.
    pub nees_in_band_frac: f64,
    /// Mean horizontal NEES over all runs (2 for a consistent filter).
    pub nees_mean: f64,
    /// Fraction of the final phase's frame times (below the TRN floor) with the horizontal NEES
    /// in the 95 % band.
    pub final_nees_in_band_frac: f64,
    /// Mean hop length, m.
    pub hop_mean_m: f64,
    /// Mean flight time, s.
    pub flight_mean_s: f64,
    /// Settings.
    pub config: DescentConfig,
    /// Per-run results.
    pub per_run: Vec<RunResult>,
}

/// Run `ground-sim descent`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    if a.runs == 0 {
        bail!("--runs must be ≥ 1");
    }
    let (map_bytes, map_label) = match (&a.tile, &a.atlas) {
        (Some(dir), None) => (load(dir)?.tile_bytes, "tile".to_string()),
        (None, Some(file)) => {
            let b = std::fs::read(file).with_context(|| format!("reading {}", file.display()))?;
            let n = nav_core::atlas::Atlas::parse(&b)
                .map_err(|e| anyhow!("{}: {e}", file.display()))?
                .len();
            (b, format!("atlas of {n} tiles"))
        }
        _ => bail!("give one of --tile and --atlas"),
    };
    let dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let d = DescentConfig::default();
    let cfg = DescentConfig {
        hop_min_m: a.hop_min_m,
        hop_max_m: a.hop_max_m,
        frame_rate_hz: a.frame_rate_hz,
        velocimeter_sigma_mps: if a.no_velocimeter {
            0.0
        } else {
            d.velocimeter_sigma_mps
        },
        star_tracker_sigma_rad: if a.no_star_tracker {
            0.0
        } else {
            d.star_tracker_sigma_rad
        },
        odometry: !a.no_odometry,
        hazard_avoidance: !a.no_hazard_avoidance,
        hazard_confirm: !a.no_hazard_confirmation,
        ..d
    };
    // Release points and targets: inside the DEM, a cruise frame's reach from the edges.
    let (x0, x1, y0, y1) = centre_extent(&dem);
    let m = frame_reach_m(&cfg.sensor, cfg.cruise_agl_m * cfg.ifov_rad * 1.3);
    let (x0, x1, y0, y1) = (x0 + m, x1 - m, y0 + m, y1 - m);
    let diag = (x1 - x0).hypot(y1 - y0);
    if !(x1 > x0 && y1 > y0) || diag < cfg.hop_min_m {
        bail!(
            "the DEM is too small for {:.0} m hops with {:.0} m frames",
            cfg.hop_min_m,
            2.0 * m
        );
    }
    let hop_max = cfg.hop_max_m.min(0.9 * diag);
    let zone_cfg = (!a.no_landing_zone).then(|| LandingZoneConfig {
        rock_k: a.rock_k,
        ..LandingZoneConfig::default()
    });
    let single;
    let mapped;
    let atlas_nav = AtlasNavigator::new(AtlasConfig::default());
    let nav = if a.atlas.is_some() {
        mapped = Box::new(
            MappedAtlas::<GROUND_ATLAS_TILES>::new(&map_bytes)
                .map_err(|e| anyhow!("atlas: {e}"))?,
        );
        MapNav::Atlas(&mapped, &atlas_nav)
    } else {
        let tile = Tile::parse(&map_bytes).map_err(|e| anyhow!("{e}"))?;
        single = Navigator::new(tile, NavConfig::default());
        MapNav::Tile(&single)
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .stack_size(WORKSPACE_STACK)
        .build()?;
    let shard = a.shard.shard.unwrap_or(Shard::WHOLE);
    let runs = shard.trials(a.runs);
    let pb = super::progress(runs.len() as u64, "descent");
    let done = AtomicUsize::new(0);
    let results: Vec<anyhow::Result<DescentRecord>> = pool.install(|| {
        runs.par_iter()
            .map_init(
                || new_workspace(a.budget.budget),
                |ws, &i| {
                    // Seeded by (campaign seed, run index) alone: a hop flies the same in any
                    // shard.
                    let mut rng = rand_pcg::Pcg64::seed_from_u64(
                        a.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ (i as u64 + 1),
                    );
                    // Draw a release point and a target at a hop length in range, both inside.
                    let mut pick = None;
                    for _ in 0..1000 {
                        let r = [
                            x0 + (x1 - x0) * rng.random::<f64>(),
                            y0 + (y1 - y0) * rng.random::<f64>(),
                        ];
                        let d = cfg.hop_min_m
                            + (hop_max - cfg.hop_min_m).max(0.0) * rng.random::<f64>();
                        let b = std::f64::consts::TAU * rng.random::<f64>();
                        let t = [r[0] + d * b.cos(), r[1] + d * b.sin()];
                        if (x0..=x1).contains(&t[0]) && (y0..=y1).contains(&t[1]) {
                            pick = Some((r, t));
                            break;
                        }
                    }
                    let (r, t) = pick.ok_or_else(|| anyhow!("run {i}: no hop fits the DEM"))?;
                    let fly_seed = rng.random::<u64>();
                    let zone = match &zone_cfg {
                        Some(z) => Some(
                            landing_zone(&dem, t, z, rng.random::<u64>())
                                .with_context(|| format!("run {i}: landing zone"))?,
                        ),
                        None => None,
                    };
                    let terrain = Terrain {
                        map: &dem,
                        zone: zone.as_ref(),
                    };
                    let out = fly(i, &terrain, &nav, ws, &cfg, r, t, fly_seed);
                    pb.set_position(done.fetch_add(1, Ordering::Relaxed) as u64 + 1);
                    // Run 0 is the pictured one: keep its history (all with --histories).
                    out.map(|r| DescentRecord::new(r, i == 0 || a.histories.is_some()))
                },
            )
            .collect()
    });
    pb.finish_and_clear();
    let records: Vec<DescentRecord> = results.into_iter().collect::<anyhow::Result<_>>()?;
    let spec = DescentSpec {
        runs: a.runs,
        seed: a.seed,
        budget: a.budget.budget,
        config: cfg,
        landing_zone: zone_cfg,
        reference: map_label,
    };
    if let Some(path) = &a.histories {
        write_histories(path, &records)?;
    }
    if a.shard.shard.is_none() {
        let dir = a
            .png
            .clone()
            .unwrap_or_else(|| a.json.parent().map(|p| p.to_path_buf()).unwrap_or_default());
        return report(&spec, records, &a.json, &dir);
    }
    let file = DescentShard {
        format: SHARD_FORMAT.into(),
        version: SHARD_VERSION,
        kind: KIND.into(),
        shard,
        trials: a.runs,
        seed: a.seed,
        budget: a.budget.budget.label(),
        inputs: CampaignInputs::new(&map_bytes, &a.dem)?,
        spec,
        trial_indices: runs,
        records,
    };
    file.write(&a.json)?;
    println!(
        "shard        {shard} of the campaign: {} of {} hops (seed {})\nshard file   {}",
        file.records.len(),
        a.runs,
        a.seed,
        a.json.display()
    );
    Ok(())
}

/// One CSV row per recorded frame of every run that kept its history (positions in the map's
/// east/north/up frame, metres; the fix state's codes are
/// [`ground_sim::evaluation::descent::Sample::fix_state`]'s).
fn write_histories(path: &Path, records: &[DescentRecord]) -> anyhow::Result<()> {
    use std::io::Write;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(
        w,
        "run,t_s,truth_e_m,truth_n_m,truth_u_m,est_e_m,est_n_m,est_u_m,sigma_e_m,sigma_n_m,nees,fix_state,fix_e_m,fix_n_m,fix_cov_ee_m2,fix_cov_en_m2,fix_cov_nn_m2,offset_e_m,offset_n_m"
    )?;
    for r in records {
        for s in r.history.iter().flatten() {
            // An absent value is an empty field.
            let opt = |v: Option<f64>| v.map_or(String::new(), |x| x.to_string());
            let (fix, off, cov) = (s.fix_m, s.offset_m, s.fix_cov_m2);
            let [fe, fn_] = [0, 1].map(|k| opt(fix.map(|f| f[k])));
            let [oe, on] = [0, 1].map(|k| opt(off.map(|o| o[k])));
            let [cee, cen, cnn] = [(0, 0), (0, 1), (1, 1)].map(|(a, b)| opt(cov.map(|c| c[a][b])));
            writeln!(
                w,
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                r.result.run,
                s.t_s,
                s.truth_m[0],
                s.truth_m[1],
                s.truth_m[2],
                s.est_m[0],
                s.est_m[1],
                s.est_m[2],
                s.sigma_m[0],
                s.sigma_m[1],
                s.nees,
                s.fix_state,
                fe,
                fn_,
                cee,
                cen,
                cnn,
                oe,
                on
            )?;
        }
    }
    w.flush()
        .with_context(|| format!("writing {}", path.display()))?;
    println!("histories    {}", path.display());
    Ok(())
}

/// Summarise a whole campaign's records (run order), print it, write its JSON and the pictures
/// of run 0 into `png_dir`: what `descent` writes unsharded and `merge` writes from the shards.
pub fn report(
    spec: &DescentSpec,
    records: Vec<DescentRecord>,
    json: &Path,
    png_dir: &Path,
) -> anyhow::Result<()> {
    if records.is_empty() {
        bail!("a descent campaign needs at least one run");
    }
    // Sums per run, then over runs in run order: a shard keeps only each run's totals.
    let samples: usize = records.iter().map(|r| r.totals.samples).sum();
    let sq: f64 = records.iter().map(|r| r.totals.sq_err_m2).sum();
    let in_band: usize = records.iter().map(|r| r.totals.nees_in_band).sum();
    let nees_sum: f64 = records.iter().map(|r| r.totals.nees_finite_sum).sum();
    let mut pictured = None;
    let mut per_run = Vec::with_capacity(records.len());
    for r in records {
        if let Some(h) = r.history {
            let mut shown = r.result.clone();
            shown.history = h;
            shown.hazard_pictures = r.hazard_pictures;
            pictured.get_or_insert(shown);
        }
        per_run.push(r.result);
    }
    let mut land: Vec<f64> = per_run.iter().map(|r| r.landing_err_m).collect();
    let site_pct = |p: f64| {
        percentile(
            &mut per_run
                .iter()
                .map(|r| r.site_from_target_m)
                .collect::<Vec<_>>(),
            p,
        )
    };
    // The runs the 99 % goal speaks of: at least half the ground within reach is safe.
    let open: Vec<&RunResult> = per_run
        .iter()
        .filter(|r| r.reach_safe_frac >= 0.5 && r.touchdown_safe.is_some())
        .collect();
    let summary = DescentSummary {
        runs: per_run.len(),
        seed: spec.seed,
        budget: spec.budget.label(),
        reference: spec.reference.clone(),
        atlas_retries: per_run.iter().map(|r| r.atlas_retries).sum(),
        atlas_tile_switches: per_run.iter().map(|r| r.atlas_tile_switches).sum(),
        landing_err_p50_m: percentile(&mut land.clone(), 0.5),
        landing_err_p95_m: percentile(&mut land.clone(), 0.95),
        landing_err_max_m: land.iter().copied().fold(0.0, f64::max),
        nav_err_at_landing_p95_m: percentile(
            &mut per_run
                .iter()
                .map(|r| r.nav_err_at_landing_m)
                .collect::<Vec<_>>(),
            0.95,
        ),
        nav_err_rms_m: (sq / samples.max(1) as f64).sqrt(),
        fixes: per_run.iter().map(|r| r.fixes).sum(),
        rejected_fixes: per_run.iter().map(|r| r.rejected_fixes).sum(),
        no_fixes: per_run.iter().map(|r| r.no_fixes).sum(),
        odometry_fixes: per_run.iter().map(|r| r.odometry_fixes).sum(),
        odometry_rejected: per_run.iter().map(|r| r.odometry_rejected).sum(),
        odometry_none: per_run.iter().map(|r| r.odometry_none).sum(),
        keyframes: per_run.iter().map(|r| r.keyframes).sum(),
        offset_nees_mean: {
            let n: usize = per_run
                .iter()
                .map(|r| r.odometry_fixes + r.odometry_rejected)
                .sum();
            per_run.iter().map(|r| r.offset_nees_sum).sum::<f64>() / n as f64
        },
        offsets_in_band_frac: {
            let n: usize = per_run
                .iter()
                .map(|r| r.odometry_fixes + r.odometry_rejected)
                .sum();
            per_run.iter().map(|r| r.offsets_in_band).sum::<usize>() as f64 / n as f64
        },
        touchdowns_judged: per_run
            .iter()
            .filter(|r| r.touchdown_safe.is_some())
            .count(),
        safe_landing_frac: per_run
            .iter()
            .filter(|r| r.touchdown_safe == Some(true))
            .count() as f64
            / per_run
                .iter()
                .filter(|r| r.touchdown_safe.is_some())
                .count() as f64,
        target_area_safe_frac: per_run
            .iter()
            .map(|r| r.target_area_safe_frac)
            .filter(|v| v.is_finite())
            .sum::<f64>()
            / per_run
                .iter()
                .filter(|r| r.target_area_safe_frac.is_finite())
                .count() as f64,
        landing_zone: spec.landing_zone,
        site_from_target_p50_m: site_pct(0.5),
        site_from_target_p95_m: site_pct(0.95),
        hazard_maps: per_run.iter().map(|r| r.hazard_maps).sum(),
        runs_retargeted: per_run.iter().filter(|r| r.site_changes > 0).count(),
        confirm_maps: per_run.iter().map(|r| r.confirm_maps).sum(),
        runs_moved_by_confirmation: per_run.iter().filter(|r| r.confirm_moves > 0).count(),
        runs_on_narrow_site: per_run
            .iter()
            .filter(|r| r.site_clearance_m < f64::from(spec.config.hazard.clearance_m))
            .count(),
        runs_aim_unjudged: per_run
            .iter()
            .filter(|r| !r.site_clearance_m.is_finite())
            .count(),
        open_zone_runs: open.len(),
        open_zone_safe_frac: open
            .iter()
            .filter(|r| r.touchdown_safe == Some(true))
            .count() as f64
            / open.len() as f64,
        unsafe_on_unsafe_site: per_run
            .iter()
            .filter(|r| r.touchdown_safe == Some(false) && r.site_safe == Some(false))
            .count(),
        unsafe_on_safe_site: per_run
            .iter()
            .filter(|r| r.touchdown_safe == Some(false) && r.site_safe == Some(true))
            .count(),
        last_aid_agl_p50_m: percentile(
            &mut per_run.iter().map(|r| r.last_aid_agl_m).collect::<Vec<_>>(),
            0.5,
        ),
        unaided_p50_s: percentile(
            &mut per_run.iter().map(|r| r.unaided_s).collect::<Vec<_>>(),
            0.5,
        ),
        nees_in_band_frac: in_band as f64 / samples.max(1) as f64,
        nees_mean: nees_sum / samples.max(1) as f64,
        final_nees_in_band_frac: per_run.iter().map(|r| r.final_nees_in_band).sum::<usize>() as f64
            / per_run
                .iter()
                .map(|r| r.final_samples)
                .sum::<usize>()
                .max(1) as f64,
        hop_mean_m: per_run.iter().map(|r| r.hop_m).sum::<f64>() / per_run.len() as f64,
        flight_mean_s: per_run.iter().map(|r| r.flight_s).sum::<f64>() / per_run.len() as f64,
        config: spec.config,
        per_run,
    };
    land.clear();
    println!(
        "runs         {} (seed {}), mean hop {:.0} m, mean flight {:.0} s",
        summary.runs, summary.seed, summary.hop_mean_m, summary.flight_mean_s
    );
    println!(
        "landing      p50 {:.2} m  p95 {:.2} m  max {:.2} m (to the spot aimed at); navigation error at touchdown p95 {:.2} m",
        summary.landing_err_p50_m,
        summary.landing_err_p95_m,
        summary.landing_err_max_m,
        summary.nav_err_at_landing_p95_m
    );
    println!(
        "navigation   RMS {:.2} m; fixes {} accepted, {} rejected by the gate, {} frames without a fix",
        summary.nav_err_rms_m, summary.fixes, summary.rejected_fixes, summary.no_fixes
    );
    if summary.reference != "tile" {
        println!(
            "reference    {}: {} tile changes, {} frames tried on a second tile",
            summary.reference, summary.atlas_tile_switches, summary.atlas_retries
        );
    }
    if summary.config.odometry {
        println!(
            "odometry     {} offsets accepted, {} rejected by the gate, {} frames without one; {} keyframes\n             offsets vs truth: mean NEES {:.2} (2 if their σ is right), {:.1} % in the 95 % band",
            summary.odometry_fixes,
            summary.odometry_rejected,
            summary.odometry_none,
            summary.keyframes,
            summary.offset_nees_mean,
            100.0 * summary.offsets_in_band_frac
        );
    }
    if summary.config.hazard_avoidance {
        println!(
            "hazards      {} maps; {} of {} runs moved their aim, by p50 {:.1} m, p95 {:.1} m",
            summary.hazard_maps,
            summary.runs_retargeted,
            summary.runs,
            summary.site_from_target_p50_m,
            summary.site_from_target_p95_m
        );
        if summary.config.hazard_confirm {
            println!(
                "confirmation {} maps around the chosen aim on finer frames; {} runs moved by them",
                summary.confirm_maps, summary.runs_moved_by_confirmation
            );
        }
        if summary.runs_on_narrow_site + summary.runs_aim_unjudged > 0 {
            println!(
                "             {} runs aimed at a site with less than {:.0} m clearance on their own map (none roomier in reach); {} aims no map judged",
                summary.runs_on_narrow_site,
                summary.config.hazard.clearance_m,
                summary.runs_aim_unjudged
            );
        }
    }
    if summary.touchdowns_judged > 0 {
        println!(
            "touchdown    {:.1} % of {} runs on safe ground (the ground within 10 m of the targets is {:.1} % safe)",
            100.0 * summary.safe_landing_frac,
            summary.touchdowns_judged,
            100.0 * summary.target_area_safe_frac
        );
        println!(
            "             {:.1} % of the {} runs whose ground within reach of the target is at least half safe",
            100.0 * summary.open_zone_safe_frac,
            summary.open_zone_runs
        );
        if summary.unsafe_on_unsafe_site + summary.unsafe_on_safe_site > 0 {
            println!(
                "             unsafe: {} on a spot the truth calls unsafe (a map's miss, or nothing safe in reach), {} carried off a safe spot",
                summary.unsafe_on_unsafe_site, summary.unsafe_on_safe_site
            );
        }
    }
    println!(
        "last aid     median {:.0} m above the terrain, {:.0} s before touchdown",
        summary.last_aid_agl_p50_m, summary.unaided_p50_s
    );
    println!(
        "consistency  {:.1} % of horizontal NEES values in the 95 % band ({:.1} % in the final phase)",
        summary.nees_in_band_frac * 100.0,
        summary.final_nees_in_band_frac * 100.0
    );
    super::write_json(json, &summary)?;
    println!("json         {}", json.display());
    if let Some(r) = &pictured {
        write_pictures(r, png_dir)?;
    }
    Ok(())
}

fn write_pictures(r: &RunResult, dir: &std::path::Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let h = &r.history;
    let km = |v: f64| v / 1000.0;
    let traj = Plot {
        width: 900,
        height: 800,
        title: format!(
            "hop {} : {:.1} km, landing error {:.1} m",
            r.run,
            r.hop_m / 1000.0,
            r.landing_err_m
        ),
        x_label: "east (km)".into(),
        y_label: "north".into(),
        equal_axes: true,
        series: vec![
            Series {
                label: "truth".into(),
                colour: [30, 30, 30],
                points: h
                    .iter()
                    .map(|s| (km(s.truth_m[0]), km(s.truth_m[1])))
                    .collect(),
                style: Style::Line,
            },
            Series {
                label: "estimate".into(),
                colour: [30, 90, 220],
                points: h.iter().map(|s| (km(s.est_m[0]), km(s.est_m[1]))).collect(),
                style: Style::Line,
            },
            Series {
                label: "TRN fixes".into(),
                colour: [30, 170, 60],
                points: h
                    .iter()
                    .filter_map(|s| s.fix_m.map(|f| (km(f[0]), km(f[1]))))
                    .collect(),
                style: Style::Dots(3),
            },
            Series {
                label: "target".into(),
                colour: [220, 40, 40],
                points: vec![(km(r.target_m[0]), km(r.target_m[1]))],
                style: Style::Dots(6),
            },
        ],
    };
    let p1 = dir.join("descent-trajectory.png");
    traj.render()
        .save(&p1)
        .with_context(|| format!("writing {}", p1.display()))?;
    let err = Plot {
        width: 1000,
        height: 600,
        title: format!("hop {}: east error with its 3-sigma envelope", r.run),
        x_label: "time (s)".into(),
        y_label: "m".into(),
        equal_axes: false,
        series: vec![
            Series {
                label: "+3 sigma".into(),
                colour: [150, 150, 150],
                points: h.iter().map(|s| (s.t_s, 3.0 * s.sigma_m[0])).collect(),
                style: Style::Line,
            },
            Series {
                label: "-3 sigma".into(),
                colour: [150, 150, 150],
                points: h.iter().map(|s| (s.t_s, -3.0 * s.sigma_m[0])).collect(),
                style: Style::Line,
            },
            Series {
                label: "east error".into(),
                colour: [30, 90, 220],
                points: h
                    .iter()
                    .map(|s| (s.t_s, s.truth_m[0] - s.est_m[0]))
                    .collect(),
                style: Style::Line,
            },
            Series {
                label: "north error".into(),
                colour: [220, 120, 30],
                points: h
                    .iter()
                    .map(|s| (s.t_s, s.truth_m[1] - s.est_m[1]))
                    .collect(),
                style: Style::Line,
            },
        ],
    };
    let p2 = dir.join("descent-error.png");
    err.render()
        .save(&p2)
        .with_context(|| format!("writing {}", p2.display()))?;
    println!("pictures     {} {}", p1.display(), p2.display());
    for hz in &r.hazard_pictures {
        let p3 = dir.join(if hz.confirmation {
            "descent-confirm.png"
        } else {
            "descent-hazard.png"
        });
        hazard_picture(hz, &p3)?;
        println!("             {}", p3.display());
    }
    Ok(())
}

/// The pictured run's hazard map: the frame's hillshade, unsafe sites tinted red, the original
/// target (blue cross; a confirmation: the aim before it) and the chosen site (green ring),
/// frame axes, 3 screen pixels per frame pixel.
fn hazard_picture(hz: &HazardPicture, path: &Path) -> anyhow::Result<()> {
    use ground_sim::dem::{Dem, GeoRef};
    use ground_sim::pictures::render::{Sun, draw_text, hillshade};
    const Z: u32 = 3;
    let dem = Dem::new(
        hz.width,
        hz.height,
        hz.heights_m.clone(),
        GeoRef::local(0.0, 0.0, hz.pixel_m, "hazard frame"),
    )?;
    let shade = hillshade(&dem, Sun::default())?;
    let (w, h) = (hz.width as u32 * Z, hz.height as u32 * Z + 20);
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let (cols, _) = hz.lattice;
    let half = hz.step_px / 2.0;
    for y in 0..hz.height {
        for x in 0..hz.width {
            let g = shade[y * hz.width + x];
            let g = if g.is_finite() { (g * 255.0) as u8 } else { 0 };
            // The lattice site whose cell holds this pixel.
            let i = ((x as f32 - hz.site_px[0] + half) / hz.step_px).floor();
            let j = ((y as f32 - hz.site_px[1] + half) / hz.step_px).floor();
            let unsafe_site = i >= 0.0
                && j >= 0.0
                && hz
                    .safe
                    .get(j as usize * cols + i as usize)
                    .is_some_and(|s| !*s)
                && (i as usize) < cols;
            let rgb = if unsafe_site {
                [g.saturating_add(90), g / 2, g / 2]
            } else {
                [g, g, g]
            };
            for dy in 0..Z {
                for dx in 0..Z {
                    img.put_pixel(x as u32 * Z + dx, y as u32 * Z + dy + 20, image::Rgb(rgb));
                }
            }
        }
    }
    let mut mark = |c: [f32; 2], rgb: [u8; 3], ring: bool| {
        let (cx, cy) = (c[0] * Z as f32, c[1] * Z as f32 + 20.0);
        for t in 0..360 {
            let a = (t as f32).to_radians();
            for r in if ring { 9..12 } else { 0..10 } {
                // A ring, or a cross of the two diagonals.
                if !ring && t % 90 != 45 {
                    continue;
                }
                let (x, y) = (cx + r as f32 * a.cos(), cy + r as f32 * a.sin());
                if x >= 0.0 && y >= 20.0 && (x as u32) < w && (y as u32) < h {
                    img.put_pixel(x as u32, y as u32, image::Rgb(rgb));
                }
            }
        }
    };
    mark(hz.target_px, [40, 90, 230], false);
    mark(hz.aim_px, [30, 190, 60], true);
    draw_text(
        &mut img,
        4,
        4,
        &if hz.confirmation {
            format!("confirm {:.2} m px: x before, o after", hz.pixel_m)
        } else {
            format!("hazards, {:.2} m px: x target, o site", hz.pixel_m)
        },
        [0, 0, 0],
    );
    img.save(path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
