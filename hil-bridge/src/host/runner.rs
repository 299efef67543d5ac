//! The HIL runner: builds the instruction-counting plugin and the firmware, starts QEMU with the
//! link on two FIFOs, streams the frames with fault injection, compares every result bit for bit
//! with nav-core on the host, and reports.

use super::frames::{Frame, FrameSet, SetTerrain};
use super::link::{Fault, HostCounters, HostLink, Incoming, spawn_reader};
use crate::convert;
use crate::job::{Atlas, FinalPhase};
use crate::msg::{
    FrameChunk, FrameCost, FrameHeader, FrameJob, FrameResult, Hello, Message, SampleFormat,
    Status, WireAimDecision, WireHazard, WireOutcome,
};
use crate::packet::MAX_CHUNK_BYTES;
use crate::target::payload_crc;
use anyhow::{Context, Result, bail};
use nav_core::atlas::TileSource;
use nav_core::{NavConfig, Navigator, Tile};
use object::{Object, ObjectSection, ObjectSymbol};
use serde::Serialize;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The bound on instructions per 200 × 200 frame.
pub const INSTRUCTION_BUDGET: u64 = 20_000_000;
/// The bound on static RAM, bytes.
pub const STATIC_RAM_BUDGET: u64 = 512 * 1024;

pub use crate::flight::Workspace;

/// Run settings.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Repository root.
    pub root: PathBuf,
    /// Use at most this many TRN frames of the set (stress frames are always kept at the end);
    /// the final-phase chain runs whole in any case.
    pub frames: Option<usize>,
    /// QEMU machine: `mps2-an386` (Cortex-M4) or `mps2-an500` (Cortex-M7).
    pub machine: String,
    /// Only frames whose name contains this.
    pub only: Option<String>,
    /// Inject link faults.
    pub faults: bool,
    /// Carry the link over the board's UART (≈ 10 KiB/s under QEMU) instead of semihosting FIFOs.
    pub uart: bool,
    /// Regenerate the frame set even if one is on disk.
    pub regenerate: bool,
    /// Print progress.
    pub progress: bool,
    /// The terrain the set is cut from (the recorded set's by default; any other lives in its
    /// own folder, `target/hil/data-LABEL`).
    pub terrain: SetTerrain,
}

impl RunOptions {
    /// Defaults for the repository at `root`.
    pub fn new(root: PathBuf) -> Self {
        Self {
            root,
            frames: None,
            only: None,
            machine: "mps2-an386".into(),
            faults: true,
            uart: false,
            regenerate: false,
            progress: true,
            terrain: SetTerrain::DEFAULT,
        }
    }
    fn work_dir(&self) -> PathBuf {
        self.root.join("target/hil")
    }
    /// Where the recorded frame set lives.
    pub fn data_dir(&self) -> PathBuf {
        if self.terrain == SetTerrain::DEFAULT {
            self.work_dir().join("data")
        } else {
            self.work_dir()
                .join(format!("data-{}", self.terrain.label()))
        }
    }
}

/// One frame's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRecord {
    /// Frame id.
    pub id: u32,
    /// Name.
    pub name: String,
    /// Outcome on the target: `fix`, a no-fix reason or a refusal.
    pub outcome: String,
    /// Inliers (0 without a fix).
    pub inliers: u16,
    /// Frame features.
    pub features: u16,
    /// Putative matches.
    pub matches: u16,
    /// MSAC samples drawn.
    pub msac_iterations: u16,
    /// Target result equals the host's bit for bit.
    pub bit_exact: bool,
    /// Instructions executed by the navigator call (TCG plugin).
    pub instructions: u64,
    /// SysTick cycles reported by the target.
    pub timer_cycles: u32,
    /// Peak stack use so far, bytes.
    pub stack_peak_bytes: u32,
    /// Position error of a fix against truth, tile pixels.
    pub position_error_px: Option<f64>,
    /// Heading error of a fix against truth, degrees.
    pub heading_error_deg: Option<f64>,
    /// Link fault injected into this frame's packets, if any.
    pub fault: Option<Fault>,
    /// The job: `locate`, `keyframe`, `odometry` or `hazard`.
    pub job: String,
    /// Odometry: error of the displacement against the truth, metres.
    pub offset_error_m: Option<f64>,
    /// Odometry: the displacement's 1σ (largest axis), metres.
    pub offset_sigma_m: Option<f64>,
    /// Hazard map: sites judged and the safe fraction.
    pub hazard_sites: Option<u32>,
    /// Hazard map: fraction of the sites judged safe.
    pub hazard_safe_frac: Option<f64>,
    /// Hazard map: the aim's distance from the target after the decision, metres (0: the aim
    /// on the target was kept; null: no site within reach).
    pub site_from_target_m: Option<f32>,
    /// Atlas frames: the tile the result comes from.
    pub atlas_tile: Option<u16>,
    /// Atlas frames: tiles located on.
    pub atlas_tried: Option<u8>,
    /// TRN frames (on the tile or the atlas): the work the navigator metered for the frame
    /// (`FrameReport::work`, estimated instructions, `nav_core::cost`), to compare with
    /// `instructions`.
    pub estimated_instructions: Option<u64>,
}

