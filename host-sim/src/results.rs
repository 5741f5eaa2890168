//! What fit and compare report, as types: each serialises to its command's `--json` object
//! (docs/cli.md) and displays as the text a user reads, so the two never drift apart. (The
//! diagnosis is [`crate::diagnose::Diagnosis`], likewise.)

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

use crate::analysis::AnalysisSummary;
use crate::fit::StartScore;
use crate::loops::LoopFeatures;
use crate::recording::Recording;
use crate::uncertainty::Uncertainty;

/// One file's score on one channel.
#[derive(Debug, Clone, Serialize)]
pub struct FileScoreRow {
    /// The file as given.
    pub file: String,
    /// `fit` or `val` (fit only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub split: Option<&'static str>,
    /// `displacement`, `current`, `flux_density`, `temperature` or `magnetization`.
    pub channel: &'static str,
    /// NRMSE on that channel (fraction).
    pub nrmse: f64,
    /// MATLAB's `compare` fit on that channel, 100 (1 − ‖y − ŷ‖/‖y − ȳ‖) [%]
    /// ([`crate::score::fit_percent`]); absent for a constant channel.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_percent: Option<f64>,
    /// Fitted displacement offset [µm] (displacement rows).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset_um: Option<f64>,
    /// Flux-density rows of recordings: the magnetization scale g of B = μ0 (H + g M) + c (how much
    /// larger the rod's magnetization swing is than the model's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flux_scale: Option<f64>,
    /// Temperature rows: the temperature the model's coil heating starts from [°C] (fitted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ambient_c: Option<f64>,
    /// The estimated initial magnetic state: the pre-history field excursion [A/m] from the
    /// first sample's field and back, the rod demagnetised there before it (displacement rows
    /// of hysteretic models).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub initial_excursion_a_per_m: Option<f64>,
    /// Plots written for the file (compare).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plots: Option<Vec<String>>,
    /// Loop features of the measurement (compare on loop files).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured: Option<LoopFeatures>,
    /// Loop features of the model (compare on loop files).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<LoopFeatures>,
    /// Residual correlation, residual spectrum and frequency response (compare on recordings).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub analysis: Option<AnalysisSummary>,
}

impl FileScoreRow {
    /// A row with only the score: the NRMSE `nrmse` on the channel's `measured` values.
    pub fn new(
        file: &str,
        split: Option<&'static str>,
        (channel, measured): (&'static str, &[f64]),
        nrmse: f64,
    ) -> Self {
        Self {
            file: file.into(),
            split,
            channel,
            nrmse,
            fit_percent: crate::score::fit_percent(measured, nrmse),
            offset_um: None,
            flux_scale: None,
            ambient_c: None,
            initial_excursion_a_per_m: None,
            plots: None,
            measured: None,
            model: None,
            analysis: None,
        }
    }
}

impl FileScoreRow {
    /// The fit % as the text shows it: `93.6 %`, `-12.0 %` ([`Self::fit_percent`]), `   — ` for
    /// a constant channel.
    pub fn fit_text(&self) -> String {
        self.fit_percent.map_or("     —  ".to_string(), |p| format!("{p:5.1} %"))
    }

    /// Whether this row is its file's first (a recording's displacement row, a loop file's only
    /// row): what counts files.
    pub fn is_first_of_file(&self) -> bool {
        !matches!(self.channel, "current" | "temperature") && self.flux_scale.is_none()
    }

