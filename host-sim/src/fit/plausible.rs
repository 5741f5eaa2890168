//! The physics a recording must agree with before a model is fitted to it or scored on it, as
//! the loop reader checks a loop's: samples a sensor got right ([`super::bad_samples`]), a coil
//! field an actuator's coil can make, a displacement that rises where the model's strain does
//! and a flux density that follows the model's. A file that fails is refused with the fix (the
//! `--column` that reads it right, the row to clean, the parameter to set); what only casts
//! doubt (a scale, both signs, a loop's direction, a delay's rate, a start mid-run) is a warning
//! ([`data_doubts`]). Nothing here changes the data.

use anyhow::Result;
use model_core::{ActuatorParams, Effect, ModelSpec};

use super::bad_samples::{check_samples, stuck_channels};
use crate::channels::MU0;
use crate::data_doubts::DataDoubt;
use crate::error::InRecording;
use crate::recording::Recording;
use crate::signal::correlation;
use crate::simulated::Simulation;
use crate::simulation::{drive_for, model_input, run_model, Drive, InitialState, Prepared};
use crate::warning::Warning;

/// The checks of `files` before any work: each drives `spec` ([`drive_for`]), has no isolated
/// bad sample ([`check_samples`]) and agrees with the physics of `params`
/// ([`check_physics`]).
pub fn check_files<'a>(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Result<()> {
    for rec in files {
        drive_for(spec, rec)?;
        check_samples(rec)?;
        check_physics(spec, params, rec)?;
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
        current_scale(params, &rec.name, "current_A", current, 1.0)?;
    }
    // The command too where it drives the model (an amplifier's structure), logged current or not.
    let by_command = rec.current_a.is_none() || !matches!(drive_for(spec, rec), Ok(Drive::Current));
    if let Some(command) = rec.command_v.as_deref().filter(|_| by_command) {
        current_scale(params, &rec.name, "command_V", command, params.amp.gain_a_per_v as f64)?;
    }
    channel_signs(spec, params, rec)
}

/// A drive whose coil field (`coil.turns_per_m` × i, i the current or `gain` × the command) is
/// beyond [`MAX_COIL_FIELD_PER_MS`], refused with the unit (mA, µA; mV for a command) that
/// brings it within.
fn current_scale(params: &ActuatorParams, name: &str, column: &str, drive: &[f64], gain: f64) -> Result<()> {
    // f32 as the file gives it (13541.7), f64 for the products.
    let (given, turns) = (params.coil.turns_per_m, params.coil.turns_per_m as f64);
    let peak = drive.iter().fold(0.0f64, |a, i| a.max(i.abs()));
    let field = turns * gain * peak;
    let limit = MAX_COIL_FIELD_PER_MS * params.magnetostriction.ms_a_per_m as f64;
    if field <= limit {
        return Ok(());
    }
    let units: &[(&str, f64)] =
        if column == "current_A" { &[("mA", 1e-3), ("uA", 1e-6)] } else { &[("mV", 1e-3)] };
    let unit = units.iter().find(|(_, scale)| field * scale <= limit);
    let fix = match unit {
        Some((unit, _)) => format!(
            "was it logged in {unit}? read it so: `--column {column}={column}:{unit}` (a column mapped \
             with --column: give that mapping the unit `{unit}`); "
        ),
        None => String::new(),
    };
    let (what, through) = if column == "current_A" {
        (format!("{peak:.4e} A"), format!("`coil.turns_per_m` = {given} × the current"))
    } else {
        (
            format!("{peak:.4e} V"),
            format!(
                "`coil.turns_per_m` = {given} × `amp.gain_a_per_v` = {} × the command",
                params.amp.gain_a_per_v
            ),
        )
    };
    Err(InRecording::error(
        name,
        format!(
            "`{column}` reaches {what}, a coil field of {field:.3e} A/m ({through}), above \
             {MAX_COIL_FIELD_PER_MS} M_s ({limit:.3e} A/m): no actuator's coil makes that, and the rod would be \
             saturated throughout, so no fit can follow the file; {fix}or the parameter set's \
             `coil.turns_per_m` is not this coil's"
        ),
    ))
}

