//! The hidden-effect suite on the INDEPENDENT reference rig (`tests/reference-rig`, crate
//! `refrig`, SIMULATED data written without reading model-core). Each registry effect is hidden
//! in turn: the rig has it (with every other effect on), the engineer's model lacks it, and
//! `diagnose` must name it; the complete model must raise no alarm. Prints one table with the
//! issue-13 targets beside the measured figures; it asserts only that the machinery runs
//! (finite figures, one row per case), because the targets are not met yet (docs/validation.md).
//!
//! Every case is diagnosed twice, on the same recordings: with the command, current and
//! displacement only, and with the rig's search coil as well (`flux_density_T`, on which the rod's
//! effects are judged); `GMA_REFRIG_FLUX=off` or `only` runs one of the two. The rig also logs
//! its coil's temperature; `GMA_REFRIG_THERMOMETER=on` keeps that column in both (coil heating
//! is then judged on the temperature).
//!
//! Run (reduced: law `ja-bulk`, seed 1, about two minutes once the recordings are cached):
//!   cargo test --release -p host-sim --test refrig_suite hidden_effects -- --ignored --nocapture
//! Full grid (4 laws × 2 seeds, about 20 minutes on 2 cores): `GMA_REFRIG_SUITE=full` in front
//! of the same command; one law on both seeds: `GMA_REFRIG_SUITE=preisach` (or `ja-original`,
//! `ja-bulk`, `ja-inverse`).
//! `GMA_REFRIG_HEAT=on` adds a heat run to the fit and to the validation files ([`heat_runs`]).
//! `ja_forms` (`diagnose --ja-variants` per J–A rig law) and `error_budget` are separate tests.
//! Generated CSVs are cached under `target/refrig-suite/` (the rig costs 1–2 s of CPU per
//! simulated second); delete the folder after changing the rig.

use std::path::{Path, PathBuf};

use host_sim::diagnose::diagnose;
use host_sim::fit::FitOptions;
use host_sim::recording::Recording;
use host_sim::simulation::preisach_plane_advice;
use host_sim::warning::Warning;
use model_core::{ActuatorParams, Effect, ModelSpec};
use rayon::prelude::*;
use refrig::{Drive, JaVariant, Law, Rig, SearchCoil, Waveform};

/// One excitation of the suite: waveform, offset [V], duration [s], sample rate [Hz].
struct Excitation {
    label: &'static str,
    waveform: Waveform,
    offset_v: f64,
    duration_s: f64,
    sample_rate_hz: f64,
}

/// The suite's sample rate, but for the heat runs.
const RATE_HZ: f64 = 10_000.0;

fn sine(
    label: &'static str,
    amplitude_v: f64,
    frequency_hz: f64,
    offset_v: f64,
    duration_s: f64,
) -> Excitation {
    Excitation {
        label,
        waveform: Waveform::Sine { amplitude_v, frequency_hz, phase_rad: 0.0 },
        offset_v,
        duration_s,
        sample_rate_hz: RATE_HZ,
    }
}

