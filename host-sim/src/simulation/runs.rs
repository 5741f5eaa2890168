//! One run of a model over a recording, and runs over several recordings at once.
//!
//! A run is a chain of dependent steps: each sample's J–A integration waits on the sample
//! before, so one run leaves most of a core's issue slots idle (the integration is bound by
//! latency, not throughput). Where files outnumber threads, [`run_models`] steps two files' runs
//! in turn on one thread, sample by sample and, within a sample, J–A sub-step by sub-step
//! ([`Actuator::step_magnetic_ramp_beside`]): the core overlaps the two independent chains. Each
//! run's arithmetic is unchanged, so the results are the same bits as [`run_model`]'s.

use std::sync::Arc;

use anyhow::Result;
use model_core::magnetization::JaBranch;
use model_core::{
    Actuator, ActuatorParams, ActuatorState, Effect, FirstOrderHold, MagneticOutput, MagnetizationLaw,
    ModelSpec, PreviousSample,
};
use rayon::prelude::*;

use super::noisy_drive::{branch_directions, REVERSAL_IN_NOISE_RMS};
use super::{at_rate_of, estimate_excursion, Drive, InitialState, MagneticMemo, Prepared};
use crate::error::InRecording;
use crate::simulated::Simulation;

/// The model input of `prep`'s first sample (the ideal amplifier's command as its current).
pub(super) fn first_drive(p: &ActuatorParams, prep: &Prepared) -> f32 {
    let first = |v: &Option<Vec<f64>>| v.as_deref().and_then(|v| v.first().copied()).unwrap_or(0.0);
    (match prep.drive {
        Drive::Current => match &prep.drive_estimate {
            Some(estimate) => estimate.first().copied().unwrap_or(0.0),
            None => first(&prep.rec.current_a),
        },
        Drive::CommandIdeal => first(&prep.rec.command_v) * p.amp.gain_a_per_v as f64,
        Drive::CommandDynamic => first(&prep.rec.command_v),
    }) as f32
}

/// [`super::simulate`]; `all_channels: false` keeps only the channels the file measured (the
/// fit's inner loop: displacement and current, and field and magnetization for a measured flux
/// density).
pub fn run_model(
    spec: ModelSpec,
    params: &ActuatorParams,
    prep: &Prepared,
    all_channels: bool,
) -> Result<Simulation> {
    Run::start(spec, params, prep, all_channels)?.run_to_end()
}

/// [`run_model`] on each of `files`, in parallel; the files beyond one per thread in pairs, the
/// two runs of a pair interleaved on one thread (consecutive files, in the order given). The
/// first error in file order, if any.
pub fn run_models(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Prepared],
    all_channels: bool,
) -> Result<Vec<Simulation>> {
    // A pair takes ≈ 1.3–1.6× one run's time on one thread: worth it only where the files
    // outnumber the threads (with no more files than threads, each gets a core of its own).
    let pairs = (files.len() / 2).min(files.len().saturating_sub(rayon::current_num_threads()));
    let (paired, alone) = files.split_at(2 * pairs);
    let runs: Vec<Result<Simulation>> = paired
        .par_chunks(2)
        .flat_map_iter(|pair| Vec::from(run_pair(spec, params, &pair[0], &pair[1], all_channels)))
        .chain(alone.par_iter().map(|prep| run_model(spec, params, prep, all_channels)))
        .collect();
    runs.into_iter().collect()
}

/// The runs on `a` and `b`, stepped in turn while both last.
fn run_pair(
    spec: ModelSpec,
    params: &ActuatorParams,
    a: &Prepared,
    b: &Prepared,
    all_channels: bool,
) -> [Result<Simulation>; 2] {
    match (Run::start(spec, params, a, all_channels), Run::start(spec, params, b, all_channels)) {
        (Ok(mut x), Ok(mut y)) => {
            while x.running() && y.running() {
                x.step_beside(&mut y);
            }
            [x.run_to_end(), y.run_to_end()]
        }
        (x, y) => [x.and_then(Run::run_to_end), y.and_then(Run::run_to_end)],
    }
}

