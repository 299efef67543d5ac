//! `ground-sim results`: regenerate `docs/results.md` from runs made now: the paper's four TRN
//! cases beside the paper's figures, Monte-Carlo campaigns on both presets, and a descent
//! campaign. Every figure in the file comes from this command's own runs (seeds recorded).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use ground_sim::evaluation::navmap::NavmapScore;
use serde_json::Value;

/// Arguments of `ground-sim results`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Markdown file to write.
    #[arg(long, default_value = "docs/results.md")]
    pub out: PathBuf,
    /// Working folder for the scenes, tiles and JSON files.
    #[arg(long, default_value = "out/results")]
    pub work: PathBuf,
    /// Frames per eval campaign.
    #[arg(long, default_value_t = 500)]
    pub trials: usize,
    /// Hops per descent campaign (each map, with and without velocimeter).
    #[arg(long, default_value_t = 30)]
    pub runs: usize,
    /// Seed of every scene and campaign.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Frames per campaign of the terrain suite.
    #[arg(long, default_value_t = 300)]
    pub suite_trials: usize,
    /// Folder of the pictures the Markdown shows (copied there from the runs).
    #[arg(long, default_value = "docs/img")]
    pub img: PathBuf,
}

/// Run `ground-sim trn` for one Fig. 7 case (`rot_deg`) of `tile` against `dem`, writing
/// `{stem}.json` and `{stem}.png` (and the frame and reference images to `export`), and return
/// its JSON.
fn trn_case(
    go: &dyn Fn(&[&str]) -> anyhow::Result<()>,
    seed: &str,
    tile: &str,
    dem: &str,
    rot_deg: f64,
    stem: &str,
    export: Option<&str>,
) -> anyhow::Result<Value> {
    let (json, png, rot) = (
        format!("{stem}.json"),
        format!("{stem}.png"),
        rot_deg.to_string(),
    );
    let mut args = vec![
        "trn",
        "--tile",
        tile,
        "--dem",
        dem,
        "--heading-deg",
        &rot,
        "--seed",
        seed,
        "--json",
        &json,
        "--png",
        &png,
    ];
    if let Some(dir) = export {
        args.extend(["--export", dir]);
    }
    go(&args)?;
    read(Path::new(&json))
}

