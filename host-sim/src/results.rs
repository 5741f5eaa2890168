//! What fit and compare report, as types: each serialises to its command's `--json` object
//! (docs/cli.md) and displays as the text a user reads, so the two never drift apart. (The
//! diagnosis is [`crate::diagnose::Diagnosis`], likewise.)

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

use crate::loops::LoopFeatures;

/// One file's score on one channel.
#[derive(Debug, Clone, Serialize)]
pub struct FileScoreRow {
    /// The file as given.
    pub file: String,
    /// `fit` or `val` (fit only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub split: Option<&'static str>,
    /// `displacement`, `current`, `flux_density` or `magnetization`.
    pub channel: &'static str,
    /// NRMSE on that channel (fraction).
    pub nrmse: f64,
    /// Fitted displacement offset [µm] (displacement rows).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset_um: Option<f64>,
    /// Plots written for the file (compare).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plots: Option<Vec<String>>,
    /// Loop features of the measurement (compare on loop files).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured: Option<LoopFeatures>,
    /// Loop features of the model (compare on loop files).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<LoopFeatures>,
}

impl FileScoreRow {
    /// A row with only the score.
    pub fn new(file: &str, split: Option<&'static str>, channel: &'static str, nrmse: f64) -> Self {
        Self {
            file: file.into(),
            split,
            channel,
            nrmse,
            offset_um: None,
            plots: None,
            measured: None,
            model: None,
        }
    }
}

/// `gma fit`'s result.
#[derive(Debug, Clone, Serialize)]
pub struct FitSummary {
    /// Canonical model spec.
    pub model: String,
    /// Identified parameters by name.
    pub params: BTreeMap<&'static str, f64>,
    /// Mean NRMSE over the fit files.
    pub nrmse_fit: f64,
    /// Mean NRMSE over the validation files.
    pub nrmse_val: Option<f64>,
    /// Per file and channel.
    pub files: Vec<FileScoreRow>,
    /// Model evaluations.
    pub evaluations: usize,
    /// Seed of the search.
    pub seed: u64,
    /// `--time-limit` stopped the search.
    pub time_limit_reached: bool,
    /// Doubts about the result (loop fits).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warnings: Option<Vec<String>>,
    /// For the text: the parameters in the fit's order, whether the files are loops, the time.
    #[serde(skip)]
    pub text: FitText,
}

/// What only the text form of a fit shows.
#[derive(Debug, Clone, Default)]
pub struct FitText {
    /// Identified parameters in the fit's order.
    pub params_in_order: Vec<(&'static str, f64)>,
    /// Fitted to magnetization loops.
    pub loops: bool,
    /// Wall time [s].
    pub seconds: f64,
}

impl fmt::Display for FitSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let fitted = self.files.iter().filter(|r| r.split == Some("fit") && r.channel != "current").count();
        let (what, width) = if self.text.loops { ("magnetization model", 20) } else { ("model", 40) };
        writeln!(
            f,
            "{what} `{}` fitted to {fitted} {}: {} evaluations in {:.1} s (seed {})",
            self.model,
            if self.text.loops { "loop file(s)" } else { "file(s)" },
            self.evaluations,
            self.text.seconds,
            self.seed
        )?;
        for (n, v) in &self.text.params_in_order {
            writeln!(f, "  {n:width$} = {v:.6e}")?;
        }
        for r in &self.files {
            writeln!(
                f,
                "  {:5} {:14} NRMSE {:6.3} %  {}",
                r.split.unwrap_or(""),
                r.channel,
                r.nrmse * 100.0,
                r.file
            )?;
        }
        write!(
            f,
            "  mean fit NRMSE {:.3} %{}",
            self.nrmse_fit * 100.0,
            self.nrmse_val.map(|v| format!(", validation {:.3} %", v * 100.0)).unwrap_or_default()
        )
    }
}

/// `gma compare`'s result.
#[derive(Debug, Clone, Serialize)]
pub struct CompareSummary {
    /// Canonical model spec.
    pub model: String,
    /// Mean NRMSE over the files.
    pub nrmse: f64,
    /// Per file and channel.
    pub files: Vec<FileScoreRow>,
}

impl fmt::Display for CompareSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for r in &self.files {
            let plots = r.plots.as_ref().map(|p| format!("  plots: {}", p.join(", "))).unwrap_or_default();
            let offset = r.offset_um.map(|o| format!("  offset {o:8.3} µm")).unwrap_or_default();
            writeln!(f, "{:40} {:14} NRMSE {:6.3} %{offset}{plots}", r.file, r.channel, r.nrmse * 100.0)?;
            if let (Some(m), Some(y)) = (r.measured, r.model) {
                writeln!(f, "  {:28} {:>14} {:>14}", "", "measured", "model")?;
                for (name, x, y) in [
                    ("coercivity H_c [A/m]", m.coercivity_a_per_m, y.coercivity_a_per_m),
                    ("remanence M_r [A/m]", m.remanence_a_per_m, y.remanence_a_per_m),
                    ("largest |M| [A/m]", m.max_magnetization_a_per_m, y.max_magnetization_a_per_m),
                ] {
                    writeln!(f, "  {name:28} {x:>14.4e} {y:>14.4e}")?;
                }
            }
        }
        let n = self.files.iter().filter(|r| r.channel != "current").count();
        write!(f, "mean NRMSE {:.3} % over {n} file(s), model `{}`", self.nrmse * 100.0, self.model)
    }
}
