//! Stack high-water mark by painting: the stack's lower part is filled with a pattern at reset
//! and the deepest overwritten word gives the peak use.
//!
//! Unsafe: painting and scanning memory below the live stack needs raw pointers; the region is
//! computed from cortex-m-rt's `_stack_start` and stays below every live frame.
#![allow(unsafe_code)]

use core::ptr;

/// Bytes of stack painted and watched below the initial stack pointer.
pub const WATCHED_BYTES: usize = 64 * 1024;
const PATTERN: u32 = 0xA5C3_5A3C;

unsafe extern "C" {
    /// Top of the stack (cortex-m-rt's linker script): the initial stack pointer.
    static _stack_start: u32;
}

fn top() -> usize {
    // Only the address of the linker symbol is taken, never its contents.
    ptr::addr_of!(_stack_start) as usize
}

/// Paint the watched region below the current stack pointer.
pub fn paint() {
    let sp = cortex_m::register::msp::read() as usize;
    let lo = top() - WATCHED_BYTES;
    let mut a = lo;
    // Keep 64 bytes of margin below the live stack pointer (this function's own frame).
    while a + 4 <= sp - 64 {
        // SAFETY: [lo, sp − 64) lies inside the stack region (RAM, 4-byte aligned) below every
        // live frame; nothing else uses it.
        unsafe { ptr::write_volatile(a as *mut u32, PATTERN) };
        a += 4;
    }
}

/// Deepest stack use since [`paint`], bytes.
pub fn peak_bytes() -> u32 {
    let lo = top() - WATCHED_BYTES;
    let mut a = lo;
    while a < top() {
        // SAFETY: reading aligned words of the stack region.
        let v = unsafe { ptr::read_volatile(a as *const u32) };
        if v != PATTERN {
            break;
        }
        a += 4;
    }
    (top() - a) as u32
}
