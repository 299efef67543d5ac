//! `ground-sim merge`: join the shard files of one `eval` or `descent` campaign (`--shard I/N`)
//! and write what the unsharded command writes, byte for byte.

use std::path::PathBuf;

use anyhow::bail;
use ground_sim::evaluation::shard::{ShardFile, check_shards, shard_kind};
use serde::Serialize;
use serde::de::DeserializeOwned;

/// Arguments of `ground-sim merge`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Summary JSON of the whole campaign (as `eval`/`descent --json`).
    #[arg(long)]
    pub json: PathBuf,
    /// eval: one CSV row per trial (default: next to the JSON, `.csv`).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// descent: folder for the pictures of run 0 (default: beside the JSON).
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// The shard files (or folders holding a `shard.json`), all N of one campaign, any order.
    #[arg(required = true, num_args = 1..)]
    pub shards: Vec<PathBuf>,
}

/// Read every shard as kind `kind`, check they make one whole campaign, join them.
fn join<S, R>(shards: &[PathBuf], kind: &str) -> anyhow::Result<ShardFile<S, R>>
where
    S: Serialize + DeserializeOwned,
    R: Serialize + DeserializeOwned,
{
    let files = shards
        .iter()
        .map(|p| Ok((p.clone(), ShardFile::<S, R>::read(p, kind)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let whole = check_shards(files)?;
    println!(
        "merged       {} shards of a `{kind}` campaign: {} trials (seed {})",
        shards.len(),
        whole.trials,
        whole.seed
    );
    Ok(whole)
}

/// Run `ground-sim merge`.
pub fn run(a: &Args) -> anyhow::Result<()> {
    let Some(first) = a.shards.first() else {
        bail!("merge needs at least one shard");
    };
    match shard_kind(first)?.as_str() {
        super::eval::KIND => {
            if a.png.is_some() {
                bail!("--png applies to descent shards; these are eval shards");
            }
            let whole: super::eval::EvalShard = join(&a.shards, super::eval::KIND)?;
            let csv = a
                .csv
                .clone()
                .unwrap_or_else(|| a.json.with_extension("csv"));
            super::eval::report(&whole.spec, &whole.records, &a.json, &csv)
        }
        super::descent::KIND => {
            if a.csv.is_some() {
                bail!("--csv applies to eval shards; these are descent shards");
            }
            let whole: super::descent::DescentShard = join(&a.shards, super::descent::KIND)?;
            let dir = a
                .png
                .clone()
                .unwrap_or_else(|| a.json.parent().map(|p| p.to_path_buf()).unwrap_or_default());
            super::descent::report(&whole.spec, whole.records, &a.json, &dir)
        }
        other => bail!(
            "{}: unknown campaign kind {other:?} (eval or descent)",
            first.display()
        ),
    }
}
