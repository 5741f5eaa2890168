//! `gma diagnose`: fit a model, analyse what it leaves unexplained, name the missing effect.

use anyhow::Result;
use clap::Args;

use crate::api::inputs::{Data, ModelFiles};
use crate::diagnose::{check_ja_variants, diagnose, other_law_structure};
use crate::provenance::Provenance;
use crate::warning::by_weight;

/// Options of `gma diagnose`. Its files are displacement recordings only (the shared `FILE`
/// help also names loop files, which `fit` and `report` take).
#[derive(Args)]
#[command(mut_arg("files", |a| a.help(
    "Displacement recordings (CSV) to fit and diagnose (not magnetization-loop files: those go \
     to `gma fit` and `gma compare`); `-` reads standard input"
)))]
pub struct DiagnoseArgs {
    #[command(flatten)]
    pub mf: ModelFiles,
    /// Also refit the model in each other form of Jiles–Atherton (`[ja] variant`) and say
    /// whether one fits clearly better (three more fits)
    #[arg(long)]
    pub ja_variants: bool,
    /// Also refit the model with the other hysteresis law (`ja` ↔ `preisach`, the rest of the
    /// structure kept) and say whether it fits clearly better (one more fit)
    #[arg(long)]
    pub laws: bool,
}

/// Runs `gma diagnose`.
pub fn run(a: &DiagnoseArgs) -> Result<()> {
    // The other law's fit starts from the same parameter file: checked for it, before any fit.
    let p = a.mf.prepare_also_for(&[], |spec| {
        a.laws
            .then(|| other_law_structure(spec).map(|o| (o, "the other law, refitted by --laws")))
            .transpose()
    })?;
    let Data::Recordings(fit_files, val_files) = &p.data else {
        let name = match &p.data {
            Data::Loops(files, _) => files.first().map_or("the input", |f| f.name.as_str()),
            Data::Recordings(..) => "the input",
        };
        return Err(crate::error::Located::file(
            name,
            "is a magnetization loop (no time axis, drive and displacement): diagnose works on displacement \
             recordings; for magnetization loops use `gma fit`, `gma compare` or `gma report` (to compare J–A \
             forms or laws on a loop, fit each: `--model ja` with `[ja] variant` set in `--params`, or `--model \
             preisach`, and compare their NRMSE)",
        )
        .into());
    };
    if a.ja_variants {
        check_ja_variants(p.spec)?;
    }
    let mut d = diagnose(p.spec, &p.init, fit_files, val_files, p.opts)?;
    // Mechanics is always a candidate (or in the model): said first when no file can show it.
    if let Some(w) = crate::fit::unsearchable_mode(fit_files.iter().chain(val_files)) {
        d.findings.insert(0, w.to_string());
    }
    if a.ja_variants {
        d.compare_ja_variants(p.spec, &p.init, fit_files, val_files, p.opts)?;
    }
    if a.laws {
        d.compare_laws(p.spec, &p.init, fit_files, val_files, p.opts)?;
    }
    // The verdict first, then the doubts about the inputs heaviest first, then the evidence.
    say!(a.mf.json, "{}", d.headline());
    for w in by_weight(&p.input_warnings) {
        w.say();
    }
    a.mf.warn_if_time_limited(d.time_limited);
    say!(a.mf.json, "{}", d.details());
    if a.mf.json {
        out!(
            "{}",
            super::merged_json(
                &d,
                &super::context_json(&p.params_source, &Provenance::now(Some(a.mf.seed)))
            )?
        );
    }
    Ok(())
}
