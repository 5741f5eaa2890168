//! The physics and the samples a recording must agree with before a model is fitted to it or
//! scored on it, as the loop reader checks a loop's: no isolated spike or dropout in a measured
//! channel, a coil field an actuator's coil can make, a displacement that rises where the model's
//! strain does and a flux density that follows the model's. A file that fails is refused with
//! the fix (the `--column` that reads it right, the row to clean, the parameter to set); nothing
//! here changes the data.

use anyhow::Result;
use model_core::{ActuatorParams, Effect, ModelSpec};

use super::{drive_for, run_model, InitialState, Prepared, Simulation, MU0};
use crate::analysis::correlation;
use crate::error::InRecording;
use crate::recording::Recording;
use crate::warning::Warning;

/// The checks of `files` before any work: each drives `spec` ([`drive_for`]), has no isolated
/// bad sample ([`isolated_samples`]) and agrees with the physics of `params`
/// ([`check_physics`]).
pub fn check_files<'a>(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Result<()> {
    for rec in files {
        drive_for(spec, rec)?;
        isolated_samples(rec)?;
        check_physics(spec, params, rec)?;
    }
    Ok(())
}

/// The channels a lone bad sample is looked for in: those a sensor measured (the command is
/// what was sent, and a drive may step in one sample).
const MEASURED: [&str; 4] = ["current_A", "displacement_um", "flux_density_T", "temperature_C"];

/// A sample this many times the local sample-to-sample change off both its neighbours is a
/// spike or a dropout: Gaussian noise reaches about 3 such changes, a square drive's step is
/// off one neighbour only, and a mode rung at a few samples a period changes as much around it.
const SPIKE_CHANGES: f64 = 20.0;

/// The samples either side whose changes give the local scale.
const SPIKE_WINDOW: usize = 32;

/// The local change is taken as at least this share of the channel's span (a noise-free channel
/// changes by nothing between some samples, and a least-significant bit is no spike).
const SPIKE_FLOOR_OF_SPAN: f64 = 1e-3;

/// A sample far off both neighbours in a measured channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spike {
    /// Its index in the recording as read.
    pub index: usize,
    /// Its value.
    pub value: f64,
    /// The samples before and after it.
    pub neighbours: (f64, f64),
    /// The local sample-to-sample change it is measured against (the mean |Δ| around it).
    pub local_change: f64,
}

/// The isolated spikes and dropouts of `x` (samples beyond both neighbours, on one side, by more
/// than [`SPIKE_CHANGES`] local changes), first to last. The first and last samples have one
/// neighbour, which cannot tell a spike from a step (`gma simulate`'s first sample is the rig at
/// rest, before the drive steps on): they are not judged.
pub fn spikes(x: &[f64]) -> Vec<Spike> {
    let n = x.len();
    if n < 5 {
        return Vec::new();
    }
    let (lo, hi) = x.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let floor = SPIKE_FLOOR_OF_SPAN * (hi - lo);
    let mut window = Vec::with_capacity(2 * SPIKE_WINDOW + 1);
    // The mean change around k, without the two into and out of the sample itself (a mean, not a
    // median: a mode ringing after a step for a few samples amid flat ones must count).
    let mut local_change = |k: usize| {
        window.clear();
        let (from, to) = (k.saturating_sub(SPIKE_WINDOW), (k + SPIKE_WINDOW).min(n - 2));
        window.extend((from..=to).filter(|&j| j + 1 != k && j != k).map(|j| (x[j + 1] - x[j]).abs()));
        (window.iter().sum::<f64>() / window.len().max(1) as f64).max(floor)
    };
    let spike = |k: usize, local_change: f64| Spike {
        index: k,
        value: x[k],
        neighbours: (x[k - 1], x[k + 1]),
        local_change,
    };
    let mut found = Vec::new();
    for k in 1..n - 1 {
        let (up, down) = (x[k] - x[k - 1], x[k] - x[k + 1]);
        let gap = up.abs().min(down.abs());
        if up * down <= 0.0 || gap <= SPIKE_CHANGES * floor {
            continue;
        }
        let local = local_change(k);
        if gap > SPIKE_CHANGES * local {
            found.push(spike(k, local));
        }
    }
    found
}