/// The run's report (written as JSON).
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The terrain the frame set was cut from (`preset-window-seed`).
    pub terrain: String,
    /// Frames sent.
    pub frames: usize,
    /// Frames with a fix.
    pub fixes: usize,
    /// Frames whose target result equals the host's bit for bit.
    pub bit_exact_frames: usize,
    /// Worst-case instructions per frame.
    pub max_instructions_per_frame: u64,
    /// Mean instructions per frame.
    pub mean_instructions_per_frame: f64,
    /// The bound asserted, instructions per frame.
    pub instruction_budget: u64,
    /// `.data` + `.bss` + `.uninit` of the firmware, bytes.
    pub static_ram_bytes: u64,
    /// Flash image (vector table, code, read-only data, `.data` initialisers), bytes.
    pub flash_bytes: u64,
    /// Of the flash: the reference tile, bytes.
    pub tile_bytes: u64,
    /// Of the flash: the flight atlas (index and tiles), bytes.
    pub atlas_bytes: u64,
    /// Deepest stack use, bytes.
    pub stack_peak_bytes: u32,
    /// Link faults injected and recovered from.
    pub link_errors_recovered: u64,
    /// Link faults injected.
    pub link_errors_injected: u64,
    /// Host-side link counters.
    pub host_link: HostCounters,
    /// The target's final counters.
    pub target_status: Status,
    /// QEMU machine.
    pub machine: String,
    /// Wall time of the QEMU session, seconds.
    pub qemu_seconds: f64,
    /// Per frame.
    pub per_frame: Vec<FrameRecord>,
}

fn say(on: bool, msg: impl AsRef<str>) {
    if on {
        eprintln!("{}", msg.as_ref());
    }
}

/// Load the recorded frame set, generating it first if needed.
pub fn load_or_generate(opts: &RunOptions) -> Result<FrameSet> {
    let dir = opts.data_dir();
    // A set recorded by an older build (another tile format: the firmware would refuse its tile
    // and the compiler would drop the navigator with it) or with another tile smoothing is
    // regenerated, not reused.
    if !opts.regenerate
        && let Ok(set) = FrameSet::read(&dir)
        && nav_core::Tile::parse(&set.tile)
            .is_ok_and(|t| t.header().smoothing_m == super::frames::tile_smoothing_m() as f32)
        && Atlas::new(&set.atlas).is_ok()
    {
        return Ok(set);
    }
    say(
        opts.progress,
        format!("generating the frame set in {}", dir.display()),
    );
    let set = super::frames::generate_set_on(opts.terrain, 18)?;
    set.write(&dir)?;
    Ok(set)
}

/// Build the TCG plugin with gcc if it is missing or older than its source.
pub fn build_plugin(opts: &RunOptions) -> Result<PathBuf> {
    let src = opts.root.join("hil-bridge/plugin/umbra_icount.c");
    let hdr = opts.root.join("hil-bridge/plugin/qemu-plugin-v1.h");
    let out = opts.work_dir().join("libumbra_icount.so");
    let stale = |p: &Path| -> bool {
        let m = |q: &Path| fs::metadata(q).and_then(|m| m.modified()).ok();
        match (m(&out), m(p)) {
            (Some(o), Some(s)) => s > o,
            _ => true,
        }
    };
    if stale(&src) || stale(&hdr) {
        fs::create_dir_all(opts.work_dir())?;
        let st = Command::new("gcc")
            .args([
                "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror", "-o",
            ])
            .arg(&out)
            .arg(&src)
            .status()
            .context("running gcc (install it: apt-get install gcc)")?;
        if !st.success() {
            bail!("gcc failed to build the instruction-count plugin");
        }
    }
    Ok(out)
}