/// The recordings an engineer would take to see every effect the rig has, each where it shows:
/// large slow loops (hysteresis, saturation), broadband drive past the first resonance
/// (eddy currents, mechanics, amplifier, sensor delay: at 20 Hz–2.5 kHz they change the
/// displacement by 2–28 % of its range, at 12–70 Hz by 0.2–4 %) and held steps (aftereffect
/// creep). Fit files: a 20 Hz sine, a 10–400 Hz multisine, a 20 Hz–2.5 kHz log chirp and a
/// staircase of 0.25 s steps. Validation files: other frequencies, amplitudes and waveforms (a
/// biased 70 Hz sine, an amplitude-ramped 12 Hz sine with nested minor loops, a biased
/// 50 Hz–2 kHz multisine, another staircase).
fn excitations() -> (Vec<Excitation>, Vec<Excitation>) {
    let low: Vec<f64> = (1..=40).map(|k| 10.0 * k as f64).collect();
    let high: Vec<f64> = (1..=40).map(|k| 50.0 * k as f64).collect();
    let steps = |label, levels_v: &[f64], duration_s| Excitation {
        label,
        waveform: Waveform::Steps { levels_v: levels_v.to_vec(), dwell_s: 0.25 },
        offset_v: 0.0,
        duration_s,
        sample_rate_hz: RATE_HZ,
    };
    let fit = vec![
        sine("sine20", 1.2, 20.0, 0.0, 0.3),
        Excitation {
            label: "multisine",
            waveform: Waveform::schroeder_multisine(1.0, &low),
            offset_v: 0.0,
            duration_s: 0.3,
            sample_rate_hz: RATE_HZ,
        },
        Excitation {
            label: "chirp20-2500",
            waveform: Waveform::Chirp {
                amplitude_v: 0.8,
                f_start_hz: 20.0,
                f_end_hz: 2500.0,
                duration_s: 0.4,
                logarithmic: true,
            },
            offset_v: 0.0,
            duration_s: 0.4,
            sample_rate_hz: RATE_HZ,
        },
        steps("steps", &[0.0, 1.2, 0.3, -0.8, 0.6, -1.2, 0.0], 1.75),
    ];
    let val = vec![
        sine("sine70", 0.8, 70.0, 0.2, 0.2),
        Excitation {
            label: "ramp12",
            waveform: Waveform::AmplitudeSweep {
                amplitude_start_v: 0.4,
                amplitude_end_v: 1.4,
                frequency_hz: 12.0,
                duration_s: 0.35,
            },
            offset_v: 0.0,
            duration_s: 0.35,
            sample_rate_hz: RATE_HZ,
        },
        Excitation {
            label: "ms50-2000",
            waveform: Waveform::schroeder_multisine(1.2, &high),
            offset_v: 0.1,
            duration_s: 0.3,
            sample_rate_hz: RATE_HZ,
        },
        steps("steps-val", &[0.0, -1.0, 0.8, -0.2, 1.3, -0.5], 1.5),
    ];
    (fit, val)
}

/// The heat runs an engineer records to see coil heating, one to fit and one to validate: a
/// slow sine at high current for seconds, logged at 200 Hz (the coil's time constant is minutes:
/// what shows is its initial rate of rise, about 0.1 °C/s here). The other files are 0.2–1.75 s
/// long: the coil warms by 0.01–0.1 °C in them, at the thermometer's noise (0.02 °C). Fit: 2 Hz,
/// 1.2 V about 0.3 V, 10 s; validation: 3 Hz, 1.0 V about 0.2 V, 8 s.
fn heat_runs() -> (Excitation, Excitation) {
    let slow = |label, amplitude_v, frequency_hz, offset_v, duration_s| Excitation {
        sample_rate_hz: 200.0,
        ..sine(label, amplitude_v, frequency_hz, offset_v, duration_s)
    };
    (slow("heat2", 1.2, 2.0, 0.3, 10.0), slow("heat3", 1.0, 3.0, 0.2, 8.0))
}

fn cache_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target"));
    target.join("refrig-suite")
}

/// The rig's recording for one excitation (read from the cache or simulated and cached).
fn recording(
    law: Law,
    law_name: &str,
    hysteresis: bool,
    seed: u64,
    exc: &Excitation,
    salt: u64,
) -> Recording {
    let dir = cache_dir();
    std::fs::create_dir_all(&dir).expect("cache folder");
    let file = dir.join(format!(
        "{law_name}-{}-s{seed}-{}-coil.csv",
        if hysteresis { "full" } else { "anhysteretic" },
        exc.label
    ));
    if !file.exists() {
        let mut rig = Rig {
            sample_rate_hz: exc.sample_rate_hz,
            duration_s: exc.duration_s,
            seed: seed * 100 + salt,
            drive: Drive { waveform: exc.waveform.clone(), offset_v: exc.offset_v },
            ..Rig::default()
        };
        rig.material.law = law;
        rig.effects.hysteresis = hysteresis;
        rig.search_coil = Some(SearchCoil::LAB);
        let rec = rig.simulate().expect("refrig simulation");
        let tmp = file.with_extension("tmp");
        rec.write_csv(std::io::BufWriter::new(std::fs::File::create(&tmp).expect("cache file")), false)
            .expect("write cache");
        std::fs::rename(&tmp, &file).expect("cache rename");
    }
    Recording::read(&file).expect("read cached recording")
}