    /// A recording's rows: displacement (with its offset and initial state), then the current
    /// the flux density and the temperature where the model is scored on them.
    pub fn for_recording(
        rec: &Recording,
        split: Option<&'static str>,
        s: &crate::score::FileScore,
    ) -> Vec<Self> {
        let file = rec.name.as_str();
        fn channel(v: &Option<Vec<f64>>) -> &[f64] {
            v.as_deref().unwrap_or_default()
        }
        let mut rows = vec![FileScoreRow {
            offset_um: Some(s.offset_um),
            initial_excursion_a_per_m: s.initial_excursion_a_per_m,
            ..FileScoreRow::new(file, split, ("displacement", channel(&rec.displacement_um)), s.nrmse)
        }];
        if let Some(c) = s.nrmse_current {
            rows.push(FileScoreRow::new(file, split, ("current", channel(&rec.current_a)), c));
        }
        if let Some(b) = s.flux {
            rows.push(FileScoreRow {
                flux_scale: Some(b.scale),
                ..FileScoreRow::new(file, split, ("flux_density", channel(&rec.flux_density_t)), b.nrmse)
            });
        }
        if let Some(t) = s.temperature {
            rows.push(FileScoreRow {
                ambient_c: Some(t.ambient_c),
                ..FileScoreRow::new(file, split, ("temperature", channel(&rec.temperature_c)), t.nrmse)
            });
        }
        rows
    }
}

/// `gma fit`'s result.
#[derive(Debug, Clone, Serialize)]
pub struct FitSummary {
    /// Canonical model spec.
    pub model: String,
    /// The Jiles–Atherton form the fit used (the parameter file's `[ja] variant`), for models
    /// with the J–A law: J–A coefficients mean something only in their form.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ja_variant: Option<&'static str>,
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
    /// Doubts about the result.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warnings: Option<Vec<String>>,
    /// Parameters held by `--fix`, by name (displacement fits; absent when none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fixed: Option<BTreeMap<&'static str, f64>>,
    /// Parameters no fit file constrained, left at their start values (the amplifier gain when
    /// every file gives the current); the parameter file marks them. Absent when none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub not_fitted: Vec<&'static str>,
    /// Per identified continuous parameter: value, standard deviation, 95 % interval
    /// (displacement fits).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<BTreeMap<&'static str, ParamEstimate>>,
    /// Correlations of those parameters (displacement fits).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub correlation: Option<Correlation>,
    /// What the uncertainty rests on (displacement fits).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_basis: Option<UncertaintyBasis>,
    /// The start values' score, and whether the fit returned them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub start: Option<StartScore>,
    /// For the text: the parameters in the fit's order, whether the files are loops, the time.
    #[serde(skip)]
    pub text: FitText,
}

/// One parameter's estimate in a fit's JSON.
#[derive(Debug, Clone, Serialize)]
pub struct ParamEstimate {
    /// The fitted value (as in `params`).
    pub value: f64,
    /// Standard deviation in the parameter's unit; null when not identifiable.
    pub std: Option<f64>,
    /// 95 % interval; null when not identifiable.
    pub ci95: Option<[f64; 2]>,
    /// The interval's ends the search range cut off (`"lower"`, `"upper"`); absent when none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub ci95_clipped: Vec<&'static str>,
    /// `log` (log-normal interval, `std` = value·σ of ln) or `linear`.
    pub scale: &'static str,
}

/// A fit's correlation matrix in JSON.
#[derive(Debug, Clone, Serialize)]
pub struct Correlation {
    /// Parameter names, the matrix's order.
    pub names: Vec<&'static str>,
    /// ρ by row and column (null for a parameter that is not identifiable).
    pub matrix: Vec<Vec<Option<f64>>>,
}

/// What a fit's uncertainty rests on.
#[derive(Debug, Clone, Serialize)]
pub struct UncertaintyBasis {
    /// Residuals N (samples of every fit file and channel).
    pub samples: usize,
    /// N_eff = N (1 − ρ₁)/(1 + ρ₁).
    pub effective_samples: f64,
    /// ρ₁, the residuals' lag-1 autocorrelation.
    pub lag1_autocorrelation: f64,
    /// Condition number of the column-normalised Jacobian (null: singular).
    pub condition: Option<f64>,
}

/// A fit's uncertainty as its JSON fields: per parameter, the correlations, the basis.
#[derive(Debug, Clone, Serialize)]
pub struct UncertaintyFields {
    /// Per identified continuous parameter: value, standard deviation, 95 % interval.
    pub uncertainty: BTreeMap<&'static str, ParamEstimate>,
    /// Correlations of those parameters.
    pub correlation: Correlation,
    /// What the uncertainty rests on.
    pub uncertainty_basis: UncertaintyBasis,
}

impl From<&Uncertainty> for UncertaintyFields {
    fn from(u: &Uncertainty) -> Self {
        let finite = |x: f64| x.is_finite().then_some(x);
        UncertaintyFields {
            uncertainty: u
                .params
                .iter()
                .map(|p| {
                    let e = ParamEstimate {
                        value: p.value,
                        std: p.std,
                        ci95: p.ci95.map(|(a, b)| [a, b]),
                        ci95_clipped: [(p.ci95_clipped.0, "lower"), (p.ci95_clipped.1, "upper")]
                            .into_iter()
                            .filter_map(|(c, end)| c.then_some(end))
                            .collect(),
                        scale: if p.bound.log { "log" } else { "linear" },
                    };
                    (p.bound.name, e)
                })
                .collect(),
            correlation: Correlation {
                names: u.params.iter().map(|p| p.bound.name).collect(),
                matrix: u.correlation.iter().map(|row| row.iter().map(|&x| finite(x)).collect()).collect(),
            },
            uncertainty_basis: UncertaintyBasis {
                samples: u.samples,
                effective_samples: u.effective_samples,
                lag1_autocorrelation: u.lag1_autocorrelation,
                condition: finite(u.condition),
            },
        }
    }
}

impl FitSummary {
    /// Adds a fit's uncertainty (JSON fields and text).
    pub fn with_uncertainty(mut self, u: &Uncertainty) -> Self {
        let f = UncertaintyFields::from(u);
        self.uncertainty = Some(f.uncertainty);
        self.correlation = Some(f.correlation);
        self.uncertainty_basis = Some(f.uncertainty_basis);
        self.text.uncertainty = Some(u.clone());
        self
    }
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
    /// Parameters held fixed, in order.
    pub fixed: Vec<(&'static str, f64)>,
    /// The parameters' uncertainty (displacement fits).
    pub uncertainty: Option<Uncertainty>,
}

impl FitSummary {
    /// The line a person reads first: the model, its mean fit (and validation) NRMSE.
    pub fn headline(&self) -> String {
        let fitted = self.files.iter().filter(|r| r.split == Some("fit") && r.is_first_of_file()).count();
        format!(
            "{} `{}`{} fitted to {fitted} {}: mean fit NRMSE {:.3} %{}",
            if self.text.loops { "magnetization model" } else { "model" },
            self.model,
            self.ja_variant.map(|v| format!(" (J–A form `{v}`)")).unwrap_or_default(),
            if self.text.loops { "loop file(s)" } else { "file(s)" },
            self.nrmse_fit * 100.0,
            self.nrmse_val.map(|v| format!(", validation {:.3} %", v * 100.0)).unwrap_or_default()
        )
    }

