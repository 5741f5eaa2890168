#![doc = include_str!("../README.md")]
#![cfg_attr(not(any(test, feature = "std")), no_std)]

pub mod amplifier;
pub mod arx;
pub mod chain;
pub mod effects;
pub mod error;
pub mod field;
pub mod inverse;
pub mod magnetization;
pub mod magnetostriction;
pub mod math;
pub mod mechanics;
pub mod params;
pub mod sinusoidal;
pub mod slow;
pub mod spec;

pub use chain::{
    Actuator, ActuatorOutput, ActuatorParams, ActuatorState, FirstOrderHold, MagneticOutput, PreviousSample,
    StepError, ThermalTailState, DT_MAX_S, DT_MIN_S,
};
pub use effects::{Effect, MagnetizationLaw};
pub use error::ParamError;
pub use inverse::{Compensator, CompensatorState};
pub use spec::{ModelSpec, SpecError};
