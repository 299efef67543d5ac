//! `ground-sim eval`: a Monte-Carlo campaign of single frames at random positions, headings and
//! scales inside the tile, scored against the truth; parallel on all cores. With `--shard I/N`
//! it flies one shard and writes a shard file for `ground-sim merge`.

use std::path::{Path, PathBuf};

use anyhow::{Context, anyhow};
use ground_sim::dem::read_geotiff;
use ground_sim::evaluation::campaign::{
    CampaignSpec, PriorSpec, print_summary, run_trials, summarize, write_csv_trials,
};
use ground_sim::evaluation::shard::{
    CampaignInputs, SHARD_FORMAT, SHARD_VERSION, Shard, ShardFile,
};
use ground_sim::evaluation::trn::TrnScore;
use ground_sim::reference::load;
use nav_core::{NavConfig, Tile};

/// Arguments of `ground-sim eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Reference folder (tile.bin, slope.tif).
    #[arg(long)]
    pub tile: PathBuf,
    /// Truth DEM (GeoTIFF).
    #[arg(long)]
    pub dem: PathBuf,
    /// Number of frames.
    #[arg(long, default_value_t = 500)]
    pub trials: usize,
    /// Campaign seed (positions, headings, scales, noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Smallest frame pixel size, metres.
    #[arg(long, default_value_t = 9.0)]
    pub pixel_min_m: f64,
    /// Largest frame pixel size, metres.
    #[arg(long, default_value_t = 11.0)]
    pub pixel_max_m: f64,
    /// The flyer's ranging sensor.
    #[command(flatten)]
    pub sensor: super::SensorArgs,
    /// The prior given with each frame, as the nav filter would in flight.
    #[command(flatten)]
    pub prior: PriorArgs,
    /// Summary JSON (with `--shard`: the shard file).
    #[arg(long)]
    pub json: PathBuf,
    /// One CSV row per trial (default: next to the JSON, `.csv`).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// The navigator budget.
    #[command(flatten)]
    pub budget: super::BudgetArgs,
    /// Record 0 ms as every frame's onboard time: the outputs then repeat byte for byte (host
    /// time is the only figure that changes from run to run).
    #[arg(long)]
    pub no_host_time: bool,
    /// Which shard of the campaign to fly.
    #[command(flatten)]
    pub shard: super::ShardArgs,
}

/// A shard file of `eval`: the campaign spec and one score per trial.
pub type EvalShard = ShardFile<CampaignSpec, TrnScore>;

/// `kind` of `eval` shard files.
pub const KIND: &str = "eval";

/// The prior of a campaign on the command line: none unless `--prior-sigma-m` is given.
#[derive(Debug, Clone, clap::Args)]
pub struct PriorArgs {
    /// Give every frame a prior drawn around the truth with this 1σ position error per axis,
    /// metres (default: no prior, lost in space).
    #[arg(long)]
    pub prior_sigma_m: Option<f64>,
    /// 1σ heading error of the prior, degrees.
    #[arg(long, default_value_t = 2.0, requires = "prior_sigma_m")]
    pub prior_heading_sigma_deg: f64,
    /// 1σ relative scale error of the prior (the altimeter's).
    #[arg(long, default_value_t = 0.02, requires = "prior_sigma_m")]
    pub prior_scale_sigma: f64,
}

impl PriorArgs {
    /// The prior these flags describe, checked.
    pub fn spec(&self) -> anyhow::Result<Option<PriorSpec>> {
        let Some(sigma_m) = self.prior_sigma_m else {
            return Ok(None);
        };
        let p = PriorSpec {
            sigma_m,
            heading_sigma_deg: self.prior_heading_sigma_deg,
            scale_sigma: self.prior_scale_sigma,
        };
        let finite = [p.sigma_m, p.heading_sigma_deg, p.scale_sigma]
            .iter()
            .all(|v| v.is_finite());
        if !(finite && p.sigma_m > 0.0 && p.heading_sigma_deg >= 0.0 && p.scale_sigma >= 0.0) {
            anyhow::bail!("the prior's σ must be finite, the position σ > 0 and the others ≥ 0");
        }
        Ok(Some(p))
    }
}

/// Run `ground-sim eval`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let reference = load(&a.tile)?;
    let tile = Tile::parse(&reference.tile_bytes).map_err(|e| anyhow!("{e}"))?;
    let dem = read_geotiff(&a.dem).with_context(|| format!("reading {}", a.dem.display()))?;
    let spec = CampaignSpec {
        trials: a.trials,
        seed: a.seed,
        pixel_min_m: a.pixel_min_m,
        pixel_max_m: a.pixel_max_m,
        sensor: a.sensor.model(),
        prior: a.prior.spec()?,
        budget: a.budget.budget,
        host_time: !a.no_host_time,
    };
    let shard = a.shard.shard.unwrap_or(Shard::WHOLE);
    let trials = shard.trials(spec.trials);
    let pb = super::progress(trials.len() as u64, "eval");
    let rows = run_trials(tile, NavConfig::default(), &dem, &spec, &trials, &pb)?;
    pb.finish_and_clear();
    let csv_path = a
        .csv
        .clone()
        .unwrap_or_else(|| a.json.with_extension("csv"));
    if a.shard.shard.is_none() {
        return report(&spec, &rows, &a.json, &csv_path);
    }
    write_csv_trials(&csv_path, &trials, &rows)?;
    let file = EvalShard {
        format: SHARD_FORMAT.into(),
        version: SHARD_VERSION,
        kind: KIND.into(),
        shard,
        trials: spec.trials,
        seed: spec.seed,
        budget: spec.budget.label(),
        inputs: CampaignInputs::new(&reference.tile_bytes, &a.dem)?,
        spec,
        trial_indices: trials,
        records: rows,
    };
    file.write(&a.json)?;
    println!(
        "shard       {shard} of the campaign: {} of {} trials (seed {})\nshard file  {}\ncsv         {}",
        file.records.len(),
        spec.trials,
        spec.seed,
        a.json.display(),
        csv_path.display()
    );
    Ok(())
}

/// Summarise a whole campaign's rows (trial order) and write its JSON and CSV: what `eval`
/// writes unsharded and `merge` writes from the shards.
pub fn report(
    spec: &CampaignSpec,
    rows: &[TrnScore],
    json: &Path,
    csv: &Path,
) -> anyhow::Result<()> {
    let summary = summarize(rows, spec);
    print_summary(&summary);
    super::write_json(json, &summary)?;
    let trials: Vec<usize> = (0..rows.len()).collect();
    write_csv_trials(csv, &trials, rows)?;
    println!(
        "json        {}\ncsv         {}",
        json.display(),
        csv.display()
    );
    Ok(())
}