    /// Everything below the headline (and the warnings, which follow it on stderr): the
    /// parameters, the start, the correlations and each file's score.
    pub fn details(&self) -> String {
        let mut text = String::new();
        // Writing to a String cannot fail.
        let _ = self.write_details(&mut text);
        text.trim_end_matches('\n').to_string()
    }
}

/// The text form of a fit: [`FitSummary::headline`], then [`FitSummary::details`].
impl fmt::Display for FitSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}\n{}", self.headline(), self.details())
    }
}

impl FitSummary {
    fn write_details(&self, f: &mut String) -> fmt::Result {
        use fmt::Write as _;
        let width = if self.text.loops { 20 } else { 40 };
        writeln!(f, "  {} evaluations in {:.1} s (seed {})", self.evaluations, self.text.seconds, self.seed)?;
        let estimate = |n: &str| {
            self.text.uncertainty.as_ref().and_then(|u| u.params.iter().find(|p| p.bound.name == n).cloned())
        };
        for (n, v) in &self.text.params_in_order {
            match estimate(n) {
                None => writeln!(f, "  {n:width$} = {v:.6e}")?,
                Some(e) => match (e.std, e.ci95) {
                    (Some(s), Some((lo, hi))) => {
                        let rel = if *v != 0.0 {
                            format!(" ({:.2} %)", 100.0 * s / v.abs())
                        } else {
                            String::new()
                        };
                        let ci = format!("95 % [{lo:.4e}, {hi:.4e}]{}", e.clipped_note());
                        writeln!(f, "  {n:width$} = {v:.6e} ± {s:.2e}{rel:10}  {ci}")?
                    }
                    _ => writeln!(f, "  {n:width$} = {v:.6e} ± ?  (not identifiable)")?,
                },
            }
        }
        for (n, v) in &self.text.fixed {
            writeln!(f, "  {n:width$} = {v:.6e} (fixed)")?;
        }
        if !self.not_fitted.is_empty() {
            writeln!(
                f,
                "  not fitted (no file constrained them; their start values are kept and marked so in a \
                 parameter file): {}",
                self.not_fitted.join(", ")
            )?;
        }
        if let Some(s) = &self.start {
            match (&s.refused, s.nrmse) {
                (Some(why), _) => writeln!(f, "  start values refused: {why}")?,
                (None, Some(e)) => writeln!(
                    f,
                    "  start values: fit NRMSE {:.3} %{}",
                    e * 100.0,
                    if s.kept { " (returned: the search did not improve on them)" } else { "" }
                )?,
                (None, None) => {}
            }
            if let Some(m) = &s.seen_mode {
                writeln!(
                    f,
                    "  mechanical mode seen in {}: {:.0} Hz, ζ ≈ {:.3} (gain peak {:.1}× the band's low-frequency \
                     level); the search also started there",
                    m.file, m.natural_frequency_hz, m.damping_ratio, m.magnification
                )?;
            }
        }
        if let Some(u) = self.text.uncertainty.as_ref().filter(|u| u.params.len() > 1) {
            writeln!(
                f,
                "  correlation (N = {} residuals, lag-1 autocorrelation {:.2}, effective N {:.0}):",
                u.samples, u.lag1_autocorrelation, u.effective_samples
            )?;
            for (i, p) in u.params.iter().enumerate() {
                write!(f, "  {:>2} {:width$}", i + 1, p.bound.name, width = width - 3)?;
                for rho in &u.correlation[i][..=i] {
                    if rho.is_finite() {
                        write!(f, " {rho:+.2}")?;
                    } else {
                        write!(f, "     ?")?;
                    }
                }
                writeln!(f)?;
            }
            write!(f, "  {:width$}", "")?;
            for i in 0..u.params.len() {
                write!(f, " {:>5}", i + 1)?;
            }
            writeln!(f)?;
        }
        for r in &self.files {
            writeln!(
                f,
                "  {:5} {:14} NRMSE {:6.3} %  fit {}  {}",
                r.split.unwrap_or(""),
                r.channel,
                r.nrmse * 100.0,
                r.fit_text(),
                r.file
            )?;
        }
        Ok(())
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
    /// Doubts about the comparison (as `fit`'s, text; empty when none).
    pub warnings: Vec<String>,
}

impl CompareSummary {
    /// The line a person reads first: the model and its mean NRMSE.
    pub fn headline(&self) -> String {
        let n = self.files.iter().filter(|r| r.is_first_of_file()).count();
        format!("model `{}`: mean NRMSE {:.3} % over {n} file(s)", self.model, self.nrmse * 100.0)
    }

