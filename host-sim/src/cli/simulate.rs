//! `gma simulate`: the run ([`crate::api::simulate`]), and its JSON on stdout.

use anyhow::Result;

use crate::api::simulate::{self, SimulateArgs};
use crate::provenance::Provenance;

/// Runs `gma simulate`.
pub fn run(a: &SimulateArgs) -> Result<()> {
    let s = simulate::run(a)?;
    if a.json {
        out!(
            "{}",
            super::merged_json(&s.result, &super::context_json(&s.source, &Provenance::now(Some(a.seed))))?
        );
    }
    Ok(())
}