/// The terrain suite (`ground-sim suite`): its table and picture, and one scene's navigability
/// map, each scene's verdict read from the suite's own JSON.
fn suite_section(
    md: &mut String,
    a: &Args,
    go: &dyn Fn(&[&str]) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let dir = a.work.join("suite");
    let (d, seed, trials) = (
        dir.to_string_lossy().into_owned(),
        a.seed.to_string(),
        a.suite_trials.to_string(),
    );
    let run_suite = |d: &str, seed: &str| {
        go(&[
            "suite",
            "--out",
            d,
            "--campaign-seed",
            seed,
            "--terrain-seed",
            seed,
            "--trials",
            &trials,
        ])
    };
    run_suite(&d, &seed)?;
    let table = std::fs::read_to_string(dir.join("suite.md"))?;
    let report = read(&dir.join("suite.json"))?;
    std::fs::create_dir_all(&a.img)?;
    std::fs::copy(dir.join("suite.png"), a.img.join("suite.png"))?;
    std::fs::copy(
        dir.join("fresh-rim").join("rehearsal-truth-noprior.png"),
        a.img.join("navmap-fresh-rim-truth.png"),
    )?;
    let img = |f: &str| {
        let rel = a.out.parent().and_then(|p| a.img.strip_prefix(p).ok());
        rel.map_or(a.img.join(f), |r| r.join(f))
            .display()
            .to_string()
    };
    writeln!(md, "## The terrain suite (`ground-sim suite`)\n")?;
    writeln!(
        md,
        "Every scene 4 km × 4 km at 5 m (terrain seed {seed}; `terrain --preset NAME --window W --seed {seed}`), \
         tiles at 20 m from the truth DEM and from the InSAR chain (the default radar, as the line above the table states), \
         frames 200 px at 9–11 m with any heading, without and with a prior (σ 50 m, heading σ 2°, scale σ 2 %, drawn around the truth). \
         The two \"navmap\" columns score the navigability maps (`ground-sim navmap`, from the reference folder alone; docs/navmap.md) against the campaign's frames: \
         the success rate of the frames each called \"go\" and the fraction of frames whose outcome it predicted. The footprint rule reads tile features, valid reference and slope texture under the frame; \
         the rehearsal (the default) flies the flight code against the tile beforehand, in the campaign's prior mode, with frames from a draw of the terrain given the reference DEM and the map's own reported error. \
         The whole suite took {:.0} s on this 2-core machine.\n",
        report["seconds"].as_f64().unwrap_or(f64::NAN)
    )?;
    writeln!(md, "![suite]({})\n", img("suite.png"))?;
    writeln!(md, "{table}")?;
    writeln!(md, "Scenes:\n")?;
    for s in report["scenes"].as_array().into_iter().flatten() {
        writeln!(
            md,
            "- `{}`: {} (slope median {:.1}°{}).",
            s["scene"]["name"].as_str().unwrap_or("?"),
            s["scene"]["what"].as_str().unwrap_or(""),
            s["slope_p50_deg"].as_f64().unwrap_or(f64::NAN),
            s["insar_height_rmse_m"]
                .as_f64()
                .map_or(String::new(), |h| format!(
                    "; InSAR height RMSE {h:.2} m, slope RMSE {:.2}°, valid {:.1} %",
                    s["insar_slope_rmse_deg"].as_f64().unwrap_or(f64::NAN),
                    100.0 * s["insar_valid_frac"].as_f64().unwrap_or(f64::NAN)
                ))
        )?;
    }
    writeln!(
        md,
        "\nThe navigability map by rehearsal of the fresh crater's rim against its truth-built tile, lost in space (green go, red no-go; grey: a frame centred there would leave the map; the crater's bowl is the bright disc):\n\n![navmap]({})\n",
        img("navmap-fresh-rim-truth.png")
    )?;
    // The same suite on other terrain and frames: nothing above may hold for one seed only.
    let seed2 = (a.seed + 1).to_string();
    let dir2 = a.work.join(format!("suite-seed{seed2}"));
    run_suite(&dir2.to_string_lossy(), &seed2)?;
    let report2 = read(&dir2.join("suite.json"))?;
    writeln!(
        md,
        "### The same suite with terrain and campaign seed {seed2}\n\nSuccess per scene (false fixes in brackets when any), {trials} frames per campaign:\n"
    )?;
    let all_cols = [
        ("truth", false),
        ("truth", true),
        ("insar", false),
        ("insar", true),
    ];
    writeln!(
        md,
        "| scene | truth, no prior | truth, prior | InSAR, no prior | InSAR, prior |\n|---|---|---|---|---|"
    )?;
    md.push_str(&success_rows(&report2, &all_cols));
    // The paper's noise-free radar beside the default one: what thermal noise costs.
    let dir_paper = a.work.join("suite-paper-radar");
    go(&[
        "suite",
        "--out",
        &dir_paper.to_string_lossy(),
        "--campaign-seed",
        &seed,
        "--terrain-seed",
        &seed,
        "--trials",
        &trials,
        "--kinds",
        "insar",
        "--radar",
        "paper",
        // Only its success rates are shown: no navigability maps.
        "--rehearsal-step-m",
        "0",
    ])?;
    let report_paper = read(&dir_paper.join("suite.json"))?;
    writeln!(
        md,
        "\n### InSAR tiles from the paper's noise-free radar (`suite --radar paper`, seed {seed})\n\nThe same scenes and frames as the first table, tiles from {}; success per scene (false fixes in brackets when any), {trials} frames per campaign:\n",
        report_paper["spec"]["radar"]["baseline_m"].as_f64().map_or(
            "the paper's radar".into(),
            |b| format!(
                "the paper's radar ({b} m baseline, no thermal noise, no diffuse echo, one look)"
            )
        )
    )?;
    writeln!(
        md,
        "| scene | InSAR, no prior | InSAR, prior |\n|---|---|---|"
    )?;
    md.push_str(&success_rows(&report_paper, &all_cols[2..]));
    // The default radar without its second pair, on both seeds beside the default radar.
    short_pair_section(md, a, go, [(&seed, &report), (&seed2, &report2)])?;
    writeln!(
        md,
        "\nThe navigability maps over all campaigns of each seed (frames called \"go\": how many, how many got a correct fix; agreement = outcomes predicted right). The footprint rule reads feature count, valid fraction and slope texture under the frame; the rehearsal flies the flight code against the reference with frames from a draw of the terrain given its own DEM and its reported error, in the campaign's prior mode (`ground_sim::evaluation::rehearsal`):\n\n| seed | tile | map | go frames | go success | agreement |\n|---|---|---|---|---|---|"
    )?;
    for (sd, rep) in [(&seed, &report), (&seed2, &report2)] {
        for (kind, (key, method)) in ["truth", "insar"]
            .into_iter()
            .flat_map(|k| [("navmap", "footprint"), ("rehearsal", "rehearsal")].map(|m| (k, m)))
        {
            let (mut go_n, mut go_ok, mut right, mut n) = (0u64, 0u64, 0u64, 0u64);
            for r in rep["rows"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|r| r["kind"] == kind && !r[key].is_null())
            {
                let m = &r[key];
                let g = |k: &str| m[k].as_u64().unwrap_or(0);
                go_n += g("go_frames");
                go_ok += g("go_success");
                right += g("go_success") + g("nogo_frames") - g("nogo_success");
                n += g("go_frames") + g("nogo_frames");
            }
            if n == 0 {
                continue;
            }
            writeln!(
                md,
                "| {sd} | {kind} | {method} | {go_n} | {:.1} % | {:.1} % |",
                100.0 * go_ok as f64 / go_n.max(1) as f64,
                100.0 * right as f64 / n.max(1) as f64
            )?;
        }
    }
    // Where a campaign's agreement misses the bar, whether any map of cells could have met it.
    writeln!(
        md,
        "\nCampaigns where the rehearsal's map agrees with fewer than 90 % of outcomes, beside the best agreement any go/no-go map could reach on the same frames while its \"go\" frames fix at 99 %, if the rehearsal's chances are right (`ground_sim::evaluation::navmap::agreement_ceiling`; the chances are calibrated, the table below):\n\n| seed | scene | tile | prior | success | go frames: success | agreement | best any map |\n|---|---|---|---|---|---|---|---|"
    )?;
    let mut misses = 0;
    for (sd, rep) in [(&seed, &report), (&seed2, &report2)] {
        for r in rep["rows"].as_array().into_iter().flatten() {
            let Ok(m) = serde_json::from_value::<NavmapScore>(r["rehearsal"].clone()) else {
                continue;
            };
            let agree = m.agreement();
            if m.go_frames + m.nogo_frames == 0 || agree >= 0.9 {
                continue;
            }
            misses += 1;
            writeln!(
                md,
                "| {sd} | {} | {} | {} | {:.1} % | {} | {:.1} % | {} |",
                r["scene"].as_str().unwrap_or("?"),
                r["kind"].as_str().unwrap_or("?"),
                match &r["summary"]["prior"] {
                    Value::Null => "none".to_string(),
                    pr => format!("{} m, {}°", pr["sigma_m"], pr["heading_sigma_deg"]),
                },
                100.0 * r["summary"]["success_rate"].as_f64().unwrap_or(f64::NAN),
                if m.go_frames > 0 {
                    format!("{:.1} % of {}", 100.0 * m.go_success_rate(), m.go_frames)
                } else {
                    "none".into()
                },
                100.0 * agree,
                r["rehearsal_agreement_ceiling"]
                    .as_f64()
                    .map_or("–".into(), |c| format!("{:.1} %", 100.0 * c)),
            )?;
        }
    }
    if misses == 0 {
        writeln!(md, "| – | none | | | | | | |")?;
    }
    // The rehearsal as a forecast: its mean predicted chance over a campaign's frames against the
    // campaign's success rate, and its calibration frame by frame.
    writeln!(
        md,
        "\nThe rehearsal as a forecast of each campaign's success rate (its predicted chance averaged over the campaign's frame centres), per seed and tile kind over the 18 campaigns:\n\n| seed | tile | mean predicted − flown | largest \\|predicted − flown\\| | campaign |\n|---|---|---|---|---|"
    )?;
    for (sd, rep) in [(&seed, &report), (&seed2, &report2)] {
        for kind in ["truth", "insar"] {
            let diffs: Vec<(f64, String)> = rep["rows"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|r| r["kind"] == kind)
                .filter_map(|r| {
                    let p = r["rehearsal_predicted_success"].as_f64()?;
                    let f = r["summary"]["success_rate"].as_f64()?;
                    let mode = if r["summary"]["prior"].is_null() {
                        "no prior"
                    } else {
                        "prior"
                    };
                    Some((
                        p - f,
                        format!("{}, {mode}", r["scene"].as_str().unwrap_or("?")),
                    ))
                })
                .collect();
            let Some(worst) = diffs.iter().max_by(|a, b| a.0.abs().total_cmp(&b.0.abs())) else {
                continue;
            };
            writeln!(
                md,
                "| {sd} | {kind} | {:+.1} points | {:.1} points | {} |",
                100.0 * diffs.iter().map(|d| d.0).sum::<f64>() / diffs.len() as f64,
                100.0 * worst.0.abs(),
                worst.1
            )?;
        }
    }
    writeln!(
        md,
        "\nCalibration over both seeds, every scene and prior mode: frames binned by the rehearsal's predicted chance at their centre, against how many of them fixed:\n\n| predicted | truth: frames | mean predicted | fixed | InSAR: frames | mean predicted | fixed |\n|---|---|---|---|---|---|---|"
    )?;
    let bins = [
        "0–0.125",
        "0.125–0.375",
        "0.375–0.625",
        "0.625–0.875",
        "0.875–1 (not 1)",
        "1",
    ];
    let mut cal = [[(0u64, 0.0f64, 0u64); 6]; 2];
    for (dir_s, rep) in [(&dir, &report), (&dir2, &report2)] {
        for r in rep["rows"].as_array().into_iter().flatten() {
            if r["rehearsal"].is_null() {
                continue;
            }
            let kind = r["kind"].as_str().unwrap_or("?");
            let k = usize::from(kind == "insar");
            let prior = &r["summary"]["prior"];
            let tag = if prior.is_null() {
                "noprior".to_string()
            } else {
                format!(
                    "prior{}m{}deg",
                    prior["sigma_m"].as_f64().unwrap_or(f64::NAN),
                    prior["heading_sigma_deg"].as_f64().unwrap_or(f64::NAN)
                )
            };
            let p = dir_s
                .join(r["scene"].as_str().unwrap_or("?"))
                .join(format!("{kind}-{tag}-navmap.csv"));
            let text =
                std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
            for line in text.lines().skip(1) {
                let c: Vec<&str> = line.split(',').collect();
                let (Some(pr), Some(ok)) = (c.get(5), c.get(7)) else {
                    continue;
                };
                let Ok(pr) = pr.parse::<f64>() else { continue };
                if !pr.is_finite() {
                    continue;
                }
                let b = match pr {
                    x if x < 0.125 => 0,
                    x if x < 0.375 => 1,
                    x if x < 0.625 => 2,
                    x if x < 0.875 => 3,
                    x if x < 0.9995 => 4,
                    _ => 5,
                };
                let e = &mut cal[k][b];
                e.0 += 1;
                e.1 += pr;
                e.2 += u64::from(*ok == "true");
            }
        }
    }
    for (b, label) in bins.iter().enumerate() {
        let cell = |k: usize| {
            let (n, sp, ok) = cal[k][b];
            if n == 0 {
                "0 | – | –".to_string()
            } else {
                format!("{n} | {:.2} | {:.3}", sp / n as f64, ok as f64 / n as f64)
            }
        };
        writeln!(md, "| {label} | {} | {} |", cell(0), cell(1))?;
    }
    writeln!(md)?;
    Ok(())
}

