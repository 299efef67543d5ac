//! `ground-sim` command-line interface.

use clap::{Parser, Subcommand};
use ground_sim::sar::cli::{PsfArgs, SarArgs, run_psf, run_sar};

/// Umbra ground segment.
#[derive(Debug, Parser)]
#[command(name = "ground-sim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Commands,
}

#[derive(Debug, Subcommand)]
enum Commands {
    /// Simulate dual-antenna SAR echoes over a DEM and focus them into SLCs.
    Sar(SarArgs),
    /// Point-target analysis (IRW, PSLR, ISLR, peak location, interferometric phase).
    Psf(PsfArgs),
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Commands::Sar(a) => run_sar(a),
        Commands::Psf(a) => run_psf(a),
    }
}
