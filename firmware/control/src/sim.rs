//! A SIMULATED rig for closed-loop tests on the host and under QEMU: the coil's R–L electrics
//! driven by the bridge, a model-core actuator driven by the coil current, and the board's
//! front end (calibration, 12-bit codes). Faults can be injected: a bridge stuck on, a shorted
//! coil, a disconnected or frozen displacement probe.

use model_core::{Actuator, ActuatorParams, ActuatorState, ModelSpec, ParamError};

use crate::units::{AdcCode, Amps, Calibration, Micrometres, Volts};
use crate::{RawSample, TickOutput};

/// Injected faults.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Injected {
    /// Displacement probe unplugged (input pulled to 0 V).
    pub probe_disconnected: bool,
    /// Displacement code frozen at its present value.
    pub probe_frozen: bool,
    /// A gate-drive fault holds the bridge at full positive voltage while it is enabled (the
    /// master output enable still switches it off).
    pub bridge_stuck_on: bool,
}

/// The simulated rig.
pub struct SimRig {
    /// Coil resistance [Ω] (change it to simulate a shorted winding).
    pub coil_resistance_ohm: f32,
    coil_inductance_h: f32,
    tick_s: f32,
    /// Bus voltage [V].
    pub bus: Volts,
    /// Front end.
    pub calibration: Calibration,
    /// Injected faults.
    pub injected: Injected,
    actuator: Actuator,
    state: ActuatorState,
    current: f32,
    displacement_m: f32,
    probe_offset_um: f32,
    frozen: Option<AdcCode>,
}

impl SimRig {
    /// A rig whose actuator is `spec` (no `amp`: the coil current drives it) with `params`,
    /// the coil of 000 Table 1 (6 Ω, 6 mH) on a 24 V bus, stepped at `tick_s`. The probe reads
    /// 20 µm at rest.
    pub fn new(spec: ModelSpec, params: &ActuatorParams, tick_s: f32) -> Result<Self, ParamError> {
        let mut p = *params;
        p.dt_s = tick_s;
        let actuator = Actuator::new(spec.without(model_core::Effect::AmplifierDynamics), &p)?;
        let state = actuator.rest_state();
        let rest_um = state.mech.displacement_m * 1e6;
        Ok(Self {
            coil_resistance_ohm: 6.0,
            coil_inductance_h: 6e-3,
            tick_s,
            bus: Volts(24.0),
            calibration: Calibration::REFERENCE_BOARD,
            injected: Injected::default(),
            actuator,
            state,
            current: 0.0,
            displacement_m: state.mech.displacement_m,
            probe_offset_um: 20.0 - rest_um,
            frozen: None,
        })
    }

    /// Actuator displacement [µm] relative to its rest position (the truth, without the probe).
    pub fn displacement_from_rest_um(&self) -> f32 {
        self.displacement_m * 1e6 + self.probe_offset_um - 20.0
    }

    /// Coil current [A].
    pub fn current(&self) -> Amps {
        Amps(self.current)
    }

    /// What the ADC converts at the start of a tick.
    pub fn sample(&mut self) -> RawSample {
        let y = self.displacement_m * 1e6 + self.probe_offset_um;
        let mut disp = self.calibration.displacement_code(Micrometres(y));
        if self.injected.probe_disconnected {
            disp = AdcCode(0);
        }
        if self.injected.probe_frozen {
            disp = *self.frozen.get_or_insert(disp);
        } else {
            self.frozen = None;
        }
        RawSample {
            current: self.calibration.current_code(Amps(self.current)),
            displacement: disp,
            bus: self.bus,
        }
    }

    /// Applies a tick's bridge command for one tick period.
    pub fn apply(&mut self, out: &TickOutput) {
        let r = self.coil_resistance_ohm.max(1e-3);
        let p = model_core::math::exp(-self.tick_s * r / self.coil_inductance_h);
        let i0 = self.current;
        let v = if out.bridge_enabled && self.injected.bridge_stuck_on {
            self.bus.0
        } else if out.bridge_enabled {
            out.duty.clamp(-1.0, 1.0) * self.bus.0
        } else if i0 != 0.0 {
            // Bridge off: the coil discharges into the bus through the body diodes.
            -i0.signum() * self.bus.0
        } else {
            0.0
        };
        let mut i1 = p * i0 + (1.0 - p) * v / r;
        if !out.bridge_enabled && i0 * i1 < 0.0 {
            i1 = 0.0; // the diodes stop conducting at zero current
        }
        self.current = i1;
        // The actuator sees the tick's mean current.
        if let Ok(o) = self.actuator.step(&mut self.state, 0.5 * (i0 + i1)) {
            self.displacement_m = o.displacement_m;
        }
    }
}