/// A run's drive per sample: the file's own column, a noisy current's smoothed estimate
/// (shared by every run on the file, its first `n` samples), or the ideal amplifier's current.
enum DriveInput<'a> {
    Logged(&'a [f64]),
    Smoothed(Arc<[f64]>, usize),
    Computed(Vec<f64>),
}

impl<'a> From<&'a [f64]> for DriveInput<'a> {
    fn from(v: &'a [f64]) -> Self {
        DriveInput::Logged(v)
    }
}

impl From<Vec<f64>> for DriveInput<'_> {
    fn from(v: Vec<f64>) -> Self {
        DriveInput::Computed(v)
    }
}

impl std::ops::Deref for DriveInput<'_> {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        match self {
            DriveInput::Logged(v) => v,
            DriveInput::Smoothed(v, n) => &v[..*n],
            DriveInput::Computed(v) => v,
        }
    }
}

/// A run in progress: the model, its state, and the channels recorded so far.
struct Run<'a> {
    rec: &'a crate::recording::Recording,
    model: Actuator,
    s: ActuatorState,
    /// The model's input per sample: current [A] or command [V].
    input: DriveInput<'a>,
    n: usize,
    /// The ramp coefficients of the model's linear stages (the first-order hold).
    hold: FirstOrderHold,
    /// The drive and the law's magnetization at sample k.
    prev: PreviousSample,
    /// The magnetic stages' output at sample k.
    before: MagneticOutput,
    /// The magnetic stages' outputs, kept from an earlier run with the same upstream parameters.
    kept: Option<Arc<[MagneticOutput]>>,
    /// A noisy current's J–A branch and each step's direction (its noise taken as no reversal).
    branch: Option<(JaBranch, Vec<f32>)>,
    /// Where this run's magnetic stages are to be kept, under which key, and what they gave.
    to_keep: Option<(&'a MagneticMemo, String, Vec<MagneticOutput>)>,
    out: Simulation,
    all_channels: bool,
    heating: bool,
    /// The next sample.
    k: usize,
    /// The outputs at sample k: displacement [m], current [A], field and magnetization [A/m].
    y: f64,
    i: f64,
    h: f64,
    m: f64,
    failed: Option<anyhow::Error>,
}

