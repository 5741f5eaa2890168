//! What a run of a model over a recording gives: every channel it predicts, sample by sample.

/// A model run over one recording (same length; displacement in µm without offset).
#[derive(Debug, Clone)]
pub struct Simulation {
    /// Model displacement [µm] (add `offset_um` to compare with the file).
    pub displacement_um: Vec<f64>,
    /// Model coil current [A].
    pub current_a: Vec<f64>,
    /// Field in the rod [A/m] (every run of a file with `flux_density_T`; otherwise only
    /// [`crate::simulation::simulate`]'s).
    pub field_a_per_m: Vec<f64>,
    /// Model magnetization [A/m] (as the field).
    pub magnetization_a_per_m: Vec<f64>,
    /// Model temperature rise of the coil heating [°C] (runs of a model with `thermal_drift`;
    /// empty otherwise: no rise).
    pub temperature_rise_c: Vec<f64>,
    /// The pre-history the run started from: the field excursion [A/m] from the first sample's
    /// field and back, the rod demagnetised there before it (0: no excursion), estimated for the
    /// file unless given.
    pub initial_excursion_a_per_m: f64,
}