/// What the engineer recorded: the rig's files with or without the search coil's column.
#[derive(Clone, Copy, PartialEq)]
enum Channels {
    /// Command, current and displacement (what most rigs record).
    DisplacementOnly,
    /// And the search coil's flux density.
    WithSearchCoil,
}

impl Channels {
    fn label(self) -> String {
        let base = match self {
            Channels::DisplacementOnly => "displacement only",
            Channels::WithSearchCoil => "with a search coil",
        };
        if Self::thermometer() {
            format!("{base} + thermometer")
        } else {
            base.to_string()
        }
    }

    /// Whether the coil's temperature column is kept (`GMA_REFRIG_THERMOMETER=on`).
    fn thermometer() -> bool {
        std::env::var("GMA_REFRIG_THERMOMETER").is_ok_and(|v| v == "on")
    }

    fn apply(self, files: &[Recording]) -> Vec<Recording> {
        files
            .iter()
            .cloned()
            .map(|mut r| {
                if self == Channels::DisplacementOnly {
                    r.flux_density_t = None;
                }
                if !Self::thermometer() {
                    r.temperature_c = None;
                }
                r
            })
            .collect()
    }

    /// Both, or the one `GMA_REFRIG_FLUX` names (`off`: displacement only; `only`: with the coil).
    fn chosen() -> Vec<Channels> {
        match std::env::var("GMA_REFRIG_FLUX").as_deref() {
            Ok("off") => vec![Channels::DisplacementOnly],
            Ok("only") => vec![Channels::WithSearchCoil],
            _ => vec![Channels::DisplacementOnly, Channels::WithSearchCoil],
        }
    }
}

/// The engineer's complete structure for a law: every registry effect the rig has.
fn complete(law: Effect) -> ModelSpec {
    [
        Effect::EddyCurrent,
        Effect::MechanicalDynamics,
        Effect::AmplifierDynamics,
        Effect::MagneticAftereffect,
        Effect::ThermalDrift,
        Effect::SensorDelay,
    ]
    .into_iter()
    .fold(ModelSpec::LINEAR.with(law), |s, e| s.with(e))
}

/// The structure without `hidden` (the law effects swap the magnetization law).
/// The engineer's model with `hidden` left out, on a rig whose hysteresis the registry calls
/// `law` (`hysteresis` for J–A, `preisach`).
fn without(hidden: Effect, law: Effect) -> ModelSpec {
    match hidden {
        // Saturation hidden: linear law (the rig runs anhysteretic).
        Effect::Saturation => [
            Effect::EddyCurrent,
            Effect::MechanicalDynamics,
            Effect::AmplifierDynamics,
            Effect::MagneticAftereffect,
            Effect::ThermalDrift,
            Effect::SensorDelay,
        ]
        .into_iter()
        .fold(ModelSpec::LINEAR, |s, e| s.with(e)),
        Effect::Hysteresis => complete(Effect::Saturation),
        // The engineer who does not know the rod is a Preisach material starts from J–A.
        Effect::Preisach => complete(Effect::Hysteresis),
        e => {
            let others: Vec<Effect> = [
                Effect::EddyCurrent,
                Effect::MechanicalDynamics,
                Effect::AmplifierDynamics,
                Effect::MagneticAftereffect,
                Effect::ThermalDrift,
                Effect::SensorDelay,
            ]
            .into_iter()
            .filter(|&x| x != e)
            .collect();
            others.into_iter().fold(ModelSpec::LINEAR.with(law), |s, x| s.with(x))
        }
    }
}

/// The engineer's parameter file: the demo set with the coil's turns and bias as the rig's
/// builder knows them (1000 turns, 80 mm, k_f 1.1; 20 kA/m magnet).
fn engineer_init() -> ActuatorParams {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.coil.turns_per_m = 11_364.0;
    p.coil.bias_a_per_m = 20_000.0;
    p
}

struct Row {
    channels: Channels,
    law: &'static str,
    seed: u64,
    hidden: &'static str,
    named: String,
    before: f64,
    after: f64,
    channel: &'static str,
}