    /// Everything below the headline (and the warnings, which follow it on stderr): each file's
    /// score, residual analysis and loop features.
    pub fn details(&self) -> String {
        let mut text = String::new();
        // Writing to a String cannot fail.
        let _ = self.write_details(&mut text);
        text.trim_end_matches('\n').to_string()
    }
}

/// The text form of a comparison: [`CompareSummary::headline`], then [`CompareSummary::details`].
impl fmt::Display for CompareSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}\n{}", self.headline(), self.details())
    }
}

impl CompareSummary {
    fn write_details(&self, f: &mut String) -> fmt::Result {
        use fmt::Write as _;
        for r in &self.files {
            let plots = r.plots.as_ref().map(|p| format!("  plots: {}", p.join(", "))).unwrap_or_default();
            let offset = r.offset_um.map(|o| format!("  offset {o:8.3} µm")).unwrap_or_default();
            let (file, channel, nrmse, fit) = (&r.file, r.channel, r.nrmse * 100.0, r.fit_text());
            writeln!(f, "{file:40} {channel:14} NRMSE {nrmse:6.3} %  fit {fit}{offset}{plots}")?;
            if let Some(a) = &r.analysis {
                writeln!(f, "{a}")?;
            }
            if let (Some(m), Some(y)) = (r.measured, r.model) {
                writeln!(f, "  {:30} {:>14} {:>14}", "", "measured", "model")?;
                for (name, x, y) in [
                    (crate::loops::COERCIVITY_LABEL, m.coercivity_a_per_m, y.coercivity_a_per_m),
                    (crate::loops::REMANENCE_LABEL, m.remanence_a_per_m, y.remanence_a_per_m),
                    ("largest |M| [A/m]", m.max_magnetization_a_per_m, y.max_magnetization_a_per_m),
                ] {
                    let (x, y) = (crate::loops::feature_text(x), crate::loops::feature_text(y));
                    writeln!(f, "  {name:30} {x:>14} {y:>14}")?;
                }
            }
        }
        Ok(())
    }
}
