//! Campaign shards: one campaign split over machines (`--shard i/N`) and joined again (`merge`).
//!
//! A campaign of `T` trials is split by trial index: shard `i` of `N` (0-based, so that Slurm's
//! `SLURM_ARRAY_TASK_ID` over `--array=0-(N-1)` is `i` as it stands) flies the trials `k` with
//! `k mod N == i`. Every trial seeds its own generator from (campaign seed, trial index) only, so
//! a trial flies the same whichever shard, thread or machine runs it, and the union of the shards
//! is the unsharded campaign record for record.
//!
//! A shard writes a [`ShardFile`]: what the campaign is (kind, spec, seed, budget, trial count,
//! checksums of its tile and DEM), which shard it is, and its per-trial records in trial order.
//! Floats are written by `serde_json` in their shortest round-trip form and read back with
//! `float_roundtrip`, so records come back bit for bit and `merge` recomputes exactly the summary
//! the unsharded command writes. [`check_shards`] refuses shards of different campaigns,
//! duplicates and gaps.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{Context, bail};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize};

/// `format` of every shard file.
pub const SHARD_FORMAT: &str = "umbra-campaign-shard";
/// Version of the shard file layout; `merge` refuses any other.
pub const SHARD_VERSION: u32 = 1;

/// One shard of a campaign: index `index` (0-based) of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// Which shard, `0..count`.
    pub index: usize,
    /// How many shards the campaign is split into, ≥ 1.
    pub count: usize,
}

/// Why a `--shard` text was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    /// Not two integers separated by `/`.
    #[error("malformed shard {0:?}: expected i/N with 0-based i, e.g. 0/4")]
    Malformed(String),
    /// `N` = 0.
    #[error("shard count must be at least 1 (got {0:?})")]
    ZeroCount(String),
    /// `i ≥ N`.
    #[error("shard index {index} out of range for {count} shards: i is 0-based, 0 ≤ i < {count}")]
    OutOfRange {
        /// Given index.
        index: usize,
        /// Given count.
        count: usize,
    },
}

impl Shard {
    /// The whole campaign as one shard.
    pub const WHOLE: Self = Self { index: 0, count: 1 };

    /// A checked shard.
    pub fn new(index: usize, count: usize) -> Result<Self, ShardError> {
        if count == 0 {
            return Err(ShardError::ZeroCount(format!("{index}/{count}")));
        }
        if index >= count {
            return Err(ShardError::OutOfRange { index, count });
        }
        Ok(Self { index, count })
    }

    /// Whether trial `trial` belongs to this shard.
    pub fn holds(&self, trial: usize) -> bool {
        trial % self.count == self.index
    }

    /// This shard's trials of a campaign of `trials`, ascending.
    pub fn trials(&self, trials: usize) -> Vec<usize> {
        (self.index..trials).step_by(self.count).collect()
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let malformed = || ShardError::Malformed(s.to_string());
        let (i, n) = s.trim().split_once('/').ok_or_else(malformed)?;
        // Plain decimal digits only: `+1`, ` 1` or `0x1` are typos, not shards.
        let num = |t: &str| {
            if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
                return Err(malformed());
            }
            t.parse::<usize>().map_err(|_| malformed())
        };
        let (index, count) = (num(i)?, num(n)?);
        if count == 0 {
            return Err(ShardError::ZeroCount(s.to_string()));
        }
        Self::new(index, count)
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// What a campaign flies against, by content: the same tile and DEM under other paths on
/// another machine are the same campaign.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CampaignInputs {
    /// CRC-64/XZ of the reference tile blob (`tile.bin`), hex.
    pub tile_crc64: String,
    /// CRC-64/XZ of the truth DEM file's bytes, hex.
    pub dem_crc64: String,
}

const CRC64: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);