/// Build the firmware with the set's tile linked in; returns the ELF path.
pub fn build_firmware(opts: &RunOptions) -> Result<PathBuf> {
    let dir = opts.root.join("hil-bridge/firmware");
    let mut cmd = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    cmd.current_dir(&dir)
        .args(["build", "--release", "--quiet"])
        .args(if opts.uart {
            &["--features", "uart-link"][..]
        } else {
            &[][..]
        })
        .env("UMBRA_HIL_TILE", opts.data_dir().join("tile.bin"))
        .env("UMBRA_HIL_ATLAS", opts.data_dir().join("atlas.bin"));
    // Settings of an outer `cargo run` must not leak into the firmware build.
    for var in [
        "CARGO_TARGET_DIR",
        "RUSTFLAGS",
        "CARGO_BUILD_TARGET",
        "CARGO_ENCODED_RUSTFLAGS",
    ] {
        cmd.env_remove(var);
    }
    let st = cmd.status().context("running cargo for the firmware")?;
    if !st.success() {
        bail!("firmware build failed");
    }
    Ok(opts
        .root
        .join("target/firmware/thumbv7em-none-eabihf/release/umbra-hil-firmware"))
}

/// Firmware facts read from the ELF.
#[derive(Debug, Clone, Copy)]
pub struct ElfFacts {
    /// Address of `hil_frame_begin`.
    pub begin: u64,
    /// Address of `hil_frame_end`.
    pub end: u64,
    /// Static RAM, bytes.
    pub static_ram: u64,
    /// Flash, bytes.
    pub flash: u64,
}

/// Marker addresses and memory figures of the firmware ELF.
pub fn elf_facts(elf: &Path) -> Result<ElfFacts> {
    let data = fs::read(elf).with_context(|| format!("{}", elf.display()))?;
    let file = object::File::parse(&*data)?;
    let find = |needle: &str| -> Result<u64> {
        let hits: Vec<u64> = file
            .symbols()
            .filter(|s| s.name().is_ok_and(|n| n.contains(needle)) && s.size() > 0)
            .map(|s| s.address())
            .collect();
        match hits.as_slice() {
            [a] => Ok(*a),
            [] => bail!("marker {needle} not in the firmware"),
            _ => bail!("marker {needle} found {} times", hits.len()),
        }
    };
    let (mut ram, mut flash) = (0u64, 0u64);
    for s in file.sections() {
        let name = s.name().unwrap_or("");
        match name {
            ".data" => {
                ram += s.size();
                flash += s.size();
            }
            ".bss" | ".uninit" => ram += s.size(),
            ".vector_table" | ".text" | ".rodata" => flash += s.size(),
            _ => {}
        }
    }
    let begin = find("hil_frame_begin")?;
    let end = find("hil_frame_end")?;
    if begin == end {
        bail!("the two markers were merged by the linker");
    }
    Ok(ElfFacts {
        begin,
        end,
        static_ram: ram,
        flash,
    })
}

struct Qemu {
    child: Child,
}