/// A measured channel with an isolated spike or dropout (a probe over range, a lost sample)
/// is refused, naming the row: one such sample sets the NRMSE's range (max − min), so a wrong
/// model would score as a right one.
fn isolated_samples(rec: &Recording) -> Result<()> {
    for name in MEASURED {
        let Some(x) = rec.column(name) else { continue };
        let found = spikes(x);
        let Some(s) = found.first() else { continue };
        let time = rec.time_s.get(s.index).copied().unwrap_or(f64::NAN);
        let more = match found.len() - 1 {
            0 => String::new(),
            1 => " (1 more such sample in this column)".to_string(),
            m => format!(" ({m} more such samples in this column)"),
        };
        let off = format!("both neighbours ({} and {})", s.neighbours.0, s.neighbours.1);
        return Err(InRecording::error(
            &rec.name,
            format!(
                "`{name}` = {} in the row at time_s = {time} (sample {} as read) stands off {off} by over \
                 {SPIKE_CHANGES}× the local sample-to-sample change ({:.3e}): an isolated spike or dropout (a \
                 sensor over range, a lost sample), not the actuator, and it would set the NRMSE's range \
                 (max − min) so that a wrong model scores as a right one{more}; remove the row from the file, or \
                 replace the value with its neighbours' mean, and run again",
                s.value, s.index, s.local_change
            ),
        ));
    }
    Ok(())
}

/// Largest coil field a recording's current may imply [multiples of the magnetostriction's
/// M_s]: beyond, the rod is saturated throughout (Terfenol-D's strain saturates near 1e5 A/m, a
/// sixth of its M_s) and no actuator's coil makes it. A current logged in mA under `current_A`
/// lands a thousand times beyond what the coil made.
const MAX_COIL_FIELD_PER_MS: f64 = 2.0;

/// Correlation of a measured channel with the model's below which it reads the other way round
/// (the loop reader's limit for M against H).
const REVERSED_CORRELATION: f64 = -0.5;

/// How many times more of the displacement's variance (1 − ρ²) one reading of a reversed file
/// must leave unexplained than the other for the other to be named alone (below, both fixes are
/// named with how to decide). Near the bias the strain is almost linear in the current, and both
/// readings correlate above 0.99: what tells them apart is the curvature's share.
const CLEARLY_WORSE: f64 = 2.0;

/// The physics a recording must agree with: a coil field an actuator's coil can make, and
/// channels that follow the model's: a displacement that rises where its strain does, a flux
/// density that rises with its field and magnetization.
pub fn check_physics(spec: ModelSpec, params: &ActuatorParams, rec: &Recording) -> Result<()> {
    if let Some(current) = rec.current_a.as_deref() {
        current_scale(params, &rec.name, current)?;
    }
    channel_signs(spec, params, rec)
}

/// A current whose coil field (`coil.turns_per_m` × i) is beyond [`MAX_COIL_FIELD_PER_MS`],
/// refused with the unit (mA, µA) that brings it within.
fn current_scale(params: &ActuatorParams, name: &str, current: &[f64]) -> Result<()> {
    // f32 as the file gives it (13541.7), f64 for the products.
    let (given, turns) = (params.coil.turns_per_m, params.coil.turns_per_m as f64);
    let peak = current.iter().fold(0.0f64, |a, i| a.max(i.abs()));
    let limit = MAX_COIL_FIELD_PER_MS * params.magnetostriction.ms_a_per_m as f64;
    if turns * peak <= limit {
        return Ok(());
    }
    let unit = [("mA", 1e-3), ("uA", 1e-6)].into_iter().find(|(_, scale)| turns * peak * scale <= limit);
    let fix = match unit {
        Some((unit, _)) => format!(
            "was it logged in {unit}? read it so: `--column current_A=current_A:{unit}` (a column mapped \
             with --column: give that mapping the unit `{unit}`); "
        ),
        None => String::new(),
    };
    Err(InRecording::error(
        name,
        format!(
            "`current_A` reaches {peak:.4e} A, a coil field of {:.3e} A/m (`coil.turns_per_m` = {given} × the \
             current), above {MAX_COIL_FIELD_PER_MS} M_s ({limit:.3e} A/m): no actuator's coil makes that, and \
             the rod would be saturated throughout, so no fit can follow the file; {fix}or the parameter \
             set's `coil.turns_per_m` is not this coil's",
            turns * peak
        ),
    ))
}

/// The model's run on `rec` from the demagnetised rod (all channels), or `None` where it cannot
/// run (the fit's to say).
fn demagnetised_run(spec: ModelSpec, params: &ActuatorParams, rec: &Recording) -> Result<Option<Simulation>> {
    let prep = Prepared::new(spec, rec)?.starting(InitialState::Demagnetized);
    Ok(run_model(spec, params, &prep, true).ok())
}