impl<'a> Run<'a> {
    fn start(
        spec: ModelSpec,
        params: &ActuatorParams,
        prep: &Prepared<'a>,
        all_channels: bool,
    ) -> Result<Self> {
        let (rec, drive) = (prep.rec, prep.drive);
        let p = at_rate_of(spec, params, prep)?;
        // The ideal amplifier's gain is used without `amplifier_dynamics` too, which model-core
        // then does not check.
        let gain = p.amp.gain_a_per_v;
        if drive == Drive::CommandIdeal && !(gain > 0.0 && gain <= 1e3) {
            return Err(InRecording::error(
                &rec.name,
                format!(
                    "parameter `amp.gain_a_per_v` = {gain} is out of range (0, 1e3] A/V: it is the ideal amplifier's \
                     gain, which turns this file's `command_V` into the coil current"
                ),
            ));
        }
        let model = super::workbench_model(spec, &p).map_err(|e| anyhow::anyhow!("{e}"))?;
        let n = rec.len();
        let all_channels = all_channels || rec.flux_density_t.is_some();
        // Borrowed from the recording or shared with the file's other runs (this runs at every
        // fit evaluation); only the ideal amplifier's scaled command is a new vector.
        let input: DriveInput = match (drive, &prep.drive_estimate) {
            (Drive::Current, Some(estimate)) => DriveInput::Smoothed(estimate.clone(), n.min(estimate.len())),
            (Drive::Current, None) => rec.current_a.as_deref().unwrap_or_default().into(),
            (Drive::CommandIdeal, _) => rec
                .command_v
                .iter()
                .flatten()
                .map(|u| u * p.amp.gain_a_per_v as f64)
                .collect::<Vec<_>>()
                .into(),
            (Drive::CommandDynamic, _) => rec.command_v.as_deref().unwrap_or_default().into(),
        };
        let excursion = match prep.initial {
            _ if !model.has_magnetic_memory() => 0.0,
            InitialState::Demagnetized => 0.0,
            InitialState::Excursion(x) => x,
            InitialState::Estimated if rec.displacement_um.is_none() => 0.0,
            InitialState::Estimated => estimate_excursion(spec, params, prep)?,
        };
        // At rest at the drive's first value (a command drive's amplifier settled there).
        let first = input.first().copied().unwrap_or(0.0) as f32;
        let s = model.rest_state_at(first, excursion as f32);
        let hold = FirstOrderHold::new(&model, p.dt_s);
        let prev = model.previous_at_rest(&s, first);
        let before = model.magnetic_at_rest(&s);
        // The magnetic stages' run kept in the memo (parameters that differ only downstream),
        // or none: then they run here, interleaved with the mechanical ones, and are kept.
        let (mut kept, mut to_keep) = (None, None);
        if let Some(memo) = prep.memo {
            let key = magnetic_key(spec, &p, excursion, drive);
            kept = memo.get(&key);
            if kept.is_none() {
                to_keep = Some((memo, key, Vec::with_capacity(n)));
            }
        }
        let branch = match kept {
            None => noise_free_branches(spec, &p, &model, s, &input, prep)?,
            Some(_) => None,
        };
        let heating = spec.has(Effect::ThermalDrift);
        let out = Simulation {
            displacement_um: Vec::with_capacity(n),
            current_a: Vec::with_capacity(n),
            field_a_per_m: Vec::with_capacity(if all_channels { n } else { 0 }),
            magnetization_a_per_m: Vec::with_capacity(if all_channels { n } else { 0 }),
            temperature_rise_c: Vec::with_capacity(if heating { n } else { 0 }),
            initial_excursion_a_per_m: excursion,
        };
        let y = s.mech.displacement_m as f64; // rest: the delay line holds this value too
        let i = if drive == Drive::CommandDynamic { s.amp.current_a as f64 } else { input[0] };
        let (h, m) = (s.rod_field_a_per_m.value() as f64, s.m_slow_a_per_m.value() as f64);
        Ok(Run {
            rec,
            model,
            s,
            hold,
            prev,
            before,
            input,
            n,
            kept,
            branch,
            to_keep,
            out,
            all_channels,
            heating,
            k: 0,
            y,
            i,
            h,
            m,
            failed: None,
        })
    }

    /// Samples left, and no fault.
    #[inline(always)]
    fn running(&self) -> bool {
        self.k < self.n && self.failed.is_none()
    }

    /// Records sample k's outputs and steps to sample k + 1 (a fault ends the run).
    #[inline(always)]
    fn step(&mut self) {
        self.record();
        let u = self.drive();
        let (model, hold) = (&self.model, &self.hold);
        let magnetic = match (&self.kept, &mut self.branch) {
            (Some(run), _) => Ok(run[self.k]),
            (None, Some((b, dirs))) => {
                model.step_magnetic_ramp_on_branch(&mut self.s, hold, &mut self.prev, b, u, dirs[self.k])
            }
            (None, None) => model.step_magnetic_ramp(&mut self.s, hold, &mut self.prev, u),
        };
        self.advance(magnetic);
    }

    /// [`Self::step`] of this run and `other`, their magnetic stages interleaved
    /// ([`Actuator::step_magnetic_beside`]) unless either has them kept.
    #[inline(always)]
    fn step_beside(&mut self, other: &mut Run) {
        let plain = |r: &Run| r.kept.is_none() && r.branch.is_none();
        if !(plain(self) && plain(other)) {
            self.step();
            other.step();
            return;
        }
        self.record();
        other.record();
        let (u, u_other) = (self.drive(), other.drive());
        let [magnetic, magnetic_other] = self.model.step_magnetic_ramp_beside(
            (&mut self.s, &self.hold, &mut self.prev, u),
            &other.model,
            (&mut other.s, &other.hold, &mut other.prev, u_other),
        );
        self.advance(magnetic);
        other.advance(magnetic_other);
    }

    /// The outputs at sample k, recorded (simultaneous sampling: the output at t_k, then the
    /// step to t_{k+1}).
    #[inline(always)]
    fn record(&mut self) {
        self.out.displacement_um.push(self.y * 1e6);
        self.out.current_a.push(self.i);
        if self.all_channels {
            self.out.field_a_per_m.push(self.h);
            self.out.magnetization_a_per_m.push(self.m);
        }
        if self.heating {
            self.out.temperature_rise_c.push(self.s.temperature_rise_c.value() as f64);
        }
    }