impl Drop for Qemu {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The QEMU command line for `elf` (used by the runner and printed for `cargo run`).
pub fn qemu_command(
    machine: &str,
    elf: &Path,
    plugin: Option<String>,
    serial: Option<&Path>,
) -> Command {
    let cpu = if machine.contains("an500") {
        "cortex-m7"
    } else {
        "cortex-m4"
    };
    let mut c = Command::new("qemu-system-arm");
    c.args([
        "-machine",
        machine,
        "-cpu",
        cpu,
        "-nographic",
        "-monitor",
        "none",
    ])
    .arg("-serial")
    .arg(match serial {
        Some(base) => format!("pipe:{}", base.display()),
        None => "null".into(),
    })
    .args(["-semihosting-config", "enable=on,target=native"])
    .args(["-icount", "shift=0,align=off,sleep=off"]);
    if let Some(p) = plugin {
        c.args(["-plugin", &p]);
    }
    c.arg("-kernel").arg(elf);
    c
}

/// The host's own result for a frame: the same job function ([`crate::job::execute`]) on the
/// host's own final-phase state `fp`, through the same wire conversion.
pub fn host_result(
    nav: &Navigator<'_>,
    atlas: Option<&Atlas<'_>>,
    ws: &mut Workspace,
    fp: &mut FinalPhase,
    f: &Frame,
) -> FrameResult {
    host_result_estimated(nav, atlas, ws, fp, f).0
}

/// [`host_result`] with, for a TRN frame (on the tile or the atlas), the work nav-core metered
/// for it (`FrameReport::work`, estimated Cortex-M4 instructions, [`nav_core::cost`]) on the
/// host.
pub fn host_result_estimated(
    nav: &Navigator<'_>,
    atlas: Option<&Atlas<'_>>,
    ws: &mut Workspace,
    fp: &mut FinalPhase,
    f: &Frame,
) -> (FrameResult, Option<u64>) {
    let payload: Vec<u8> = f.heights_m.iter().flat_map(|h| h.to_le_bytes()).collect();
    let header = frame_header(f, &payload);
    let out = crate::job::execute(nav, atlas, ws, fp, &header, &f.heights_m);
    let estimate = match &out {
        crate::job::JobOutput::Locate(Ok(report)) => Some(u64::from(report.work)),
        crate::job::JobOutput::AtlasLocate(Ok(a)) => a.report.map(|r| u64::from(r.work)),
        _ => None,
    };
    (convert::job_result(f.meta.id, &out, fp), estimate)
}

fn outcome_name(o: &WireOutcome) -> String {
    match o {
        WireOutcome::Fix(_) => "fix".into(),
        WireOutcome::NoFix(n) => format!("no_fix:{n:?}"),
        WireOutcome::Refused(e) => format!("refused:{e:?}"),
        WireOutcome::Keyframe(_) => "keyframe".into(),
        WireOutcome::Hazard => "hazard_map".into(),
    }
}

fn job_name(f: &Frame) -> String {
    match f.meta.job {
        FrameJob::Locate => "locate",
        FrameJob::Keyframe(_) => "keyframe",
        FrameJob::Odometry(_) => "odometry",
        FrameJob::Hazard(_) => "hazard",
        FrameJob::Confirm(_) => "confirm",
        FrameJob::AtlasLocate => "atlas",
    }
    .into()
}

/// Pick the frames to run: of the TRN frames, the first `n − stress` terrain frames and (up to
/// `n`) the stress frames; the atlas sequence and the final-phase chain (keyframes, odometry,
/// hazard map) always run whole, after them (a sequence crosses tile edges in order, and each
/// final-phase frame needs the keyframe before it).
fn select(set: &FrameSet, n: Option<usize>) -> Vec<&Frame> {
    let all: Vec<&Frame> = set.frames.iter().collect();
    let Some(n) = n else { return all };
    let (trn, final_phase): (Vec<&Frame>, Vec<&Frame>) = all
        .into_iter()
        .partition(|f| matches!(f.meta.job, FrameJob::Locate));
    let (stress, terrain): (Vec<&Frame>, Vec<&Frame>) =
        trn.into_iter().partition(|f| f.meta.truth.is_none());
    let keep_stress = stress.len().min(n);
    let keep_terrain = n - keep_stress;
    terrain
        .into_iter()
        .take(keep_terrain)
        .chain(stress.into_iter().take(keep_stress))
        .chain(final_phase)
        .collect()
}

/// The host → target byte stream of a session without faults: hello, every frame (header and
/// chunks), shutdown. The target acknowledges into its own stream; nothing is read back.
pub fn record_session(frames: &[&Frame]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut seq = 0u16;
    let mut put = |m: &Message<'_>| -> Result<()> {
        let mut scratch = [0u8; crate::packet::MAX_PACKET_BYTES];
        let mut wire = [0u8; crate::packet::MAX_WIRE_BYTES];
        let n = crate::packet::encode_wire(seq, m, &mut scratch, &mut wire)?;
        out.extend_from_slice(&wire[..n]);
        seq = seq.wrapping_add(1);
        Ok(())
    };
    put(&Message::Hello(Hello {
        version: crate::PROTOCOL_VERSION,
        session: 1,
    }))?;
    for f in frames {
        let payload: Vec<u8> = f.heights_m.iter().flat_map(|h| h.to_le_bytes()).collect();
        put(&Message::FrameHeader(frame_header(f, &payload)))?;
        for (i, chunk) in payload.chunks(MAX_CHUNK_BYTES).enumerate() {
            put(&Message::FrameChunk(FrameChunk {
                frame_id: f.meta.id,
                offset: (i * MAX_CHUNK_BYTES) as u32,
                data: chunk,
            }))?;
        }
    }
    put(&Message::Shutdown)?;
    Ok(out)
}