/// The model's flux density μ0 (H + M) (the search coil's scale and zero aside).
fn model_flux(sim: &Simulation) -> Vec<f64> {
    sim.field_a_per_m.iter().zip(&sim.magnetization_a_per_m).map(|(h, m)| MU0 * (h + m)).collect()
}

/// `rec` with its drive column negated (a current clamp on backwards).
fn drive_negated(rec: &Recording) -> Recording {
    let negate = |v: &Option<Vec<f64>>| v.as_ref().map(|v| v.iter().map(|x| -x).collect());
    Recording { current_a: negate(&rec.current_a), command_v: negate(&rec.command_v), ..rec.clone() }
}

/// Channels that fall where the model's rise (their correlation with the model's run below
/// [`REVERSED_CORRELATION`]) are refused with the `--column` that negates the one read the other
/// way round. The model is run from the demagnetised rod: its strain grows with |M|, λ =
/// (3/2)(λ_s/M_s²)(M² − M_b²), and M follows the field turns × i + bias, so with a bias the
/// strain rises with the current on the bias's side and without one with |i|; the model's
/// dynamics, where the spec has them, keep a fast drive's phase. A displacement against the
/// model has three causes: the probe, the current's sign (the strain is even in the field, so
/// with a bias a negated current moves the operating point to the field's other side, where the
/// strain curves the other way) and a sensor delay counted at another rate; each is tried.
fn channel_signs(spec: ModelSpec, params: &ActuatorParams, rec: &Recording) -> Result<()> {
    let Some(sim) = demagnetised_run(spec, params, rec)? else { return Ok(()) };
    let flux_rho = rec.flux_density_t.as_deref().map(|b| correlation(b, &model_flux(&sim)));
    let flux_reversed = flux_rho.is_some_and(|r| r < REVERSED_CORRELATION);
    let y = rec.displacement_um.as_deref().unwrap_or_default();
    let rho = correlation(y, &sim.displacement_um);
    if rho.is_nan() || rho >= REVERSED_CORRELATION {
        return match (flux_reversed, flux_rho) {
            (true, Some(r)) => Err(InRecording::error(&rec.name, flux_against_model(r))),
            _ => Ok(()),
        };
    }
    if let Some(why) = delay_at_other_rate(spec, params, rec, y)? {
        return Err(InRecording::error(&rec.name, why));
    }
    let against = format!(
        "the displacement falls where the model's strain rises (correlation {rho:.2} with the model's \
         displacement for these parameters): a Terfenol-D rod lengthens as its magnetization grows"
    );
    let probe_fix = "`--column displacement_um=-displacement_um` (a column mapped with --column: put `-` \
                     before its HEADER)";
    let drive = super::model_input(spec, rec)?.column();
    let current_fix = format!("`--column {drive}=-{drive}`");
    let bias = params.coil.bias_a_per_m;
    // Both measured channels against the model: the one they share, the drive, is reversed.
    if flux_reversed {
        return Err(InRecording::error(
            &rec.name,
            format!(
                "{against}, and the search coil's flux density falls where the model's rises too: the drive \
                 both follow reads the other way round (a current clamp on backwards); read it negated: \
                 {current_fix}; or the parameter set's bias field (`coil.bias_a_per_m` = {bias} A/m) has the \
                 wrong sign for this rig"
            ),
        ));
    }
    // The probe negated follows the model as well as −ρ; the drive negated, as its own run does.
    let drive_rho = demagnetised_run(spec, params, &drive_negated(rec))?
        .map_or(f64::NAN, |s| correlation(y, &s.displacement_um));
    let probe_rho = -rho;
    let unexplained = |r: f64| if r > 0.0 { 1.0 - r * r } else { 1.0 };
    let (drive_left, probe_left) = (unexplained(drive_rho), unexplained(probe_rho));
    let message = if probe_left > CLEARLY_WORSE * drive_left {
        format!(
            "{against}; with `{drive}` negated it follows the model ({:.2} % of its variance unexplained, \
             against {:.2} % with the displacement negated): with a bias field the strain is not symmetric in \
             the current, so the drive most likely reads the other way round (a current clamp on backwards); \
             read it negated: {current_fix}; or the parameter set's bias field (`coil.bias_a_per_m` = {bias} \
             A/m) has the wrong sign for this rig",
            100.0 * drive_left,
            100.0 * probe_left
        )
    } else if drive_left > CLEARLY_WORSE * probe_left || drive_rho.is_nan() {
        format!(
            "{against}, so the probe most likely reads the other way round; read the column negated: \
             {probe_fix}; or the parameter set's bias field (`coil.bias_a_per_m` = {bias} A/m) has the wrong \
             sign for this rig"
        )
    } else {
        format!(
            "{against}; negating the displacement ({probe_fix}) or the drive ({current_fix}) follows the model \
             about as well ({:.2} % and {:.2} % of its variance unexplained), so the file cannot tell which \
             sensor reads the other way round: check which way the probe reads (it must read more as the rod \
             lengthens) and the current clamp's arrow, and negate that column; or the parameter set's bias \
             field (`coil.bias_a_per_m` = {bias} A/m) has the wrong sign for this rig",
            100.0 * probe_left,
            100.0 * drive_left
        )
    };
    Err(InRecording::error(&rec.name, message))
}

