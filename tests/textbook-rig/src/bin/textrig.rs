//! `textrig`: write a SIMULATED recording of the textbook rig and its true parameters.

use clap::{Parser, ValueEnum};
use std::process::ExitCode;
use textrig::{simulate, Drive, Experiment, Noise, Params, Start, Waveform};

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Wave {
    Sine,
    Square,
    Steps,
    Multisine,
    Chirp,
    Logchirp,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum StartArg {
    Demagnetised,
    Anhysteretic,
    History,
}

/// The textbook rig: an independent continuous-time simulation of the documented GMA physics.
#[derive(Parser, Debug)]
#[command(name = "textrig", version)]
struct Args {
    /// Model structure (effects joined by `+`, as `gma --model`).
    #[arg(long, default_value = "ja+mech")]
    structure: String,
    /// Waveform.
    #[arg(long, value_enum, default_value = "sine")]
    wave: Wave,
    /// Frequency [Hz] (sine, square; chirp start; multisine lowest tone).
    #[arg(long, default_value_t = 1.0)]
    freq: f64,
    /// Second frequency [Hz]: chirp end, multisine highest tone (default 10 × --freq).
    #[arg(long)]
    freq2: Option<f64>,
    /// Multisine tones.
    #[arg(long, default_value_t = 8)]
    tones: usize,
    /// Square-wave edge time [s].
    #[arg(long, default_value_t = 1e-3)]
    rise: f64,
    /// Step levels, comma separated (times --amp).
    #[arg(long, default_value = "0,1,-1,0.5")]
    levels: String,
    /// Hold time per step level [s].
    #[arg(long, default_value_t = 0.1)]
    hold: f64,
    /// Amplitude [A in current mode, V with `amp`].
    #[arg(long, default_value_t = 0.8)]
    amp: f64,
    /// Offset [A or V].
    #[arg(long, default_value_t = 0.0)]
    offset: f64,
    /// Logged duration [s].
    #[arg(long, default_value_t = 2.0)]
    duration: f64,
    /// Logging rate [Hz]; also sets the parameter file's dt_s.
    #[arg(long, default_value_t = 10_000.0)]
    rate: f64,
    /// Initial state.
    #[arg(long, value_enum, default_value = "demagnetised")]
    start: StartArg,
    /// With --start history: duration of the pre-drive (the same waveform) [s].
    #[arg(long, default_value_t = 1.0)]
    history_duration: f64,
    /// With --start history: amplitude of the pre-drive (default: --amp).
    #[arg(long)]
    history_amp: Option<f64>,
    /// Current ADC noise [LSB rms].
    #[arg(long, default_value_t = 0.0)]
    current_noise_lsb: f64,
    /// Do not quantise the logged current.
    #[arg(long)]
    no_quantise: bool,
    /// Displacement noise [µm rms].
    #[arg(long, default_value_t = 0.03)]
    disp_noise_um: f64,
    /// Log flux_density_T (search coil).
    #[arg(long)]
    flux: bool,
    /// Flux noise [T rms].
    #[arg(long, default_value_t = 0.2e-3)]
    flux_noise_t: f64,
    /// Log temperature_C (coil thermometer).
    #[arg(long)]
    temperature: bool,
    /// Thermometer noise [°C rms].
    #[arg(long, default_value_t = 0.01)]
    temp_noise_c: f64,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output CSV.
    #[arg(long)]
    out: String,
    /// Write the true parameters as a gma parameter file.
    #[arg(long)]
    truth_params: Option<String>,
    /// Override parameters from a gma parameter file.
    #[arg(long)]
    params_in: Option<String>,
}

fn run(a: Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut params = Params::terfenol();
    if let Some(p) = &a.params_in {
        params.apply_gma_toml(&std::fs::read_to_string(p)?)?;
    }
    params.dt_s = 1.0 / a.rate;
    let f2 = a.freq2.unwrap_or(10.0 * a.freq);
    let waveform = match a.wave {
        Wave::Sine => Waveform::Sine { freq_hz: a.freq },
        Wave::Square => Waveform::Square { freq_hz: a.freq, rise_s: a.rise },
        Wave::Steps => Waveform::Steps {
            levels: a.levels.split(',').map(|s| s.trim().parse::<f64>()).collect::<Result<_, _>>()?,
            hold_s: a.hold,
        },
        Wave::Multisine => Waveform::Multisine { f_lo_hz: a.freq, f_hi_hz: f2, tones: a.tones },
        Wave::Chirp | Wave::Logchirp => {
            Waveform::Chirp { f0_hz: a.freq, f1_hz: f2, log: matches!(a.wave, Wave::Logchirp) }
        }
    };
    let drive = Drive { waveform, amplitude: a.amp, offset: a.offset };
    let start = match a.start {
        StartArg::Demagnetised => Start::Demagnetised,
        StartArg::Anhysteretic => Start::Anhysteretic,
        StartArg::History => Start::History {
            drive: Drive { amplitude: a.history_amp.unwrap_or(a.amp), ..drive.clone() },
            duration_s: a.history_duration,
        },
    };
    let noise = Noise {
        current_lsb_rms: a.current_noise_lsb,
        quantise_current: !a.no_quantise,
        displacement_um_rms: a.disp_noise_um,
        flux_t_rms: a.flux_noise_t,
        temperature_c_rms: a.temp_noise_c,
    };
    let e = Experiment {
        structure: a.structure.clone(),
        params: params.clone(),
        drive,
        duration_s: a.duration,
        rate_hz: a.rate,
        start,
        noise,
        seed: a.seed,
        log_flux: a.flux,
        log_temperature: a.temperature,
    };
    let rec = simulate(&e)?;
    rec.write_csv(std::fs::File::create(&a.out)?)?;
    if let Some(p) = &a.truth_params {
        std::fs::write(p, params.to_gma_toml())?;
    }
    eprintln!(
        "textrig: SIMULATED `{}` {} samples -> {} ({} steps, {} rejected, {} reversals, {} rhs, {:.3} s)",
        a.structure,
        rec.time_s.len(),
        a.out,
        rec.stats.accepted,
        rec.stats.rejected,
        rec.stats.events,
        rec.stats.rhs_evals,
        rec.stats.seconds
    );
    Ok(())
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("textrig: error: {e}");
            ExitCode::FAILURE
        }
    }
}
