//! The link over semihosting files: the host runner makes two FIFOs in QEMU's working
//! directory and the firmware opens them like files. Reads block until bytes arrive and return
//! what is there (megabytes per second), so this is the fast transport for frames; the
//! protocol above it is the same one a UART carries.
//!
//! Unsafe: a semihosting call is a `bkpt` with a pointer to an argument block; the three calls
//! below pass live, correctly sized buffers. This is the only way to reach the host's files.
#![allow(unsafe_code)]
// With the UART link only the defmt log and the panic path use host files.
#![cfg_attr(feature = "uart-link", allow(dead_code))]

use cortex_m_semihosting::nr;
use embedded_io::{ErrorKind, ErrorType, Read, Write};

/// Name of the host → target stream, relative to QEMU's working directory (NUL-terminated).
pub const RX_NAME: &str = "hil-link.rx\0";
/// Name of the target → host stream (NUL-terminated).
pub const TX_NAME: &str = "hil-link.tx\0";

/// A semihosting transport error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HostIoError;

impl core::fmt::Display for HostIoError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("semihosting I/O failed")
    }
}

impl core::error::Error for HostIoError {}

impl embedded_io::Error for HostIoError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// A file on the debug host, opened through semihosting.
pub struct HostFile {
    fd: usize,
}

impl HostFile {
    /// Open `name` (NUL-terminated) with a semihosting open mode.
    pub fn open(name: &str, mode: usize) -> Result<Self, HostIoError> {
        if !name.ends_with('\0') {
            return Err(HostIoError);
        }
        // SAFETY: SYS_OPEN reads `len` bytes at `ptr`, a live NUL-terminated string; the length
        // excludes the NUL as the semihosting specification requires.
        let fd = unsafe {
            cortex_m_semihosting::syscall(nr::OPEN, &[name.as_ptr() as usize, mode, name.len() - 1])
        };
        if fd == usize::MAX {
            Err(HostIoError)
        } else {
            Ok(Self { fd })
        }
    }
    /// The host → target link stream.
    pub fn link_rx() -> Result<Self, HostIoError> {
        Self::open(RX_NAME, nr::open::R_BINARY)
    }
    /// The target → host link stream.
    pub fn link_tx() -> Result<Self, HostIoError> {
        Self::open(TX_NAME, nr::open::W_TRUNC_BINARY)
    }
}

impl ErrorType for HostFile {
    type Error = HostIoError;
}

impl Read for HostFile {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, HostIoError> {
        if buf.is_empty() {
            return Ok(0);
        }
        // SAFETY: SYS_READ writes at most `buf.len()` bytes into `buf`, which we borrow mutably.
        let not_read = unsafe {
            cortex_m_semihosting::syscall(
                nr::READ,
                &[self.fd, buf.as_mut_ptr() as usize, buf.len()],
            )
        };
        // Returns the number of bytes NOT read: len means end of file (or an error).
        buf.len().checked_sub(not_read).ok_or(HostIoError)
    }
}

impl Write for HostFile {
    fn write(&mut self, buf: &[u8]) -> Result<usize, HostIoError> {
        if buf.is_empty() {
            return Ok(0);
        }
        // SAFETY: SYS_WRITE reads `buf.len()` bytes from `buf`, which we borrow.
        let not_written = unsafe {
            cortex_m_semihosting::syscall(nr::WRITE, &[self.fd, buf.as_ptr() as usize, buf.len()])
        };
        match buf.len().checked_sub(not_written) {
            Some(0) | None => Err(HostIoError),
            Some(n) => Ok(n),
        }
    }
    fn flush(&mut self) -> Result<(), HostIoError> {
        Ok(())
    }
}