/// One Markdown row per scene of a `suite.json`: the success rate of each (tile kind, prior)
/// column, false fixes in brackets when any, "–" where the suite did not fly that campaign.
fn success_rows(report: &Value, cols: &[(&str, bool)]) -> String {
    let rows = report["rows"].as_array().cloned().unwrap_or_default();
    let mut md = String::new();
    for sc in report["scenes"].as_array().into_iter().flatten() {
        let name = sc["scene"]["name"].as_str().unwrap_or("?");
        let cells: Vec<String> = cols
            .iter()
            .map(|&(kind, prior)| {
                rows.iter()
                    .find(|r| {
                        r["scene"] == name
                            && r["kind"] == kind
                            && r["summary"]["prior"].is_null() != prior
                    })
                    .map_or("–".into(), |r| {
                        let f = r["summary"]["false_fixes"].as_u64().unwrap_or(0);
                        format!(
                            "{:.1} %{}",
                            100.0 * r["summary"]["success_rate"].as_f64().unwrap_or(f64::NAN),
                            if f > 0 {
                                format!(" ({f} false)")
                            } else {
                                String::new()
                            }
                        )
                    })
            })
            .collect();
        md += &format!("| {name} | {} |\n", cells.join(" | "));
    }
    md
}

/// The InSAR suite again with the default radar's 32 m pair alone (`suite --kinds insar
/// --long-baseline-m 0`, the default radar until session 49), at both seeds, beside the
/// default radar's rows of `defaults` (seed, that seed's suite report).
fn short_pair_section(
    md: &mut String,
    a: &Args,
    go: &dyn Fn(&[&str]) -> anyhow::Result<()>,
    defaults: [(&String, &Value); 2],
) -> anyhow::Result<()> {
    let trials = a.suite_trials.to_string();
    let long = ground_sim::sar::RadarPreset::default().long_baseline_m();
    let mut reports = Vec::new();
    for (sd, _) in defaults {
        let dir = a.work.join(format!("suite-short-pair-seed{sd}"));
        go(&[
            "suite",
            "--out",
            &dir.to_string_lossy(),
            "--campaign-seed",
            sd,
            "--terrain-seed",
            sd,
            "--trials",
            &trials,
            "--kinds",
            "insar",
            "--long-baseline-m",
            "0",
            "--rehearsal-step-m",
            "0",
        ])?;
        reports.push(read(&dir.join("suite.json"))?);
    }
    let (s1, s2) = (defaults[0].0, defaults[1].0);
    writeln!(
        md,
        "\n### InSAR tiles from the 32 m pair alone (`suite --kinds insar --long-baseline-m 0`, seeds {s1} and {s2})\n\n\
         The same scenes and frames as the tables above, the tiles made without the default radar's second, {long} m pair (each look's heights from the 32 m interferogram alone; half the SAR time; the default radar until session 49). \
         Each cell: seed {s1} / seed {s2}, {trials} frames per campaign; the default radar's figure (with its second pair) in brackets.\n\n\
         | scene | success, no prior | success, prior | position p95 (m), no prior | fixes within 3σ, no prior | mean NEES, no prior | height RMSE (m) |\n|---|---|---|---|---|---|---|"
    )?;
    let row = |rep: &Value, scene: &str, prior: bool| -> Option<Value> {
        rep["rows"]
            .as_array()?
            .iter()
            .find(|r| {
                r["scene"] == scene
                    && r["kind"] == "insar"
                    && r["summary"]["prior"].is_null() != prior
            })
            .cloned()
    };
    let scene_of = |rep: &Value, scene: &str, key: &str| -> Option<f64> {
        rep["scenes"]
            .as_array()?
            .iter()
            .find(|s| s["scene"]["name"] == scene)?[key]
            .as_f64()
    };
    let pct = |v: Option<f64>| v.map_or("–".into(), |x| format!("{:.1} %", 100.0 * x));
    let num = |v: Option<f64>, d: usize| v.map_or("–".into(), |x| format!("{x:.d$}"));
    for sc in reports[0]["scenes"].as_array().into_iter().flatten() {
        let name = sc["scene"]["name"].as_str().unwrap_or("?");
        let cell = |prior: bool, key: &str, fmt: &dyn Fn(Option<f64>) -> String| {
            let pair = |reps: [&Value; 2]| {
                reps.map(|r| fmt(row(r, name, prior).and_then(|x| x["summary"][key].as_f64())))
                    .join(" / ")
            };
            format!(
                "{} ({})",
                pair([&reports[0], &reports[1]]),
                pair([defaults[0].1, defaults[1].1])
            )
        };
        let rmse = |reps: [&Value; 2]| {
            reps.map(|r| num(scene_of(r, name, "insar_height_rmse_m"), 2))
                .join(" / ")
        };
        writeln!(
            md,
            "| {name} | {} | {} | {} | {} | {} | {} ({}) |",
            cell(false, "success_rate", &pct),
            cell(true, "success_rate", &pct),
            cell(false, "pos_err_p95_m", &|v| num(v, 2)),
            cell(false, "within_3sigma_frac", &pct),
            cell(false, "nees_mean", &|v| num(v, 2)),
            rmse([&reports[0], &reports[1]]),
            rmse([defaults[0].1, defaults[1].1]),
        )?;
    }
    let false_fixes: u64 = reports
        .iter()
        .flat_map(|r| r["rows"].as_array().cloned().unwrap_or_default())
        .map(|r| r["summary"]["false_fixes"].as_u64().unwrap_or(0))
        .sum();
    writeln!(md, "\nFalse fixes over these campaigns: {false_fixes}.")?;
    Ok(())
}