#[test]
#[ignore = "minutes of CPU: run with --ignored (see the file's header)"]
fn hidden_effects_on_the_independent_rig() {
    let all_laws = [
        ("ja-original", Law::JilesAtherton(JaVariant::Original1986)),
        ("ja-bulk", Law::JilesAtherton(JaVariant::BulkVenkataraman)),
        ("ja-inverse", Law::JilesAtherton(JaVariant::InverseSadowski)),
        ("preisach", Law::Preisach),
    ];
    // `full`: every law; a law's name: that law; both with seeds 1 and 2.
    let choice = std::env::var("GMA_REFRIG_SUITE").unwrap_or_default();
    let full = !choice.is_empty();
    let laws: Vec<(&'static str, Law)> = match choice.as_str() {
        "" => vec![all_laws[1]],
        "full" => all_laws.to_vec(),
        name => {
            let law = all_laws.iter().find(|(n, _)| *n == name);
            vec![*law.unwrap_or_else(|| panic!("GMA_REFRIG_SUITE={name}: not `full` nor a law of the suite"))]
        }
    };
    let seeds: &[u64] = if full { &[1, 2] } else { &[1] };
    let (mut fit_exc, mut val_exc) = excitations();
    if std::env::var("GMA_REFRIG_HEAT").is_ok_and(|v| v == "on") {
        let (heat_fit, heat_val) = heat_runs();
        fit_exc.push(heat_fit);
        val_exc.push(heat_val);
    }
    let init = engineer_init();
    let mut rows = Vec::new();
    let mut forms: Vec<(&str, &str)> = Vec::new();
    for &(law_name, law) in &laws {
        for &seed in seeds {
            let files = |hysteresis: bool| {
                // Simulated in parallel the first time (the rig is serial).
                let fit: Vec<Recording> = fit_exc
                    .par_iter()
                    .enumerate()
                    .map(|(i, e)| recording(law, law_name, hysteresis, seed, e, i as u64))
                    .collect();
                let val: Vec<Recording> = val_exc
                    .par_iter()
                    .enumerate()
                    .map(|(i, e)| recording(law, law_name, hysteresis, seed, e, 10 + i as u64))
                    .collect();
                (fit, val)
            };
            let full_rig = files(true);
            // The engineer sets the Preisach plane as `gma` advises from the fit files (a plane
            // far wider than the fields they reach is said, with the value to set).
            let mut init = init;
            if let Some(Warning::PreisachPlaneWide { advised, .. }) =
                preisach_plane_advice(complete(Effect::Preisach), &init, &full_rig.0)
            {
                init.preisach.h_max_a_per_m = advised as f32;
            }
            // The engineer's first step on a J–A rig: which of our forms fits it
            // (`diagnose --ja-variants` on the complete structure, displacement only, as
            // documented); every case of this rig then uses the form it names.
            let law_effect = if matches!(law, Law::Preisach) { Effect::Preisach } else { Effect::Hysteresis };
            let init = if law_effect == Effect::Hysteresis {
                let rows = ja_forms_of(&init, &full_rig.0, &full_rig.1).ja_variants.expect("variant scores");
                let named = rows.iter().find(|r| r.fits_better).map(|r| r.variant);
                let scores: Vec<String> =
                    rows.iter().map(|r| format!("{} {:.2} %", r.variant, r.nrmse * 100.0)).collect();
                println!(
                    "{law_name} s{seed}: `--ja-variants` names {} ({})",
                    named.unwrap_or("none"),
                    scores.join(", ")
                );
                forms.push((law_name, named.unwrap_or("bulk (given)")));
                let mut init = init;
                if let Some(v) = named {
                    init.ja.variant =
                        model_core::magnetization::JaVariant::from_name(v).expect("a form of ours");
                }
                init
            } else {
                init
            };
            let mut cases: Vec<Option<Effect>> = vec![
                Some(Effect::Saturation),
                Some(Effect::Hysteresis),
                Some(Effect::EddyCurrent),
                Some(Effect::MechanicalDynamics),
                Some(Effect::AmplifierDynamics),
                Some(Effect::MagneticAftereffect),
                Some(Effect::ThermalDrift),
                Some(Effect::SensorDelay),
                None,
            ];
            // On a Preisach rig the complete model has the Preisach law, and Preisach is hidden
            // once: the engineer's model has J–A instead.
            if law_effect == Effect::Preisach {
                cases.insert(2, Some(Effect::Preisach));
            }
            for (channels, hidden) in
                Channels::chosen().into_iter().flat_map(|c| cases.iter().map(move |&h| (c, h)))
            {
                let (model, data) = match hidden {
                    Some(Effect::Saturation) => (without(Effect::Saturation, law_effect), files(false)),
                    Some(e) => (without(e, law_effect), (full_rig.0.clone(), full_rig.1.clone())),
                    None => (complete(law_effect), (full_rig.0.clone(), full_rig.1.clone())),
                };
                let data = (channels.apply(&data.0), channels.apply(&data.1));
                let started = std::time::Instant::now();
                let d = diagnose(model, &init, &data.0, &data.1, FitOptions::default()).expect("diagnose");
                let before = d.nrmse_val.expect("validation files given");
                let named = d.verdict.map_or("none".to_string(), |e| e.name().to_string());
                let hit = hidden.and_then(|h| d.candidates.iter().find(|c| c.effect == h));
                let (after, channel, cand_before) = match hit {
                    Some(c) => (c.nrmse_after, c.channel, c.nrmse_before),
                    None => (before, "displacement", before),
                };
                eprintln!(
                    "{law_name} s{seed} ({}) hidden {:?}: {named} ({:.0} s)\n{d}",
                    channels.label(),
                    hidden.map(|e| e.name()),
                    started.elapsed().as_secs_f64()
                );
                assert!(before.is_finite() && after.is_finite(), "non-finite NRMSE");
                rows.push(Row {
                    channels,
                    law: law_name,
                    seed,
                    hidden: hidden.map_or("complete", |e| e.name()),
                    named,
                    before: cand_before,
                    after,
                    channel,
                });
            }
        }
    }
    println!(
        "\n| recorded | law | seed | hidden effect | named | baseline val NRMSE | with the hidden effect | cut × | channel |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {} | {} | {} | {} | {:.2} % | {:.2} % | {:.2} | {} |",
            r.channels.label(),
            r.law,
            r.seed,
            r.hidden,
            r.named,
            r.before * 100.0,
            r.after * 100.0,
            r.before / r.after.max(1e-12),
            r.channel
        );
    }
    for (channels, &(law_name, _)) in
        Channels::chosen().into_iter().flat_map(|c| laws.iter().map(move |l| (c, l)))
    {
        let of_law = |r: &&Row| r.channels == channels && r.law == law_name;
        let hidden: Vec<&Row> = rows.iter().filter(of_law).filter(|r| r.hidden != "complete").collect();
        let named = hidden.iter().filter(|r| r.named == r.hidden).count();
        let mut cuts: Vec<f64> = hidden.iter().map(|r| r.before / r.after.max(1e-12)).collect();
        cuts.sort_by(f64::total_cmp);
        let median = cuts.get(cuts.len() / 2).copied().unwrap_or(f64::NAN);
        let complete: Vec<&Row> = rows.iter().filter(of_law).filter(|r| r.hidden == "complete").collect();
        let alarms = complete.iter().filter(|r| r.named != "none").count();
        let form: Vec<&str> = forms.iter().filter(|f| f.0 == law_name).map(|f| f.1).collect();
        println!(
            "{law_name}{}, {}: named {named} of {} (target ≥ 8 of 9 per seed), median cut {median:.2}× (target ≥ 3×), \
             smallest {:.2}× (target ≥ 1.5×), false alarms on the complete case {alarms} of {}, complete val NRMSE {} \
             (target ≤ 2 %)",
            if form.is_empty() { String::new() } else { format!(" (J–A form per seed: {})", form.join(", ")) },
            channels.label(),
            hidden.len(),
            cuts.first().copied().unwrap_or(f64::NAN),
            complete.len(),
            complete.iter().map(|r| format!("{:.2} %", r.before * 100.0)).collect::<Vec<_>>().join(", ")
        );
    }
    // Nine cases per law and seed, ten under Preisach (the law itself hidden once).
    let preisach_laws = laws.iter().filter(|(_, l)| matches!(l, Law::Preisach)).count();
    let per_channels = (laws.len() * 9 + preisach_laws) * seeds.len();
    assert_eq!(rows.len(), Channels::chosen().len() * per_channels);
}

