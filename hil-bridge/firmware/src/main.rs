//! # Umbra HIL firmware
//!
//! nav-core on a Cortex-M (QEMU `mps2-an386` Cortex-M4 or `mps2-an500` Cortex-M7), the
//! reference tile and a flight atlas linked into flash, frames received over the hil-bridge
//! link, each frame's job run (TRN on the tile or on the atlas, keyframe capture, odometry on the keyframe, hazard map: see
//! [`hil_bridge::job`]), its result (fix or typed no-fix, offset, hazard map digest and site)
//! and its cost sent back.
//!
//! * Link: semihosting FIFOs `hil-link.rx` / `hil-link.tx` in QEMU's working directory (fast);
//!   the protocol state machine ([`hil_bridge::target::TargetLink`]) only sees `embedded_io`
//!   traits, so a UART driver is a drop-in replacement.
//! * Cost: the frame job sits between [`hil_frame_begin`] and [`hil_frame_end`]; the host's
//!   TCG plugin counts the instructions between them; SysTick gives the target's own view.
//! * Failure: a panic or a fault ends QEMU through semihosting with exit code 1, never a hang.
#![no_std]
#![no_main]

#[cfg(feature = "defmt")]
mod log;
mod semihosting;
mod stack;
mod timer;
#[cfg(feature = "uart-link")]
mod uart;

/// `defmt::info!` with the `defmt` feature, nothing without it.
macro_rules! info {
    ($($t:tt)*) => {
        #[cfg(feature = "defmt")]
        defmt::info!($($t)*);
    };
}

use core::hint::black_box;
use cortex_m_rt::{ExceptionFrame, entry, exception};
use cortex_m_semihosting::debug::{self, EXIT_FAILURE, EXIT_SUCCESS};
use cortex_m_semihosting::hprintln;
use hil_bridge::convert;
use hil_bridge::flight::{MAX_FRAME_PX, MAX_FRAME_WIDTH, Workspace};
use hil_bridge::job::{self, Atlas, FinalPhase};
use hil_bridge::msg::{FrameCost, Message};
use hil_bridge::target::{Event, TargetInfo, TargetLink};
use nav_core::atlas::TileSource;
use nav_core::{NavConfig, Navigator, Tile};
#[cfg(not(feature = "uart-link"))]
use semihosting::HostFile;
use timer::{CycleCounter, SysTickCounter};

/// Core clock the SysTick count refers to, Hz (the MPS2 FPGA images run at 25 MHz).
pub const CORE_HZ: u32 = 25_000_000;

/// The reference tile, 4-byte aligned in flash (its records are 4-byte aligned inside).
#[repr(C, align(4))]
struct Aligned<T: ?Sized>(T);
static TILE: &Aligned<[u8]> = &Aligned(*include_bytes!(concat!(env!("OUT_DIR"), "/tile.bin")));
/// The flight atlas (index and tiles), 4-byte aligned in flash.
static ATLAS: &Aligned<[u8]> = &Aligned(*include_bytes!(concat!(env!("OUT_DIR"), "/atlas.bin")));

/// Wire-format version stamped into the binary (find it with `strings`).
#[used]
static VERSION_STAMP: [u8; 24] = *b"UMBRA-HIL-PROTOCOL-v1\0\0\0";

/// Start of a measured window (the instruction counter's begin marker). Its body differs from
/// [`hil_frame_end`] so the linker cannot merge the two.
#[inline(never)]
pub fn hil_frame_begin(window: u32) {
    black_box(window);
}

/// End of a measured window (the instruction counter's end marker).
#[inline(never)]
pub fn hil_frame_end(window: u32) {
    black_box(window ^ 0x5EED_F00D);
}

fn fail(what: &str) -> ! {
    hprintln!("umbra-hil-firmware: {}", what);
    loop {
        debug::exit(EXIT_FAILURE);
    }
}

