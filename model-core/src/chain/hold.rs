//! The workbench's stepping of the chain: a first-order hold. A recording knows its drive only at
//! its samples; between two, the drive is taken as the straight line through them, every linear
//! stage (amplifier, eddy lag, aftereffect, coil heating, mechanics) is stepped exactly for a
//! ramp of its own input between its values at the two samples, and the static stages (coil
//! field, magnetization law, magnetostriction) are evaluated at each sample's own value. Every
//! output of a step is then the model's state at the next sample's instant: no stage lags half a
//! sample behind another (a held drive, as the board's [`Actuator::step`], answers at t_{k+1}
//! the drive of t_k; the mean of the two samples held, the static stages at t_{k+½}).
//!
//! The hysteresis law is rate independent and already integrated along the field between its
//! values at the two samples, so it steps as in [`Actuator::step`].

use super::{Actuator, ActuatorOutput, ActuatorState, MagneticOutput, Magnetization, StepError, MAX_INPUT};
use crate::amplifier::Amplifier;
use crate::magnetization::JaBranch;

/// The ramp coefficients of a model's linear stages at one sample period (built once per run).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirstOrderHold {
    amp: AmpRamp,
    eddy: f32,
    aftereffect: f32,
    heating: (f32, f32),
    mech: [f32; 2],
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum AmpRamp {
    None,
    FirstOrder(f32),
    SecondOrder([f32; 2]),
}

/// What a first-order-hold step needs of the sample before it beside the model's state: the
/// drive and the magnetization law's output there.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PreviousSample {
    input: f32,
    law_magnetization_a_per_m: f32,
}

impl FirstOrderHold {
    /// The coefficients of `model`'s stages at sample period `dt_s` (the period it was built for).
    pub fn new(model: &Actuator, dt_s: f32) -> Self {
        Self {
            amp: match &model.amp {
                None => AmpRamp::None,
                Some(Amplifier::FirstOrder(a)) => AmpRamp::FirstOrder(a.ramp_factor(dt_s)),
                Some(Amplifier::SecondOrder(a)) => AmpRamp::SecondOrder(a.ramp_term(dt_s)),
            },
            eddy: model.eddy.as_ref().map_or(0.0, |l| l.ramp_factor(dt_s)),
            aftereffect: model.aftereffect.as_ref().map_or(0.0, |a| a.ramp_factor(dt_s)),
            heating: model.thermal.as_ref().map_or((0.0, 0.0), |t| t.ramp_factors(dt_s)),
            mech: model.mech.as_ref().map_or([0.0; 2], |m| m.ramp_term(dt_s)),
        }
    }
}

impl Actuator {
    /// The sample a run starting from `s` (at rest at drive `input`, [`Actuator::rest_state_at`])
    /// comes from.
    pub fn previous_at_rest(&self, s: &ActuatorState, input: f32) -> PreviousSample {
        // At rest the slow magnetization has caught up with the law's.
        PreviousSample { input, law_magnetization_a_per_m: s.m_slow_a_per_m.value() }
    }

    /// What the magnetic stages give at rest in `s` (the `before` of a run's first step).
    pub fn magnetic_at_rest(&self, s: &ActuatorState) -> MagneticOutput {
        MagneticOutput {
            current_a: s.amp.current_a,
            field_a_per_m: s.rod_field_a_per_m.value(),
            magnetization_a_per_m: s.m_slow_a_per_m.value(),
        }
    }

    /// The magnetic stages of one first-order-hold step to the next sample's drive `input`
    /// (`prev` is this sample's, and becomes the next's).
    #[inline]
    pub fn step_magnetic_ramp(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        prev: &mut PreviousSample,
        input: f32,
    ) -> Result<MagneticOutput, StepError> {
        let (current, h) = self.rod_field_ramp(s, hold, prev, input)?;
        let m = self.step_magnetization(s, h);
        Ok(self.observed_ramp(s, hold, prev, current, h, m))
    }

    /// [`Actuator::step_magnetic_ramp`] with a Jiles–Atherton law kept on branch `b` of
    /// direction `dir` ([`Actuator::step_magnetic_on_branch`]).
    #[inline]
    pub fn step_magnetic_ramp_on_branch(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        prev: &mut PreviousSample,
        b: &mut JaBranch,
        input: f32,
        dir: f32,
    ) -> Result<MagneticOutput, StepError> {
        let (current, h) = self.rod_field_ramp(s, hold, prev, input)?;
        let m = match &self.magnetization {
            Magnetization::JilesAtherton(j) => j.step_on_branch(&mut s.ja, b, h, dir),
            _ => self.step_magnetization(s, h),
        };
        Ok(self.observed_ramp(s, hold, prev, current, h, m))
    }