/// The model's run on `rec` from the demagnetised rod (all channels), or `None` where it cannot
/// run (the fit's to say).
pub(crate) fn demagnetised_run(
    spec: ModelSpec,
    params: &ActuatorParams,
    rec: &Recording,
) -> Result<Option<Simulation>> {
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
    let drive = model_input(spec, rec)?.column();
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

/// The doubts about `files` the model's physics and their samples raise, none a refusal: a
/// channel stuck or clipped while the drive moved,
/// a displacement whose scale the drive cannot make ([`displacement_scale`]), a loop run the
/// other way round ([`loop_direction`]), a sensor delay that follows the file better counted in
/// its own samples ([`delay_rate_doubt`]), a coil temperature that reads like °F or K
/// ([`temperature_unit`]). Each holds whatever the parameters, so start values may judge them;
/// the channels' signs may not ([`sign_doubts`]).
pub fn data_doubts<'a>(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Result<Vec<Warning>> {
    let mut doubts = Vec::new();
    for rec in files {
        doubts.extend(stuck_channels(rec));
        doubts.extend(temperature_unit(rec));
        if let Some(sim) = demagnetised_run(spec, params, rec)? {
            doubts.extend(displacement_scale(spec, rec, &sim)?);
            doubts.extend(loop_direction(spec, params, rec, &sim)?);
            doubts.extend(delay_rate_doubt(spec, params, rec, &sim)?);
        }
    }
    Ok(doubts)
}

/// Files among `files` that read better with their drive and displacement both negated
/// ([`both_negated`]), judged at parameters that hold the rig (fitted, or given to be scored):
/// which way the strain curves at the bias depends on where the bias sits on the rod's curve,
/// so a start set for another rod (the demo set) curves the other way on a correctly wired file.
pub fn sign_doubts<'a>(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Result<Vec<Warning>> {
    files.into_iter().filter_map(|rec| both_negated(spec, params, rec).transpose()).collect()
}

/// A coil's temperature at a file's start above which, read in °C, it is doubted [°C]: a coil
/// before its drive is near its room (10–40 °C), which in °F reads 50–104.
const WARM_START_C: f64 = 45.0;

/// A `temperature_C` whose first value is above [`WARM_START_C`] and, read as °F or as K, a
/// room's temperature (10–40 °C: 50–104 °F, 283–313 K; the two ranges do not meet).
fn temperature_unit(rec: &Recording) -> Option<Warning> {
    let first = *rec.temperature_c.as_ref()?.first()?;
    let room = |c: f64| first > WARM_START_C && (10.0..=40.0).contains(&c);
    let file = rec.name.clone();
    if room((first - 32.0) * 5.0 / 9.0) {
        Some(Warning::Data(DataDoubt::TemperatureLikeFahrenheit { file, first }))
    } else if room(first - 273.15) {
        Some(Warning::Data(DataDoubt::TemperatureLikeKelvin { file, first }))
    } else {
        None
    }
}

/// How many times the model's displacement spread (rms about its mean, for the start
/// parameters, from the demagnetised rod) and the file's may differ before the scale is doubted: a start set's strain
/// or a rig's prestress moves it by a few times, a unit by a thousand (a hundred and more where
/// the law saturates: a small drive gives more strain per ampere than a large one).
const SCALE_RATIO_DOUBTED: f64 = 100.0;