    /// The drive at sample k + 1, where the step from k goes (the last sample's, past the end).
    #[inline(always)]
    fn drive(&self) -> f32 {
        next_drive(&self.input, self.k)
    }

    /// The mechanical stages from the magnetic ones' output (kept, or just stepped and then
    /// kept if asked), to sample k + 1; a fault ends the run.
    #[inline(always)]
    fn advance(&mut self, magnetic: Result<MagneticOutput, model_core::StepError>) {
        let magnetic = match magnetic {
            Ok(o) => o,
            Err(e) => {
                self.failed = Some(InRecording::error(&self.rec.name, format!("sample {}: {e}", self.k)));
                return;
            }
        };
        // Only a run without kept magnetic stages has them to keep.
        if let Some((_, _, run)) = &mut self.to_keep {
            run.push(magnetic);
        }
        let o = self.model.step_mechanical_ramp(&mut self.s, &self.hold, &self.before, magnetic);
        self.before = magnetic;
        self.y = o.displacement_m as f64;
        self.i = o.current_a as f64;
        self.h = o.field_a_per_m as f64;
        self.m = o.magnetization_a_per_m as f64;
        self.k += 1;
    }

    /// Steps to the last sample; the run's channels, or its fault.
    fn run_to_end(mut self) -> Result<Simulation> {
        while self.running() {
            self.step();
        }
        if let Some(e) = self.failed {
            return Err(e);
        }
        if let Some((memo, key, run)) = self.to_keep {
            memo.keep(key, run);
        }
        Ok(self.out)
    }
}

/// The drive at sample k + 1 of `input`, where a step from sample k goes: the drive runs
/// linearly between the two (the first-order hold, [`FirstOrderHold`]); past the last sample it
/// stays there.
#[inline(always)]
fn next_drive(input: &[f64], k: usize) -> f32 {
    input[(k + 1).min(input.len() - 1)] as f32
}

/// The J–A branch and step directions of a logged current whose noise turns the field back
/// ([`branch_directions`] on the field this run's drive gives, from state `s`), or `None`: a
/// command drive, another law, or no turn within the noise (the plain run is then the same).
fn noise_free_branches(
    spec: ModelSpec,
    p: &ActuatorParams,
    model: &Actuator,
    mut s: ActuatorState,
    input: &[f64],
    prep: &Prepared,
) -> Result<Option<(JaBranch, Vec<f32>)>> {
    if prep.drive != Drive::Current
        || prep.drive_noise_a <= 0.0
        || spec.law() != MagnetizationLaw::JilesAtherton
        || !(prep.drive_turns_in_noise || spec.has(Effect::EddyCurrent))
    {
        return Ok(None);
    }
    let threshold = (REVERSAL_IN_NOISE_RMS * prep.drive_noise_a) as f32 * p.coil.turns_per_m;
    let start = JaBranch::from(s.ja);
    let hold = FirstOrderHold::new(model, p.dt_s);
    let mut prev = model.previous_at_rest(&s, input[0] as f32);
    let mut field = Vec::with_capacity(input.len() + 1);
    field.push(s.ja.h_a_per_m);
    for k in 0..input.len() {
        let (_, h) = model
            .rod_field_ramp(&mut s, &hold, &mut prev, next_drive(input, k))
            .map_err(|e| InRecording::error(&prep.rec.name, format!("sample {k}: {e}")))?;
        field.push(h);
    }
    Ok(branch_directions(&field, threshold).map(|dirs| (start, dirs)))
}

/// Whether the current `input` (at rest at its first value, as a run starts) turns back by no
/// more than `threshold` [A] somewhere: [`branch_directions`] on the current a run's field
/// follows through the coil alone.
pub(super) fn turns_within(input: &[f64], threshold: f64) -> bool {
    let path: Vec<f32> = input.iter().map(|&i| i as f32).collect();
    branch_directions(&path, threshold as f32).is_some()
}

