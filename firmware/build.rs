//! Linker setup and generated data for the firmware binaries.
//!
//! Every binary links with the STM32G474RE map in the workspace-root `memory.x`. The QEMU binaries
//! use it too: QEMU's `netduinoplus2` (an STM32F405) has flash at 0x0800_0000 (1 MiB), SRAM at
//! 0x2000_0000 (128 KiB) and CCM at 0x1000_0000 (64 KiB), a superset of the G474's map.

use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let board = env::var_os("CARGO_FEATURE_BOARD").is_some();
    if qemu && board {
        panic!("build the firmware with either the `board` or the `qemu` feature, not both");
    }
    let memory = manifest.join("../memory.x");
    fs::copy(&memory, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rerun-if-changed=build.rs");
    write_smoke_expected(&out);
    write_drive_params(&out);

    // Only the ARM binaries get the cortex-m-rt (and defmt) linker scripts.
    if env::var("TARGET").is_ok_and(|t| t.starts_with("thumb")) {
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        if board {
            println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
        }
    }
}

/// The drive's model: `GMA_MODEL` (spec, default `ja+eddy+mech`) and `GMA_PARAMS` (a TOML file
/// from `gma fit --params-out`; default: the demo set), validated here as the firmware would
/// validate them at start-up, and compiled in as postcard bytes.
fn write_drive_params(out: &std::path::Path) {
    println!("cargo:rerun-if-env-changed=GMA_MODEL");
    println!("cargo:rerun-if-env-changed=GMA_PARAMS");
    let spec = env::var("GMA_MODEL").unwrap_or_else(|_| "ja+eddy+mech".to_string());
    let model = model_core::ModelSpec::parse(&spec).unwrap_or_else(|e| panic!("GMA_MODEL=`{spec}`: {e}"));
    let (source, params): (String, model_core::ActuatorParams) = match env::var("GMA_PARAMS") {
        Ok(path) => {
            println!("cargo:rerun-if-changed={path}");
            let text = fs::read_to_string(&path).unwrap_or_else(|e| panic!("GMA_PARAMS={path}: {e}"));
            (format!("GMA_PARAMS={path}"), read_params(&path, &text))
        }
        Err(_) => {
            println!(
                "cargo:warning=no GMA_PARAMS: the drive embeds the built-in demo set for `{spec}` (a simulated \
                 Terfenol-D rod, not your actuator); GMA_PARAMS=$PWD/p.toml from `gma fit` (firmware/README.md)"
            );
            ("the demo parameter set".to_string(), model_core::ActuatorParams::TERFENOL_DEMO)
        }
    };
    // Refused here rather than on the board (bridge never enabled): the set against its model,
    // and the compensator's model that gma-drive's controller builds from it.
    if let Err(e) = model_core::Actuator::new(model, &params) {
        panic!("{source} for model `{spec}`: {e}");
    }
    let tick_s = gma_control::ControlConfig::REFERENCE.current_loop.tick_s;
    if let Err(e) = gma_control::compensator_model(model, &params, tick_s) {
        panic!("{source}: the compensator for model `{spec}` at the {tick_s} s tick: {e}");
    }
    let bytes = postcard::to_stdvec(&params).expect("serialise parameters");
    let body = format!(
        "/// Model spec of the drive (GMA_MODEL at build time).\npub const MODEL_SPEC: &str = {spec:?};\n\
         /// Where the parameter set came from (GMA_PARAMS at build time, or the demo set).\n\
         pub const PARAMS_SOURCE: &str = {source:?};\n\
         /// Identified parameter set, postcard-encoded (GMA_PARAMS at build time).\n\
         pub const PARAMS_POSTCARD: &[u8] = &{bytes:?};\n"
    );
    fs::write(out.join("drive_params.rs"), body).expect("write drive_params.rs");
}

/// A parameter file as `gma` reads it: any format up to model-core's, the tables of effects and
/// laws it leaves out taken from the demo set (said as a build warning).
fn read_params(path: &str, text: &str) -> model_core::ActuatorParams {
    use model_core::effects::{parameter_tables, PARAMETER_FILE_FORMAT};
    let mut table: toml::Table =
        toml::from_str(text).unwrap_or_else(|e| panic!("GMA_PARAMS={path}: not a parameter file: {e}"));
    match table.remove("format_version") {
        None => {}
        Some(toml::Value::Integer(v)) if (1..=PARAMETER_FILE_FORMAT).contains(&v) => {}
        Some(v) => panic!(
            "GMA_PARAMS={path}: format_version = {v}: this build reads formats 1 to {PARAMETER_FILE_FORMAT}"
        ),
    }
    let demo =
        toml::Table::try_from(model_core::ActuatorParams::TERFENOL_DEMO).expect("serialise the demo set");
    let missing: Vec<&str> = parameter_tables().filter(|t| !table.contains_key(*t)).collect();
    for t in missing {
        println!("cargo:warning=GMA_PARAMS={path} has no `{t}`: the demo set's value stands in");
        table.insert(t.to_string(), demo[t].clone());
    }
    table.try_into().unwrap_or_else(|e| panic!("GMA_PARAMS={path}: not a parameter file: {e}"))
}

/// Host-side expected values for the QEMU smoke test, from the very same workload code.
mod smoke {
    #![allow(dead_code)]
    include!("src/smoke_case.rs");
}

fn write_smoke_expected(out: &std::path::Path) {
    let r = smoke::smoke_workload().expect("smoke workload parameters are valid");
    let body = format!(
        "/// Mechanics displacements [µm] the host computed for the smoke workload (generated by build.rs).\n\
         pub const EXPECTED_MECHANICS_UM: [f32; {n}] = {:?};\n\
         /// Compensated-chain displacements [µm] the host computed.\n\
         pub const EXPECTED_CHAIN_UM: [f32; {n}] = {:?};\n\
         /// Compensator commands [V] the host computed.\n\
         pub const EXPECTED_COMMAND_V: [f32; {n}] = {:?};\n\
         /// Tracking RMS error [%] the host computed.\n\
         pub const EXPECTED_TRACKING_RMS_PERCENT: f32 = {:?};\n\
         /// Preisach compensated-chain displacements [µm] the host computed.\n\
         pub const EXPECTED_PREISACH_UM: [f32; {n}] = {:?};\n\
         /// Its tracking RMS error [%] the host computed.\n\
         pub const EXPECTED_PREISACH_TRACKING_RMS_PERCENT: f32 = {:?};\n",
        r.mechanics_um,
        r.chain_um,
        r.command_v,
        r.tracking_rms_percent,
        r.preisach_um,
        r.preisach_tracking_rms_percent,
        n = r.chain_um.len(),
    );
    fs::write(out.join("smoke_expected.rs"), body).expect("write smoke_expected.rs");
    println!("cargo:rerun-if-changed=src/smoke_case.rs");
}
