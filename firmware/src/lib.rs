//! Drive firmware for giant-magnetostrictive actuators on the STM32G474, and the HAL-free
//! pieces its QEMU smoke test and benches share.
#![no_std]

#[cfg(feature = "qemu")]
pub mod semihosting;

/// The model-core workload of the QEMU smoke test (also run on the host by build.rs).
pub mod smoke_case {
    include!("smoke_case.rs");
    include!(concat!(env!("OUT_DIR"), "/smoke_expected.rs"));
}
