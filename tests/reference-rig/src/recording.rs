//! Simulated measurement: the measured channels, the true (noise-free) signals behind them,
//! and the CSV writer.

use crate::integrator::StepStats;
use std::io::{self, Write};

/// One simulated recording, uniformly sampled.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Recording {
    /// Sample period (s).
    pub dt_s: f64,
    /// Time of each sample (s), k·dt.
    pub time_s: Vec<f64>,
    /// Command voltage u(t_k) (V) (exact: it is the generator's output).
    pub command_v: Vec<f64>,
    /// Measured coil current (A).
    pub current_a: Vec<f64>,
    /// Measured displacement (µm) (offset, drift, noise, delay, quantisation).
    pub displacement_um: Vec<f64>,
    /// Measured coil temperature [°C].
    pub temperature_c: Vec<f64>,
    /// True coil current (A).
    pub true_current_a: Vec<f64>,
    /// True output displacement x2 (µm) (relative to the unstrained rod).
    pub true_displacement_um: Vec<f64>,
    /// True coil temperature [°C].
    pub coil_temperature_c: Vec<f64>,
    /// True rod temperature [°C].
    pub rod_temperature_c: Vec<f64>,
    /// Area-averaged rod magnetization (before the aftereffect) [A/m].
    pub mean_magnetization_a_per_m: Vec<f64>,
    /// Field at the rod surface, n·i + H_bias [A/m].
    pub surface_field_a_per_m: Vec<f64>,
    /// Field in the innermost shell [A/m] (equal to the surface field without eddy currents).
    pub core_field_a_per_m: Vec<f64>,
    /// Measured flux density of the search coil (T), when the rig has one.
    pub flux_density_t: Option<Vec<f64>>,
    /// True mean flux density over the search coil's area, divided by the rod's (T).
    pub true_flux_density_t: Option<Vec<f64>>,
    /// Work of the adaptive integrator.
    pub stats: StepStats,
}

impl Recording {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Write the recording as CSV: `time_s,command_V,current_A,displacement_um,temperature_C`,
    /// then `flux_density_T` when the rig had a search coil, and, with `truth`, the true signals
    /// as extra columns. `time_s` gets
    /// ceil(−log10 dt) + 3 decimals; every value is finite (the simulation refuses
    /// non-finite states).
    pub fn write_csv<W: Write>(&self, mut w: W, truth: bool) -> io::Result<()> {
        let decimals = ((-self.dt_s.log10()).ceil().max(0.0) as usize) + 3;
        write!(w, "time_s,command_V,current_A,displacement_um,temperature_C")?;
        let flux = self.flux_density_t.as_deref().zip(self.true_flux_density_t.as_deref());
        if flux.is_some() {
            write!(w, ",flux_density_T")?;
        }
        if truth {
            write!(
                w,
                ",true_current_A,true_displacement_um,coil_temperature_C,rod_temperature_C,\
                 mean_magnetization_A_per_m,surface_field_A_per_m,core_field_A_per_m"
            )?;
            if flux.is_some() {
                write!(w, ",true_flux_density_T")?;
            }
        }
        writeln!(w)?;
        for k in 0..self.len() {
            write!(
                w,
                "{:.*},{:.6},{:.6},{:.5},{:.4}",
                decimals,
                self.time_s[k],
                self.command_v[k],
                self.current_a[k],
                self.displacement_um[k],
                self.temperature_c[k]
            )?;
            if let Some((b, _)) = flux {
                write!(w, ",{:.6}", b[k])?;
            }
            if truth {
                write!(
                    w,
                    ",{:.7},{:.6},{:.5},{:.5},{:.2},{:.3},{:.3}",
                    self.true_current_a[k],
                    self.true_displacement_um[k],
                    self.coil_temperature_c[k],
                    self.rod_temperature_c[k],
                    self.mean_magnetization_a_per_m[k],
                    self.surface_field_a_per_m[k],
                    self.core_field_a_per_m[k]
                )?;
                if let Some((_, b)) = flux {
                    write!(w, ",{:.6}", b[k])?;
                }
            }
            writeln!(w)?;
        }
        Ok(())
    }

    /// The CSV as a string (see [`Recording::write_csv`]).
    pub fn to_csv_string(&self, truth: bool) -> String {
        let mut buf = Vec::new();
        // Writing to a Vec cannot fail.
        let _ = self.write_csv(&mut buf, truth);
        String::from_utf8(buf).unwrap_or_default()
    }
}
