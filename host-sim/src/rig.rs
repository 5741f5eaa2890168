//! A SIMULATED drive-board rig for closed-loop tests: the workbench plant (coil R–L as its
//! first-order `amp` stage), the board's H-bridge and front end, and faults injected between
//! them at chosen ticks — what the sensors and the power stage do when something breaks.

use anyhow::Result;
use gma_control::units::{AdcCode, Amps, Calibration, Micrometres, Volts};
use gma_control::{RawSample, TickOutput};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::plant::PlantStepper;

/// A fault of the sensors, the supply or the power stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The displacement probe's cable is unplugged: its input is pulled to 0 V.
    DisplacementDropout,
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
    /// A gate-drive fault holds the bridge at full positive voltage while it is enabled.
    BridgeStuckOn,
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

/// The rig: plant, bridge, front end and the injected faults.
pub struct Rig {
    plant: PlantStepper,
    /// The front end's calibration.
    pub calibration: Calibration,
    /// Nominal bus voltage [V].
    pub bus_v: f64,
    /// Faults to inject.
    pub injections: Vec<Injection>,
    tick: u64,
    rest_um: f64,
    rng: rand::rngs::StdRng,
}

impl Rig {
    /// `plant`'s drive must be the coil voltage (its `amp` stage is the coil). The probe reads
    /// 20 µm at rest, the bus is 24 V.
    pub fn new(plant: PlantStepper, seed: u64) -> Self {
        let rest_um = plant.displacement_um();
        Self {
            plant,
            calibration: Calibration::REFERENCE_BOARD,
            bus_v: 24.0,
            injections: Vec::new(),
            tick: 0,
            rest_um,
            rng: rand::rngs::StdRng::seed_from_u64(seed),
        }
    }

    fn active(&self) -> impl Iterator<Item = Fault> + '_ {
        let t = self.tick;
        self.injections.iter().filter(move |j| t >= j.from && t - j.from < j.ticks).map(|j| j.fault)
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

    fn bus_now(&self) -> f64 {
        self.active()
            .filter_map(|f| if let Fault::BusSag { bus_v } = f { Some(bus_v) } else { None })
            .fold(self.bus_v, f64::min)
    }

    /// What the ADC converts at the start of this tick.
    pub fn sample(&mut self) -> RawSample {
        let mut y = self.displacement_from_rest_um() + 20.0;
        let mut current = self.calibration.current_code(Amps(self.current_a() as f32));
        let mut dropout = false;
        let t = self.tick;
        // Fields borrowed apart: the injections are read while the noise generator advances.
        let active = self.injections.iter().filter(|j| t >= j.from && t - j.from < j.ticks);
        for j in active {
            match j.fault {
                Fault::DisplacementSaturation { offset_um } => y += offset_um,
                Fault::NoiseBurst { rms_um } => {
                    y += Normal::new(0.0, rms_um).map(|n| n.sample(&mut self.rng)).unwrap_or(0.0)
                }
                Fault::DisplacementDropout => dropout = true,
                Fault::CurrentSenseDropout => current = AdcCode(0),
                _ => {}
            }
        }
        let displacement =
            if dropout { AdcCode(0) } else { self.calibration.displacement_code(Micrometres(y as f32)) };
        RawSample { current, displacement, bus: Volts(self.bus_now() as f32) }
    }

    /// Applies one tick's bridge command for one tick period.
    pub fn apply(&mut self, out: &TickOutput) -> Result<()> {
        let bus = self.bus_now();
        let i = self.current_a();
        let mut v = if !out.bridge_enabled {
            // Bridge off: the coil discharges into the bus through the body diodes. The plant's
            // coil stage cannot stop exactly at zero current, so the last 0.5 A decays through R.
            if i.abs() > 0.5 {
                -i.signum() * bus
            } else {
                0.0
            }
        } else if self.active().any(|f| f == Fault::BridgeStuckOn) {
            bus
        } else {
            out.duty.clamp(-1.0, 1.0) as f64 * bus
        };
        for f in self.active() {
            if let Fault::AmplifierSaturation { max_v } = f {
                v = v.clamp(-max_v, max_v);
            }
        }
        self.plant.step(v)?;
        self.tick += 1;
        Ok(())
    }
}
