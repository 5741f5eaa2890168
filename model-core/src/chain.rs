//! The actuator model composed from a [`ModelSpec`] and one parameter set:
//!
//! ```text
//! u [V] -amp-> i [A] -coil-> H -eddy-> H_rod -magnetization-> M -aftereffect-> M_obs
//!   -magnetostriction-> λ -(× rod length, + thermal elongation)-> y_free -mechanics-> y -delay-> y_meas
//! ```
//!
//! Every stage the spec does not name is its minimal form (ideal amplifier: the current is the
//! input; no eddy lag; linear M = a + bH; no creep; static mechanics y = y_free; no heating; no
//! delay). The parameter set always holds every stage, so one file serves every spec; only the
//! stages a spec uses are validated.

use crate::amplifier::{AmpState, Amplifier, SecondOrderAmp};
use crate::effects::{Effect, MagnetizationLaw};
use crate::error::{check, ParamError};
use crate::field::{CoilField, FirstOrderLag, LagState};
use crate::magnetization::{
    Anhysteretic, JaBranch, JaState, JilesAtherton, LinearMagnetization, Preisach, PreisachState,
    ValidPreisachParams,
};
use crate::magnetostriction::QuadraticMagnetostriction;
use crate::mechanics::{MechState, SecondOrderZoh};
use crate::slow::{Aftereffect, DelayLine, ThermalDrift};
use crate::spec::ModelSpec;

pub use crate::params::{ActuatorParams, ModalMechanics};
pub use hold::{FirstOrderHold, PreviousSample};

mod hold;

/// The chain's sensor delays lie below this [samples] (its delay line's capacity).
pub const MAX_DELAY_SAMPLES: usize = 64;

/// Largest |command| [V] or |current| [A] a step accepts: beyond it the input is a fault, not
/// a drive signal, and would only push the models towards overflow.
pub const MAX_INPUT: f32 = 1.0e4;

/// Shortest sample period accepted [s] (10 MHz): below it a recording would need more samples
/// than fit in memory. (Each lag checks its own dt/τ: [`crate::field::MAX_TAU_IN_SAMPLES`].)
pub const DT_MIN_S: f32 = 1.0e-7;
/// Longest sample period accepted [s] (0.1 Hz).
pub const DT_MAX_S: f32 = 10.0;

/// The magnetization stage the spec selects.
// No heap: the Preisach table (4 KB) lives inline; an actuator is built once and kept.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Magnetization {
    /// M = a + bH.
    Linear(LinearMagnetization),
    /// M = M_s L(H/a).
    Anhysteretic(Anhysteretic),
    /// Jiles–Atherton.
    JilesAtherton(JilesAtherton),
    /// Preisach relay plane.
    Preisach(Preisach),
}

/// A magnetization law whose parameters passed their checks. The Preisach law's table (4 KB) is
/// built only in the model's final expression: a fallible layer between builder and model
/// holds a copy of what it returns, and the firmware builds models on its deepest stack path.
enum CheckedLaw {
    Preisach(ValidPreisachParams),
    JilesAtherton(JilesAtherton),
    Anhysteretic(Anhysteretic),
    Linear(LinearMagnetization),
}

/// The validated, discretised actuator model (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Actuator {
    spec: ModelSpec,
    /// `None` when the current is the input.
    pub(crate) amp: Option<Amplifier>,
    pub(crate) coil: CoilField,
    pub(crate) eddy: Option<FirstOrderLag>,
    pub(crate) magnetization: Magnetization,
    pub(crate) aftereffect: Option<Aftereffect>,
    pub(crate) magnetostriction: QuadraticMagnetostriction,
    pub(crate) rod_length_m: f32,
    pub(crate) mech: Option<SecondOrderZoh>,
    pub(crate) thermal: Option<ThermalDrift>,
    pub(crate) delay_samples: f32,
}

/// Everything that evolves from sample to sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorState {
    /// Coil current [A] and the amplifier's internal state.
    pub amp: AmpState,
    /// Field in the rod after the eddy lag [A/m].
    pub rod_field_a_per_m: LagState,
    /// J–A state (unused by the other magnetization models).
    pub ja: JaState,
    /// Preisach memory (unused by the other magnetization models).
    pub preisach: PreisachState,
    /// Slow magnetization of the aftereffect [A/m].
    pub m_slow_a_per_m: LagState,
    /// Coil temperature rise [°C] (what a thermometer on the winding reads).
    pub temperature_rise_c: LagState,
    /// The rod's temperature rise [°C] (behind the coil's by `thermal.rod_tau_s`).
    pub rod_temperature_rise_c: LagState,
    /// Mechanics.
    pub mech: MechState,
    /// Sensor delay line [m].
    pub delay: DelayLine<MAX_DELAY_SAMPLES>,
}

