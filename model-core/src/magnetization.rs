//! Magnetization M [A/m] from the effective field H [A/m] in the rod.

mod anhysteretic;
mod jiles_atherton;
mod linear;

pub use anhysteretic::{Anhysteretic, AnhystereticParams};
pub use jiles_atherton::{JaParams, JaState, JilesAtherton};
pub use linear::{LinearFit, LinearMagnetization};