/// A displacement spread [`SCALE_RATIO_DOUBTED`] times the model's or more, or as many times
/// less: a drive or a displacement logged in another unit than its column says (a current in A
/// read as mA, a displacement in mm under `displacement_um`), or a coil not the parameter set's.
fn displacement_scale(spec: ModelSpec, rec: &Recording, sim: &Simulation) -> Result<Option<Warning>> {
    let Some(y) = rec.displacement_um.as_deref() else { return Ok(None) };
    let (measured, model) = (spread(y), spread(&sim.displacement_um));
    if !(measured > 0.0 && model > 0.0) {
        return Ok(None);
    }
    let ratio = measured / model;
    if (1.0 / SCALE_RATIO_DOUBTED..=SCALE_RATIO_DOUBTED).contains(&ratio) {
        return Ok(None);
    }
    Ok(Some(Warning::Data(DataDoubt::DisplacementScale {
        file: rec.name.clone(),
        drive: model_input(spec, rec)?.column(),
        measured_um: measured,
        model_um: model,
    })))
}

/// A displacement's spread: rms about its mean past the first tenth (the model's start from the
/// demagnetised rod to the bias's state is a transient the rig's file need not show).
pub(crate) fn spread(v: &[f64]) -> f64 {
    let v = &v[v.len() / 10..];
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// The file's displacement and drive both read the other way round: the strain is even in the
/// field, so with a bias a negated current puts the operating point on the field's other side,
/// where the strain curves the other way, and the displacement negated too follows that model
/// about as well as the right reading by correlation; the curvature tells them apart. Each
/// reading is run from the start state that best explains it (a file that starts mid-history
/// is not the demagnetised rod's). Said when both negated leave a quarter of the variance
/// (1 − ρ²) the file as read leaves, or less, and the file as read leaves more than 1 %.
fn both_negated(spec: ModelSpec, params: &ActuatorParams, rec: &Recording) -> Result<Option<Warning>> {
    let Some(y) = rec.displacement_um.as_deref() else { return Ok(None) };
    let negated = Recording { displacement_um: Some(y.iter().map(|v| -v).collect()), ..drive_negated(rec) };
    let follows = |r: &Recording| -> Result<f64> {
        let prep = Prepared::new(spec, r)?;
        Ok(run_model(spec, params, &prep, false).map_or(1.0, |sim| {
            unexplained(correlation(r.displacement_um.as_deref().unwrap_or_default(), &sim.displacement_um))
        }))
    };
    let (as_read, both) = (follows(rec)?, follows(&negated)?);
    if !(as_read > 0.01 && both * 4.0 <= as_read) {
        return Ok(None);
    }
    Ok(Some(Warning::Data(DataDoubt::BothNegated {
        file: rec.name.clone(),
        drive: model_input(spec, rec)?.column(),
        as_read,
        both,
    })))
}

/// The loop's signed area ∮ y di as a share of its box (the spans of i and y) per cycle (the
/// drive's travel Σ|Δi| over twice its span counts the cycles): positive where y lags i, as a
/// hysteresis law's and a mechanical lag's do on a rising bias side.
fn loop_area(i: &[f64], y: &[f64]) -> f64 {
    let (y_lo, y_hi) = y.iter().fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    let travel: f64 = i.windows(2).map(|i| (i[1] - i[0]).abs()).sum();
    let area: f64 = i.windows(2).zip(y.windows(2)).map(|(i, y)| (i[1] - i[0]) * (y[1] + y[0]) / 2.0).sum();
    // ∮ y di runs clockwise-positive: a lagging y makes it negative, so the sign is turned. Per
    // cycle of travel 2 × span(i), the box is span(i) × span(y): the share is area / (travel/2 × span(y)).
    -area / (travel / 2.0 * (y_hi - y_lo)).max(f64::MIN_POSITIVE)
}

/// The drive's frequency from its crossings of its mean (with a tenth of its span of
/// hysteresis, so noise does not count): crossings / (2 × duration).
fn drive_frequency_hz(i: &[f64], dt_s: f64) -> f64 {
    let mean = i.iter().sum::<f64>() / i.len().max(1) as f64;
    let (lo, hi) = i.iter().fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    let band = 0.1 * (hi - lo);
    let (mut above, mut crossings) = (None, 0usize);
    for &x in i {
        let side = if x > mean + band {
            Some(true)
        } else if x < mean - band {
            Some(false)
        } else {
            None
        };
        if let Some(side) = side {
            crossings += usize::from(above.is_some_and(|a| a != side));
            above = Some(side);
        }
    }
    crossings as f64 / (2.0 * i.len() as f64 * dt_s)
}

/// Smallest loop area, as a share of its box, whose direction is judged (a loop thinner than
/// that is a line whose noise sets its sign).
const LOOP_AREA_JUDGED: f64 = 0.02;

/// A file whose displacement loop against its drive runs the other way round from the model's,
/// both open enough to tell: the displacement leads the drive where every law and lag makes it
/// follow, as a file in reverse time order (its samples reversed under a rising time column) or
/// a drive column taken from another file reads.
fn loop_direction(
    spec: ModelSpec,
    params: &ActuatorParams,
    rec: &Recording,
    sim: &Simulation,
) -> Result<Option<Warning>> {
    let drive = model_input(spec, rec)?.column();
    let (Some(i), Some(y)) = (rec.column(drive), rec.displacement_um.as_deref()) else { return Ok(None) };
    // Past a mode (or a delay of half a period) the lag passes 180° and a loop turns round
    // honestly: judged only on drives well below both.
    let f = drive_frequency_hz(i, rec.dt_s());
    let mode = spec.has(Effect::MechanicalDynamics).then_some(params.mech.natural_frequency_hz as f64);
    let delay_s = spec.has(Effect::SensorDelay).then_some(params.delay_samples as f64 * params.dt_s as f64);
    if mode.is_some_and(|f_n| f > f_n / 4.0) || delay_s.is_some_and(|d| f * d > 0.125) {
        return Ok(None);
    }
    let (file, model) = (loop_area(i, y), loop_area(i, &sim.displacement_um));
    let judged = file.abs() > LOOP_AREA_JUDGED && model.abs() > LOOP_AREA_JUDGED;
    Ok((judged && file * model < 0.0).then(|| {
        Warning::Data(DataDoubt::LoopReversed {
            file: rec.name.clone(),
            drive,
            area: file,
            model_area: model,
        })
    }))
}

/// With a sensor delay and a parameter set whose `dt_s` is not the file's step: the delay
/// counted in this file's samples follows the file with at most a quarter of the variance left
/// unexplained as given, and the file as given leaves more than 1 % (the refusal of
/// [`channel_signs`] covers a displacement that then falls against the model).
fn delay_rate_doubt(
    spec: ModelSpec,
    params: &ActuatorParams,
    rec: &Recording,
    sim: &Simulation,
) -> Result<Option<Warning>> {
    let step = rec.dt_s();
    if !spec.has(Effect::SensorDelay)
        || params.delay_samples <= 0.0
        || (params.dt_s as f64 / step - 1.0).abs() <= 1e-5
    {
        return Ok(None);
    }
    let Some(y) = rec.displacement_um.as_deref() else { return Ok(None) };
    let here = ActuatorParams { dt_s: step as f32, ..*params };
    let Some(counted_here) = demagnetised_run(spec, &here, rec)? else { return Ok(None) };
    let (given, at_step) = (
        unexplained(correlation(y, &sim.displacement_um)),
        unexplained(correlation(y, &counted_here.displacement_um)),
    );
    Ok((given > 0.01 && 4.0 * at_step <= given).then(|| {
        Warning::Data(DataDoubt::DelayAtOtherRate {
            file: rec.name.clone(),
            delay_samples: params.delay_samples as f64,
            params_dt_s: params.dt_s,
            // Six significant digits: a step read off a time column is 9.99999999999994e-5 s.
            step_s: format!("{step:.5e}").parse::<f64>().unwrap_or(step),
            given,
            at_step,
        })
    }))
}

/// The share of a channel's variance a model leaves unexplained at correlation `r` (1 − r²),
/// all of it when the model runs against it (r ≤ 0).
fn unexplained(r: f64) -> f64 {
    if r > 0.0 {
        1.0 - r * r
    } else {
        1.0
    }
}