impl CampaignInputs {
    /// Checksums of the tile blob and of the DEM file at `dem`.
    pub fn new(tile_bytes: &[u8], dem: &Path) -> anyhow::Result<Self> {
        let dem_bytes = std::fs::read(dem).with_context(|| format!("reading {}", dem.display()))?;
        Ok(Self {
            tile_crc64: format!("{:016x}", CRC64.checksum(tile_bytes)),
            dem_crc64: format!("{:016x}", CRC64.checksum(&dem_bytes)),
        })
    }
}

/// The file one shard writes: the campaign's identity, the shard, its records in trial order.
/// `S` is the campaign spec, `R` one trial's record.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardFile<S, R> {
    /// [`SHARD_FORMAT`].
    pub format: String,
    /// [`SHARD_VERSION`].
    pub version: u32,
    /// Which command flew it: `eval` or `descent`.
    pub kind: String,
    /// This shard, `i/N`, 0-based.
    pub shard: Shard,
    /// Trials of the whole campaign.
    pub trials: usize,
    /// Campaign seed.
    pub seed: u64,
    /// Navigator budget label.
    pub budget: String,
    /// Checksums of the tile and DEM.
    pub inputs: CampaignInputs,
    /// Everything else that decides the trials (campaign settings).
    pub spec: S,
    /// This shard's trial indices, ascending, one per record.
    pub trial_indices: Vec<usize>,
    /// One record per trial, in the order of `trial_indices`.
    pub records: Vec<R>,
}

/// The campaign's identity part of a shard file, compared across shards by [`check_shards`].
#[derive(Debug, Clone, PartialEq, Serialize)]
struct Identity<'a> {
    kind: &'a str,
    count: usize,
    trials: usize,
    seed: u64,
    budget: &'a str,
    inputs: &'a CampaignInputs,
    spec: serde_json::Value,
}

impl<S: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned> ShardFile<S, R> {
    /// Write as JSON to `path`.
    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        crate::write_json(path, self)
    }

    /// Read a shard file of kind `kind` (a folder: its `shard.json`).
    pub fn read(path: &Path, kind: &str) -> anyhow::Result<Self> {
        let path = shard_path(path);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading shard {}", path.display()))?;
        let head: Head = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a campaign shard file", path.display()))?;
        if head.format != SHARD_FORMAT {
            bail!(
                "{} is not a campaign shard file (format {:?})",
                path.display(),
                head.format
            );
        }
        if head.version != SHARD_VERSION {
            bail!(
                "{}: shard file version {} (this ground-sim reads version {SHARD_VERSION})",
                path.display(),
                head.version
            );
        }
        if head.kind != kind {
            bail!(
                "{} holds a `{}` shard, not `{kind}`",
                path.display(),
                head.kind
            );
        }
        serde_json::from_str(&text).with_context(|| format!("parsing shard {}", path.display()))
    }
}

/// The first fields of a shard file, read before its records.
#[derive(Debug, Deserialize)]
struct Head {
    format: String,
    version: u32,
    kind: String,
}

/// The kind (`eval`, `descent`) of the shard file at `path` (a folder: its `shard.json`).
pub fn shard_kind(path: &Path) -> anyhow::Result<String> {
    let path = shard_path(path);
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("reading shard {}", path.display()))?;
    let head: Head = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a campaign shard file", path.display()))?;
    Ok(head.kind)
}

/// A shard given as a folder means its `shard.json`.
pub fn shard_path(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join("shard.json")
    } else {
        path.to_path_buf()
    }
}

