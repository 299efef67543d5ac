//! The board timer behind a small trait, so the measuring code ports to a flight board
//! (whose DWT cycle counter QEMU does not emulate: it reads 0 there).

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;

/// A free-running cycle counter.
pub trait CycleCounter {
    /// Current count, core-clock cycles (wrapping).
    fn now(&mut self) -> u32;
    /// Core clock, Hz.
    fn hz(&self) -> u32;
}

/// SysTick as a 24-bit down-counter at the core clock, reload 2²⁴ − 1, no interrupt (so no
/// instruction of an interrupt handler ever lands inside a measured window).
pub struct SysTickCounter {
    syst: SYST,
    hz: u32,
    last: u32,
    acc: u32,
}

/// SysTick reload value (the counter's full 24-bit range).
const RELOAD: u32 = 0x00FF_FFFF;

impl SysTickCounter {
    /// Start SysTick counting at the processor clock of `hz`.
    pub fn new(mut syst: SYST, hz: u32) -> Self {
        syst.disable_interrupt();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(RELOAD);
        syst.clear_current();
        syst.enable_counter();
        Self {
            syst,
            hz,
            last: RELOAD,
            acc: 0,
        }
    }
}

/// Busy-wait delays on the same counter, through the embedded-hal trait drivers expect.
impl embedded_hal::delay::DelayNs for SysTickCounter {
    fn delay_ns(&mut self, ns: u32) {
        let cycles = (ns as u64 * self.hz as u64).div_ceil(1_000_000_000) as u32;
        let start = self.now();
        while self.now().wrapping_sub(start) < cycles {}
    }
}

impl CycleCounter for SysTickCounter {
    /// Extends the 24-bit counter: correct as long as it is read at least once per 2²⁴ cycles
    /// (0.67 s at 25 MHz); the firmware reads it around every frame.
    fn now(&mut self) -> u32 {
        let v = SYST::get_current();
        let elapsed = self.last.wrapping_sub(v) & RELOAD;
        self.last = v;
        self.acc = self.acc.wrapping_add(elapsed);
        let _ = &self.syst;
        self.acc
    }
    fn hz(&self) -> u32 {
        self.hz
    }
}