fn read(p: &Path) -> anyhow::Result<Value> {
    let t = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
    Ok(serde_json::from_str(&t)?)
}

fn f(v: &Value, k: &str, digits: usize) -> String {
    v[k].as_f64()
        .map_or("–".into(), |x| format!("{x:.digits$}"))
}

/// Which of issue 7's `eval` bars (success ≥ 99 %, no false fix, position p95 ≤ 20 m, heading
/// p95 ≤ 0.5°) the campaign `e` misses, from its own figures.
fn eval_bars(e: &Value) -> String {
    let g = |k: &str| e[k].as_f64().unwrap_or(f64::NAN);
    let mut missed = Vec::new();
    if !(g("success_rate") >= 0.99) {
        missed.push("success");
    }
    if !(g("false_fix_rate") == 0.0) {
        missed.push("false fixes");
    }
    if !(g("pos_err_p95_m") <= 20.0) {
        missed.push("position p95");
    }
    if !(g("heading_err_p95_deg") <= 0.5) {
        missed.push("heading p95");
    }
    if missed.is_empty() {
        "all met".into()
    } else {
        format!("missed: {}", missed.join(", "))
    }
}

/// The cells of one `trn` JSON in the Fig. 7 tables: matches, inliers, rotation, scale,
/// max / mean registration error, position error (or why there was no fix).
fn case_cells(t: &Value) -> String {
    if t["fix"].as_bool() != Some(true) {
        return format!(
            "{} | – | no fix: {} | | | ",
            t["matches"],
            t["no_fix_reason"].as_str().unwrap_or("?")
        );
    }
    format!(
        "{} | {} | {} | {} | {} / {} | {}",
        t["matches"],
        t["inliers"],
        f(t, "rotation_deg", 2),
        f(t, "scale", 3),
        f(t, "pos_err_max_px", 2),
        f(t, "pos_err_mean_px", 2),
        f(t, "pos_err_m", 1)
    )
}

/// Run `ground-sim eval` of `tile` against `dem` (campaign settings of `a`) into `json` and
/// return its table row, labelled `label`.
fn eval_row(
    a: &Args,
    go: &dyn Fn(&[&str]) -> anyhow::Result<()>,
    label: &str,
    tile: &str,
    dem: &str,
    json: &str,
) -> anyhow::Result<String> {
    go(&[
        "eval",
        "--tile",
        tile,
        "--dem",
        dem,
        "--trials",
        &a.trials.to_string(),
        "--seed",
        &a.seed.to_string(),
        "--json",
        json,
    ])?;
    let e = read(Path::new(json))?;
    let pc = |k: &str| {
        e[k].as_f64()
            .map_or("–".into(), |x| format!("{:.1} %", 100.0 * x))
    };
    Ok(format!(
        "| {label} | {} | {} | {} | {} | {} / {} | {} / {} | {} | {} | {} | {} |",
        e["trials"],
        pc("success_rate"),
        pc("false_fix_rate"),
        pc("no_fix_rate"),
        f(&e, "pos_err_p50_m", 2),
        f(&e, "pos_err_p95_m", 2),
        f(&e, "heading_err_p95_deg", 3),
        f(&e, "heading_err_max_deg", 3),
        pc("scale_err_p95"),
        pc("within_3sigma_frac"),
        f(&e, "time_ms_mean", 2),
        eval_bars(&e)
    ))
}

