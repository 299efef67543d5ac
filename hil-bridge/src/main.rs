//! `hil-bridge`: generate the recorded frame set, or run it through the firmware under QEMU.
//!
//! ```text
//! cargo run --release -p hil-bridge -- gen
//! cargo run --release -p hil-bridge -- run [--frames N] [--json OUT] [--budget INSNS]
//! cargo run --release -p hil-bridge -- run --terrain plains   # the set cut from other ground
//! ```

use anyhow::{Result, bail};
use clap::{Parser, Subcommand};
use hil_bridge::host::frames::{SetTerrain, generate_set_on};
use hil_bridge::host::runner::{INSTRUCTION_BUDGET, RunOptions, STATIC_RAM_BUDGET, run};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    version,
    about = "Umbra hardware-in-the-loop: nav-core firmware under QEMU"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Write the recorded frame set (tile, frames, truth) to target/hil/data (another terrain's
    /// to target/hil/data-LABEL).
    Gen {
        /// Terrain frames (five stress frames follow them).
        #[arg(long, default_value_t = 18)]
        terrain_frames: usize,
        /// Terrain `PRESET[:WINDOW[:SEED]]` (e.g. `plains`, `fresh:rim`); another terrain than
        /// the recorded set's is written to `target/hil/data-LABEL`.
        #[arg(long, value_parser = SetTerrain::parse)]
        terrain: Option<SetTerrain>,
    },
    /// Write a recorded host → target session (hello, the first N frames, shutdown) that the
    /// firmware can replay without a host: `cargo run` in `hil-bridge/firmware` does.
    Record {
        /// Frames to record.
        #[arg(long, default_value_t = 3)]
        frames: usize,
        /// Output file.
        #[arg(long, default_value = "target/hil/replay/hil-link.rx")]
        out: PathBuf,
    },
    /// Decode and print a target → host byte stream (e.g. the replay's `hil-link.tx`).
    Decode {
        /// The stream.
        file: PathBuf,
    },
    /// Print a digest of nav-core's host results on every frame of the set (one line per frame):
    /// a change of any output bit changes the digest, so optimisations can be checked exactly.
    Digest {
        /// The set cut from this terrain, `PRESET[:WINDOW[:SEED]]` (as for `run`).
        #[arg(long, value_parser = SetTerrain::parse)]
        terrain: Option<SetTerrain>,
    },
    /// Build the firmware, run every frame through it under QEMU, compare with the host.
    Run {
        /// Send at most N frames (the stress frames are kept).
        #[arg(long)]
        frames: Option<usize>,
        /// Only frames whose name contains this.
        #[arg(long)]
        only: Option<String>,
        /// Write the report here as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// QEMU machine: mps2-an386 (Cortex-M4) or mps2-an500 (Cortex-M7).
        #[arg(long, default_value = "mps2-an386")]
        machine: String,
        /// Link transport: `semihosting` (FIFOs, fast) or `uart` (the board's serial port,
        /// ≈ 10 KiB/s under QEMU: about 16 s per frame).
        #[arg(long, default_value = "semihosting")]
        link: String,
        /// Do not inject link faults.
        #[arg(long)]
        no_faults: bool,
        /// Regenerate the frame set first.
        #[arg(long)]
        regen: bool,
        /// Run the set cut from this terrain, `PRESET[:WINDOW[:SEED]]` (e.g. `plains`,
        /// `fresh:rim`), generated into its own folder and linked into the firmware: checks the
        /// counts and the work model on other ground than the recorded set's Shoemaker floor.
        #[arg(long, value_parser = SetTerrain::parse)]
        terrain: Option<SetTerrain>,
        /// Fail if any frame costs more instructions than this.
        #[arg(long, default_value_t = INSTRUCTION_BUDGET)]
        budget: u64,
    },
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("."))
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.cmd {
        Cmd::Gen {
            terrain_frames,
            terrain,
        } => {
            let mut opts = RunOptions::new(root());
            opts.terrain = terrain.unwrap_or(SetTerrain::DEFAULT);
            let set = generate_set_on(opts.terrain, terrain_frames)?;
            set.write(&opts.data_dir())?;
            eprintln!(
                "wrote {} frames and a {}-byte tile to {}",
                set.frames.len(),
                set.tile.len(),
                opts.data_dir().display()
            );
        }
        Cmd::Record { frames, out } => {
            let opts = RunOptions::new(root());
            let set = hil_bridge::host::runner::load_or_generate(&opts)?;
            let frames: Vec<_> = set.frames.iter().take(frames).collect();
            let bytes = hil_bridge::host::runner::record_session(&frames)?;
            let out = if out.is_relative() {
                root().join(out)
            } else {
                out
            };
            if let Some(dir) = out.parent() {
                std::fs::create_dir_all(dir)?;
            }
            std::fs::write(&out, &bytes)?;
            eprintln!(
                "recorded {} frames ({} bytes) to {}",
                frames.len(),
                bytes.len(),
                out.display()
            );
        }
        Cmd::Decode { file } => {
            let bytes = std::fs::read(&file)?;
            let mut rx = hil_bridge::Receiver::new();
            for b in bytes {
                match rx.push(b) {
                    hil_bridge::Received::Pending => {}
                    hil_bridge::Received::Packet(seq, m) => println!("{seq:>5} {m:?}"),
                    hil_bridge::Received::Error(e) => println!("  bad packet: {e}"),
                }
            }
        }
        Cmd::Digest { terrain } => {
            let mut opts = RunOptions::new(root());
            opts.terrain = terrain.unwrap_or(SetTerrain::DEFAULT);
            let set = hil_bridge::host::runner::load_or_generate(&opts)?;
            let tile = nav_core::Tile::parse(&set.tile).map_err(|e| anyhow::anyhow!("{e}"))?;
            let nav = nav_core::Navigator::new(tile, nav_core::NavConfig::default());
            let atlas = Box::new(
                hil_bridge::job::Atlas::new(&set.atlas).map_err(|e| anyhow::anyhow!("{e}"))?,
            );
            let mut ws = Box::new(hil_bridge::host::runner::Workspace::new());
            let mut fp: Box<hil_bridge::job::FinalPhase> = Box::default();
            for f in &set.frames {
                let r =
                    hil_bridge::host::runner::host_result(&nav, Some(&atlas), &mut ws, &mut fp, f);
                let mut bytes = postcard::to_stdvec(&r)?;
                for ft in ws.features().as_slice() {
                    let k = &ft.keypoint;
                    for v in [k.x_px, k.y_px, k.scale_px, k.orientation_rad, k.response] {
                        bytes.extend_from_slice(&v.to_le_bytes());
                    }
                    bytes.push(k.laplacian_positive as u8);
                    ft.descriptor
                        .iter()
                        .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
                }
                for m in ws.matches() {
                    bytes.extend_from_slice(&m.frame.to_le_bytes());
                    bytes.extend_from_slice(&m.tile.to_le_bytes());
                    bytes.extend_from_slice(&m.ssd.to_le_bytes());
                }
                let h = bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
                    (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
                });
                println!("{:>3} {:<26} {h:016x}", f.meta.id, f.meta.name);
            }
        }
        Cmd::Run {
            frames,
            only,
            json,
            machine,
            link,
            no_faults,
            regen,
            terrain,
            budget,
        } => {
            let mut opts = RunOptions::new(root());
            opts.terrain = terrain.unwrap_or(SetTerrain::DEFAULT);
            opts.frames = frames;
            opts.only = only;
            opts.machine = machine;
            opts.faults = !no_faults;
            opts.uart = match link.as_str() {
                "uart" => true,
                "semihosting" => false,
                other => bail!("unknown link {other}: semihosting or uart"),
            };
            opts.regenerate = regen;
            let report = run(&opts)?;
            if let Some(path) = json {
                if let Some(dir) = path.parent() {
                    std::fs::create_dir_all(dir)?;
                }
                std::fs::write(&path, serde_json::to_string_pretty(&report)?)?;
                eprintln!("report: {}", path.display());
            }
            let mut failures = Vec::new();
            if report.bit_exact_frames != report.frames {
                failures.push(format!(
                    "{} of {} frames differ between target and host",
                    report.frames - report.bit_exact_frames,
                    report.frames
                ));
            }
            if report.max_instructions_per_frame > budget {
                failures.push(format!(
                    "worst frame costs {} instructions, budget {budget}",
                    report.max_instructions_per_frame
                ));
            }
            // The work model the navigator meters its frames with (and bounds them by) must
            // track the measured counts, and no frame's work may pass the budget.
            let (lo, hi) = nav_core::cost::HIL_RATIO_BOUNDS;
            let work_budget = u64::from(nav_core::NavConfig::default().work_budget);
            for f in &report.per_frame {
                if let Some(e) = f.estimated_instructions {
                    let ratio = e as f64 / f.instructions.max(1) as f64;
                    if !(lo..=hi).contains(&ratio) {
                        failures.push(format!(
                            "{}: the work model estimates {e} instructions, measured {} \
                             (ratio {ratio:.3}, bounds {lo}–{hi}): recalibrate nav_core::cost",
                            f.name, f.instructions
                        ));
                    }
                    if e > work_budget {
                        failures.push(format!(
                            "{}: the navigator metered {e} work units, budget {work_budget}",
                            f.name
                        ));
                    }
                }
            }
            if report.static_ram_bytes > STATIC_RAM_BUDGET {
                failures.push(format!(
                    "static RAM {} B exceeds {STATIC_RAM_BUDGET} B",
                    report.static_ram_bytes
                ));
            }
            if !failures.is_empty() {
                bail!("{}", failures.join("; "));
            }
        }
    }
    Ok(())
}
