//! The HardFault entry of every firmware binary.
//!
//! The stack sits at the bottom of SRAM, under `.data`/`.bss` (flip-link, `.cargo/config.toml`):
//! an overflow runs off the start of SRAM (0x2000_0000) into unmapped addresses and raises a
//! bus fault, escalated to HardFault, instead of silently overwriting the statics. The fault
//! then arrives with the stack pointer below SRAM, where a handler could not push one register
//! (a fault inside the HardFault handler locks the core up). So the entry below moves MSP back
//! to the top of the stack before any Rust code runs, and only then calls the binary's
//! `gma_hard_fault`. Nothing returns from a HardFault here: what was on the stack is abandoned.
//! It replaces cortex-m-rt's default `HardFault` (a weak `PROVIDE` in its `link.x`).

#![allow(unsafe_code)]

// SAFETY: runs only as the HardFault vector; `_stack_start` is the top of the stack (flip-link),
// 8-byte aligned; `gma_hard_fault` never returns.
core::arch::global_asm!(
    ".section .HardFault.user, \"ax\", %progbits",
    ".global HardFault",
    ".type HardFault, %function",
    ".thumb_func",
    "HardFault:",
    "    ldr r0, =_stack_start",
    "    msr msp, r0",
    "    isb",
    "    b gma_hard_fault",
    "    .ltorg",
);

/// What the fault status registers say about a HardFault (SCB, ARMv7-M ARM B3.2.15–B3.2.18).
#[derive(Clone, Copy, Debug)]
pub struct FaultStatus {
    /// Configurable fault status (MemManage, BusFault, UsageFault bits).
    pub cfsr: u32,
    /// HardFault status (FORCED: a configurable fault escalated).
    pub hfsr: u32,
    /// The bus fault's address, when CFSR.BFARVALID says it holds one.
    pub bus_fault_address: Option<u32>,
}

impl FaultStatus {
    /// Reads the fault status registers (call from the HardFault handler).
    pub fn read() -> Self {
        const CFSR: *const u32 = 0xE000_ED28 as *const u32;
        const HFSR: *const u32 = 0xE000_ED2C as *const u32;
        const BFAR: *const u32 = 0xE000_ED38 as *const u32;
        const BFARVALID: u32 = 1 << 15;
        // SAFETY: the System Control Block's fault registers, always mapped on ARMv7-M; reads
        // have no side effect.
        let (cfsr, hfsr, bfar) = unsafe {
            (core::ptr::read_volatile(CFSR), core::ptr::read_volatile(HFSR), core::ptr::read_volatile(BFAR))
        };
        Self { cfsr, hfsr, bus_fault_address: (cfsr & BFARVALID != 0).then_some(bfar) }
    }

    /// Whether this fault is the stack running off its end: a bus fault on an address within
    /// `reach` bytes below the stack's lowest address.
    pub fn is_stack_overflow(&self, reach: u32) -> bool {
        let floor = crate::stack::lowest() as u32;
        self.bus_fault_address.is_some_and(|a| a < floor && a >= floor.saturating_sub(reach))
    }
}
