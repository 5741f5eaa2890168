//! A SIMULATED drive rig for closed-loop tests on the host and under QEMU: the board's side —
//! full bridge, bus, analog front end (calibration, 12-bit codes) — around a [`Plant`] (coil and
//! actuator), with faults injected at chosen ticks: what the sensors and the power stage do when
//! something breaks.
//!
//! The board's timing: the ADC is triggered at the centre of each PWM period, so one conversion
//! sees the period-mean coil current (an averaged bridge model has no ripple to alias); the tick
//! computes during that period and writes the compare registers, which load at the next update
//! (preload + repetition counter). The duty computed from sample n is therefore across the coil
//! from trigger n + 1 to n + 2: [`Rig::apply`] holds the previous tick's duty for this period.
//! Switching the bridge off (MOE cleared by software or the break input) is not preloaded: it
//! acts at once. The bus voltage goes through a divider into a 12-bit channel. [`CoilActuator`] is the no_std plant; the workbench (host-sim) puts its
//! plant simulator in the same rig.
//!
//! The bus: stiff by default (the supply holds [`Rig::bus_v`] whatever the bridge does). With
//! [`Rig::bus_capacitance`] set it is a capacitance fed from the supply through a diode: the
//! supply cannot sink current, so what the bridge returns (the coil's current through the body
//! diodes on a trip, or the bridge's input current d·i when negative in regenerative running)
//! charges the capacitance above the supply's voltage, and only the bus divider's bleed and
//! the coil take it back. Per tick the coil sees the bus at the tick's midpoint, predicted from
//! the current at its start; the charge is the tick's mean current (trapezoid) — within 0.1 V
//! of a fine integration of the L–R–C discharge (`tests::the_rig_bus_follows_the_lrc_discharge`).
//!
//! The rig's analog side is `f64`, the workbench plant's precision; [`CoilActuator`] rounds to
//! `f32` at its input.

use model_core::{Actuator, ActuatorParams, ActuatorState, Effect, ModelSpec, ParamError, StepError};

use crate::tick::{RawSample, TickOutput};
use crate::units::{AdcCode, Amps, Calibration, Micrometres, Volts, ADC_FULL_SCALE};

/// Most faults a rig holds in its schedule.
pub const MAX_INJECTIONS: usize = 8;

/// What the displacement probe reads at the actuator's rest position [µm].
const PROBE_AT_REST_UM: f64 = 20.0;

/// What the bridge puts across the coil for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CoilDrive {
    /// Bridge enabled: this voltage [V].
    Voltage(f64),
    /// Bridge off: the body diodes return the coil current into the bus until it reaches zero.
    Freewheel {
        /// The voltage the diodes conduct against [V].
        bus_v: f64,
    },
}

/// The coil and actuator a [`Rig`] drives.
pub trait Plant {
    /// Why a step failed.
    type Error;
    /// Holds `drive` across the coil for one tick.
    fn step(&mut self, drive: CoilDrive) -> Result<(), Self::Error>;
    /// Coil current [A].
    fn current_a(&self) -> f64;
    /// Displacement [µm] (absolute: the rig takes its zero at rest).
    fn displacement_um(&self) -> f64;
}

/// A fault of the sensors, the supply or the power stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The displacement probe's cable is unplugged: its input is pulled to 0 V.
    DisplacementDropout,
    /// The displacement code freezes at the value it has when the fault starts.
    DisplacementFrozen,
    /// The current-sense amplifier loses its supply: its output reads 0 V.
    CurrentSenseDropout,
    /// The probe is mounted off-centre by this much [µm]: the signal clips at the ADC's full scale.
    DisplacementSaturation {
        /// Extra probe offset [µm].
        offset_um: f64,
    },
    /// Broadband interference on the displacement channel [µm rms].
    NoiseBurst {
        /// Noise level [µm rms].
        rms_um: f64,
    },
    /// The supply folds back: the bus sags to this voltage (the board measures it).
    BusSag {
        /// Bus voltage during the fault [V].
        bus_v: f64,
    },
    /// The power stage cannot follow: its output clips at ± this voltage (amplifier saturation).
    AmplifierSaturation {
        /// Largest output magnitude [V].
        max_v: f64,
    },
    /// A gate-drive fault holds the bridge at full positive voltage while it is enabled (the
    /// master output enable still switches it off).
    BridgeStuckOn,
    /// The gate driver's fault pin (or the over-current comparator) pulls the timer's break
    /// input: the hardware switches the outputs off by itself, and the tick reads the break flag.
    GateDriverFault,
}

/// A fault active for ticks `from..from + ticks`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Injection {
    /// What breaks.
    pub fault: Fault,
    /// First tick.
    pub from: u64,
    /// Duration [ticks] (`u64::MAX`: until the end).
    pub ticks: u64,
}