/// The seed-1 rig (seed 100 + `salt`, as the suite's recordings) under `law` driven by `exc`
/// with `switches` applied to its effects, written to `path` and read back as a user's file.
fn seed_one_rig(
    law: Law,
    exc: &Excitation,
    salt: u64,
    switches: &[fn(&mut refrig::Effects)],
    path: &Path,
) -> Recording {
    let mut rig = Rig {
        duration_s: exc.duration_s,
        seed: 100 + salt,
        drive: Drive { waveform: exc.waveform.clone(), offset_v: exc.offset_v },
        ..Rig::default()
    };
    rig.material.law = law;
    switches.iter().for_each(|s| s(&mut rig.effects));
    let mut bytes = Vec::new();
    rig.simulate().expect("refrig simulation").write_csv(&mut bytes, false).expect("csv");
    std::fs::write(path, bytes).expect("write");
    Recording::read(path).expect("read")
}

/// Where the complete structure's error comes from on the independent rig: the rig with all
/// effects on, then with one rig feature switched off at a time; the complete J–A structure
/// (the rig's variant where we have it) fitted on the fit files, scored per validation file
/// after the burn-in. Prints only. The Jiles 1986 rig by default; `GMA_BUDGET_LAW=preisach`
/// takes the Preisach rig and the complete `preisach` structure; `GMA_BUDGET_ONLY=nothing` (or
/// another switch's name) runs that row alone.
///   cargo test --release -p host-sim --test refrig_suite error_budget -- --ignored --nocapture
#[test]
#[ignore = "minutes of CPU: run with --ignored"]
fn error_budget_of_the_complete_structure() {
    let (fit_exc, val_exc) = excitations();
    let preisach = std::env::var("GMA_BUDGET_LAW").is_ok_and(|v| v == "preisach");
    let law = if preisach { Law::Preisach } else { Law::JilesAtherton(JaVariant::Original1986) };
    let mut init = engineer_init();
    // `GMA_BUDGET_VARIANT` names another of our J–A forms for the fit (default `ja1986`).
    let variant = std::env::var("GMA_BUDGET_VARIANT").unwrap_or_else(|_| "ja1986".into());
    init.ja.variant = model_core::magnetization::JaVariant::from_name(&variant)
        .unwrap_or_else(|| panic!("GMA_BUDGET_VARIANT={variant}: not one of our J–A forms"));
    let model = complete(if preisach { Effect::Preisach } else { Effect::Hysteresis });
    type Switch = fn(&mut refrig::Effects);
    let switches: Vec<(&str, Switch)> = vec![
        ("nothing", |_| {}),
        ("eddy_currents", |e| e.eddy_currents = false),
        ("prestress", |e| e.prestress = false),
        ("delta_e", |e| e.delta_e = false),
        ("second_mode", |e| e.second_mode = false),
        ("second_mode+delta_e", |e| {
            e.second_mode = false;
            e.delta_e = false
        }),
        ("prehistory", |e| e.prehistory = false),
        ("current_limit", |e| e.current_limit = false),
        ("sensor_offset_drift", |e| e.sensor_offset_drift = false),
        ("coil_heating", |e| e.coil_heating = false),
    ];
    let only = std::env::var("GMA_BUDGET_ONLY").ok();
    for (name, switch) in switches.into_iter().filter(|(n, _)| only.as_deref().is_none_or(|o| o == *n)) {
        let run = |exc: &Excitation, salt: u64| {
            let tag = if preisach { "preisach-" } else { "" };
            std::fs::create_dir_all(cache_dir()).expect("cache folder");
            let path = cache_dir().join(format!("budget-{tag}{name}-{}.csv", exc.label));
            seed_one_rig(law, exc, salt, &[switch], &path)
        };
        let fit_files: Vec<Recording> = fit_exc.iter().enumerate().map(|(i, e)| run(e, i as u64)).collect();
        let val_files: Vec<Recording> =
            val_exc.iter().enumerate().map(|(i, e)| run(e, 10 + i as u64)).collect();
        let f = host_sim::fit::fit(model, &init, &fit_files, FitOptions::default()).expect("fit");
        let score = |rec: &Recording| {
            let sim = host_sim::simulation::simulate(model, &f.params, rec).expect("simulate");
            let k = host_sim::diagnose::burn_in(rec);
            let m = &rec.displacement_um.as_deref().expect("displacement")[k..];
            let y = &sim.displacement_um[k..];
            // The sensor's offset is not a model property: scored as the fit scores it.
            let off = m.iter().zip(y).map(|(a, b)| a - b).sum::<f64>() / m.len() as f64;
            let shifted: Vec<f64> = y.iter().map(|v| v + off).collect();
            host_sim::score::nrmse(m, &shifted) * 100.0
        };
        let fit: Vec<String> = fit_files.iter().map(|r| format!("{:.2}", score(r))).collect();
        let val: Vec<String> = val_files.iter().map(|r| format!("{:.2}", score(r))).collect();
        println!("rig without {name:>20}: fit files {} %, validation {} %", fit.join(" / "), val.join(" / "));
    }
}

