//! The board's serial port as a link (feature `uart-link`): the ARM CMSDK APB UART of the MPS2
//! FPGA images (UART0 at 0x4000_4000), behind `embedded_io::{Read, Write}` like the
//! semihosting transport. QEMU carries it at ≈ 10 KiB/s (a 200 × 200 frame takes ≈ 16 s), so the
//! runner uses it only on request (`--link uart`); a flight board's driver would slot in here.
//!
//! Unsafe: memory-mapped register access through volatile reads and writes of the fixed,
//! documented register addresses; nothing else touches UART0.
#![allow(unsafe_code)]

use core::ptr::{read_volatile, write_volatile};
use embedded_io::{ErrorType, Read, Write};

/// UART0 base address on the MPS2 AN385/AN386/AN500 images.
const UART0: usize = 0x4000_4000;
const DATA: usize = 0x000;
const STATE: usize = 0x004;
const CTRL: usize = 0x008;
const BAUDDIV: usize = 0x010;
const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;

/// UART0, enabled for transmit and receive.
pub struct Uart {
    base: usize,
}

impl Uart {
    /// Enable UART0 (baud divider 16: the smallest the CMSDK UART accepts).
    pub fn uart0() -> Self {
        let u = Self { base: UART0 };
        u.wr(BAUDDIV, 16);
        u.wr(CTRL, CTRL_TX_EN | CTRL_RX_EN);
        u
    }
    fn rd(&self, reg: usize) -> u32 {
        // SAFETY: an aligned, always-mapped device register of UART0.
        unsafe { read_volatile((self.base + reg) as *const u32) }
    }
    fn wr(&self, reg: usize, v: u32) {
        // SAFETY: an aligned, always-mapped device register of UART0.
        unsafe { write_volatile((self.base + reg) as *mut u32, v) }
    }
}

impl ErrorType for Uart {
    type Error = core::convert::Infallible;
}

impl Read for Uart {
    /// Blocks for the first byte, then takes what is already there.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let mut n = 0;
        for slot in buf.iter_mut() {
            if n > 0 && self.rd(STATE) & STATE_RX_FULL == 0 {
                break;
            }
            while self.rd(STATE) & STATE_RX_FULL == 0 {}
            *slot = self.rd(DATA) as u8;
            n += 1;
        }
        Ok(n)
    }
}

impl Write for Uart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for &b in buf {
            while self.rd(STATE) & STATE_TX_FULL != 0 {}
            self.wr(DATA, b as u32);
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