/// The header announcing `f` with its payload bytes.
pub fn frame_header(f: &Frame, payload: &[u8]) -> FrameHeader {
    FrameHeader {
        frame_id: f.meta.id,
        width: f.meta.width,
        height: f.meta.height,
        pixel_m: f.meta.pixel_m,
        format: SampleFormat::HeightF32Le,
        payload_bytes: payload.len() as u32,
        payload_crc: payload_crc(payload),
        prior: f.meta.prior,
        job: f.meta.job,
    }
}

fn mkfifo(p: &Path) -> Result<()> {
    let _ = fs::remove_file(p);
    let st = Command::new("mkfifo").arg(p).status().context("mkfifo")?;
    if !st.success() {
        bail!("mkfifo {} failed", p.display());
    }
    Ok(())
}

/// Run the whole HIL session.
pub fn run(opts: &RunOptions) -> Result<Report> {
    let t_all = Instant::now();
    let set = load_or_generate(opts)?;
    let mut frames = select(&set, opts.frames);
    if let Some(only) = &opts.only {
        frames.retain(|f| f.meta.name.contains(only.as_str()));
    }
    say(
        opts.progress,
        "building the instruction-count plugin and the firmware",
    );
    let plugin = build_plugin(opts)?;
    let elf = build_firmware(opts)?;
    let facts = elf_facts(&elf)?;
    let tile = Tile::parse(&set.tile).map_err(|e| anyhow::anyhow!("tile: {e}"))?;
    let nav = Navigator::new(tile, NavConfig::default());
    let atlas: Box<Atlas<'_>> =
        Box::new(Atlas::new(&set.atlas).map_err(|e| anyhow::anyhow!("atlas: {e}"))?);
    let atlas_crc = atlas.atlas().index_crc();
    let mut ws: Box<Workspace> = Box::new(Workspace::new());
    let mut fp: Box<FinalPhase> = Box::default();

    let session_dir = opts
        .work_dir()
        .join(format!("session-{}", std::process::id()));
    fs::create_dir_all(&session_dir)?;
    // Semihosting FIFOs (the firmware opens them), or the UART's pipe pair (QEMU opens it).
    let uart_base = session_dir.join("hil-uart");
    let (rx_path, tx_path) = if opts.uart {
        (
            session_dir.join("hil-uart.in"),
            session_dir.join("hil-uart.out"),
        )
    } else {
        (
            session_dir.join("hil-link.rx"),
            session_dir.join("hil-link.tx"),
        )
    };
    mkfifo(&rx_path)?;
    mkfifo(&tx_path)?;
    let icount_path = session_dir.join("icount.txt");
    let mut plugin_arg = format!(
        "{},begin={:#x},end={:#x},out={}",
        plugin.display(),
        facts.begin,
        facts.end,
        icount_path.display()
    );
    // Hot-spot profile of the measured windows (block address, instructions) for development.
    if let Some(p) = std::env::var_os("UMBRA_HIL_PROFILE") {
        plugin_arg.push_str(&format!(",profile={}", PathBuf::from(p).display()));
    }
    let qemu_log = session_dir.join("qemu.log");
    let log = fs::File::create(&qemu_log)?;
    let child = qemu_command(
        &opts.machine,
        &elf,
        Some(plugin_arg),
        opts.uart.then_some(uart_base.as_path()),
    )
    .current_dir(&session_dir)
    .stdin(Stdio::null())
    .stdout(log.try_clone()?)
    .stderr(log)
    .spawn()
    .context("starting qemu-system-arm (install it: apt-get install qemu-system-arm)")?;
    let mut qemu = Qemu { child };
    let t_qemu = Instant::now();

    // Open the FIFOs in the firmware's order (rx, then tx) on a helper thread: each open blocks
    // until QEMU opens the other end; if QEMU dies first, opening them ourselves unblocks it.
    let (otx, orx) = std::sync::mpsc::channel();
    {
        let (rx_path, tx_path) = (rx_path.clone(), tx_path.clone());
        std::thread::spawn(move || {
            let w = fs::OpenOptions::new().write(true).open(&rx_path);
            let r = w.as_ref().ok().map(|_| fs::File::open(&tx_path));
            let _ = otx.send((w, r));
        });
    }
    let (w, r) = loop {
        match orx.recv_timeout(Duration::from_millis(100)) {
            Ok((Ok(w), Some(Ok(r)))) => break (w, r),
            Ok(_) => bail!("cannot open the link FIFOs"),
            Err(_) => {
                if let Some(st) = qemu.child.try_wait()? {
                    let _ = fs::File::open(&rx_path);
                    let _ = fs::OpenOptions::new().write(true).open(&tx_path);
                    bail!(
                        "QEMU exited ({st}) before opening the link:\n{}",
                        fs::read_to_string(&qemu_log).unwrap_or_default()
                    );
                }
            }
        }
    };
    let (itx, irx) = std::sync::mpsc::channel::<Incoming>();
    spawn_reader(r, itx);
    let mut link = HostLink::new(w, irx);

    // Handshake.
    let session = 0x5EED_0001;
    link.send(
        &Message::Hello(Hello {
            version: crate::PROTOCOL_VERSION,
            session,
        }),
        None,
    )?;
    let ack = match link.wait_for(Duration::from_secs(30), |m| {
        matches!(m, Message::HelloAck(_))
    })? {
        Message::HelloAck(a) => a,
        _ => bail!("no hello ack"),
    };
    if !ack.accepted || ack.version != crate::PROTOCOL_VERSION || ack.session != session {
        bail!("handshake refused: {ack:?}");
    }
    let tile_crc = nav_core::tile::stored_crc(&set.tile).unwrap_or(0);
    if ack.tile_crc != tile_crc {
        bail!(
            "the firmware's tile (CRC {:08x}) is not this frame set's ({tile_crc:08x})",
            ack.tile_crc
        );
    }
    if ack.atlas_crc != atlas_crc || usize::from(ack.atlas_tiles) != atlas.atlas().len() {
        bail!(
            "the firmware's atlas (index CRC {:08x}, {} tiles) is not this frame set's ({atlas_crc:08x}, {})",
            ack.atlas_crc,
            ack.atlas_tiles,
            atlas.atlas().len()
        );
    }
    say(
        opts.progress,
        format!(
            "target: protocol v{}, tile {} features, frames up to {} px; {} frames to send",
            ack.version,
            ack.tile_features,
            ack.max_frame_px,
            frames.len()
        ),
    );

    let mut records = Vec::new();
    let mut costs: Vec<(u32, FrameCost)> = Vec::new();
    let mut fault_cycle = 0usize;
    for (k, f) in frames.iter().enumerate() {
        let payload: Vec<u8> = f.heights_m.iter().flat_map(|h| h.to_le_bytes()).collect();
        let header = frame_header(f, &payload);
        // Every other frame gets one fault, cycling through the kinds, at a varying packet.
        let fault = (opts.faults && k % 2 == 1).then(|| {
            let kind = Fault::ALL[fault_cycle % Fault::ALL.len()];
            fault_cycle += 1;
            kind
        });
        let n_chunks = payload.len().div_ceil(MAX_CHUNK_BYTES);
        let fault_at = fault.map(|_| (k * 7) % (n_chunks + 1));
        let t0 = Instant::now();
        link.send(
            &Message::FrameHeader(header),
            fault.filter(|_| fault_at == Some(0)).map(|x| (x, k * 13)),
        )?;
        for (i, chunk) in payload.chunks(MAX_CHUNK_BYTES).enumerate() {
            let msg = Message::FrameChunk(FrameChunk {
                frame_id: f.meta.id,
                offset: (i * MAX_CHUNK_BYTES) as u32,
                data: chunk,
            });
            link.send(
                &msg,
                fault
                    .filter(|_| fault_at == Some(i + 1))
                    .map(|x| (x, k * 31 + i)),
            )?;
        }
        let id = f.meta.id;
        let got = match link
            .wait_for(Duration::from_secs(300), |m| {
                matches!(m, Message::FrameResult(r) if r.frame_id == id)
                    || matches!(m, Message::Error(e) if e.frame_id == id)
            })
            .with_context(|| {
                format!(
                    "frame {id} ({}): QEMU said:\n{}",
                    f.meta.name,
                    fs::read_to_string(&qemu_log).unwrap_or_default()
                )
            })? {
            Message::FrameResult(r) => r,
            other => bail!("frame {id}: the target answered {other:?}"),
        };
        let cost = match link.wait_for(
            Duration::from_secs(5),
            |m| matches!(m, Message::FrameCost(c) if c.frame_id == id),
        )? {
            Message::FrameCost(c) => c,
            _ => bail!("frame {id}: no cost"),
        };
        costs.push((id, cost));
        let (host, estimated_instructions) =
            host_result_estimated(&nav, Some(&atlas), &mut ws, &mut fp, f);
        let bit_exact = postcard::to_stdvec(&host)? == postcard::to_stdvec(&got)?;
        let (pos_err, head_err) = match (&got.outcome, &f.meta.truth) {
            (WireOutcome::Fix(fx), Some(t)) => {
                // Atlas fixes are in their tile's pixels; the truth is in atlas pixels.
                let off = got.atlas.map_or([0.0; 2], |a| {
                    [
                        f64::from(a.tile_offset_px[0]),
                        f64::from(a.tile_offset_px[1]),
                    ]
                });
                let dx = fx.center_tile_px[0] + off[0] - t.center_tile_px[0];
                let dy = fx.center_tile_px[1] + off[1] - t.center_tile_px[1];
                let dh = (fx.heading_rad - t.heading_rad)
                    .to_degrees()
                    .rem_euclid(360.0);
                (
                    Some(dx.hypot(dy)),
                    Some(if dh > 180.0 { dh - 360.0 } else { dh }),
                )
            }
            _ => (None, None),
        };
        let (offset_error_m, offset_sigma_m) = match (&got.offset, &f.meta.truth_offset_m) {
            (Some(o), Some(t)) => (
                Some((o.east_m - t[0]).hypot(o.north_m - t[1])),
                Some(o.cov_m2[0].max(o.cov_m2[3]).sqrt()),
            ),
            (Some(o), None) => (None, Some(o.cov_m2[0].max(o.cov_m2[3]).sqrt())),
            _ => (None, None),
        };
        let (hazard_sites, hazard_safe_frac, site_from_target_m) = match &got.hazard {
            Some(WireHazard::Map(st, decision)) => (
                Some(st.sites),
                Some(st.safe as f64 / st.sites.max(1) as f64),
                match decision {
                    WireAimDecision::Move(x) => Some(x.from_target_m),
                    WireAimDecision::Keep(_) => Some(0.0),
                    WireAimDecision::NoSite => None,
                },
            ),
            _ => (None, None, None),
        };
        let inliers = match &got.outcome {
            WireOutcome::Fix(fx) => fx.inliers,
            _ => 0,
        };
        records.push(FrameRecord {
            id,
            name: f.meta.name.clone(),
            outcome: outcome_name(&got.outcome),
            inliers,
            features: got.features,
            matches: got.matches,
            msac_iterations: got.msac_iterations,
            bit_exact,
            instructions: 0,
            timer_cycles: cost.timer_cycles,
            stack_peak_bytes: cost.stack_peak_bytes,
            position_error_px: pos_err,
            heading_error_deg: head_err,
            fault,
            job: job_name(f),
            offset_error_m,
            offset_sigma_m,
            hazard_sites,
            hazard_safe_frac,
            site_from_target_m,
            atlas_tile: got.atlas.map(|a| a.tile),
            atlas_tried: got.atlas.map(|a| a.tried),
            estimated_instructions,
        });
        let mut extra = String::new();
        if let Some(a) = got.atlas {
            extra.push_str(&format!(
                "  atlas tile {} ({} tried of {}{})",
                a.tile,
                a.tried,
                a.candidates,
                if a.straddles { ", straddles" } else { "" }
            ));
        }
        if let Some(e) = offset_error_m {
            extra.push_str(&format!(
                "  offset err {e:.2} m (σ {:.2})",
                offset_sigma_m.unwrap_or(f64::NAN)
            ));
        }
        if let (Some(n), Some(fr)) = (hazard_sites, hazard_safe_frac) {
            extra.push_str(&format!(
                "  hazard {n} sites, {:.1} % safe, site {}",
                100.0 * fr,
                site_from_target_m.map_or("none".into(), |d| format!("{d:.1} m off"))
            ));
        }
        say(
            opts.progress,
            format!(
                "[{:>2}/{}] {:<26} {:<28} feats {:>3} inliers {:>3} {:>6.2} s{}{}{}",
                k + 1,
                frames.len(),
                f.meta.name,
                outcome_name(&got.outcome),
                got.features,
                inliers,
                t0.elapsed().as_secs_f64(),
                extra,
                if bit_exact {
                    "  bit-exact"
                } else {
                    "  MISMATCH"
                },
                fault
                    .map(|x| format!("  (fault {x:?} recovered)"))
                    .unwrap_or_default()
            ),
        );
    }
    let status = link.status()?;
    link.send(&Message::Shutdown, None)?;
    let _ = link.wait_for(Duration::from_secs(10), |m| matches!(m, Message::Status(_)));
    let deadline = Instant::now() + Duration::from_secs(30);
    let exit = loop {
        if let Some(st) = qemu.child.try_wait()? {
            break st;
        }
        if Instant::now() > deadline {
            bail!("QEMU did not exit after the shutdown");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    if !exit.success() {
        bail!(
            "QEMU exited with {exit}:\n{}",
            fs::read_to_string(&qemu_log).unwrap_or_default()
        );
    }
    let qemu_seconds = t_qemu.elapsed().as_secs_f64();

    // Pair the plugin's windows with the frames.
    let text = fs::read_to_string(&icount_path).context("instruction counts")?;
    let mut windows = std::collections::HashMap::new();
    for line in text.lines() {
        let parts: Vec<&str> = line.split_whitespace().collect();
        if let ["window", w, "insns", n] = parts.as_slice() {
            windows.insert(w.parse::<u32>()?, n.parse::<u64>()?);
        }
    }
    for (rec, (_, cost)) in records.iter_mut().zip(&costs) {
        rec.instructions = *windows
            .get(&cost.window)
            .with_context(|| format!("no instruction count for window {}", cost.window))?;
    }
    let _ = fs::remove_dir_all(&session_dir);

    let n = records.len();
    let max = records.iter().map(|r| r.instructions).max().unwrap_or(0);
    let mean = if n > 0 {
        records.iter().map(|r| r.instructions as f64).sum::<f64>() / n as f64
    } else {
        0.0
    };
    let report = Report {
        terrain: opts.terrain.label(),
        frames: n,
        fixes: records.iter().filter(|r| r.outcome == "fix").count(),
        bit_exact_frames: records.iter().filter(|r| r.bit_exact).count(),
        max_instructions_per_frame: max,
        mean_instructions_per_frame: mean,
        instruction_budget: INSTRUCTION_BUDGET,
        static_ram_bytes: facts.static_ram,
        flash_bytes: facts.flash,
        tile_bytes: set.tile.len() as u64,
        atlas_bytes: set.atlas.len() as u64,
        stack_peak_bytes: records
            .iter()
            .map(|r| r.stack_peak_bytes)
            .max()
            .unwrap_or(0),
        link_errors_recovered: link.counters.faults_recovered,
        link_errors_injected: link.counters.faults_injected,
        host_link: link.counters,
        target_status: status,
        machine: opts.machine.clone(),
        qemu_seconds,
        per_frame: records,
    };
    say(
        opts.progress,
        format!(
            "{} frames, {} fixes, {} bit-exact; instructions/frame max {} mean {:.0}; static RAM {} B, flash {} B; {} link faults recovered; {:.1} s",
            report.frames,
            report.fixes,
            report.bit_exact_frames,
            report.max_instructions_per_frame,
            report.mean_instructions_per_frame,
            report.static_ram_bytes,
            report.flash_bytes,
            report.link_errors_recovered,
            t_all.elapsed().as_secs_f64()
        ),
    );
    Ok(report)
}