impl Injection {
    fn active_at(&self, tick: u64) -> bool {
        tick >= self.from && tick - self.from < self.ticks
    }
}

/// A bus capacitance behind a supply that cannot sink current (a diode in series).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusCapacitance {
    /// Bulk capacitance [F].
    pub capacitance_f: f32,
    /// What discharges it besides the bridge (the bus divider) [Ω].
    pub bleed_ohm: f32,
    /// The rig's tick [s].
    pub tick_s: f32,
}

impl BusCapacitance {
    /// The reference board: 100 µF bulk, the 56 kΩ + 3.3 kΩ divider, 10 kHz.
    pub const REFERENCE_BOARD: BusCapacitance =
        BusCapacitance { capacitance_f: 100e-6, bleed_ohm: 59.3e3, tick_s: 1e-4 };
}

/// Peak bus voltage when a coil carrying `i0_a` discharges through ideal diodes into
/// `capacitance_f` charged to `bus_v` (all four switches off at once: L di/dt = −v − R i,
/// C dv/dt = i until i = 0; the supply's diode blocks). Fine fixed-step RK4 (10 ns); the figure
/// the hardware break's worst case is documented with.
pub fn diode_discharge_peak_v(i0_a: f64, r_ohm: f64, l_h: f64, capacitance_f: f64, bus_v: f64) -> f64 {
    let dt = 1e-8;
    let f = |i: f64, v: f64| ((-v - r_ohm * i) / l_h, i / capacitance_f);
    let (mut i, mut v) = (i0_a.abs(), bus_v);
    let mut peak = v;
    // Bounded: a quarter of the L–C period is at most 2.5 ms for any coil and bank here.
    for _ in 0..10_000_000 {
        if i <= 0.0 {
            break;
        }
        let k1 = f(i, v);
        let k2 = f(i + 0.5 * dt * k1.0, v + 0.5 * dt * k1.1);
        let k3 = f(i + 0.5 * dt * k2.0, v + 0.5 * dt * k2.1);
        let k4 = f(i + dt * k3.0, v + dt * k3.1);
        i += dt / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        v += dt / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        peak = peak.max(v);
    }
    peak
}

/// The rig: a plant behind the board's bridge and front end, and the faults injected between.
pub struct Rig<P> {
    /// The plant (a test may change it mid-run, e.g. short the winding).
    pub plant: P,
    /// The front end's calibration.
    pub calibration: Calibration,
    /// Nominal bus voltage [V]: the supply's (with [`Rig::bus_capacitance`], the voltage the
    /// supply's diode holds the bus at, at least).
    pub bus_v: f64,
    /// `None`: a stiff bus. `Some`: the bus capacitance behind a supply that cannot sink.
    pub bus_capacitance: Option<BusCapacitance>,
    /// The capacitance's voltage [V] (with a capacitance; starts at the supply's).
    pub bus_cap_v: f64,
    /// The highest bus voltage so far [V].
    pub bus_peak_v: f64,
    /// Bus voltage at the bus channel's full-scale code [V] (the divider ratio × ADC reference).
    pub bus_full_scale_v: f64,
    /// Conversion noise on the current and displacement channels: uniform in ± this many codes.
    pub adc_noise_codes: u16,
    /// Faults to inject.
    pub injections: heapless::Vec<Injection, MAX_INJECTIONS>,
    tick: u64,
    rest_um: f64,
    frozen: Option<AdcCode>,
    noise: Noise,
    /// The duty loaded into the compare registers at the last update (across the coil now).
    loaded_duty: f32,
}

impl<P: Plant> Rig<P> {
    /// `plant` at rest; the probe reads 20 µm there, the bus is 24 V through a 1:16 divider
    /// (52.8 V full scale, 12.9 mV per code), no conversion noise. `seed` fixes the noise.
    #[inline(never)]
    pub fn new(plant: P, seed: u64) -> Self {
        let rest_um = plant.displacement_um();
        Self {
            plant,
            calibration: Calibration::REFERENCE_BOARD,
            bus_v: 24.0,
            bus_capacitance: None,
            bus_cap_v: 24.0,
            bus_peak_v: 24.0,
            bus_full_scale_v: 52.8,
            adc_noise_codes: 0,
            injections: heapless::Vec::new(),
            tick: 0,
            rest_um,
            frozen: None,
            noise: Noise(seed),
            loaded_duty: 0.0,
        }
    }