/// Check that `shards` (with the paths they came from, for messages) are all the shards of one
/// campaign, each once, with exactly their own trials; return them joined as the whole campaign
/// (shard 0/1, every trial's record in trial order).
pub fn check_shards<S: Serialize, R>(
    shards: Vec<(PathBuf, ShardFile<S, R>)>,
) -> anyhow::Result<ShardFile<S, R>> {
    let Some((first_path, first)) = shards.first() else {
        bail!("merge needs at least one shard");
    };
    let identity = |f: &ShardFile<S, R>| -> anyhow::Result<serde_json::Value> {
        Ok(serde_json::to_value(Identity {
            kind: &f.kind,
            count: f.shard.count,
            trials: f.trials,
            seed: f.seed,
            budget: &f.budget,
            inputs: &f.inputs,
            spec: serde_json::to_value(&f.spec)?,
        })?)
    };
    let id0 = identity(first)?;
    let n = first.shard.count;
    let mut seen: Vec<Option<&Path>> = vec![None; n];
    for (path, f) in &shards {
        let id = identity(f)?;
        if id != id0 {
            bail!(
                "{} and {} are shards of different campaigns:{}",
                first_path.display(),
                path.display(),
                differences(&id0, &id)
            );
        }
        if f.shard.index >= n {
            bail!("{}: shard {} is out of range", path.display(), f.shard);
        }
        if let Some(other) = seen[f.shard.index] {
            bail!(
                "shard {} given twice: {} and {}",
                f.shard,
                other.display(),
                path.display()
            );
        }
        seen[f.shard.index] = Some(path);
        if f.trial_indices != f.shard.trials(f.trials) || f.records.len() != f.trial_indices.len() {
            bail!(
                "{}: shard {} should hold trials {:?} of {} ({} records), it holds {:?} ({} records)",
                path.display(),
                f.shard,
                abbreviate(&f.shard.trials(f.trials)),
                f.trials,
                f.shard.trials(f.trials).len(),
                abbreviate(&f.trial_indices),
                f.records.len()
            );
        }
    }
    let missing: Vec<String> = (0..n)
        .filter(|&i| seen[i].is_none())
        .map(|i| format!("{i}/{n}"))
        .collect();
    if !missing.is_empty() {
        bail!(
            "incomplete campaign: shard(s) {} missing ({} of {n} given)",
            missing.join(", "),
            shards.len()
        );
    }
    let total = first.trials;
    let mut slots: Vec<Option<R>> = (0..total).map(|_| None).collect();
    let mut meta = None;
    for (_, mut f) in shards {
        for (k, r) in f.trial_indices.iter().zip(f.records.drain(..)) {
            slots[*k] = Some(r);
        }
        if f.shard.index == 0 {
            meta = Some(f);
        }
    }
    // Every shard holds exactly its residue class and all N are present: every slot is full.
    let records = slots
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .context("a trial is missing after the checks (bug)")?;
    let mut whole = meta.context("shard 0 missing after the checks (bug)")?;
    whole.shard = Shard::WHOLE;
    whole.trial_indices = (0..total).collect();
    whole.records = records;
    Ok(whole)
}

/// The top-level fields in which two identities differ, for an error message.
fn differences(a: &serde_json::Value, b: &serde_json::Value) -> String {
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else {
        return String::new();
    };
    a.iter()
        .filter(|(k, v)| b.get(*k) != Some(v))
        .map(|(k, v)| {
            let field = if k == "count" { "shard count N" } else { k };
            format!(
                "\n  {field}: {} vs {}",
                v,
                b.get(k).unwrap_or(&serde_json::Value::Null)
            )
        })
        .collect()
}

/// A short form of a trial list for messages.
fn abbreviate(v: &[usize]) -> String {
    if v.len() <= 6 {
        format!("{v:?}")
    } else {
        format!("[{}, {}, {}, …, {}]", v[0], v[1], v[2], v[v.len() - 1])
    }
}

