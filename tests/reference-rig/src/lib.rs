//! # refrig — independent reference simulator of a Terfenol-D actuator rig
//!
//! A rig written apart from the project's model library (it shares no code with
//! `model-core` or `host-sim`), on purpose richer and built differently, so that the `gma`
//! workbench can be tried on data it did not generate. See `README.md` for every equation
//! and its source.
//!
//! Signal chain: command u(t) → amplifier (voltage mode with lag, rail and current limit, or
//! current mode) → coil (L di/dt = v − R(T) i, coil and rod temperatures) → surface field
//! n i + H_bias → field diffusion into the conducting rod over radial shells, each with its
//! own hysteresis state (three Jiles–Atherton variants or a Preisach model) → mean
//! magnetization → magnetic aftereffect → magnetostriction with pre-stress, ΔE effect and
//! thermal expansion → two-mass mechanics → sensors (noise, quantisation, offset, drift,
//! delay). Everything continuous is integrated by an adaptive Dormand–Prince 5(4) method.
//!
//! ```no_run
//! let rig = refrig::Rig { duration_s: 0.1, ..refrig::Rig::default() };
//! let rec = rig.simulate().expect("simulation");
//! rec.write_csv(std::io::stdout().lock(), false).expect("write");
//! ```

pub mod drive;
pub mod integrator;
pub mod magnetics;
pub mod mechanics;
pub mod recording;
pub mod rig;
pub mod sensor;

pub use drive::{Drive, Tone, Waveform};
pub use integrator::{DormandPrince, IntegrationError, OdeSystem, StepStats};
pub use magnetics::{JaParams, JaVariant, Material, PreisachParams, ShellState, MU0};
pub use mechanics::Mechanics;
pub use recording::Recording;
pub use rig::{
    Aftereffect, Amplifier, AmplifierMode, Coil, Effects, Law, Magnetostriction, MaterialConfig, PreHistory,
    Rig, RigError, Rod, Solver, Thermal,
};
pub use sensor::{SearchCoil, Sensor};