    fn active(&self) -> impl Iterator<Item = Fault> + '_ {
        let t = self.tick;
        self.injections.iter().filter(move |j| j.active_at(t)).map(|j| j.fault)
    }

    /// Coil current [A] (the truth).
    pub fn current_a(&self) -> f64 {
        self.plant.current_a()
    }

    /// Displacement from rest [µm] (the truth, without the probe).
    pub fn displacement_from_rest_um(&self) -> f64 {
        self.plant.displacement_um() - self.rest_um
    }

    /// Ticks applied so far.
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// A capacitive bus charged to its supply: call after setting `bus_v`.
    pub fn with_bus_capacitance(mut self, c: BusCapacitance) -> Self {
        self.bus_capacitance = Some(c);
        self.bus_cap_v = self.bus_v;
        self.bus_peak_v = self.bus_v;
        self
    }

    /// What the supply holds the bus at (its sag included).
    fn supply_now(&self) -> f64 {
        self.active()
            .filter_map(|f| if let Fault::BusSag { bus_v } = f { Some(bus_v) } else { None })
            .fold(self.bus_v, f64::min)
    }

    /// The bus voltage now [V].
    pub fn bus_now(&self) -> f64 {
        match self.bus_capacitance {
            None => self.supply_now(),
            Some(_) => self.bus_cap_v.max(self.supply_now()),
        }
    }

    /// `c` plus this conversion's noise, within the 12-bit range.
    fn noisy(&mut self, c: AdcCode) -> AdcCode {
        let n = self.adc_noise_codes as i32;
        if n == 0 {
            return c;
        }
        let offset = (self.noise.uniform() * (2 * n + 1) as f64) as i32 - n;
        AdcCode((c.0 as i32 + offset).clamp(0, ADC_FULL_SCALE as i32) as u16)
    }

    /// What the ADC converts at this tick's trigger (the PWM centre).
    pub fn sample(&mut self) -> RawSample {
        let mut y = self.displacement_from_rest_um() + PROBE_AT_REST_UM;
        let mut current = self.calibration.current_code(Amps(self.current_a() as f32));
        let (mut dropout, mut frozen) = (false, false);
        let t = self.tick;
        // Fields borrowed apart: the injections are read while the noise generator advances.
        for j in self.injections.iter().filter(|j| j.active_at(t)) {
            match j.fault {
                Fault::DisplacementSaturation { offset_um } => y += offset_um,
                Fault::NoiseBurst { rms_um } => y += rms_um * self.noise.gaussian(),
                Fault::DisplacementDropout => dropout = true,
                Fault::DisplacementFrozen => frozen = true,
                Fault::CurrentSenseDropout => current = AdcCode(0),
                _ => {}
            }
        }
        let mut displacement =
            if dropout { AdcCode(0) } else { self.calibration.displacement_code(Micrometres(y as f32)) };
        if frozen {
            // A frozen front end still converts: the held level carries the converter's noise.
            displacement = *self.frozen.get_or_insert(displacement);
        } else {
            self.frozen = None;
        }
        let current = self.noisy(current);
        let displacement = self.noisy(displacement);
        // The bus channel: 12-bit code of the divided bus, back to volts as the board reads it.
        let lsb = self.bus_full_scale_v / ADC_FULL_SCALE as f64;
        let bus = ((self.bus_now() / lsb + 0.5).max(0.0) as u32).min(ADC_FULL_SCALE as u32) as f64 * lsb;
        let break_tripped = self.active().any(|f| f == Fault::GateDriverFault);
        RawSample { current, displacement, bus: Volts(bus as f32), break_tripped }
    }

    /// Runs the PWM period after the tick that produced `out`: the duty loaded at this period's
    /// update is the previous tick's, `out.duty` loads at the next; `out.bridge_enabled == false`
    /// (and the break input) switches the bridge off at once.
    pub fn apply(&mut self, out: &TickOutput) -> Result<(), P::Error> {
        let bus0 = self.bus_now();
        let duty = self.loaded_duty;
        // A disabled bridge writes no duty: it restarts from the zero the firmware leaves loaded.
        self.loaded_duty = if out.bridge_enabled { out.duty } else { 0.0 };
        let enabled = out.bridge_enabled && !self.active().any(|f| f == Fault::GateDriverFault);
        // A clipping power stage limits whatever it puts across the coil.
        let limit = self
            .active()
            .filter_map(|f| if let Fault::AmplifierSaturation { max_v } = f { Some(max_v) } else { None })
            .fold(f64::INFINITY, f64::min);
        let stuck = self.active().any(|f| f == Fault::BridgeStuckOn);
        let i0 = self.plant.current_a();
        // The share of the bus across the coil (≥ 0 into the coil), and the bus the coil sees:
        // at the tick's midpoint, predicted from the current at its start (a stiff bus: the
        // supply's).
        let share = if !enabled {
            -i0.signum()
        } else if stuck {
            1.0
        } else {
            duty.clamp(-1.0, 1.0) as f64
        };
        let bus = match self.bus_capacitance {
            None => bus0,
            Some(c) => {
                (bus0 - share * i0 * 0.5 * c.tick_s as f64 / c.capacitance_f as f64).max(self.supply_now())
            }
        };
        let drive = if !enabled {
            CoilDrive::Freewheel { bus_v: bus.min(limit) }
        } else {
            CoilDrive::Voltage((share * bus).clamp(-limit, limit))
        };
        self.plant.step(drive)?;
        if let Some(c) = self.bus_capacitance {
            let (tick_s, cap_f, bleed_ohm) = (c.tick_s as f64, c.capacitance_f as f64, c.bleed_ohm as f64);
            let i_mean = 0.5 * (i0 + self.plant.current_a());
            // The bridge's input current (averaged: the coil's current times the share of the
            // bus across it; a clipped stage draws what its output delivers).
            let v_coil = match drive {
                CoilDrive::Voltage(v) => v,
                CoilDrive::Freewheel { bus_v } => -i0.signum() * bus_v,
            };
            let i_bridge = if bus > 1e-9 { v_coil / bus * i_mean } else { 0.0 };
            let mut v = self.bus_cap_v.max(self.supply_now()) - i_bridge * tick_s / cap_f;
            v -= v * tick_s / (bleed_ohm * cap_f); // τ = 5.9 s: Euler is exact enough
                                                   // The supply's diode: it sources whatever holds the bus at its voltage, sinks nothing.
            self.bus_cap_v = v.max(self.supply_now());
            self.bus_peak_v = self.bus_peak_v.max(self.bus_cap_v);
        }
        self.tick += 1;
        Ok(())
    }
}