/// State of [`Actuator::thermal_tail_step`] (the coil-heating share of the displacement).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalTailState {
    temperature_rise_c: LagState,
    rod_temperature_rise_c: LagState,
    mech: MechState,
    delay: DelayLine<MAX_DELAY_SAMPLES>,
}

/// What the magnetic stages of one step produce ([`Actuator::step_magnetic`], SI units).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MagneticOutput {
    /// Coil current [A].
    pub current_a: f32,
    /// Field in the rod [A/m].
    pub field_a_per_m: f32,
    /// Observed magnetization [A/m].
    pub magnetization_a_per_m: f32,
}

/// What one step produces (SI units).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ActuatorOutput {
    /// Coil current [A].
    pub current_a: f32,
    /// Field in the rod [A/m].
    pub field_a_per_m: f32,
    /// Observed magnetization [A/m].
    pub magnetization_a_per_m: f32,
    /// Magnetostrictive strain λ.
    pub strain: f32,
    /// Measured displacement [m] (after mechanics and sensor delay; zero offset).
    pub displacement_m: f32,
}

/// A step that could not be taken; the state is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepError {
    /// The input was NaN, infinite or beyond [`MAX_INPUT`].
    InputOutOfRange,
}

impl core::fmt::Display for StepError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StepError::InputOutOfRange => write!(f, "model input is not finite or beyond ±{MAX_INPUT}"),
        }
    }
}

impl core::error::Error for StepError {}

/// How closely `[magnetostriction] ms_a_per_m` must agree with the law's M_s (relative): the
/// same number written twice, allowing for a decimal round trip.
const MS_AGREEMENT: f32 = 1e-4;

impl Actuator {
    /// Builds the model for `spec`, validating only the stages it uses.
    pub fn new(spec: ModelSpec, p: &ActuatorParams) -> Result<Self, ParamError> {
        let dt = check("dt_s", p.dt_s, |v| (DT_MIN_S..=DT_MAX_S).contains(&v), "in [1e-7, 10] s")?;
        let coil = CoilField::new(p.coil.turns_per_m, p.coil.bias_a_per_m)?;
        let amp = match (spec.has(Effect::AmplifierDynamics), p.amp_second_order) {
            (false, _) => None,
            (true, None) => Some(Amplifier::FirstOrder(p.amp.build(dt)?)),
            (true, Some(p2)) => Some(Amplifier::SecondOrder(SecondOrderAmp::new(p2, dt)?)),
        };
        let eddy = if spec.has(Effect::EddyCurrent) {
            Some(FirstOrderLag::new("eddy_tau_s", p.eddy_tau_s, 1.0, dt)?)
        } else {
            None
        };
        let law = match spec.law() {
            MagnetizationLaw::Preisach => CheckedLaw::Preisach(p.preisach.validated()?),
            MagnetizationLaw::JilesAtherton => CheckedLaw::JilesAtherton(JilesAtherton::new(p.ja)?),
            MagnetizationLaw::Anhysteretic => CheckedLaw::Anhysteretic(Anhysteretic::new(p.anhysteretic)?),
            MagnetizationLaw::Linear => CheckedLaw::Linear(LinearMagnetization::new(
                p.linear.offset_a_per_m,
                p.linear.susceptibility,
            )?),
        };
        let aftereffect = if spec.has(Effect::MagneticAftereffect) {
            Some(Aftereffect::new(p.aftereffect, dt)?)
        } else {
            None
        };
        let magnetostriction = QuadraticMagnetostriction::new(p.magnetostriction)?;
        // One rod, one saturation magnetization: the strain is normalised by the law's M_s. A set
        // whose `[magnetostriction]` M_s was half its `[ja]` one drove the strain to 3.3× its
        // saturation, and a fit answered with λ_s a quarter of the truth.
        let law_ms = match spec.law() {
            MagnetizationLaw::Preisach => Some(p.preisach.ms_a_per_m),
            MagnetizationLaw::JilesAtherton => Some(p.ja.ms_a_per_m),
            MagnetizationLaw::Anhysteretic => Some(p.anhysteretic.ms_a_per_m),
            MagnetizationLaw::Linear => None,
        };
        if law_ms.is_some_and(|ms| (p.magnetostriction.ms_a_per_m - ms).abs() > MS_AGREEMENT * ms) {
            return Err(ParamError::OutOfRange(
                "magnetostriction.ms_a_per_m",
                "the magnetization law's own M_s (`ms_a_per_m` of its [ja], [preisach] or [anhysteretic] table), within 1e-4",
            ));
        }
        let rod_length_m =
            check("rod_length_m", p.rod_length_m, |l| (1e-4..=10.0).contains(&l), "in [1e-4, 10] m")?;
        let mech = if spec.has(Effect::MechanicalDynamics) { Some(p.mech.discretised(dt)?) } else { None };
        let thermal =
            if spec.has(Effect::ThermalDrift) { Some(ThermalDrift::new(p.thermal, dt)?) } else { None };
        let delay_samples = if spec.has(Effect::SensorDelay) {
            if !(0.0..MAX_DELAY_SAMPLES as f32).contains(&p.delay_samples) {
                return Err(ParamError::OutOfRange("delay_samples", "in [0, 64) samples"));
            }
            p.delay_samples
        } else {
            0.0
        };
        Ok(Self {
            spec,
            amp,
            coil,
            eddy,
            // Last, once nothing can fail: the Preisach table is built right here.
            magnetization: match law {
                CheckedLaw::Preisach(v) => Magnetization::Preisach(Preisach::lorentzian(&v)),
                CheckedLaw::JilesAtherton(m) => Magnetization::JilesAtherton(m),
                CheckedLaw::Anhysteretic(m) => Magnetization::Anhysteretic(m),
                CheckedLaw::Linear(m) => Magnetization::Linear(m),
            },
            aftereffect,
            magnetostriction,
            rod_length_m,
            mech,
            thermal,
            delay_samples,
        })
    }

