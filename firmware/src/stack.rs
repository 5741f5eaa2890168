//! Stack high-water mark: the stack region below the current stack pointer is painted with a
//! pattern, and the deepest word no longer holding it shows how far the stack has reached. The
//! stack is the one RAM use the linker does not budget (flip-link puts it at the bottom of RAM,
//! under `.data`/`.bss`, growing down towards 0x2000_0000, past which an overflow faults, see
//! [`crate::fault`]): the model constructors build their tables by value, and a frame that grows
//! with an inlining decision is found here, not as a fault on the board.

#![allow(unsafe_code)]

use core::ptr::{addr_of, read_volatile, write_volatile};

/// What an unused stack word holds after [`paint`].
const PATTERN: u32 = 0x5AC4_5AC4;
/// Words right below the stack pointer left alone: the painting loop's own frame.
const GUARD_BYTES: usize = 256;

extern "C" {
    /// Lowest address the stack may reach: the start of SRAM (set by flip-link).
    static _stack_end: u32;
    /// Initial stack pointer, right under `.data`/`.bss` (set by flip-link).
    static _stack_start: u32;
}

/// The stack's region [lowest, top) in bytes.
#[allow(unused_unsafe)] // taking an extern static's address is safe since Rust 1.82, not before
fn region() -> (usize, usize) {
    // SAFETY: only the addresses of the linker symbols are taken, never their contents.
    unsafe { (addr_of!(_stack_end) as usize, addr_of!(_stack_start) as usize) }
}

/// The lowest address the stack may reach; below it an access faults.
pub fn lowest() -> usize {
    region().0
}

/// Bytes the stack may use in all.
pub fn size() -> usize {
    let (lo, hi) = region();
    hi - lo
}

/// Paints the free stack below the caller's frame. Call once, early in `main`.
#[inline(never)]
pub fn paint() {
    let (lo, _) = region();
    let sp = cortex_m::register::msp::read() as usize;
    let mut p = (lo + 3) & !3;
    while p + GUARD_BYTES < sp {
        // SAFETY: [lo, sp − GUARD) is stack no frame has claimed yet (it lies below the current
        // stack pointer, above the end of .bss), word-aligned, and nothing else owns it.
        unsafe { write_volatile(p as *mut u32, PATTERN) };
        p += 4;
    }
}

/// The deepest the stack has reached since [`paint`], in bytes from its top.
pub fn peak() -> usize {
    let (lo, hi) = region();
    let mut p = (lo + 3) & !3;
    // SAFETY: reads of word-aligned RAM inside the stack region.
    while p < hi && unsafe { read_volatile(p as *const u32) } == PATTERN {
        p += 4;
    }
    hi - p
}