/// Interference for [`Fault::NoiseBurst`]: SplitMix64, and the sum of twelve uniforms less six
/// (unit variance, near-Gaussian, and no logarithm needed without std).
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (z ^ (z >> 31)) as f64 / 18_446_744_073_709_551_616.0 // 2^64
    }

    fn gaussian(&mut self) -> f64 {
        (0..12).map(|_| self.uniform()).sum::<f64>() - 6.0
    }
}

/// The no_std plant: the coil's R–L electrics, integrated exactly over the tick, driving a
/// model-core actuator with the tick's mean current.
pub struct CoilActuator {
    /// Coil resistance [Ω] (change it to simulate a shorted winding).
    pub coil_resistance_ohm: f32,
    coil_inductance_h: f32,
    tick_s: f32,
    actuator: Actuator,
    state: ActuatorState,
    current_a: f32,
    displacement_m: f32,
}

impl CoilActuator {
    /// The coil of 000 Table 1 (6 Ω, 6 mH) driving `spec` (no `amp`: the coil current drives it)
    /// with `params`, stepped at `tick_s`.
    pub fn new(spec: ModelSpec, params: &ActuatorParams, tick_s: f32) -> Result<Self, ParamError> {
        let mut p = *params;
        p.dt_s = tick_s;
        let actuator = Actuator::new(spec.without(Effect::AmplifierDynamics), &p)?;
        let state = actuator.rest_state();
        Ok(Self {
            coil_resistance_ohm: 6.0,
            coil_inductance_h: 6e-3,
            tick_s,
            actuator,
            state,
            current_a: 0.0,
            displacement_m: state.mech.displacement_m,
        })
    }
}

impl CoilActuator {
    /// Coil inductance [H] (a Terfenol-D coil's follows the rod's permeability).
    pub fn coil_inductance_h(&self) -> f32 {
        self.coil_inductance_h
    }

    /// Sets the coil's inductance [H] (at least 1 µH).
    pub fn set_coil_inductance_h(&mut self, l_h: f32) {
        self.coil_inductance_h = l_h.max(1e-6);
    }
}

impl Plant for CoilActuator {
    type Error = StepError;

    fn step(&mut self, drive: CoilDrive) -> Result<(), StepError> {
        let r = self.coil_resistance_ohm.max(1e-3);
        let p = model_core::math::exp(-self.tick_s * r / self.coil_inductance_h);
        let i0 = self.current_a;
        let (v, freewheel) = match drive {
            CoilDrive::Voltage(v) => (v as f32, false),
            CoilDrive::Freewheel { bus_v } if i0 != 0.0 => (-i0.signum() * bus_v as f32, true),
            CoilDrive::Freewheel { .. } => (0.0, true),
        };
        let mut i1 = p * i0 + (1.0 - p) * v / r;
        if freewheel && i0 * i1 < 0.0 {
            i1 = 0.0; // the diodes stop conducting at zero current
        }
        self.current_a = i1;
        // The actuator sees the tick's mean current.
        self.displacement_m = self.actuator.step(&mut self.state, 0.5 * (i0 + i1))?.displacement_m;
        Ok(())
    }

    fn current_a(&self) -> f64 {
        self.current_a as f64
    }

    fn displacement_um(&self) -> f64 {
        (self.displacement_m * 1e6) as f64
    }
}