/// Deserialize an `f64` written by `serde_json`, which writes NaN and ±∞ as `null`: `null`
/// reads back as NaN (the fields using this are NaN when undefined, e.g. no fix yet).
pub fn f64_or_nan<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// `Option<f64>` that keeps non-finite values: `serde_json` would write `Some(∞)` as `null` and
/// read it back as `None`, changing which values a summary counts. Finite values and `None` are
/// written as before; NaN and ±∞ as the strings `"NaN"`, `"inf"`, `"-inf"`.
pub mod opt_f64 {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Serialize `v`.
    pub fn serialize<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            None => s.serialize_none(),
            Some(x) if x.is_finite() => s.serialize_some(x),
            Some(x) if x.is_nan() => s.serialize_str("NaN"),
            Some(x) if *x > 0.0 => s.serialize_str("inf"),
            Some(_) => s.serialize_str("-inf"),
        }
    }

    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Repr {
        Num(f64),
        Text(String),
    }

    /// Deserialize what [`serialize`] wrote.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        match Option::<Repr>::deserialize(d)? {
            None => Ok(None),
            Some(Repr::Num(x)) => Ok(Some(x)),
            Some(Repr::Text(t)) => match t.as_str() {
                "NaN" => Ok(Some(f64::NAN)),
                "inf" => Ok(Some(f64::INFINITY)),
                "-inf" => Ok(Some(f64::NEG_INFINITY)),
                _ => Err(serde::de::Error::custom(format!(
                    "expected a number, null, \"NaN\", \"inf\" or \"-inf\", got {t:?}"
                ))),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses_shard_texts() {
        assert_eq!("0/1".parse::<Shard>(), Ok(Shard::WHOLE));
        assert_eq!("6/7".parse::<Shard>(), Ok(Shard { index: 6, count: 7 }));
        assert_eq!(
            "7/7".parse::<Shard>(),
            Err(ShardError::OutOfRange { index: 7, count: 7 })
        );
        assert!(matches!(
            "0/0".parse::<Shard>(),
            Err(ShardError::ZeroCount(_))
        ));
        for bad in [
            "", "1", "1/", "/3", "a/3", "1/b", "-1/3", "+1/3", "1/3/5", "1.0/3", "0x1/3",
        ] {
            assert!(
                matches!(bad.parse::<Shard>(), Err(ShardError::Malformed(_))),
                "{bad:?} accepted"
            );
        }
    }

    #[test]
    fn shards_partition_the_trials() {
        for n in 1..9 {
            let mut all: Vec<usize> = (0..n)
                .flat_map(|i| Shard::new(i, n).unwrap().trials(23))
                .collect();
            all.sort_unstable();
            assert_eq!(all, (0..23).collect::<Vec<_>>(), "N = {n}");
        }
        let s = Shard::new(2, 3).unwrap();
        assert_eq!(s.trials(10), vec![2, 5, 8]);
        assert!(s.holds(5) && !s.holds(6));
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Row {
        #[serde(with = "opt_f64")]
        v: Option<f64>,
        #[serde(deserialize_with = "f64_or_nan")]
        w: f64,
    }

    #[test]
    fn floats_come_back_bit_for_bit() {
        // Values whose shortest decimal form is long: a lossy parser rounds some of them.
        let mut x = 0.1f64;
        for k in 0..2000 {
            x = (x * 1.618_033_988_749_895 + 1e-7 * k as f64).fract() * 10f64.powi(k % 40 - 20);
            let r = Row { v: Some(x), w: -x };
            let back: Row = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
            assert_eq!(back.v.unwrap().to_bits(), x.to_bits());
            assert_eq!(back.w.to_bits(), (-x).to_bits());
        }
        for v in [f64::INFINITY, f64::NEG_INFINITY] {
            let r = Row { v: Some(v), w: 1.0 };
            let back: Row = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
            assert_eq!(back, r);
        }
        let nan = Row {
            v: Some(f64::NAN),
            w: f64::NAN,
        };
        let back: Row = serde_json::from_str(&serde_json::to_string(&nan).unwrap()).unwrap();
        assert!(back.v.unwrap().is_nan() && back.w.is_nan());
        let none: Row = serde_json::from_str(r#"{"v":null,"w":2.5}"#).unwrap();
        assert_eq!(none.v, None);
    }
}
