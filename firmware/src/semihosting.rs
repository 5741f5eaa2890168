//! The two semihosting calls the QEMU binaries need beyond printing: the command line
//! (`-append`) and an exit with a status code.

#![allow(unsafe_code)]

use cortex_m_semihosting::{nr, syscall1};

/// Reads the command line QEMU was given with `-append` into `buf`; empty on failure.
pub fn cmdline(buf: &mut [u8]) -> &str {
    let mut block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: SYS_GET_CMDLINE writes at most block[1] bytes into the buffer block[0] points at,
    // which lives for this call, and updates block[1] with the length written.
    let rc = unsafe { syscall1(nr::GET_CMDLINE, block.as_mut_ptr() as usize) };
    if rc != 0 {
        return "";
    }
    let len = block[1].min(buf.len());
    core::str::from_utf8(&buf[..len]).unwrap_or("")
}

/// Ends the QEMU run with exit status `code` (SYS_EXIT_EXTENDED, ADP_Stopped_ApplicationExit).
pub fn exit(code: u32) -> ! {
    const ADP_STOPPED_APPLICATION_EXIT: usize = 0x20026;
    const SYS_EXIT_EXTENDED: usize = 0x20;
    let block = [ADP_STOPPED_APPLICATION_EXIT, code as usize];
    // SAFETY: the block is a valid two-word parameter block for the duration of the call.
    unsafe { syscall1(SYS_EXIT_EXTENDED, block.as_ptr() as usize) };
    // Only reached when no debugger/emulator services semihosting.
    loop {
        cortex_m::asm::bkpt();
    }
}