    /// This model with its hysteresis law integrated `factor` times finer
    /// ([`JilesAtherton::refined`]; the other laws as they are): for the workbench, whose time
    /// per sample is not budgeted. The board steps the model as built.
    pub fn with_finer_hysteresis(mut self, factor: u32) -> Self {
        if let Magnetization::JilesAtherton(j) = self.magnetization {
            self.magnetization = Magnetization::JilesAtherton(j.refined(factor));
        }
        self
    }

    /// This model with its hysteresis law's sub-steps corrected to second order
    /// ([`JilesAtherton::second_order`]; the other laws as they are): for the workbench.
    pub fn with_second_order_hysteresis(mut self) -> Self {
        if let Magnetization::JilesAtherton(j) = self.magnetization {
            self.magnetization = Magnetization::JilesAtherton(j.second_order());
        }
        self
    }

    /// The structure this model was built for.
    pub fn spec(&self) -> ModelSpec {
        self.spec
    }

    /// Whether the input is a command voltage (amplifier modelled) rather than the coil current.
    pub fn input_is_voltage(&self) -> bool {
        self.amp.is_some()
    }

    /// The state the board boots in: zero input, cold coil, the rod demagnetised at zero field
    /// and then brought to the bias field in one step (its virgin curve).
    pub fn rest_state(&self) -> ActuatorState {
        let mut ja = JaState::default();
        let mut preisach = match &self.magnetization {
            Magnetization::Preisach(p) => p.demagnetized(),
            _ => PreisachState::default(),
        };
        let h0 = self.coil.bias_a_per_m;
        let m0 = match &self.magnetization {
            Magnetization::Linear(l) => l.magnetization(h0),
            Magnetization::Anhysteretic(a) => a.magnetization(h0),
            Magnetization::JilesAtherton(j) => j.step(&mut ja, h0),
            Magnetization::Preisach(p) => p.step(&mut preisach, h0),
        };
        self.at_rest(AmpState::default(), h0, (ja, preisach), m0)
    }