/// Run `ground-sim results`; `dispatch` runs one ground-sim command line.
pub fn run(a: &Args, dispatch: &dyn Fn(&[String]) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let w = |s: &str| a.work.join(s).to_string_lossy().into_owned();
    let seed = a.seed.to_string();
    let go = |v: &[&str]| -> anyhow::Result<()> {
        let mut args = vec!["ground-sim".to_string()];
        args.extend(v.iter().map(|s| s.to_string()));
        println!("\n$ {}", args.join(" "));
        dispatch(&args)
    };
    std::fs::create_dir_all(&a.work)?;
    let t0 = std::time::Instant::now();
    let mut md = String::new();
    writeln!(md, "# Results\n")?;
    writeln!(
        md,
        "Generated by `cargo run --release -p ground-sim -- results` (seed {}, {} eval frames per preset, {} hops). \
         Every figure below comes from that run; rerun it to reproduce or update them. Reference tiles here are built \
         from the truth DEM at 20 m with the default 40 m terrain smoothing (`ground-sim tile`, a perfect InSAR; the flyer smooths its frames alike), \
         except in the section on the InSAR reference, whose tiles come out of the simulated radar (`ground-sim insar`); frames are synthesised from the truth DEM at \
         10 m with 0.5 m range noise and 0.5 % dropouts (`ground-sim trn`). \
         The onboard chain is the flight code's defaults with the firmware's budget (`nav_core::flight`: {} keypoints, {} matches; every campaign below flies it): SURF, matching and MSAC give the feature fix, which is then refined over the frame's pixels \
         against the tile's slope raster and refused where that slope correlation contradicts it (`nav_core::refine`, docs/registration.md).\n",
        a.seed,
        a.trials,
        a.runs,
        nav_core::flight::MAX_KEYPOINTS,
        nav_core::flight::MAX_MATCHES
    )?;
    suite_section(&mut md, a, &go)?;
    // The paper's four cases.
    writeln!(md, "## The paper's Fig. 7 cases\n")?;
    writeln!(
        md,
        "| scene | rotation | matches | inliers | φ̂ (°) | ŝ | max / mean reg. error (ref px) | position error (m) | paper: matches, φ̂, ŝ, max/mean |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|")?;
    let paper = [
        ("shoemaker", 0.0, "27, 0.30°, 0.50, 1.2 / 0.5"),
        ("shoemaker", 45.0, "23, 44.95°, 0.50, 1.4 / 0.5"),
        ("shackleton", 0.0, "17, 0.09°, 0.50, 1.3 / 0.7"),
        ("shackleton", 60.0, "23, 61.5°, 0.51, 0.9 / 0.5"),
    ];
    for preset in ["shoemaker", "shackleton"] {
        go(&[
            "terrain",
            "--preset",
            preset,
            "--seed",
            &seed,
            "--out",
            &w(&format!("{preset}.tif")),
        ])?;
        go(&[
            "tile",
            "--dem",
            &w(&format!("{preset}.tif")),
            "--out",
            &w(&format!("{preset}-ref")),
        ])?;
    }
    for (preset, rot, p) in paper {
        let t = trn_case(
            &go,
            &seed,
            &w(&format!("{preset}-ref")),
            &w(&format!("{preset}.tif")),
            rot,
            &w(&format!("trn-{preset}-{rot}")),
            Some(&w(&format!("case-{preset}-{rot}"))),
        )?;
        writeln!(md, "| {preset} | {rot}° | {} | {p} |", case_cells(&t))?;
    }
    writeln!(
        md,
        "\nRegistration error: the estimated map against the true map at every inlier's frame position, in reference (20 m) pixels; the paper's is presumably the residual against the matched points.\n"
    )?;
    opencv_section(&mut md, a, &paper.map(|(p, r, _)| (p, r)))?;
    // Campaigns.
    writeln!(md, "## Monte-Carlo campaigns (`ground-sim eval`)\n")?;
    writeln!(
        md,
        "Random frame centres inside the tile, headings 0–360°, frame pixels 9–11 m (scale 0.45–0.55), noise as above.\n"
    )?;
    writeln!(
        md,
        "| preset | trials | success | false fix | no fix | position p50 / p95 (m) | heading p95 / max (°) | scale error p95 | fixes within 3σ | onboard ms/frame (host) | issue 7 bars |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|")?;
    for preset in ["shoemaker", "shackleton"] {
        let row = eval_row(
            a,
            &go,
            preset,
            &w(&format!("{preset}-ref")),
            &w(&format!("{preset}.tif")),
            &w(&format!("eval-{preset}.json")),
        )?;
        writeln!(md, "{row}")?;
    }
    insar_section(&mut md, a, &go, &paper.map(|(p, r, _)| (p, r)))?;
    // Descent.
    writeln!(md, "\n## Descent campaign (`ground-sim descent`)\n")?;
    writeln!(
        md,
        "16 km × 16 km maps at 10 m from three suite presets (terrain seed {seed}), truth-built tiles at 20 m. Release at 3.8 km above the terrain (10 m frame pixels), hops of 2–15 km (clipped to the map), TRN at 1 Hz down to 2 km above the terrain with the flight navigator, IMU at 100 Hz (accelerometer bias 1σ 3 mm/s², gyro bias 2·10⁻⁵ rad/s, noise 3·10⁻³ m/s²/√Hz and 5·10⁻⁵ rad/s/√Hz), altimeter 1 m, star tracker 10″; the velocimeter rows add a Doppler velocimeter (0.05 m/s).\n"
    )?;
    writeln!(
        md,
        "Around each target the truth terrain carries a landing zone (`ground-sim landing-zone`: 512 m at 0.25 m, sub-metre roughness, equilibrium small craters, Golombek & Rapp rocks with k = 0.08; docs/terrain.md). Below 2 km every frame (range noise shrinking with range, 2 cm floor) is located on a keyframe of the flyer's own (`nav_core::odometry`: an earlier frame turned into a tile in RAM, a new one whenever the frames are 0.55× finer) down to 30 m above the terrain; the displacement goes to the filter against its cloned keyframe position. With hazard avoidance, the first frame of 0.4 m pixels or finer (about 150 m up) is mapped instead of being used for odometry (`nav_core::hazard`: plane tilt ≤ {hz_slope}° and relief ≤ {hz_relief} m over the 4 m footprint, the lander's 10° and 0.3 m less a sensing margin measured with `ground-sim hazard-calibrate`, docs/registration.md); an aim with 2 m of clearance is kept, else guidance diverts to the nearest safe site with 4 m clearance (else 2 m, else the widest) within 30 m. The chosen site is then confirmed once on the first frame of {cf_px} m pixels or finer (about 95 m up): a map of the ±{cf_win} m window around the aim only (`HazardMap::build_around`, relief ≤ {cf_relief} m), which keeps the aim if it has 2 m of clearance there or moves it up to {cf_reach} m. A touchdown is safe when the truth landing zone under its 4 m footprint is within 10° and 0.3 m; the landing error is measured to the spot aimed at (the ground the last hazard map judged under the aim, chosen or kept; the target without hazard avoidance). The goal (≥ 99 % safe) is set for landing zones where at least half the cells are safe: the column after the safe touchdowns counts the runs whose ground within the choice's 30 m reach of the target is (truth), the others are targets on a crater wall or a rock field with little or nothing safe in reach. Unsafe touchdowns are split into those on a spot the truth calls unsafe (the maps passed it, or no safe site was in reach) and those carried off a safe spot.\n",
        hz_slope = nav_core::hazard::HazardConfig::default().max_slope_deg,
        hz_relief = nav_core::hazard::HazardConfig::default().max_relief_m,
        cf_px = nav_core::hazard::CONFIRM_MAX_PIXEL_M,
        cf_win = nav_core::hazard::CONFIRM_HALF_WINDOW_M,
        cf_relief = nav_core::hazard::HazardConfig::confirmation().max_relief_m,
        cf_reach = nav_core::hazard::HazardConfig::confirmation().max_reach_m,
    )?;
    writeln!(
        md,
        "The filter (`nav_core::filter`) takes each fix and each odometry offset with the covariance nav-core reports, no inflation. Successive fixes see mostly the same ground, so their errors are not independent: half of each covariance (`FilterConfig::fix_shared_fraction`; over a map that claims height noise of its own, e.g. an InSAR tile, the larger share `nav_core::filter::map_noise_share` gives it) is carried as a fix-error state that the next measurement keeps in proportion to the footprints' overlap, topped up with fresh error whenever a measurement's own shared part exceeds it (the fixes' σ grows several-fold as the frames get finer), the rest is white. As the footprint shrinks on the way down, a drift state (`FilterConfig::fix_scale_drift`) lets the fix error move smoothly with the log of its side, so the filter does not read that trend as velocity. NEES here is the filter's horizontal NEES at every frame (2 dof; 95 % band 0.05–7.38); \"final\" is the phase below 2 km. \"Offset NEES\" scores each odometry offset against the truth displacement under its own covariance (2 if its σ is right).\n"
    )?;
    writeln!(md, "{DESCENT_TABLE_HEAD}")?;
    let mut first = true;
    for (preset, map_label) in DESCENT_MAPS {
        let (dem, tile) = (w(&format!("{preset}16.tif")), w(&format!("{preset}16-ref")));
        go(&[
            "terrain",
            "--preset",
            preset,
            "--seed",
            &seed,
            "--size-m",
            "16000",
            "--pixel-m",
            "10",
            "--out",
            &dem,
        ])?;
        go(&["tile", "--dem", &dem, "--out", &tile])?;
        for (label, vel) in [
            ("TRN + odometry + velocimeter", true),
            ("TRN + odometry", false),
        ] {
            for hazard in [true, false] {
                let tag = format!(
                    "{preset}-{}-{}",
                    if vel { "vel" } else { "novel" },
                    if hazard { "hz" } else { "blind" }
                );
                let json = w(&format!("descent-{tag}.json"));
                let runs = a.runs.to_string();
                let mut v = vec![
                    "descent", "--tile", &tile, "--dem", &dem, "--runs", &runs, "--seed", &seed,
                    "--json", &json,
                ];
                // Pictures of the first map's first campaign only: the others read alike.
                let png = w(&format!("descent-{tag}"));
                if first {
                    v.extend(["--png", &png]);
                    first = false;
                }
                if !vel {
                    v.push("--no-velocimeter");
                }
                if !hazard {
                    v.push("--no-hazard-avoidance");
                }
                go(&v)?;
                // The first campaign's hazard and confirmation maps, shown in
                // docs/registration.md.
                if v.contains(&"--png") {
                    for (from, to) in [
                        ("descent-hazard.png", "descent-hazard-lola.png"),
                        ("descent-confirm.png", "descent-confirm-lola.png"),
                    ] {
                        let src = Path::new(&png).join(from);
                        if src.exists() {
                            std::fs::create_dir_all(&a.img)?;
                            std::fs::copy(&src, a.img.join(to))
                                .with_context(|| format!("copying {}", src.display()))?;
                        }
                    }
                }
                let d = read(Path::new(&json))?;
                writeln!(md, "{}", descent_row(map_label, label, hazard, &d))?;
            }
        }
    }
    writeln!(
        md,
        "\nBefore keyframe odometry (session 11) the last ~80 s below 2 km were unaided by TRN and, without a velocimeter, landing errors reached p95 9.7–21.4 m on these maps (30 runs each, same seeds).\n"
    )?;
    insar_descent_section(&mut md, a, &go)?;
    writeln!(
        md,
        "Pictures of the runs (match pictures, trajectories, error envelopes) are in `{}`.\n",
        a.work.display()
    )?;
    writeln!(md, "_Generated in {:.0} s._", t0.elapsed().as_secs_f64())?;
    super::ensure_parent(&a.out)?;
    std::fs::write(&a.out, md).with_context(|| format!("writing {}", a.out.display()))?;
    println!("\nwrote {}", a.out.display());
    Ok(())
}