    /// One whole first-order-hold step to the next sample's drive `input`: `before` is what
    /// the magnetic stages gave at this sample ([`MagneticOutput`]; at rest its current, field
    /// and magnetization), and becomes the next's.
    #[inline]
    pub fn step_ramp(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        prev: &mut PreviousSample,
        before: &mut MagneticOutput,
        input: f32,
    ) -> Result<ActuatorOutput, StepError> {
        self.step_ramp_with_field_stage(s, hold, (prev, before), input, |_, h| h)
    }

    /// [`Actuator::step_ramp`] with one more stage between the coil field and the eddy lag, as
    /// [`Actuator::step_with_field_stage`]: `rod_field` maps the coil field at this sample and
    /// at the next [A/m] to the field the rod sees at the next (the plant's distributed eddy
    /// currents; the board does not use it).
    #[inline]
    pub fn step_ramp_with_field_stage(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        (prev, before): (&mut PreviousSample, &mut MagneticOutput),
        input: f32,
        rod_field: impl FnOnce(f32, f32) -> f32,
    ) -> Result<ActuatorOutput, StepError> {
        let (current, h) = self.rod_field_ramp_with(s, hold, prev, input, rod_field)?;
        let m = self.step_magnetization(s, h);
        let magnetic = self.observed_ramp(s, hold, prev, current, h, m);
        let out = self.step_mechanical_ramp(s, hold, before, magnetic);
        *before = magnetic;
        Ok(out)
    }