    /// The state at rest with the amplifier in `amp`, the rod's field `h0` and its magnetic
    /// state (`law`, giving `m0`): the slow magnetization caught up, the coil cold, the
    /// mechanics and the delay line at the strain's displacement. (Inlined: the board builds its
    /// state on its deepest stack path, where a frame of its own would cost the state's size.)
    #[inline(always)]
    fn at_rest(&self, amp: AmpState, h0: f32, law: (JaState, PreisachState), m0: f32) -> ActuatorState {
        let y0 = self.rod_length_m * self.magnetostriction.strain(m0);
        ActuatorState {
            amp,
            rod_field_a_per_m: LagState::at(h0),
            ja: law.0,
            preisach: law.1,
            m_slow_a_per_m: LagState::at(m0),
            temperature_rise_c: LagState::default(),
            rod_temperature_rise_c: LagState::default(),
            mech: MechState { displacement_m: y0, velocity_m_per_rad: 0.0 },
            delay: DelayLine::clamped(self.delay_samples, y0), // checked ≤ capacity in `new`
        }
    }

    /// Whether the magnetization law carries a history (J–A, Preisach): then the state at rest
    /// depends on the fields the rod has seen, not only on the field it sits in.
    pub fn has_magnetic_memory(&self) -> bool {
        matches!(self.magnetization, Magnetization::JilesAtherton(_) | Magnetization::Preisach(_))
    }

    /// The state of a rig at rest at drive `input` (the command [V] when the amplifier is
    /// modelled, else the coil current [A]) before a record starts: the amplifier, the eddy lag
    /// and the mechanics settled at it, the coil cold, and the rod demagnetised at the field
    /// that drive gives (J–A: the integrated magnetization, M_irr or the total forms' M, is 0
    /// there; Preisach: the demagnetised plane raised to it), then taken through a field
    /// excursion of `excursion_a_per_m` from that field and back. Every magnetic state a rod can
    /// hold at that field lies on this one line: a J–A state at a field is its integrated
    /// magnetization alone, and the excursions reach every value between the branches, the
    /// demagnetised (0) and the anhysteretic state too. A file's first row is this state.
    pub fn rest_state_at(&self, input: f32, excursion_a_per_m: f32) -> ActuatorState {
        let input = if input.is_finite() { input.clamp(-MAX_INPUT, MAX_INPUT) } else { 0.0 };
        let mut amp = AmpState::default();
        let current = match &self.amp {
            Some(Amplifier::FirstOrder(a)) => {
                amp.first_order = LagState::at(a.gain() * input);
                a.gain() * input
            }
            Some(Amplifier::SecondOrder(a)) => a.settle_at(&mut amp.internal, input),
            None => input,
        };
        amp.current_a = current;
        let h0 = self.coil.field(current);
        let mut ja = JaState::default();
        let mut preisach = match &self.magnetization {
            Magnetization::Preisach(p) => p.demagnetized(),
            _ => PreisachState::default(),
        };
        let mut m0 = match &self.magnetization {
            Magnetization::Linear(l) => l.magnetization(h0),
            Magnetization::Anhysteretic(a) => a.magnetization(h0),
            Magnetization::JilesAtherton(j) => {
                ja = j.demagnetized_at(h0);
                ja.m_a_per_m
            }
            Magnetization::Preisach(p) => p.step(&mut preisach, h0),
        };
        let excursion = if excursion_a_per_m.is_finite() { excursion_a_per_m } else { 0.0 };
        if excursion != 0.0 && self.has_magnetic_memory() {
            // 64 equal steps a leg: the state then depends smoothly on the excursion (a fit
            // differentiates through it).
            for (from, to) in [(h0, h0 + excursion), (h0 + excursion, h0)] {
                for k in 1..=64 {
                    let h = from + (to - from) * k as f32 / 64.0;
                    m0 = match &self.magnetization {
                        Magnetization::JilesAtherton(j) => j.step(&mut ja, h),
                        Magnetization::Preisach(p) => p.step(&mut preisach, h),
                        _ => m0,
                    };
                }
            }
        }
        self.at_rest(amp, h0, (ja, preisach), m0)
    }

    /// The start of [`Actuator::thermal_tail_step`]: cold coil, mechanics and delay line at 0.
    pub fn thermal_tail_rest(&self) -> ThermalTailState {
        ThermalTailState {
            temperature_rise_c: LagState::default(),
            rod_temperature_rise_c: LagState::default(),
            mech: MechState::default(),
            delay: DelayLine::clamped(self.delay_samples, 0.0),
        }
    }

