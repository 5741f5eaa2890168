//! What the workbench writes, it reads back: `gma simulate` under arbitrary options and
//! `gma record` under arbitrary tick lengths and frame values either refuse with a message that
//! names an option, or write files that the measurement reader (the one `gma fit` uses) accepts,
//! with the values written.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use gma_control::telemetry::{Frame, MAX_ENCODED};
use host_sim::api::inputs::ReadArgs;
use host_sim::api::simulate::{run, SimulateArgs, Waveform};
use host_sim::plant::EddyModel;
use host_sim::recording::Recording;
use proptest::prelude::*;

/// Values from ordinary to absurd, as option values and telemetry fields.
fn wide() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1e3..1e3f64,
        (-12.0..40.0f64).prop_map(|e| 10f64.powf(e)),
        Just(0.0),
        Just(-0.0),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(1e-308),
    ]
}

fn waveform() -> impl Strategy<Value = Waveform> {
    prop_oneof![
        Just(Waveform::Sine),
        Just(Waveform::Square),
        Just(Waveform::Chirp),
        Just(Waveform::Multisine),
        Just(Waveform::Sweep)
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn simulate_refuses_or_writes_what_the_reader_accepts(
        model in prop_oneof![Just("ja+mech"), Just("linear"), Just("ja+amp+eddy"), Just("anhysteretic+delay")],
        waveform in waveform(),
        freq_hz in wide(),
        amplitude in wide(),
        bias in -2.0..2.0f64,
        duration_s in prop_oneof![1e-6..0.03f64, wide()],
        noise_um in prop_oneof![Just(0.0), wide()],
        quantum_um in prop_oneof![Just(0.0), wide()],
        offset_um in wide(),
        oversample in prop_oneof![1u32..5, Just(0), Just(1000)],
        search_coil in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("sim.csv");
        let args = SimulateArgs {
            model: model.into(), params: None, waveform, freq_hz, amplitude, bias, duration_s, noise_um,
            quantum_um, offset_um, oversample, eddy_model: EddyModel::Distributed, no_current: false,
            search_coil, flux_noise_mt: 0.5, seed: 7, out: out.clone(), overwrite: false, drive: None, initial_excursion: None, json: false, read: ReadArgs::default(), quiet: true,
        };
        match run(&args) {
            Err(e) => {
                let msg = format!("{e:#}");
                prop_assert!(!out.exists(), "refused, yet wrote {}", out.display());
                prop_assert!(msg.contains("--") || msg.contains("plausible") || msg.contains("plant input"),
                    "unclear refusal: {msg}");
            }
            Ok(_) => {
                let r = Recording::read(&out).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
                prop_assert!(r.len() >= 3);
                prop_assert_eq!(r.flux_density_t.is_some(), search_coil);
                // The demo parameter set samples at 10 kHz.
                prop_assert_eq!(r.len() as f64, (duration_s / 1e-4).round());
            }
        }
    }

    #[test]
    fn record_writes_only_what_the_reader_accepts(
        tick_s in prop_oneof![(-7.0..1.0f64).prop_map(|e| 10f64.powf(e)), wide()],
        values in proptest::collection::vec((wide(), wide()), 3..60),
    ) {
        let mut bytes = Vec::new();
        for (seq, (i, y)) in values.iter().enumerate() {
            let f = Frame { seq: seq as u32, reference_um: 0.0, command_v: 0.0, current_a: *i as f32,
                            displacement_um: *y as f32, faults: 0 };
            let mut buf = [0u8; MAX_ENCODED];
            let n = f.encode(&mut buf);
            bytes.extend_from_slice(&buf[..n]);
        }
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("rec.csv");
        let stop = Arc::new(AtomicBool::new(false));
        match host_sim::record::record(Box::new(std::io::Cursor::new(bytes)), &out, tick_s, stop) {
            Err(e) => {
                let msg = format!("{e:#}");
                prop_assert!(msg.contains("--tick-s") || msg.contains("no recording in the stream"), "{msg}");
            }
            Ok(sum) => {
                let mut rows = 0;
                for f in &sum.files {
                    let r = Recording::read(Path::new(f)).map_err(|e| TestCaseError::fail(format!("{e:#}")))?;
                    prop_assert!((r.dt_s() / tick_s - 1.0).abs() < 1e-3);
                    rows += r.len() as u64;
                }
                prop_assert_eq!(rows + sum.short, sum.frames - sum.invalid);
            }
        }
    }
}