/// What decides a run's magnetic stages on one file ([`MagneticMemo`]'s key): the spec, the
/// parameters at the file's rate with the mechanical stages' (magnetostriction, rod length,
/// mechanics, thermal drift, sensor delay) set aside, the initial excursion and the drive. Debug
/// text prints every float exactly (shortest round trip, −0 kept).
fn magnetic_key(spec: ModelSpec, p: &ActuatorParams, excursion: f64, drive: Drive) -> String {
    let reference = ActuatorParams::TERFENOL_DEMO;
    let magnetic = ActuatorParams {
        magnetostriction: reference.magnetostriction,
        rod_length_m: reference.rod_length_m,
        mech: reference.mech,
        thermal: reference.thermal,
        delay_samples: reference.delay_samples,
        ..*p
    };
    format!("{spec:?} {magnetic:?} {excursion:?} {drive:?}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::Excitation;
    use crate::plant::Plant;
    use crate::recording::Recording;

    fn bits(sim: &Simulation) -> Vec<u64> {
        [
            &sim.displacement_um,
            &sim.current_a,
            &sim.field_a_per_m,
            &sim.magnetization_a_per_m,
            &sim.temperature_rise_c,
        ]
        .iter()
        .flat_map(|v| v.iter().map(|x| x.to_bits()))
        .collect()
    }

    /// `f` with one rayon thread: every file beyond the first is then paired.
    fn on_one_thread<T: Send>(f: impl FnOnce() -> T + Send) -> T {
        rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(f)
    }

    fn sine(plant: &Plant, name: &str, freq_hz: f64, seconds: f64) -> Recording {
        plant.record(name, &Excitation::Sine { freq_hz, amplitude: 1.0, bias: 0.2 }, seconds, 3).unwrap()
    }

    /// Files run in pairs give the runs one at a time gives, bit for bit: files of different
    /// lengths (the longer finishes alone), an odd one out, and a file whose magnetic stages go
    /// to the memo and then come from it (its pair then alternates whole samples).
    #[test]
    fn runs_in_pairs_are_the_runs_one_at_a_time() {
        let spec = ModelSpec::parse("amp+eddy+ja+aftereffect+mech+thermal+delay").unwrap();
        let truth = ActuatorParams::TERFENOL_DEMO;
        let plant = Plant::new(spec, truth);
        let recs =
            [sine(&plant, "a", 150.0, 0.05), sine(&plant, "b", 70.0, 0.08), sine(&plant, "c", 300.0, 0.03)];
        let mut preps: Vec<Prepared> = recs
            .iter()
            .zip([1500.0, -800.0, 0.0])
            .map(|(r, x)| Prepared::new(spec, r).unwrap().starting(InitialState::Excursion(x)))
            .collect();
        let mut p = truth;
        p.ja.k_a_per_m *= 1.1;
        let alone = |preps: &[Prepared], all_channels| -> Vec<Vec<u64>> {
            preps.iter().map(|prep| bits(&run_model(spec, &p, prep, all_channels).unwrap())).collect()
        };
        let paired = |preps: &[Prepared], all_channels| -> Vec<Vec<u64>> {
            on_one_thread(|| run_models(spec, &p, preps, all_channels).unwrap().iter().map(bits).collect())
        };
        for all_channels in [false, true] {
            assert!(
                paired(&preps, all_channels) == alone(&preps, all_channels),
                "all_channels = {all_channels}"
            );
        }
        // Another order pairs other files.
        preps.reverse();
        assert!(paired(&preps, false) == alone(&preps, false), "reversed");
        // File b through the memo: kept by the first paired run, taken from it by the second.
        let expected = alone(&preps, false);
        let memo = MagneticMemo::default();
        preps[1].memo = Some(&memo);
        for pass in ["kept", "taken from the memo"] {
            assert!(paired(&preps, false) == expected, "{pass}");
            assert_eq!(memo.kept(), 1);
        }
    }

    /// `Run`'s bookkeeping against model-core stepped by hand, sample by sample (simultaneous
    /// sampling: the output at t_k, then the step to t_{k+1} with the mean of the drive's two
    /// ends), alone and paired.
    #[test]
    fn a_run_is_model_core_stepped_sample_by_sample() {
        let spec = ModelSpec::parse("eddy+ja+aftereffect+mech+thermal+delay").unwrap();
        let plant = Plant::new(spec, ActuatorParams::TERFENOL_DEMO);
        let recs = [sine(&plant, "a", 150.0, 0.05), sine(&plant, "b", 70.0, 0.03)];
        let excursion = 1500.0;
        let preps: Vec<Prepared> = recs
            .iter()
            .map(|r| Prepared::new(spec, r).unwrap().starting(InitialState::Excursion(excursion)))
            .collect();
        let mut p = ActuatorParams::TERFENOL_DEMO;
        p.ja.alpha *= 0.9;
        let by_hand = |prep: &Prepared| -> (Vec<u64>, Vec<u64>) {
            let model = super::super::workbench_model(spec, &at_rate_of(spec, &p, prep).unwrap()).unwrap();
            // The logged current, or what a noisy one is smoothed to.
            let input = prep.drive_estimate.as_deref().or(prep.rec.current_a.as_deref()).unwrap();
            let n = input.len();
            let mut s = model.rest_state_at(input[0] as f32, excursion as f32);
            let hold = model_core::FirstOrderHold::new(&model, prep.dt_s as f32);
            let mut prev = model.previous_at_rest(&s, input[0] as f32);
            let mut before = model.magnetic_at_rest(&s);
            let (mut y, mut i) = (s.mech.displacement_m as f64, input[0]);
            let (mut ys, mut is) = (Vec::new(), Vec::new());
            for k in 0..n {
                ys.push((y * 1e6).to_bits());
                is.push(i.to_bits());
                let u = input[(k + 1).min(n - 1)] as f32;
                let o = model.step_ramp(&mut s, &hold, &mut prev, &mut before, u).unwrap();
                (y, i) = (o.displacement_m as f64, o.current_a as f64);
            }
            (ys, is)
        };
        let channels = |sim: &Simulation| -> (Vec<u64>, Vec<u64>) {
            (
                sim.displacement_um.iter().map(|x| x.to_bits()).collect(),
                sim.current_a.iter().map(|x| x.to_bits()).collect(),
            )
        };
        let paired = on_one_thread(|| run_models(spec, &p, &preps, false).unwrap());
        for (prep, sim) in preps.iter().zip(&paired) {
            let expected = by_hand(prep);
            assert!(
                channels(&run_model(spec, &p, prep, false).unwrap()) == expected,
                "{} alone",
                prep.rec.name
            );
            assert!(channels(sim) == expected, "{} paired", prep.rec.name);
        }
    }

    /// A fault in a file ends its run only: the error is that file's, the first in file order
    /// when several fail, and it names the file and the sample.
    #[test]
    fn a_fault_in_one_file_of_a_pair_is_that_files() {
        let spec = ModelSpec::parse("ja+mech").unwrap();
        let plant = Plant::new(spec, ActuatorParams::TERFENOL_DEMO);
        let good = sine(&plant, "good.csv", 100.0, 0.02);
        let broken = |name: &str, at: usize| -> Recording {
            let mut r = good.clone();
            r.name = name.into();
            r.current_a.as_mut().unwrap()[at] = 1e9;
            r
        };
        let (late, early) = (broken("late.csv", 150), broken("early.csv", 20));
        let run = |recs: &[&Recording]| {
            let preps: Vec<Prepared> = recs.iter().map(|r| Prepared::new(spec, r).unwrap()).collect();
            on_one_thread(|| run_models(spec, &ActuatorParams::TERFENOL_DEMO, &preps, false).map(|s| s.len()))
        };
        assert_eq!(run(&[&good, &good, &good]).unwrap(), 3);
        for (recs, file, sample) in [
            (vec![&good, &late], "late.csv", 149),
            (vec![&late, &good], "late.csv", 149),
            (vec![&late, &early], "late.csv", 149),
            (vec![&good, &good, &early], "early.csv", 19),
        ] {
            let e = format!("{:#}", run(&recs).unwrap_err());
            assert!(e.contains(file) && e.contains(&format!("sample {sample}")), "{e}");
        }
    }
}