/// The 16 km descent maps: suite preset and the label the tables give it. The InSAR descents
/// fly the same scenes (made by the truth descents' section first).
const DESCENT_MAPS: [(&str, &str); 3] = [
    ("lola", "LOLA-calibrated"),
    ("shoemaker", "Shoemaker-like floor"),
    ("plains", "smooth plains"),
];

/// The sentence that says what the comparison rows of the InSAR descents flew: every descent
/// map again with the radar's 32 m pair alone (`insar --long-baseline-m 0`), the default
/// radar before session 49, so that what the second pair buys stands beside it.
fn short_pair_words() -> String {
    format!(
        " The rows marked \"32 m pair alone\" fly the same maps made without the default radar's second pair (`insar --long-baseline-m 0`: half the SAR time; the default until session 49). The default's second pair is a second satellite in formation, {} m from the first antenna; each look's heights come from its interferogram wherever it agrees with the 32 m one and claims a smaller bound (docs/insar.md, \"A second, longer baseline\").",
        ground_sim::sar::MISSION_LONG_BASELINE_M
    )
}

/// Header of every descent table, matching [`descent_row`]'s columns.
const DESCENT_TABLE_HEAD: &str = "| map | aiding | hazard avoidance | runs | landing error p50 / p95 / max (m) | safe touchdowns | … where ≥ 50 % of the ground within 30 m of the target is safe (runs) | ground within 10 m of the targets safe | site from target p50 / p95 (m) | nav error RMS (m) | nav error at touchdown p95 (m) | fixes / offsets accepted | offset NEES mean | NEES in 95 % band (all / final) | mean NEES |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|";

/// The default radar in words, for the sections whose maps `insar` makes with it.
fn default_radar_words() -> String {
    let preset = ground_sim::sar::RadarPreset::default();
    format!(
        "{}, a second {} m pair fused in",
        ground_sim::evaluation::suite::radar_words(
            &preset.config(),
            ground_sim::insar::pipeline::LookDirections::of_preset(preset),
            1,
        ),
        preset.long_baseline_m()
    )
}

