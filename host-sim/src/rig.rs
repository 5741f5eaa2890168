//! The workbench plant in the board's SIMULATED rig ([`gma_control::sim::Rig`]): its coil R–L
//! is the plant's first-order `amp` stage, so its drive must be the coil voltage.

use gma_control::sim::{CoilDrive, Plant};

use crate::plant::PlantStepper;

impl Plant for PlantStepper {
    type Error = anyhow::Error;

    fn step(&mut self, drive: CoilDrive) -> anyhow::Result<()> {
        let v = match drive {
            CoilDrive::Voltage(v) => v,
            // The coil stage cannot stop exactly at zero current, so the last 0.5 A decays
            // through R.
            CoilDrive::Freewheel { bus_v } => {
                let i = self.current_a();
                if i.abs() > 0.5 {
                    -i.signum() * bus_v
                } else {
                    0.0
                }
            }
        };
        PlantStepper::step(self, v)
    }

    fn current_a(&self) -> f64 {
        PlantStepper::current_a(self)
    }

    fn displacement_um(&self) -> f64 {
        PlantStepper::displacement_um(self)
    }
}