#[entry]
fn main() -> ! {
    // cortex-m-rt turns these into `&'static mut` references (initialised at compile time, in
    // .bss/.data, no copy through the stack).
    static mut HEIGHTS: [f32; MAX_FRAME_PX] = [0.0; MAX_FRAME_PX];
    static mut WORKSPACE: Workspace = Workspace::new();
    static mut FINAL_PHASE: FinalPhase = FinalPhase::new();

    stack::paint();
    if cfg!(feature = "selftest-panic") {
        panic!("selftest-panic: the panic handler must end QEMU with exit code 1");
    }
    let Some(core) = cortex_m::Peripherals::take() else {
        fail("core peripherals taken twice");
    };
    let mut clock = SysTickCounter::new(core.SYST, CORE_HZ);
    let tile = match Tile::parse(&TILE.0) {
        Ok(t) => t,
        Err(_) => fail("the linked reference tile does not parse"),
    };
    let nav = Navigator::new(tile, NavConfig::default());
    // Every atlas tile validated once, here (CRC and features), never again per frame.
    let atlas = match Atlas::new(&ATLAS.0) {
        Ok(a) => a,
        Err(_) => fail("the linked flight atlas does not parse"),
    };
    let atlas_crc = atlas.atlas().index_crc();
    #[cfg(not(feature = "uart-link"))]
    let (Ok(mut rx), Ok(mut tx)) = (HostFile::link_rx(), HostFile::link_tx()) else {
        fail("cannot open hil-link.rx / hil-link.tx in QEMU's working directory");
    };
    #[cfg(feature = "uart-link")]
    let (mut rx, mut tx) = (uart::Uart::uart0(), uart::Uart::uart0());
    info!("umbra-hil-firmware: tile of {=usize} features", tile.len());
    let info = TargetInfo {
        tile_crc: nav_core::tile::stored_crc(&TILE.0).unwrap_or(0),
        tile_features: tile.len() as u32,
        max_frame_width: MAX_FRAME_WIDTH as u16,
        atlas_crc,
        atlas_tiles: atlas.atlas().len() as u16,
    };
    let mut link = TargetLink::new(info, HEIGHTS);
    let ws = WORKSPACE;
    let fp = FINAL_PHASE;
    let mut window = 0u32;
    loop {
        match link.poll(&mut rx, &mut tx) {
            Ok(Event::Frame(f)) => {
                let h = f.header;
                let t0 = clock.now();
                hil_frame_begin(window);
                let out = job::execute(&nav, Some(&atlas), ws, fp, &h, link.heights_m());
                hil_frame_end(window);
                let cycles = clock.now().wrapping_sub(t0);
                let cost = FrameCost {
                    frame_id: h.frame_id,
                    window,
                    timer_cycles: cycles,
                    core_hz: clock.hz(),
                    stack_peak_bytes: stack::peak_bytes(),
                };
                info!(
                    "frame {=u32}: {=u32} cycles, stack {=u32} B",
                    h.frame_id, cycles, cost.stack_peak_bytes
                );
                window = window.wrapping_add(1);
                let res = convert::job_result(h.frame_id, &out, fp);
                if link.send(&mut tx, &Message::FrameCost(cost)).is_err()
                    || link.send(&mut tx, &Message::FrameResult(res)).is_err()
                {
                    fail("link write failed");
                }
            }
            Ok(Event::Shutdown) | Ok(Event::EndOfStream) => loop {
                debug::exit(EXIT_SUCCESS);
            },
            Err(_) => fail("link failed"),
        }
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("umbra-hil-firmware panicked: {}", info);
    loop {
        debug::exit(EXIT_FAILURE);
    }
}

// cortex-m-rt requires the HardFault handler to be declared `unsafe fn`; it only reports.
#[allow(unsafe_code)]
#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    hprintln!("umbra-hil-firmware: hard fault at pc {:#010x}", ef.pc());
    loop {
        debug::exit(EXIT_FAILURE);
    }
}
