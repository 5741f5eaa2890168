//! `gma`, the model workbench: measurement files, the plant simulator, identification,
//! diagnosis of missing physics, plots and reports. The command line is [`cli`], one file per
//! subcommand; `src/main.rs` only calls it. Papers are cited as 000–003: the list, and what the
//! code takes from each, is docs/references.md.

pub mod analysis;
pub mod analysis_plots;
pub mod api;
pub mod cases;
pub mod cell_text;
pub mod channels;
pub mod cli;
pub mod columns;
pub mod data_doubts;
pub mod diagnose;
pub mod digests;
pub mod error;
pub mod excitation;
pub mod field_units;
pub mod files;
pub mod fit;
pub mod loop_fit;
pub mod loop_plots;
pub mod loops;
pub mod params;
pub mod partials;
pub mod plant;
pub mod plots;
pub mod progress;
pub mod provenance;
pub mod read_doubts;
pub mod record;
pub mod recording;
pub mod report;
pub mod resonance;
pub mod results;
pub mod rig;
pub mod rod_diffusion;
pub mod same_samples;
pub mod score;
pub mod search;
pub mod signal;
pub mod simulated;
pub mod simulation;
pub mod spectral;
pub mod uncertainty;
pub mod warning;