/// How much each rig effect shows in the suite's files, whatever a model does: the NRMSE (after
/// the burn-in, mean removed, as the suite scores) between the noise-free rig and (first column)
/// the rig with its sensor noise, quantisation and offset drift, then the noise-free rig with one
/// effect switched off. An effect far below the first column cannot be seen in these files by any
/// diagnosis, and the cut it allows is bounded by it. The `ja-bulk` rig by default;
/// `GMA_VISIBILITY_LAW=preisach` (or `ja-original`, `ja-inverse`) for another. Prints only.
///   cargo test --release -p host-sim --test refrig_suite effect_visibility -- --ignored --nocapture
#[test]
#[ignore = "minutes of CPU: run with --ignored"]
fn effect_visibility_in_the_suite_files() {
    let law = match std::env::var("GMA_VISIBILITY_LAW").as_deref() {
        Ok("preisach") => Law::Preisach,
        Ok("ja-original") => Law::JilesAtherton(JaVariant::Original1986),
        Ok("ja-inverse") => Law::JilesAtherton(JaVariant::InverseSadowski),
        Ok("ja-bulk") | Err(_) => Law::JilesAtherton(JaVariant::BulkVenkataraman),
        Ok(other) => panic!("GMA_VISIBILITY_LAW={other}: not a law of the suite"),
    };
    type Switch = fn(&mut refrig::Effects);
    let quiet: Switch = |e| {
        e.sensor_noise = false;
        e.sensor_quantisation = false;
        e.sensor_offset_drift = false;
    };
    let effects: Vec<(&str, Switch)> = vec![
        ("eddy currents", |e| e.eddy_currents = false),
        ("aftereffect", |e| e.aftereffect = false),
        ("coil heating", |e| {
            e.coil_heating = false;
            e.rod_thermal_expansion = false
        }),
        ("sensor delay", |e| e.sensor_delay = false),
        ("amplifier lag", |e| e.amplifier_lag = false),
        ("current limit", |e| e.current_limit = false),
        ("second mode", |e| e.second_mode = false),
        ("ΔE effect", |e| e.delta_e = false),
    ];
    let (fit_exc, val_exc) = excitations();
    let displacement = |exc: &Excitation, salt: u64, switches: &[Switch]| {
        let path = std::env::temp_dir().join(format!("gma-visibility-{}-{salt}.csv", std::process::id()));
        let rec = seed_one_rig(law, exc, salt, switches, &path);
        let _ = std::fs::remove_file(&path);
        rec
    };
    println!(
        "\n| file | sensor noise, quantisation, offset drift | {} |",
        effects.iter().map(|e| e.0).collect::<Vec<_>>().join(" | ")
    );
    println!("|---|---|{}", "---|".repeat(effects.len()));
    let files = fit_exc
        .iter()
        .enumerate()
        .map(|(i, e)| (e, i as u64))
        .chain(val_exc.iter().enumerate().map(|(i, e)| (e, 10 + i as u64)));
    for (exc, salt) in files {
        let truth = displacement(exc, salt, &[quiet]);
        let k = host_sim::diagnose::burn_in(&truth);
        let reference = &truth.displacement_um.as_deref().expect("displacement")[k..];
        let off_by = |rec: &Recording| {
            let y = &rec.displacement_um.as_deref().expect("displacement")[k..];
            let mean = reference.iter().zip(y).map(|(a, b)| a - b).sum::<f64>() / y.len() as f64;
            let shifted: Vec<f64> = y.iter().map(|v| v + mean).collect();
            let nrmse = host_sim::score::nrmse(reference, &shifted);
            assert!(nrmse.is_finite(), "{}: non-finite NRMSE", exc.label);
            format!("{:.3} %", 100.0 * nrmse)
        };
        let mut row = vec![off_by(&displacement(exc, salt, &[]))];
        row.extend(effects.iter().map(|(_, off)| off_by(&displacement(exc, salt, &[quiet, *off]))));
        let role = if salt < 10 { "fit" } else { "val" };
        println!("| {role} {} | {} |", exc.label, row.join(" | "));
    }
}

