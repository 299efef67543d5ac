//! defmt logging (feature `defmt`): frames go to the semihosting file `hil-defmt.bin` in QEMU's
//! working directory; decode them with `defmt-print -e <firmware ELF> < hil-defmt.bin`. Set
//! `DEFMT_LOG=info` (or `debug`) when building, or nothing is logged.
//!
//! Unsafe: a defmt global logger is an `unsafe impl` by contract (the logger must not be
//! re-entered); it holds a critical section from `acquire` to `release`, during which the encoder
//! and the file handle (two `static mut`s) are only touched from here.
#![allow(unsafe_code)]

use crate::semihosting::HostFile;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, Ordering};
use cortex_m_semihosting::nr;

static TAKEN: AtomicBool = AtomicBool::new(false);
static mut RESTORE: critical_section::RestoreState = critical_section::RestoreState::invalid();
static mut ENCODER: defmt::Encoder = defmt::Encoder::new();
static mut FILE: Option<HostFile> = None;

#[defmt::global_logger]
struct Logger;

// SAFETY: acquire/release bracket every use in a critical section and refuse re-entry.
unsafe impl defmt::Logger for Logger {
    fn acquire() {
        // SAFETY: released in `release`, which defmt always calls after `acquire`.
        let restore = unsafe { critical_section::acquire() };
        if TAKEN.swap(true, Ordering::Relaxed) {
            // Re-entered (a log inside a log): drop this one rather than corrupt the stream.
            // SAFETY: undo the critical section just taken.
            unsafe { critical_section::release(restore) };
            return;
        }
        // SAFETY: inside the critical section, sole user of the statics.
        unsafe {
            *addr_of_mut!(RESTORE) = restore;
            (*addr_of_mut!(ENCODER)).start_frame(write);
        }
    }

    unsafe fn flush() {}

    unsafe fn release() {
        // SAFETY: inside the critical section taken by `acquire`.
        unsafe {
            (*addr_of_mut!(ENCODER)).end_frame(write);
            TAKEN.store(false, Ordering::Relaxed);
            critical_section::release(*addr_of_mut!(RESTORE));
        }
    }

    unsafe fn write(bytes: &[u8]) {
        // SAFETY: inside the critical section taken by `acquire`.
        unsafe { (*addr_of_mut!(ENCODER)).write(bytes, write) }
    }
}

fn write(bytes: &[u8]) {
    // SAFETY: only called from the logger, inside its critical section.
    let file = unsafe { &mut *addr_of_mut!(FILE) };
    if file.is_none() {
        *file = HostFile::open("hil-defmt.bin\0", nr::open::W_TRUNC_BINARY).ok();
    }
    if let Some(f) = file {
        let _ = embedded_io::Write::write_all(f, bytes);
    }
}
