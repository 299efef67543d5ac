//! `ground-sim` command-line interface: terrain in and out, pictures and statistics.
//!
//! Subcommands live in `src/cli/`, one file each; `Commands` below lists them.

mod cli;

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use ground_sim::sar::cli::{PsfArgs, SarArgs, run_psf, run_sar};

/// Umbra ground segment: lunar terrain, SAR/InSAR simulation, reference tiles, TRN evaluation.
#[derive(Debug, Parser)]
#[command(name = "ground-sim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Commands,
}

#[derive(Debug, Subcommand)]
enum Commands {
    /// Generate a synthetic lunar terrain preset as a GeoTIFF DEM (and pictures).
    Terrain(cli::terrain::Args),
    /// A fine truth DEM around a landing target (rocks, small craters, sub-metre roughness)
    /// over a coarse scene, with its truth safety map: GeoTIFF, PNG, JSON.
    LandingZone(cli::landing::Args),
    /// How often the onboard hazard map calls a site safe that the truth calls unsafe, per
    /// relief threshold, over landing zones of several presets and seeds: table and JSON.
    HazardCalibrate(cli::hazard_calibrate::Args),
    /// Size, georeferencing, elevation and slope statistics of a DEM.
    Info(cli::info::Args),
    /// Resample a DEM to another pixel size and/or crop it by map coordinates.
    Resample(cli::resample::Args),
    /// Register a frame image against a reference image with the onboard chain (SURF, matching,
    /// MSAC, pose) and report rotation, scale, affine and position.
    Register(cli::register::Args),
    /// Build a reference folder (tile.bin, slope.tif) straight from a DEM.
    Tile(cli::tile::Args),
    /// One synthetic flyer frame against a reference tile, scored against the truth.
    Trn(cli::trn::Args),
    /// Monte-Carlo campaign of frames at random poses against a reference tile.
    Eval(cli::eval::Args),
    /// Campaign of closed-loop hops: dynamics, IMU, TRN fixes, nav filter, guidance.
    Descent(cli::descent::Args),
    /// Cut a reference tile's map into a flight atlas: overlapping tiles of bounded size plus
    /// an index, as the flyer reads it.
    Atlas(cli::atlas::Args),
    /// Join the shard files of one `eval` or `descent` campaign (`--shard I/N`) into the summary,
    /// CSV and pictures the unsharded command writes.
    Merge(cli::merge::Args),
    /// The terrain suite: every scene × {truth-built, InSAR tile} × {no prior, prior} as eval
    /// campaigns, with the navigability map scored; one table, one picture, JSON.
    Suite(cli::suite::Args),
    /// Radar design trade: thermal noise × baseline × look directions → CRLB, measured DEM
    /// accuracy, tile features and TRN success per point; JSON, table, picture.
    Trade(cli::trade::Args),
    /// Navigability map of a reference folder: where a frame is predicted to get a fix.
    Navmap(cli::navmap::Args),
    /// Regenerate docs/results.md from fresh runs (paper cases, campaigns, descents).
    Results(cli::results::Args),
    /// Simulate dual-antenna SAR echoes over a DEM and focus them into SLCs.
    Sar(SarArgs),
    /// DEM from the interferogram: SAR (or given SLCs) → InSAR DEM, slope, mask, reference tile,
    /// pictures and report.json, compared with the input DEM.
    Insar(cli::insar::Args),
    /// Point-target analysis (IRW, PSLR, ISLR, peak location, interferometric phase).
    Psf(PsfArgs),
    /// The whole ground chain on the shackleton preset: terrain → SAR → InSAR → reference tile →
    /// one TRN check, with a summary table.
    Demo(cli::demo::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match dispatch(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Run one parsed command line.
fn dispatch(cli: Cli) -> anyhow::Result<()> {
    match &cli.command {
        Commands::Terrain(a) => cli::terrain::run(a),
        Commands::LandingZone(a) => cli::landing::run(a),
        Commands::HazardCalibrate(a) => cli::hazard_calibrate::run(a),
        Commands::Info(a) => cli::info::run(a),
        Commands::Resample(a) => cli::resample::run(a),
        Commands::Demo(a) => cli::demo::run(a),
        Commands::Register(a) => cli::register::run(a),
        Commands::Tile(a) => cli::tile::run(a),
        Commands::Trn(a) => cli::trn::run(a),
        Commands::Eval(a) => cli::eval::run(a),
        Commands::Descent(a) => cli::descent::run(a),
        Commands::Atlas(a) => cli::atlas::run(a),
        Commands::Merge(a) => cli::merge::run(a),
        Commands::Suite(a) => cli::suite::run(a),
        Commands::Navmap(a) => cli::navmap::run(a),
        Commands::Trade(a) => cli::trade::run(a),
        Commands::Sar(a) => run_sar(a.clone()),
        Commands::Insar(a) => cli::insar::run(a),
        Commands::Psf(a) => run_psf(a.clone()),
        Commands::Results(a) => cli::results::run(a, &|args| dispatch(Cli::try_parse_from(args)?)),
    }
}
