//! `gma`, the model workbench: measurement files, the plant simulator, identification,
//! diagnosis of missing physics, plots and reports. The binary (`src/main.rs`) is the CLI over
//! these modules.

pub mod cases;
pub mod cli;
pub mod diagnose;
pub mod error;
pub mod excitation;
pub mod files;
pub mod fit;
pub mod loops;
pub mod params;
pub mod plant;
pub mod plots;
pub mod progress;
pub mod record;
pub mod recording;
pub mod report;
pub mod rig;
pub mod rod_diffusion;
pub mod search;