    /// [`Actuator::step_magnetic_ramp`] of this actuator and of `other` at once, their
    /// Jiles–Atherton integrations interleaved as in [`Actuator::step_magnetic_beside`]; each
    /// result is the same bits as its own `step_magnetic_ramp` gives.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn step_magnetic_ramp_beside(
        &self,
        (s, hold, prev, input): (&mut ActuatorState, &FirstOrderHold, &mut PreviousSample, f32),
        other: &Actuator,
        (s_other, hold_other, prev_other, input_other): (
            &mut ActuatorState,
            &FirstOrderHold,
            &mut PreviousSample,
            f32,
        ),
    ) -> [Result<MagneticOutput, StepError>; 2] {
        match (
            self.rod_field_ramp(s, hold, prev, input),
            other.rod_field_ramp(s_other, hold_other, prev_other, input_other),
        ) {
            (Ok((current, h)), Ok((current_other, h_other))) => {
                let (m, m_other) = match (&self.magnetization, &other.magnetization) {
                    (Magnetization::JilesAtherton(ja), Magnetization::JilesAtherton(ja_other)) => {
                        ja.step_beside(&mut s.ja, h, ja_other, &mut s_other.ja, h_other)
                    }
                    _ => (self.step_magnetization(s, h), other.step_magnetization(s_other, h_other)),
                };
                [
                    Ok(self.observed_ramp(s, hold, prev, current, h, m)),
                    Ok(other.observed_ramp(s_other, hold_other, prev_other, current_other, h_other, m_other)),
                ]
            }
            (a, b) => [
                a.map(|(current, h)| {
                    let m = self.step_magnetization(s, h);
                    self.observed_ramp(s, hold, prev, current, h, m)
                }),
                b.map(|(current, h)| {
                    let m = other.step_magnetization(s_other, h);
                    other.observed_ramp(s_other, hold_other, prev_other, current, h, m)
                }),
            ],
        }
    }

    /// The coil current [A] and the rod's field [A/m] one first-order-hold step to `input`
    /// gives (they touch only the amplifier and eddy parts of `s`; `prev.input` becomes `input`).
    #[inline]
    pub fn rod_field_ramp(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        prev: &mut PreviousSample,
        input: f32,
    ) -> Result<(f32, f32), StepError> {
        self.rod_field_ramp_with(s, hold, prev, input, |_, h| h)
    }

    /// [`Actuator::rod_field_ramp`] through the field stage `rod_field` (coil field at this
    /// sample and at the next → the rod's, before the eddy lag).
    #[inline(always)]
    fn rod_field_ramp_with(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        prev: &mut PreviousSample,
        input: f32,
        rod_field: impl FnOnce(f32, f32) -> f32,
    ) -> Result<(f32, f32), StepError> {
        if !input.is_finite() || input.abs() > MAX_INPUT {
            return Err(StepError::InputOutOfRange);
        }
        let current_before = s.amp.current_a;
        let current = match (&self.amp, hold.amp) {
            (Some(Amplifier::FirstOrder(a)), AmpRamp::FirstOrder(r)) => {
                a.step_ramp(&mut s.amp.first_order, prev.input, input, r)
            }
            (Some(Amplifier::SecondOrder(a)), AmpRamp::SecondOrder(r)) => {
                a.step_ramp(&mut s.amp.internal, prev.input, input, &r)
            }
            (Some(amp), _) => amp.step(&mut s.amp, input), // a hold built for another model
            (None, _) => input,
        };
        s.amp.current_a = current;
        prev.input = input;
        let h_coil_before = self.coil.field(current_before);
        let h_coil = rod_field(h_coil_before, self.coil.field(current));
        let h = match &self.eddy {
            // (A field stage stands in for the lumped lag: the plant builds its chain without it.)
            Some(lag) => lag.step_ramp(&mut s.rod_field_a_per_m, h_coil_before, h_coil, hold.eddy),
            None => {
                s.rod_field_a_per_m = super::LagState::at(h_coil);
                h_coil
            }
        };
        Ok((current, h))
    }

    /// The law's magnetization `m` seen through the aftereffect, its input a ramp from the
    /// previous sample's.
    #[inline(always)]
    fn observed_ramp(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        prev: &mut PreviousSample,
        current: f32,
        h: f32,
        m: f32,
    ) -> MagneticOutput {
        let m_obs = match &self.aftereffect {
            Some(ae) => {
                ae.step_ramp(&mut s.m_slow_a_per_m, prev.law_magnetization_a_per_m, m, hold.aftereffect)
            }
            None => m,
        };
        prev.law_magnetization_a_per_m = m;
        MagneticOutput { current_a: current, field_a_per_m: h, magnetization_a_per_m: m_obs }
    }

    /// The mechanical stages of one first-order-hold step, from the magnetic stages' output at
    /// this sample (`before`) and at the next (`magnetic`): magnetostriction, coil heating,
    /// mechanics (each input a ramp between the two) and the sensor delay.
    #[inline(always)]
    pub fn step_mechanical_ramp(
        &self,
        s: &mut ActuatorState,
        hold: &FirstOrderHold,
        before: &MagneticOutput,
        magnetic: MagneticOutput,
    ) -> ActuatorOutput {
        let strain = self.magnetostriction.strain(magnetic.magnetization_a_per_m);
        let (thermal_before, thermal) = match &self.thermal {
            Some(th) => (
                th.elongation_m(s.rod_temperature_rise_c.value()),
                th.step_ramp(
                    &mut s.temperature_rise_c,
                    &mut s.rod_temperature_rise_c,
                    before.current_a,
                    magnetic.current_a,
                    hold.heating,
                ),
            ),
            None => (0.0, 0.0),
        };
        let y_free = strain * self.rod_length_m + thermal;
        let y = match &self.mech {
            Some(zoh) => {
                let y_free_before = self.magnetostriction.strain(before.magnetization_a_per_m)
                    * self.rod_length_m
                    + thermal_before;
                zoh.step_ramp(&mut s.mech, y_free_before, y_free, &hold.mech)
            }
            None => {
                s.mech.displacement_m = y_free;
                y_free
            }
        };
        ActuatorOutput {
            current_a: magnetic.current_a,
            field_a_per_m: magnetic.field_a_per_m,
            magnetization_a_per_m: magnetic.magnetization_a_per_m,
            strain,
            displacement_m: s.delay.step(y),
        }
    }

    /// [`Actuator::thermal_tail_step`] under the first-order hold: the coil-heating share of
    /// the displacement one step on, the coil current a ramp from `i0` to `i1`.
    #[inline]
    pub fn thermal_tail_step_ramp(
        &self,
        s: &mut super::ThermalTailState,
        hold: &FirstOrderHold,
        i0: f32,
        i1: f32,
    ) -> f32 {
        let (before, elongation) = match &self.thermal {
            Some(th) => (
                th.elongation_m(s.rod_temperature_rise_c.value()),
                th.step_ramp(&mut s.temperature_rise_c, &mut s.rod_temperature_rise_c, i0, i1, hold.heating),
            ),
            None => (0.0, 0.0),
        };
        let y = match &self.mech {
            Some(zoh) => zoh.step_ramp(&mut s.mech, before, elongation, &hold.mech),
            None => elongation,
        };
        s.delay.step(y)
    }
}