    /// The part of the measured displacement [m] that coil heating alone makes: the thermal
    /// elongation at coil current `current_a` (the current [`Actuator::step`] reported) through
    /// the same mechanics and sensor delay. Both are linear, so the chain's displacement is this
    /// plus what the magnetostriction makes: the workbench splits the two (to solve λ_s in
    /// closed form) without running the magnetization twice. 0 without `thermal_drift`.
    #[inline]
    pub fn thermal_tail_step(&self, s: &mut ThermalTailState, current_a: f32) -> f32 {
        let elongation = match &self.thermal {
            Some(th) => th.step(&mut s.temperature_rise_c, &mut s.rod_temperature_rise_c, current_a),
            None => 0.0,
        };
        let y = match &self.mech {
            Some(zoh) => zoh.step(&mut s.mech, elongation),
            None => elongation,
        };
        s.delay.step(y)
    }

    /// One sample. `input` is the command voltage [V] when the amplifier is modelled, else the
    /// coil current [A].
    #[inline]
    pub fn step(&self, s: &mut ActuatorState, input: f32) -> Result<ActuatorOutput, StepError> {
        self.step_with_field_stage(s, input, |h_coil| h_coil)
    }

    /// [`Actuator::step`] with one more stage between the coil field and the eddy lag:
    /// `rod_field` maps the coil field [A/m] to the field the rod sees. The workbench's plant
    /// simulator puts its distributed (radial diffusion) eddy-current model here; the board
    /// does not use it.
    #[inline]
    pub fn step_with_field_stage(
        &self,
        s: &mut ActuatorState,
        input: f32,
        rod_field: impl FnOnce(f32) -> f32,
    ) -> Result<ActuatorOutput, StepError> {
        let magnetic = self.step_magnetic(s, input, rod_field)?;
        Ok(self.step_mechanical(s, magnetic))
    }

    /// The magnetic stages of one step: drive → coil current → field in the rod (through
    /// `rod_field`, as in [`Actuator::step_with_field_stage`]) → observed magnetization. They
    /// touch only the amplifier, eddy, magnetization and aftereffect parts of `s`, and nothing
    /// downstream feeds back into them: the workbench runs them once for parameter sets that
    /// differ only in the mechanical stages.
    #[inline]
    pub fn step_magnetic(
        &self,
        s: &mut ActuatorState,
        input: f32,
        rod_field: impl FnOnce(f32) -> f32,
    ) -> Result<MagneticOutput, StepError> {
        let (current, h) = self.step_rod_field(s, input, rod_field)?;
        let m = self.step_magnetization(s, h);
        Ok(self.observed(s, current, h, m))
    }

    /// [`Actuator::step_magnetic`] with a Jiles–Atherton law kept on branch `b` of direction
    /// `dir` ([`JilesAtherton::step_on_branch`]): for a measured drive whose noise is not to
    /// open minor loops. The other laws step as in `step_magnetic`.
    #[inline]
    pub fn step_magnetic_on_branch(
        &self,
        s: &mut ActuatorState,
        b: &mut JaBranch,
        input: f32,
        dir: f32,
    ) -> Result<MagneticOutput, StepError> {
        let (current, h) = self.step_rod_field(s, input, |h| h)?;
        let m = match &self.magnetization {
            Magnetization::JilesAtherton(j) => j.step_on_branch(&mut s.ja, b, h, dir),
            _ => self.step_magnetization(s, h),
        };
        Ok(self.observed(s, current, h, m))
    }

    /// The stages before the magnetization alone: the coil current [A] and the rod's field
    /// [A/m] one step of `input` gives (they touch only the amplifier and eddy parts of `s`).
    #[inline]
    pub fn step_field(&self, s: &mut ActuatorState, input: f32) -> Result<(f32, f32), StepError> {
        self.step_rod_field(s, input, |h| h)
    }