/// What a search coil's flux density that falls where the model's rises (correlation `rho`) says.
fn flux_against_model(rho: f64) -> String {
    format!(
        "the flux density falls where the model's rises (correlation {rho:.2} with μ0 (H + M) for these \
         parameters), while the displacement follows the model: the search coil or its integrator is wired \
         the other way round; read the column negated: `--column flux_density_T=-flux_density_T` (a column \
         mapped with --column: put `-` before its HEADER)"
    )
}

/// With a sensor delay and a parameter set whose `dt_s` is not the recording's step, why the
/// displacement falls against the model when the delay, counted in this recording's samples,
/// lets it follow: `delay_samples` counts periods of the set's `dt_s` (the documented rule: the
/// delay is a time), so a `dt_s` edited or carried from another rig's files scales the delay.
fn delay_at_other_rate(
    spec: ModelSpec,
    params: &ActuatorParams,
    rec: &Recording,
    y: &[f64],
) -> Result<Option<String>> {
    let step = rec.dt_s();
    let ratio = params.dt_s as f64 / step;
    if !spec.has(Effect::SensorDelay) || params.delay_samples <= 0.0 || (ratio - 1.0).abs() <= 1e-5 {
        return Ok(None);
    }
    let here = ActuatorParams { dt_s: step as f32, ..*params };
    let Some(sim) = demagnetised_run(spec, &here, rec)? else { return Ok(None) };
    let rho = correlation(y, &sim.displacement_um);
    Ok((rho >= -REVERSED_CORRELATION).then(|| {
        let delay = params.delay_samples as f64;
        // Six significant digits: a step read off a time column is 9.99999999999994e-5 s.
        let step = format!("{step:.5e}").parse::<f64>().unwrap_or(step);
        format!(
            "the displacement falls where the model's rises with the sensor delay these parameters give: \
             `delay_samples` = {delay} counts periods of the parameter set's `dt_s` = {} s, so the delay is \
             {:.4} ms, {:.1} samples of this recording (a step of {step:.4e} s); counted in this recording's \
             samples the displacement follows the model (correlation {rho:.2}): if the delay was meant in \
             this recording's samples, set `dt_s = {step:e}` in the parameter file (every command replaces \
             `dt_s` by the recording's step, but the delay keeps its time)",
            params.dt_s,
            delay * params.dt_s as f64 * 1e3,
            delay * ratio
        )
    }))
}

/// [`started_mid_run`] of each of `files`.
pub fn started_mid_run_all<'a>(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Result<Vec<Warning>> {
    files.into_iter().filter_map(|rec| started_mid_run(spec, params, rec).transpose()).collect()
}

/// Samples the drive is held at its first value before a file to settle the model there (a
/// mechanical mode and the eddy and amplifier lags settle within a few ms at 10 kHz).
const SETTLE_SAMPLES: usize = 2000;

/// The start of a file judged for its start transient [samples].
const START_WINDOW: usize = 200;