/// Descents over InSAR maps of the same 16 km scenes (the default radar, hazard avoidance on):
/// the product the flyer flies against, where the map's own error reaches the touchdown.
fn insar_descent_section(
    md: &mut String,
    a: &Args,
    go: &dyn Fn(&[&str]) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let w = |s: &str| a.work.join(s).to_string_lossy().into_owned();
    let seed = a.seed.to_string();
    writeln!(md, "### The same descents over InSAR maps\n")?;
    writeln!(
        md,
        "The same 16 km scenes, hops and seeds, the tile now made by `ground-sim insar` from each scene (the default radar: {}, radar seed {seed}), hazard avoidance on. Frames still come from the truth DEM. Here the map's own error (its height noise, and the blobs it puts a little off where the frames find them) moves every fix near the target alike, so the flyer carries it to the ground: the landing error to the spot aimed at stays small (the hazard map and the odometry are the flyer's own frames), while the navigation error at touchdown is the distance from the intended target's ground.{}\n",
        default_radar_words(),
        short_pair_words()
    )?;
    writeln!(md, "{DESCENT_TABLE_HEAD}")?;
    let mut verdicts = Vec::new();
    let mut maps = Vec::new();
    // The default radar's maps first, then each again with the 32 m pair alone.
    let default = DESCENT_MAPS.iter().map(|&(p, l)| (p, l, false));
    let short = DESCENT_MAPS.iter().map(|&(p, l)| (p, l, true));
    for (preset, map_label, short_pair) in default.chain(short) {
        let (map_label, stack) = if short_pair {
            (format!("{map_label}, InSAR, 32 m pair alone"), "-short")
        } else {
            (format!("{map_label}, InSAR"), "")
        };
        let map_label = map_label.as_str();
        let dem = w(&format!("{preset}16.tif"));
        let tile = w(&format!("{preset}16-insar{stack}"));
        let mut v = vec![
            "insar",
            "--dem",
            &dem,
            "--out",
            &tile,
            "--seed",
            &seed,
            "--no-progress",
        ];
        if short_pair {
            v.extend(["--long-baseline-m", "0"]);
        }
        go(&v)?;
        let r = read(&Path::new(&tile).join("report.json"))?;
        maps.push(format!(
            "{map_label}: height RMSE {} m (CRLB {} m), slope RMSE {}°, {} tile features ({} of them ground)",
            f(&r, "height_rmse_m", 2),
            f(&r, "crlb_height_m", 2),
            f(&r, "slope_rmse_deg", 2),
            r["tile_features"],
            r["tile_features_on_truth"]
        ));
        for (label, vel, bar_m) in [
            ("TRN + odometry + velocimeter", true, 3.0),
            ("TRN + odometry", false, 5.0),
        ] {
            let tag = format!(
                "{preset}-insar{stack}-{}",
                if vel { "vel" } else { "novel" }
            );
            let json = w(&format!("descent-{tag}.json"));
            let runs = a.runs.to_string();
            let mut v = vec![
                "descent", "--tile", &tile, "--dem", &dem, "--runs", &runs, "--seed", &seed,
                "--json", &json,
            ];
            if !vel {
                v.push("--no-velocimeter");
            }
            go(&v)?;
            let d = read(Path::new(&json))?;
            writeln!(md, "{}", descent_row(map_label, label, true, &d))?;
            // The bars on the error from the intended target: 3 m with a velocimeter,
            // 5 m without; said per row, met or not.
            if let Some(e) = d["nav_err_at_landing_p95_m"].as_f64() {
                verdicts.push(format!(
                    "{map_label} ({label}): {e:.2} m against {bar_m} m, {}",
                    if e <= bar_m { "met" } else { "**missed**" }
                ));
            }
        }
    }
    writeln!(
        md,
        "\nNavigation error at touchdown (p95) against the bars on the error from the intended target (3 m with a velocimeter, 5 m without): {}.\n",
        verdicts.join("; ")
    )?;
    writeln!(md, "The maps: {}.\n", maps.join("; "))?;
    Ok(())
}

/// One row of a descent table from a `descent` summary JSON `d`: the map, the aiding, whether
/// hazard avoidance flew, then landing, safety, navigation and NEES figures.
fn descent_row(map_label: &str, label: &str, hazard: bool, d: &Value) -> String {
    let pct = |k: &str| {
        d[k].as_f64()
            .map_or("–".into(), |x| format!("{:.1} %", 100.0 * x))
    };
    format!(
        "| {map_label} | {label} | {} | {} | {} / {} / {} | {} | {} ({}) | {} | {} | {} | {} | {} / {} | {} | {} / {} | {} |",
        if hazard { "yes" } else { "no" },
        d["runs"],
        f(d, "landing_err_p50_m", 2),
        f(d, "landing_err_p95_m", 2),
        f(d, "landing_err_max_m", 2),
        {
            // Where the unsafe touchdowns came from: a spot the map passed that the
            // truth calls unsafe, or a safe spot the lander missed.
            let (m, d) = (
                d["unsafe_on_unsafe_site"].as_u64().unwrap_or(0),
                d["unsafe_on_safe_site"].as_u64().unwrap_or(0),
            );
            let safe = pct("safe_landing_frac");
            if hazard && m + d > 0 {
                format!("{safe} ({m} on an unsafe spot, {d} off a safe one)")
            } else {
                safe
            }
        },
        pct("open_zone_safe_frac"),
        d["open_zone_runs"],
        pct("target_area_safe_frac"),
        if hazard {
            format!(
                "{} / {}",
                f(d, "site_from_target_p50_m", 1),
                f(d, "site_from_target_p95_m", 1)
            )
        } else {
            "–".into()
        },
        f(d, "nav_err_rms_m", 2),
        f(d, "nav_err_at_landing_p95_m", 2),
        d["fixes"],
        d["odometry_fixes"],
        f(d, "offset_nees_mean", 2),
        pct("nees_in_band_frac"),
        pct("final_nees_in_band_frac"),
        f(d, "nees_mean", 2)
    )
}