/// `diagnose --ja-variants` of the complete J–A structure (given as `init` says) on the
/// displacement-only recordings, as documented (docs/cli.md): the engineer's question which of
/// our J–A forms fits a rig.
fn ja_forms_of(init: &ActuatorParams, fit: &[Recording], val: &[Recording]) -> host_sim::diagnose::Diagnosis {
    let only = Channels::DisplacementOnly;
    let (fit, val) = (only.apply(fit), only.apply(val));
    let model = complete(Effect::Hysteresis);
    let mut d = diagnose(model, init, &fit, &val, FitOptions::default()).expect("diagnose");
    d.compare_ja_variants(model, init, &fit, &val, FitOptions::default()).expect("variants");
    d
}

/// `diagnose --ja-variants` on the independent rig: the complete structure, given in the
/// default `bulk` form, refitted in each J–A form and scored on the validation files, per rig
/// law and seed. Asserted, because it could fail: no false claim — a form named as fitting
/// better is the rig's own where we implement it (`ja-original`, the 1986 equation without the
/// δ_M gate, = `ja1986-ungated`; `ja-bulk` = `bulk`). Which form scores lowest is printed, not
/// asserted (2026-11-26: `ja1986-ungated` named on the Jiles 1986 rig, 0.74 % against 1.9–2.1 %
/// for the gated forms; none on the others). The rig's inverse form (Sadowski), which we do not
/// implement, is reported only. About five minutes:
///   cargo test --release -p host-sim --test refrig_suite ja_forms -- --ignored --nocapture
#[test]
#[ignore = "a minute of CPU: run with --ignored"]
fn ja_forms_on_the_independent_rig() {
    let (fit_exc, val_exc) = excitations();
    let init = engineer_init();
    let laws = [
        ("ja-original", JaVariant::Original1986, Some("ja1986-ungated")),
        ("ja-bulk", JaVariant::BulkVenkataraman, Some("bulk")),
        ("ja-inverse", JaVariant::InverseSadowski, None),
    ];
    let mut problems = Vec::new();
    println!("\n| rig law | seed | bulk (given) | ja1986 | szewczyk | ja1986-ungated | named |");
    println!("|---|---|---|---|---|---|---|");
    for (law_name, variant, ours) in laws {
        for seed in [1, 2] {
            let law = Law::JilesAtherton(variant);
            let files = |exc: &[Excitation], salt: u64| -> Vec<Recording> {
                exc.iter()
                    .enumerate()
                    .map(|(i, e)| recording(law, law_name, true, seed, e, salt + i as u64))
                    .collect()
            };
            let d = ja_forms_of(&init, &files(&fit_exc, 0), &files(&val_exc, 10));
            let rows = d.ja_variants.clone().expect("variant scores");
            let score = |name: &str| rows.iter().find(|r| r.variant == name).map(|r| r.nrmse).unwrap();
            let finding = d.findings.last().cloned().unwrap_or_default();
            let named = rows.iter().find(|r| r.fits_better).map_or("none", |r| r.variant);
            println!(
                "| {law_name} | {seed} | {:.2} % | {:.2} % | {:.2} % | {:.2} % | {named} |",
                score("bulk") * 100.0,
                score("ja1986") * 100.0,
                score("szewczyk") * 100.0,
                score("ja1986-ungated") * 100.0
            );
            if let Some(form) = ours {
                if named != "none" && named != form {
                    problems
                        .push(format!("{law_name} s{seed}: `{named}` named on a `{form}` rig: {finding}"));
                }
            }
        }
    }
    assert!(problems.is_empty(), "{problems:#?}");
}
