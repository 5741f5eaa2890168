//! QEMU smoke test (netduinoplus2: a Cortex-M4F with the board's memory map): runs real model-core code on the target and
//! compares it with the values the host computed at build time. Exit status 0 only when every
//! check passes. `-append force-fail` perturbs the expectation, to prove a failure is reported.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use firmware::semihosting::{cmdline, exit};
use firmware::smoke_case::{smoke_workload, SMOKE_EXPECTED};

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("qemu-smoke: PANIC {}", info);
    exit(101)
}

#[entry]
fn main() -> ! {
    let mut buf = [0u8; 128];
    let args = cmdline(&mut buf);
    let force_fail = args.split_whitespace().any(|a| a == "force-fail");

    let mut failures = 0u32;
    match smoke_workload() {
        Err(e) => {
            hprintln!("qemu-smoke: FAIL model parameters rejected: {}", e);
            failures += 1;
        }
        Ok(got) => {
            let scale = SMOKE_EXPECTED.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            for (i, (g, e)) in got.iter().zip(SMOKE_EXPECTED.iter()).enumerate() {
                let e = if force_fail { e + 0.01 * scale } else { *e };
                if !((g - e).abs() <= 1e-5 * scale) {
                    hprintln!("qemu-smoke: FAIL mechanics checkpoint {}: target {} µm, host {} µm", i, g, e);
                    failures += 1;
                }
            }
            hprintln!("qemu-smoke: mechanics ZOH, {} checkpoints vs host", got.len());
        }
    }
    if failures == 0 {
        hprintln!("qemu-smoke: PASS");
        exit(0)
    } else {
        hprintln!("qemu-smoke: FAIL ({} checks failed)", failures);
        exit(1)
    }
}