/// The paper's setting: reference tiles from the simulated InSAR of each preset
/// (`ground-sim insar` with the default radar, the noisy mission design), the Fig. 7 cases
/// and an `eval` campaign against them.
fn insar_section(
    md: &mut String,
    a: &Args,
    go: &dyn Fn(&[&str]) -> anyhow::Result<()>,
    cases: &[(&str, f64)],
) -> anyhow::Result<()> {
    let w = |s: &str| a.work.join(s).to_string_lossy().into_owned();
    let seed = a.seed.to_string();
    writeln!(md, "\n## Against the InSAR reference (the product)\n")?;
    writeln!(
        md,
        "Each preset through `ground-sim insar` (SAR echoes, focusing, interferogram, DEM at 20 m, tile with 50 m terrain smoothing (`ground_sim::reference::INSAR_SMOOTHING_M`) and the detector threshold of every tile, twice the sensor's noise floor (`ground_sim::reference::noise_floor`); the default radar: {}, radar seed {seed}), then the Fig. 7 frames and an `eval` campaign (same seed and frames as above) against that tile. Frames still come from the truth DEM, as the flyer's sensor sees the real terrain. The paper's noise-free radar (`--radar paper`) is flown over the suite's scenes in the suite section.\n",
        default_radar_words()
    )?;
    let mut dem_rows = String::new();
    let mut case_rows = String::new();
    let mut eval_rows = String::new();
    for preset in ["shoemaker", "shackleton"] {
        let dir = w(&format!("{preset}-insar"));
        go(&[
            "insar",
            "--dem",
            &w(&format!("{preset}.tif")),
            "--out",
            &dir,
            "--seed",
            &seed,
            "--no-progress",
        ])?;
        let r = read(&Path::new(&dir).join("report.json"))?;
        writeln!(
            dem_rows,
            "| {preset} | {} / {} | {} | {} | {} % | {} |",
            f(&r, "height_rmse_m", 2),
            f(&r, "height_bias_m", 2),
            f(&r, "crlb_height_m", 2),
            f(&r, "slope_rmse_deg", 2),
            r["valid_fraction"]
                .as_f64()
                .map_or("–".into(), |x| format!("{:.2}", 100.0 * x)),
            r["tile_features"]
        )?;
        for &(_, rot) in cases.iter().filter(|(p, _)| *p == preset) {
            let t = trn_case(
                go,
                &seed,
                &dir,
                &w(&format!("{preset}.tif")),
                rot,
                &w(&format!("trn-insar-{preset}-{rot}")),
                None,
            )?;
            let row = format!("| {preset} | {rot}° | {} |", case_cells(&t));
            writeln!(case_rows, "{row}")?;
        }
        let row = eval_row(
            a,
            go,
            &format!("{preset} (InSAR tile)"),
            &dir,
            &w(&format!("{preset}.tif")),
            &w(&format!("eval-insar-{preset}.json")),
        )?;
        writeln!(eval_rows, "{row}")?;
    }
    writeln!(
        md,
        "| preset | height RMSE / bias (m) | CRLB (m) | slope RMSE (°) | valid | tile features |\n|---|---|---|---|---|---|\n{dem_rows}"
    )?;
    writeln!(
        md,
        "| scene | rotation | matches | inliers | φ̂ (°) | ŝ | max / mean reg. error (ref px) | position error (m) |\n|---|---|---|---|---|---|---|---|\n{case_rows}"
    )?;
    writeln!(
        md,
        "| preset | trials | success | false fix | no fix | position p50 / p95 (m) | heading p95 / max (°) | scale error p95 | fixes within 3σ | onboard ms/frame (host) | issue 7 bars |\n|---|---|---|---|---|---|---|---|---|---|---|\n{eval_rows}"
    )?;
    Ok(())
}

/// The same four frames registered by OpenCV SIFT and ORB (tools/opencv_compare.py in its own
/// Python environment, made by tools/setup-opencv.sh), beside nav-core.
fn opencv_section(md: &mut String, a: &Args, cases: &[(&str, f64)]) -> anyhow::Result<()> {
    writeln!(md, "## The same frames with OpenCV SIFT and ORB\n")?;
    let python = std::env::var("UMBRA_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|_| PathBuf::from("tools/.venv/bin/python"));
    if !python.exists() {
        writeln!(
            md,
            "Skipped: no OpenCV environment at `{}` (run `tools/setup-opencv.sh`, or set `UMBRA_PYTHON`).\n",
            python.display()
        )?;
        println!("opencv comparison skipped: {} not found", python.display());
        return Ok(());
    }
    let out = a.work.join("opencv.json");
    let dirs: Vec<String> = cases
        .iter()
        .map(|(p, r)| {
            a.work
                .join(format!("case-{p}-{r}"))
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let status = std::process::Command::new(&python)
        .arg("tools/opencv_compare.py")
        .arg(&out)
        .args(&dirs)
        .status()
        .context("running tools/opencv_compare.py")?;
    if !status.success() {
        anyhow::bail!("tools/opencv_compare.py failed");
    }
    let v = read(&out)?;
    writeln!(
        md,
        "Same exported frames and references (`ground-sim trn --export`), 8-bit slope images for OpenCV {}; Lowe ratio 0.8, RANSAC similarity (`estimateAffinePartial2D`, 3 px). nav-core's row is the table above; times are this host's, single frame, detection + matching + estimation.\n",
        v["opencv"].as_str().unwrap_or("?")
    )?;
    writeln!(
        md,
        "| scene | rotation | method | matches | inliers | heading error (°) | mean / max reg. error (ref px) | centre error (ref px) | ms |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|")?;
    for (p, r) in cases {
        let t = read(&a.work.join(format!("trn-{p}-{r}.json")))?;
        writeln!(
            md,
            "| {p} | {r}° | nav-core | {} | {} | {} | {} / {} | {} | {} |",
            t["matches"],
            t["inliers"],
            f(&t, "heading_err_deg", 3),
            f(&t, "pos_err_mean_px", 2),
            f(&t, "pos_err_max_px", 2),
            f(&t, "center_err_px", 2),
            f(&t, "time_ms", 1)
        )?;
        let case = a
            .work
            .join(format!("case-{p}-{r}"))
            .to_string_lossy()
            .into_owned();
        for row in v["results"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|x| x["case"].as_str() == Some(case.as_str()))
        {
            writeln!(
                md,
                "| {p} | {r}° | {} | {} | {} | {} | {} / {} | {} | {} |",
                row["method"].as_str().unwrap_or("?"),
                row["matches"],
                row.get("inliers").unwrap_or(&Value::Null),
                f(row, "heading_err_deg", 3),
                f(row, "pos_err_mean_px", 2),
                f(row, "pos_err_max_px", 2),
                f(row, "center_err_px", 2),
                f(row, "time_ms", 1)
            )?;
        }
    }
    writeln!(md)?;
    Ok(())
}