/// A file whose drive starts away from rest (no current) while its displacement does not show
/// the step the model then takes at the first sample: the model is run from rest (the rig off
/// before the file, the state `gma simulate` starts from), and a fit bends the dynamics to hide
/// the start transient of a rig already running when the file began (a mode pushed above the
/// Nyquist frequency, the eddy lag to its bound). Said when the model settled at the first
/// drive value follows the file's first samples at least twice as well (for `params`).
pub fn started_mid_run(spec: ModelSpec, params: &ActuatorParams, rec: &Recording) -> Result<Option<Warning>> {
    let steps = [Effect::MechanicalDynamics, Effect::EddyCurrent, Effect::AmplifierDynamics];
    let drive = super::model_input(spec, rec)?;
    let input = rec.column(drive.column()).map(Vec::as_slice).unwrap_or_default();
    let Some(y) = rec.displacement_um.as_deref() else { return Ok(None) };
    let (lo, hi) = input.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let first = input.first().copied().unwrap_or(0.0);
    if !steps.iter().any(|e| spec.has(*e)) || rec.len() < 4 * START_WINDOW || first.abs() <= 0.05 * (hi - lo)
    {
        return Ok(None);
    }
    // Its start only (the window and what precedes it in the runs), with the drive (and the
    // displacement, for the checks) held before it.
    let rec = &rec.head(4 * START_WINDOW);
    let settled = {
        let held = |v: &Option<Vec<f64>>| {
            v.as_ref().map(|v| std::iter::repeat_n(v[0], SETTLE_SAMPLES).chain(v.iter().copied()).collect())
        };
        let dt = rec.dt_s();
        let t0 = rec.time_s[0] - SETTLE_SAMPLES as f64 * dt;
        Recording {
            time_s: (0..SETTLE_SAMPLES)
                .map(|k| t0 + k as f64 * dt)
                .chain(rec.time_s.iter().copied())
                .collect(),
            command_v: held(&rec.command_v),
            current_a: held(&rec.current_a),
            displacement_um: held(&rec.displacement_um),
            force_n: None,
            temperature_c: None,
            flux_density_t: None,
            ..rec.clone()
        }
    };
    // A start the model cannot run on (a drive held through the whole start) says nothing.
    let run = |r: &Recording| demagnetised_run(spec, params, r).ok().flatten();
    let (Some(from_rest), Some(from_settled)) = (run(rec), run(&settled)) else {
        return Ok(None);
    };
    let head = &y[..START_WINDOW];
    let error = |model: &[f64]| {
        let offset = head.iter().zip(model).map(|(a, b)| a - b).sum::<f64>() / head.len() as f64;
        let shifted: Vec<f64> = model.iter().map(|m| m + offset).collect();
        super::nrmse(head, &shifted)
    };
    let (rest, settled) = (
        error(&from_rest.displacement_um[..START_WINDOW]),
        error(&from_settled.displacement_um[SETTLE_SAMPLES..]),
    );
    Ok((settled.is_finite() && rest > 2.0 * settled).then(|| Warning::StartedMidRun {
        file: rec.name.clone(),
        column: drive.column(),
        first,
        from_rest: rest,
        settled,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A noisy sine with an odd value somewhere (from a small deterministic generator).
    fn noisy_sine(n: usize, samples_per_period: f64, noise: f64) -> Vec<f64> {
        let mut state = 12345u64;
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..n)
            .map(|k| {
                let t = k as f64 / samples_per_period;
                20.0 + 15.0 * (2.0 * std::f64::consts::PI * t).sin()
                    + noise * (uniform() + uniform() + uniform())
            })
            .collect()
    }

    /// One over-range sample or one dropout to 0 in 10 000 is found at its index; the noisy
    /// recording without it, a sine sampled at a few samples a period, and a square wave whose
    /// steps are a sample long or ring for several samples are not.
    #[test]
    fn a_lone_spike_or_dropout_is_found_and_steps_and_noise_are_not() {
        let clean = noisy_sine(10_000, 50.0, 0.05);
        assert!(spikes(&clean).is_empty());
        // The dropout near a crest, where the signal is far from 0 and changes slowly.
        for (at, bad) in [(5000, 9999.99), (5012, 0.0)] {
            let mut x = clean.clone();
            x[at] = bad;
            let found = spikes(&x);
            assert_eq!(found.iter().map(|s| s.index).collect::<Vec<_>>(), vec![at], "{bad}");
            assert_eq!(found[0].value, bad);
        }
        assert!(spikes(&noisy_sine(10_000, 4.0, 0.5)).is_empty());
        // A square drive: exact steps, then a displacement that rings after each (a mode at a
        // fifth of the sample rate, decaying over ~15 samples).
        let square: Vec<f64> = (0..4000).map(|k| if (k / 100) % 2 == 0 { 0.0 } else { 2.0 }).collect();
        assert!(spikes(&square).is_empty());
        let ringing: Vec<f64> = (0..4000)
            .map(|k| {
                let (level, since) = ((k / 100) % 2, (k % 100) as f64);
                let step = if level == 0 { -1.0 } else { 1.0 };
                let decay = (-since / 15.0).exp() * (2.0 * std::f64::consts::PI * since / 5.0).cos();
                10.0 * step * (1.0 - decay)
            })
            .collect();
        assert!(spikes(&ringing).is_empty(), "{:?}", spikes(&ringing).first());
    }
}
