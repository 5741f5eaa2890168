//! Magnetization M [A/m] from the effective field H [A/m] in the rod.

mod anhysteretic;
mod jiles_atherton;
mod linear;
mod preisach;

pub use anhysteretic::{Anhysteretic, AnhystereticParams};
pub use jiles_atherton::{JaBranch, JaParams, JaState, JaVariant, JilesAtherton, MAX_SUBSTEPS};
pub use linear::LinearMagnetization;
pub(crate) use preisach::ValidPreisachParams;
pub use preisach::{
    EverettTable, InverseCache, Preisach, PreisachParams, PreisachState, PREISACH_LEVELS, PREISACH_MEMORY,
};
