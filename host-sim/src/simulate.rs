//! `gma simulate`: a model-core actuator chain driven by a standard excitation, written as a
//! measurement CSV (contract columns). The data are simulated and the command says so on stderr.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use model_core::{Actuator, ActuatorParams, ModelSpec};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// Excitation waveforms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Waveform {
    /// bias + amplitude · sin(2π f t)
    Sine,
    /// bias ± amplitude, period 1/f
    Square,
    /// Linear chirp from f/10 to f over the duration.
    Chirp,
}

/// Options of `gma simulate`.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Model spec, e.g. `ja+mech+eddy` (see shared/docs/contracts.md for effect names).
    #[arg(long, default_value = "ja+mech")]
    pub model: String,
    /// Parameter file (TOML, as written by `gma fit --params-out`); default: a Terfenol-D demo set.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Excitation waveform.
    #[arg(long, value_enum, default_value = "sine")]
    pub waveform: Waveform,
    /// Excitation frequency [Hz] (end frequency for a chirp).
    #[arg(long, default_value_t = 50.0)]
    pub freq_hz: f64,
    /// Amplitude [A] of the coil current, or [V] of the command when the spec has `amp`.
    #[arg(long, default_value_t = 1.0)]
    pub amplitude: f64,
    /// DC bias [A] or [V], added to the excitation.
    #[arg(long, default_value_t = 1.0)]
    pub bias: f64,
    /// Duration [s].
    #[arg(long, default_value_t = 0.2)]
    pub duration_s: f64,
    /// Displacement sensor noise, standard deviation [µm].
    #[arg(long, default_value_t = 0.0)]
    pub noise_um: f64,
    /// Seed of the noise generator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output CSV (written atomically: temporary file, then rename).
    #[arg(long, short)]
    pub out: PathBuf,
}

/// Loads a parameter file, or the built-in demo set.
pub fn load_params(path: Option<&Path>) -> Result<ActuatorParams> {
    match path {
        None => Ok(ActuatorParams::TERFENOL_DEMO),
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            toml::from_str(&text).with_context(|| format!("{}: not a valid parameter file", p.display()))
        }
    }
}

/// Parses a spec, turning the byte range of an error into the offending word.
pub fn parse_spec(text: &str) -> Result<ModelSpec> {
    ModelSpec::parse(text).map_err(|e| match e {
        model_core::SpecError::UnknownEffect { start, end, suggestion } => {
            let hint = suggestion.map(|s| format!("; did you mean `{s}`?")).unwrap_or_default();
            anyhow::anyhow!("model spec `{text}`: unknown effect `{}`{hint}", &text[start..end])
        }
        other => anyhow::anyhow!("model spec `{text}`: {other}"),
    })
}

/// Runs the simulation and writes the CSV.
pub fn run(a: &SimulateArgs) -> Result<()> {
    let spec = parse_spec(&a.model)?;
    let params = load_params(a.params.as_deref())?;
    let model = Actuator::new(spec, &params).context("parameter set")?;
    for (name, v) in [("--freq-hz", a.freq_hz), ("--duration-s", a.duration_s)] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} must be a positive number, got {v}");
        }
    }
    if !(a.noise_um.is_finite() && a.noise_um >= 0.0) {
        bail!("--noise-um must be ≥ 0, got {}", a.noise_um);
    }
    let dt = params.dt_s as f64;
    let n = (a.duration_s / dt).round() as usize;
    let noise = Normal::new(0.0, a.noise_um).context("noise")?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(a.seed);

    let dir = a.out.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let tmp = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("creating a file in {}", dir.display()))?;
    let mut w = csv::Writer::from_writer(std::io::BufWriter::new(tmp.as_file()));
    let voltage = model.input_is_voltage();
    if voltage {
        w.write_record(["time_s", "command_V", "current_A", "displacement_um"])?;
    } else {
        w.write_record(["time_s", "current_A", "displacement_um"])?;
    }
    let mut s = model.rest_state();
    for k in 0..n {
        let t = k as f64 * dt;
        let phase = match a.waveform {
            Waveform::Chirp => {
                let (f0, f1) = (a.freq_hz / 10.0, a.freq_hz);
                2.0 * std::f64::consts::PI * (f0 * t + 0.5 * (f1 - f0) / a.duration_s * t * t)
            }
            _ => 2.0 * std::f64::consts::PI * a.freq_hz * t,
        };
        let x = match a.waveform {
            Waveform::Square => phase.sin().signum(),
            _ => phase.sin(),
        };
        let input = (a.bias + a.amplitude * x) as f32;
        let out = model.step(&mut s, input).with_context(|| format!("sample {k} (t = {t} s)"))?;
        let y_um = out.displacement_m as f64 * 1e6 + noise.sample(&mut rng);
        let row = if voltage {
            vec![format!("{t:.6}"), format!("{input}"), format!("{}", out.current_a), format!("{y_um:.5}")]
        } else {
            vec![format!("{t:.6}"), format!("{}", out.current_a), format!("{y_um:.5}")]
        };
        w.write_record(&row)?;
    }
    w.flush()?;
    drop(w);
    tmp.as_file().sync_all()?;
    tmp.persist(&a.out).with_context(|| format!("writing {}", a.out.display()))?.flush()?;
    eprintln!(
        "gma: wrote {} samples of SIMULATED data (model-core chain `{spec}`, {:?} {} Hz) to {}",
        n,
        a.waveform,
        a.freq_hz,
        a.out.display()
    );
    Ok(())
}