    /// [`Actuator::step_magnetic`] of this actuator and of `other` (each with its own state and
    /// input; no extra field stage) at once, their Jiles–Atherton integrations interleaved
    /// ([`JilesAtherton::step_beside`]): for a caller running two independent simulations on
    /// one core, which then overlaps their chains of dependent arithmetic. Each result is the
    /// same bits as its own `step_magnetic` gives.
    #[inline]
    pub fn step_magnetic_beside(
        &self,
        s: &mut ActuatorState,
        input: f32,
        other: &Actuator,
        s_other: &mut ActuatorState,
        input_other: f32,
    ) -> [Result<MagneticOutput, StepError>; 2] {
        match (self.step_rod_field(s, input, |h| h), other.step_rod_field(s_other, input_other, |h| h)) {
            (Ok((current, h)), Ok((current_other, h_other))) => {
                let (m, m_other) = match (&self.magnetization, &other.magnetization) {
                    (Magnetization::JilesAtherton(ja), Magnetization::JilesAtherton(ja_other)) => {
                        ja.step_beside(&mut s.ja, h, ja_other, &mut s_other.ja, h_other)
                    }
                    _ => (self.step_magnetization(s, h), other.step_magnetization(s_other, h_other)),
                };
                [
                    Ok(self.observed(s, current, h, m)),
                    Ok(other.observed(s_other, current_other, h_other, m_other)),
                ]
            }
            (a, b) => [
                a.map(|(current, h)| {
                    let m = self.step_magnetization(s, h);
                    self.observed(s, current, h, m)
                }),
                b.map(|(current, h)| {
                    let m = other.step_magnetization(s_other, h);
                    other.observed(s_other, current, h, m)
                }),
            ],
        }
    }

    /// The stages before the magnetization: drive → coil current → field in the rod (through
    /// `rod_field`, then the eddy lag). Returns the current [A] and the rod's field [A/m].
    #[inline(always)]
    fn step_rod_field(
        &self,
        s: &mut ActuatorState,
        input: f32,
        rod_field: impl FnOnce(f32) -> f32,
    ) -> Result<(f32, f32), StepError> {
        if !input.is_finite() || input.abs() > MAX_INPUT {
            return Err(StepError::InputOutOfRange);
        }
        let current = match &self.amp {
            Some(amp) => amp.step(&mut s.amp, input),
            None => {
                s.amp.current_a = input;
                input
            }
        };
        let h_coil = rod_field(self.coil.field(current));
        let h = match &self.eddy {
            Some(lag) => lag.step(&mut s.rod_field_a_per_m, h_coil),
            None => {
                s.rod_field_a_per_m = LagState::at(h_coil);
                h_coil
            }
        };
        Ok((current, h))
    }

    /// The magnetization law's step to the rod field `h` [A/m].
    #[inline(always)]
    fn step_magnetization(&self, s: &mut ActuatorState, h: f32) -> f32 {
        match &self.magnetization {
            Magnetization::Linear(l) => l.magnetization(h),
            Magnetization::Anhysteretic(a) => a.magnetization(h),
            Magnetization::JilesAtherton(j) => j.step(&mut s.ja, h),
            Magnetization::Preisach(p) => p.step(&mut s.preisach, h),
        }
    }

    /// The magnetic stages' output, the magnetization `m` seen through the aftereffect.
    #[inline(always)]
    fn observed(&self, s: &mut ActuatorState, current: f32, h: f32, m: f32) -> MagneticOutput {
        let m_obs = match &self.aftereffect {
            Some(ae) => ae.step(&mut s.m_slow_a_per_m, m),
            None => m,
        };
        MagneticOutput { current_a: current, field_a_per_m: h, magnetization_a_per_m: m_obs }
    }

    /// The mechanical stages of one step, from what [`Actuator::step_magnetic`] produced:
    /// magnetostriction, coil heating, mechanics and sensor delay. They touch only the
    /// temperature, mechanics and delay-line parts of `s`.
    // Always inlined: returned through memory, its output's f32 pairs were read back as one
    // wider load, which stalls a host run every sample (≈ 15 % of a paired run's time).
    #[inline(always)]
    pub fn step_mechanical(&self, s: &mut ActuatorState, magnetic: MagneticOutput) -> ActuatorOutput {
        let MagneticOutput { current_a: current, field_a_per_m: h, magnetization_a_per_m: m_obs } = magnetic;
        let strain = self.magnetostriction.strain(m_obs);
        let thermal = match &self.thermal {
            Some(th) => th.step(&mut s.temperature_rise_c, &mut s.rod_temperature_rise_c, current),
            None => 0.0,
        };
        let y_free = strain * self.rod_length_m + thermal;
        let y = match &self.mech {
            Some(zoh) => zoh.step(&mut s.mech, y_free),
            None => {
                s.mech.displacement_m = y_free;
                y_free
            }
        };
        let y_meas = s.delay.step(y);
        ActuatorOutput {
            current_a: current,
            field_a_per_m: h,
            magnetization_a_per_m: m_obs,
            strain,
            displacement_m: y_meas,
        }
    }
}
