//! `refrig`: write a simulated Terfenol-D rig recording as CSV.
//!
//! ```text
//! refrig [--out FILE] [--duration S] [--rate HZ] [--seed N] [--law NAME]
//!        [--wave sine|square|chirp|multisine|sweep|steps|dc] [--amp V] [--freq HZ]
//!        [--f-end HZ] [--offset V] [--current-mode] [--shells N] [--search-coil]
//!        [--disable EFFECT[,EFFECT…]] [--truth] [--list-effects]
//! ```

use refrig::{AmplifierMode, Drive, Effects, Law, Rig, SearchCoil, Waveform};
use std::io::Write;
use std::process::ExitCode;

const USAGE: &str = "usage: refrig [--out FILE] [--duration S] [--rate HZ] [--seed N]
              [--law ja-original|ja-bulk|ja-inverse|preisach]
              [--wave sine|square|chirp|multisine|sweep|steps|dc] [--amp V] [--freq HZ]
              [--f-end HZ] [--offset V] [--current-mode] [--shells N] [--search-coil]
              [--disable EFFECT[,EFFECT...]] [--truth] [--list-effects]
Writes time_s,command_V,current_A,displacement_um,temperature_C (CSV) to FILE or stdout;
--search-coil adds flux_density_T (a search coil on the rod, read through an integrator).
Defaults: the Terfenol-D set of refrig::Rig::default(), 0.2 s at 10 kHz, 1 V 50 Hz sine.";

struct Args {
    rig: Rig,
    out: Option<String>,
    truth: bool,
}

fn num(v: Option<String>, name: &str) -> Result<f64, String> {
    let s = v.ok_or_else(|| format!("{name} needs a value"))?;
    let x: f64 = s.parse().map_err(|_| format!("{name}: not a number: {s}"))?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("{name}: not finite: {s}"))
    }
}

fn parse() -> Result<Option<Args>, String> {
    let mut rig = Rig::default();
    let mut out = None;
    let mut truth = false;
    let (mut wave, mut amp, mut freq, mut f_end, mut offset) = ("sine".to_string(), 1.0, 50.0, None, 0.0);
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(None);
            }
            "--list-effects" => {
                for n in Effects::NAMES {
                    println!("{n}");
                }
                return Ok(None);
            }
            "--out" | "-o" => out = Some(it.next().ok_or("--out needs a file")?),
            "--duration" => rig.duration_s = num(it.next(), "--duration")?,
            "--rate" => rig.sample_rate_hz = num(it.next(), "--rate")?,
            "--seed" => {
                let s = it.next().ok_or("--seed needs a value")?;
                rig.seed = s.parse().map_err(|_| format!("--seed: not an integer: {s}"))?;
            }
            "--law" => {
                let s = it.next().ok_or("--law needs a value")?;
                rig.material.law = Law::from_name(&s).ok_or_else(|| format!("unknown law: {s}"))?;
            }
            "--wave" => wave = it.next().ok_or("--wave needs a value")?,
            "--amp" => amp = num(it.next(), "--amp")?,
            "--freq" => freq = num(it.next(), "--freq")?,
            "--f-end" => f_end = Some(num(it.next(), "--f-end")?),
            "--offset" => offset = num(it.next(), "--offset")?,
            "--current-mode" => rig.amplifier.mode = AmplifierMode::Current,
            "--shells" => rig.rod.shells = num(it.next(), "--shells")? as usize,
            "--truth" => truth = true,
            "--search-coil" => rig.search_coil = Some(SearchCoil::LAB),
            "--disable" => {
                let list = it.next().ok_or("--disable needs a list of effects")?;
                for name in list.split(',').filter(|s| !s.is_empty()) {
                    if !rig.effects.set(name, false) {
                        return Err(format!("unknown effect: {name} (see --list-effects)"));
                    }
                }
            }
            other => return Err(format!("unknown argument: {other}\n{USAGE}")),
        }
    }
    let d = rig.duration_s;
    let waveform = match wave.as_str() {
        "sine" => Waveform::Sine { amplitude_v: amp, frequency_hz: freq, phase_rad: 0.0 },
        "square" => Waveform::Square { amplitude_v: amp, frequency_hz: freq },
        "chirp" => Waveform::Chirp {
            amplitude_v: amp,
            f_start_hz: freq,
            f_end_hz: f_end.unwrap_or(freq * 40.0),
            duration_s: d,
            logarithmic: true,
        },
        "multisine" => {
            let f_hi = f_end.unwrap_or(freq * 40.0);
            let n = 12;
            let freqs: Vec<f64> =
                (0..n).map(|k| freq * (f_hi / freq).powf(k as f64 / (n - 1) as f64)).collect();
            Waveform::schroeder_multisine(amp, &freqs)
        }
        "sweep" => Waveform::AmplitudeSweep {
            amplitude_start_v: amp * 0.05,
            amplitude_end_v: amp,
            frequency_hz: freq,
            duration_s: d,
        },
        "steps" => Waveform::Steps { levels_v: vec![0.0, amp, -amp, 0.5 * amp, 0.0], dwell_s: d / 5.0 },
        "dc" => Waveform::Dc,
        other => return Err(format!("unknown waveform: {other}")),
    };
    rig.drive = Drive { waveform, offset_v: offset };
    Ok(Some(Args { rig, out, truth }))
}

fn main() -> ExitCode {
    let args = match parse() {
        Ok(Some(a)) => a,
        Ok(None) => return ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("refrig: {e}");
            return ExitCode::from(2);
        }
    };
    let started = std::time::Instant::now();
    let rec = match args.rig.simulate() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("refrig: {e}");
            return ExitCode::FAILURE;
        }
    };
    let res = match &args.out {
        Some(path) if path != "-" => std::fs::File::create(path).and_then(|f| {
            let mut w = std::io::BufWriter::new(f);
            rec.write_csv(&mut w, args.truth)?;
            w.flush()
        }),
        _ => {
            let mut w = std::io::BufWriter::new(std::io::stdout().lock());
            rec.write_csv(&mut w, args.truth).and_then(|_| w.flush())
        }
    };
    if let Err(e) = res {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            // The reader (e.g. `head`) has seen enough.
            return ExitCode::SUCCESS;
        }
        eprintln!("refrig: cannot write: {e}");
        return ExitCode::FAILURE;
    }
    let s = rec.stats;
    eprintln!(
        "refrig: {} samples, {} accepted / {} rejected steps, {} rhs evaluations, {:.2} s",
        rec.len(),
        s.accepted,
        s.rejected,
        s.rhs_evals,
        started.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}
