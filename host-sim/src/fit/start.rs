//! A fit's start values, scored: every fit evaluates them and never ends worse.

/// The start values of a fit: every fit evaluates them, and returns them when its search ends
/// worse (a fit never ends worse than where it started).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StartScore {
    /// Mean NRMSE over the fit files at the start values; null when they cannot be used.
    pub nrmse: Option<f64>,
    /// The search ended worse than the start values, so the fit returned them.
    pub kept: bool,
    /// Why the start values cannot be used (e.g. α·M_s/(3a) ≥ 1), if so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
    /// A mechanical mode the recordings' frequency response shows (models with `mech`): the
    /// search also starts from it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seen_mode: Option<crate::resonance::SeenMode>,
}
