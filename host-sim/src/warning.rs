//! What makes a result doubtful or invalid, as values: commands print them (`gma: warning: …`),
//! put them in JSON as text, and decide from [`Warning::invalidates`] whether a result may be
//! written — never by searching message text.

use std::cell::RefCell;
use std::fmt;

mod words;
use words::*;

/// Says one doubt on stderr, in the one form every command uses (`gma: warning: …`), or hands it
/// to [`heard`]'s caller.
pub fn warn(what: impl fmt::Display) {
    say(Said::Warning(what.to_string()));
}

/// Says what stands in for something not given (the demo set for a missing parameter file,
/// samples filled in by resampling) on stderr (`gma: note: …`), or hands it to [`heard`]'s caller.
pub fn note(what: impl fmt::Display) {
    say(Said::Note(what.to_string()));
}

/// A note or a warning said while a command ran.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Said {
    /// [`note`]'s.
    Note(String),
    /// [`warn`]'s.
    Warning(String),
}

impl fmt::Display for Said {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Said::Note(text) => write!(f, "note: {text}"),
            Said::Warning(text) => write!(f, "warning: {text}"),
        }
    }
}

thread_local! {
    /// What [`heard`] collects on this thread (None: stderr).
    static HEARD: RefCell<Option<Vec<Said>>> = const { RefCell::new(None) };
}

impl Said {
    /// The same kind of message with its text changed (a temporary file's path named as given).
    pub fn map_text(self, f: impl FnOnce(&str) -> String) -> Said {
        match self {
            Said::Note(t) => Said::Note(f(&t)),
            Said::Warning(t) => Said::Warning(f(&t)),
        }
    }
}

/// Says `said` again, as it was first said: to [`heard`]'s caller if one listens, else stderr.
pub fn say(said: Said) {
    let unheard = HEARD.with(|h| match h.borrow_mut().as_mut() {
        Some(heard) => {
            heard.push(said);
            None
        }
        None => Some(said),
    });
    if let Some(said) = unheard {
        eprintln!("gma: {said}");
    }
}

/// Runs `f` with the notes and warnings it says on this thread collected, not written to stderr
/// (a binding shows them its own way: the Python package as `UserWarning`s, which a notebook
/// shows; it does not show the process's stderr). Those said on other threads (none today: the
/// parallel searches say nothing) still go to stderr.
pub fn heard<T>(f: impl FnOnce() -> T) -> (T, Vec<Said>) {
    struct Restore(Option<Vec<Said>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let outer = self.0.take();
            HEARD.with(|h| *h.borrow_mut() = outer);
        }
    }
    let outer = HEARD.with(|h| h.borrow_mut().replace(Vec::new()));
    let restore = Restore(outer);
    let value = f();
    let said = HEARD.with(|h| h.borrow_mut().take()).unwrap_or_default();
    drop(restore);
    (value, said)
}

/// One doubt about a result.
#[derive(Debug, Clone, PartialEq)]
pub enum Warning {
    /// A parameter ended within 0.5 % of its search range's end.
    AtEdge {
        /// Its name.
        param: &'static str,
        /// Its value.
        value: f64,
        /// The range.
        lo: f64,
        /// The range.
        hi: f64,
    },
    /// Jiles–Atherton with α·M_s/(3a) ≥ 1: the anhysteretic curve is multivalued and the loop an
    /// artefact of the integration.
    Multivalued {
        /// α·M_s/(3a).
        ratio: f64,
    },
    /// A J–A loop fit's mean-field ratio α·M_s/(3a) ended at its upper limit: the loop is
    /// squarer than single-valued J–A can follow (hard magnets).
    SquarerThanJa {
        /// The ratio it ended at.
        ratio: f64,
    },
    /// The model could not be integrated along a file's path at the result.
    IntegrationFailed {
        /// The file.
        file: String,
        /// Why.
        why: String,
    },
    /// Two parameters' estimates are almost interchangeable (|ρ| > 0.95).
    Correlated {
        /// One parameter.
        a: &'static str,
        /// The other.
        b: &'static str,
        /// Their correlation.
        rho: f64,
    },
    /// The data do not determine these parameters (the Jacobian is rank-deficient there).
    NotIdentifiable {
        /// Their names.
        params: Vec<&'static str>,
        /// Condition number of the column-normalised Jacobian.
        condition: f64,
    },
    /// The search ended worse than the start values; the fit returned the start values.
    StartKept {
        /// Mean fit NRMSE at the start values.
        start_nrmse: f64,
        /// Mean fit NRMSE where the search ended.
        found_nrmse: f64,
    },
    /// A start value lay outside its parameter's search range: the search began at the range's
    /// nearest end instead.
    StartMoved {
        /// Its name.
        param: &'static str,
        /// The value given (parameter file, `--init` or built-in set).
        given: f64,
        /// Where the search began.
        used: f64,
        /// The range.
        lo: f64,
        /// The range.
        hi: f64,
    },
    /// A validation file has the same content as a fit file (the same file, or a copy): its
    /// validation figure is a fit figure.
    ValidationIsFitFile {
        /// The `--val` file.
        val: String,
        /// The fit file with the same bytes.
        fit: String,
    },
    /// Two inputs of one command with the same content (the same file given twice, or a copy):
    /// it counts twice in a mean over the files.
    SameInputTwice {
        /// The input given first.
        first: String,
        /// The later one with the same bytes.
        again: String,
        /// Where it counts twice.
        counts_in: &'static str,
    },
    /// A fit file typed right after a `--val` file: `--val` takes one file, so it is fitted.
    FitFileAfterVal {
        /// The `--val` file.
        val: String,
        /// The file after it, read as a fit file.
        fit: String,
    },
    /// The Preisach relay plane reaches far beyond the fields the recordings drive the rod to.
    PreisachPlaneWide {
        /// `preisach.h_max_a_per_m` as given [A/m].
        h_max: f64,
        /// The largest field the recordings reach [A/m].
        reach: f64,
        /// The extent advised [A/m].
        advised: f64,
    },
    /// The parameters' uncertainty could not be estimated (e.g. fewer residuals than unknowns).
    NoUncertainty {
        /// Why.
        why: String,
    },
    /// The time limit (`--time-limit`, Python's `time_limit_s`) stopped the search: the best point so far.
    TimeLimit {
        /// The limit [s].
        seconds: f64,
    },
    /// The identified saturation magnetostriction lies outside the range of magnetostrictive
    /// materials: most often a displacement in the wrong unit, or a wrong rod length.
    StrainScaleUnlikely {
        /// λ_s as identified.
        lambda_s: f64,
        /// The physical range (the registry's for `magnetostriction.lambda_s`).
        lo: f64,
        /// The physical range.
        hi: f64,
        /// Field-valued parameters the set holds at a value a kA/m slip gives
        /// ([`crate::field_units::fields_in_kilo`]): the strain scale's likelier cause then.
        fields_in_kilo: Vec<(&'static str, f64)>,
    },
    /// The mechanical mode lies above every recording's Nyquist frequency: no file can show it,
    /// and the mechanics acts as a static gain (often a time column in ms read as seconds).
    ModeAboveNyquist {
        /// `mech.natural_frequency_hz`.
        natural_frequency_hz: f64,
        /// Half the fastest file's sample rate [Hz].
        nyquist_hz: f64,
        /// That file's sample period [s].
        step_s: f64,
        /// `natural_frequency_hz` is the lowest the search tries, not a result or a given value.
        lowest_searched: bool,
    },
    /// The mode lies above the Nyquist frequency of some files only ([`crate::fit::unresolved_mode`]).
    ModeAboveSomeFiles {
        /// `mech.natural_frequency_hz`.
        natural_frequency_hz: f64,
        /// The files sampled too slowly to show it.
        files: Vec<String>,
        /// The highest of their Nyquist frequencies [Hz].
        nyquist_hz: f64,
    },
    /// `--max-samples` cut an input short: the result rests on its first part only.
    Truncated {
        /// The input.
        file: String,
        /// Samples (recordings) or points (loop files) it holds.
        found: u64,
        /// How many were kept.
        kept: usize,
        /// The kept part's duration [s] (recordings).
        kept_s: Option<f64>,
        /// The count is after `--trim-start`.
        after_trim_start: bool,
    },
    /// A loop whose largest |M| is below the smallest saturation magnetization the models hold.
    WeakLoop {
        /// The loop files' largest |M| [A/m].
        max_magnetization_a_per_m: f64,
        /// The models' smallest M_s [A/m].
        ms_floor_a_per_m: f64,
    },
    /// A J–A loop fit whose α ended at the model's limit |α| < 1 (α is not searched: its ratio
    /// α·M_s/(3a) is).
    AlphaAtLimit {
        /// The fitted α.
        alpha: f64,
    },
    /// A loop whose M at its field extreme is over a thousand times that field
    /// ([`crate::loops::field_in_kilo`]): H in kA/m read as A/m, or not a magnetostrictive rod.
    LoopFieldSmall {
        /// The loop file.
        file: String,
        /// Its largest |H| [A/m], as read.
        h_peak_a_per_m: f64,
        /// Its largest |M| [A/m].
        m_peak_a_per_m: f64,
    },
    /// A loop traversed clockwise in the H–M plane (a ferromagnet's runs counterclockwise).
    LoopClockwise {
        /// The loop file.
        file: String,
        /// ∮ M dH over the loop's bounding box (positive: clockwise).
        share: f64,
    },
    /// A recording's search-coil magnetization scale g ended at an end of its range
    /// ([`crate::channels::FLUX_SCALE_RANGE`]): the column is not the rod's flux density B in T.
    FluxScaleAtBound {
        /// The recording.
        file: String,
        /// The scale it ended at (the range's end).
        scale: f64,
    },
    /// One recording's displacement per unit drive disagrees with the other files' beyond what
    /// the model explains ([`crate::fit::sign_and_scale_doubts`]).
    GainsDisagree {
        /// The recording.
        file: String,
        /// Its displacement spread per what the other files' model makes of its drive.
        gain: f64,
        /// The joint fit's NRMSE on it.
        joint_nrmse: f64,
        /// The smallest and largest NRMSE of the fit without it on the other files.
        others_nrmse: (f64, f64),
        /// The ratio from which scales are doubted.
        doubted_from: f64,
        /// With only two files, the other one: neither can be told the odd one (`gain` is then
        /// `file`'s scale against this one's, and `others_nrmse` each file's own fit).
        pair: Option<String>,
    },
    /// One recording's drive column at another scale than the other files' (a clamp's or
    /// monitor's range): the other files' model follows its displacement far better with the
    /// drive rescaled than at any probe gain ([`crate::fit::sign_and_scale_doubts`]).
    DriveScaleOff {
        /// The recording.
        file: String,
        /// The drive column (`current_A` or `command_V`).
        column: &'static str,
        /// The scale its drive is followed best at.
        scale: f64,
        /// The share of its displacement's spread (rms) left unexplained so.
        rescaled: f64,
        /// The same, its drive as logged and the displacement at its best gain.
        as_logged: f64,
        /// With only two files, the other one: neither can be told the odd one (`scale` is then
        /// `file`'s drive scale against this one's; the shares the worse of the two readings).
        pair: Option<String>,
    },
    /// A parameter set run with effects the model it was fitted as lacks: their values are start
    /// values.
    EffectsNotFitted {
        /// The parameter file.
        params: String,
        /// The model it is run as.
        model: String,
        /// The effects its header's model lacks.
        effects: Vec<&'static str>,
    },
    /// A command-driven recording is run through an amplifier gain that no recording constrained
    /// (the parameter file marks it not fitted).
    UnfittedGain {
        /// The recording (the first that gives the command alone).
        file: String,
        /// The parameter file.
        params: String,
        /// `amp.gain_a_per_v` as given [A/V].
        gain: f64,
    },
    /// A loop driven symmetrically whose magnetization is not centred on zero.
    LoopOffCentre {
        /// The loop file.
        file: String,
        /// (max M + min M)/2 [A/m].
        centre_a_per_m: f64,
        /// That centre over the half-swing (max M − min M)/2.
        share: f64,
        /// The file gives B (the offset is then μ0 × the centre in B).
        flux_density: bool,
    },
    /// A doubt about a recording's samples or physics that needs no refusal.
    Data(crate::data_doubts::DataDoubt),
    /// How a measurement file was read: columns not used, a name that looks like a recognised
    /// column, time stamps rebased, an implausible time axis.
    Read(crate::read_doubts::ReadDoubt),
}

/// How much a doubt matters to the person reading the result; text lists warnings heaviest
/// first ([`by_weight`]), so the one that changes what the result means is not buried.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Weight {
    /// The result is invalid ([`Warning::invalidates`]).
    Invalid,
    /// The data or their reading look wrong: a unit, a sign or order, a time base, the files
    /// given; the numbers may mean something else than they seem to.
    Data,
    /// The search: where it started or ended, a limit it met, its time limit.
    Search,
    /// The statistics of a sound estimate: correlated or unidentifiable parameters.
    Statistical,
}

impl Warning {
    /// How much it matters, by kind (never by its text).
    pub fn weight(&self) -> Weight {
        match self {
            Warning::Multivalued { .. } | Warning::IntegrationFailed { .. } => Weight::Invalid,
            // What the reader did (a note) weighs least; what it doubts is about the data.
            Warning::Read(d) if d.is_note() => Weight::Statistical,
            Warning::Read(_) => Weight::Data,
            Warning::StrainScaleUnlikely { .. }
            | Warning::ModeAboveNyquist { .. }
            | Warning::ModeAboveSomeFiles { .. }
            | Warning::WeakLoop { .. }
            | Warning::LoopClockwise { .. }
            | Warning::LoopFieldSmall { .. }
            | Warning::LoopOffCentre { .. }
            | Warning::ValidationIsFitFile { .. }
            | Warning::SameInputTwice { .. }
            | Warning::FitFileAfterVal { .. }
            | Warning::Truncated { .. }
            | Warning::PreisachPlaneWide { .. }
            | Warning::FluxScaleAtBound { .. }
            | Warning::GainsDisagree { .. }
            | Warning::DriveScaleOff { .. }
            | Warning::EffectsNotFitted { .. }
            | Warning::UnfittedGain { .. }
            | Warning::Data(_) => Weight::Data,
            Warning::AtEdge { .. }
            | Warning::SquarerThanJa { .. }
            | Warning::StartKept { .. }
            | Warning::StartMoved { .. }
            | Warning::TimeLimit { .. }
            | Warning::AlphaAtLimit { .. } => Weight::Search,
            Warning::Correlated { .. } | Warning::NotIdentifiable { .. } | Warning::NoUncertainty { .. } => {
                Weight::Statistical
            }
        }
    }
}

/// `warnings` heaviest first ([`Warning::weight`]), those of one weight in the order given.
pub fn by_weight<'a>(warnings: impl IntoIterator<Item = &'a Warning>) -> Vec<&'a Warning> {
    let mut sorted: Vec<&Warning> = warnings.into_iter().collect();
    sorted.sort_by_key(|w| w.weight());
    sorted
}

impl Warning {
    /// Whether the result is invalid (nothing may be written from it), not merely doubtful.
    pub fn invalidates(&self) -> bool {
        self.weight() == Weight::Invalid
    }

    /// As said on stderr: a note (what was done) or a warning.
    pub fn said(&self) -> Said {
        match self {
            Warning::Read(d) if d.is_note() => Said::Note(self.to_string()),
            _ => Said::Warning(self.to_string()),
        }
    }

    /// Says it on stderr (`gma: note: …` or `gma: warning: …`), or to [`heard`]'s caller.
    pub fn say(&self) {
        say(self.said());
    }
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Warning::AtEdge { param, value, lo, hi } => {
                write!(f, "`{param}` = {value:.4e} ended at the edge of its search range [{lo:.3e}, {hi:.3e}]")
            }
            Warning::Multivalued { ratio } => write!(
                f,
                "J–A region α·M_s/(3a) = {ratio:.2} ≥ 1: the mean field makes the anhysteretic curve multivalued; \
                 the loop there is an artefact of the integration limits, not physics"
            ),
            Warning::SquarerThanJa { ratio } => write!(
                f,
                "the loop is squarer than Jiles–Atherton can follow: α·M_s/(3a) = {ratio:.2} is at its limit \
                 (at ≥ 1 the model is multivalued and refused); the Preisach law follows square loops: \
                 try `--model preisach` and compare the two fits"
            ),
            Warning::IntegrationFailed { file, why } => {
                write!(f, "{file}: the model integration failed at the best parameters: {why}")
            }
            Warning::Correlated { a, b, rho } => write!(
                f,
                "`{a}` and `{b}` are correlated (ρ = {rho:+.3}): the data barely tell them apart; \
                 consider --fix on one of them or data that separate them"
            ),
            Warning::NotIdentifiable { params, condition } => write!(
                f,
                "not identifiable from these files: {} (Jacobian condition {condition:.2e}); their \
                 values are one of many that fit equally well: --fix them or add data that excite them",
                params.iter().map(|p| format!("`{p}`")).collect::<Vec<_>>().join(", ")
            ),
            Warning::StartKept { start_nrmse, found_nrmse } if !found_nrmse.is_finite() => write!(
                f,
                "the search ended where the model cannot be integrated along every file: the start values \
                 ({:.3} % NRMSE) are returned",
                start_nrmse * 100.0
            ),
            Warning::StartKept { start_nrmse, found_nrmse } => write!(
                f,
                "the search ended at {:.3} % NRMSE, worse than the start values' {:.3} %: the start values are \
                 returned (a fit never ends worse than its start)",
                found_nrmse * 100.0,
                start_nrmse * 100.0
            ),
            Warning::StartMoved { param, given, used, lo, hi } => {
                // A value a log scale cannot place (0, negative) starts in the range's middle.
                let at_end = [*lo, *hi].iter().any(|end| (used - end).abs() <= 1e-9 * end.abs());
                let where_ = if at_end {
                    "that range's nearest end"
                } else {
                    "the middle of that range (its scale is logarithmic: a value ≤ 0 has no place on it)"
                };
                write!(
                    f,
                    "start value `{param}` = {given:.4e} lies outside its search range [{lo:.3e}, {hi:.3e}]: the \
                     search began at {used:.4e}, {where_}"
                )
            }
            Warning::ValidationIsFitFile { val, fit } => write!(
                f,
                "{val} is also a fit file (same content as {fit}): its validation figure is not independent"
            ),
            Warning::SameInputTwice { first, again, counts_in } => {
                write!(f, "{again} has the same content as {first}: it counts twice in {counts_in}")
            }
            Warning::FitFileAfterVal { val, fit } => write!(
                f,
                "{fit} follows `--val {val}` and is read as a fit file: `--val` takes one file; repeat it \
                 (`--val {val} --val {fit}`) if {fit} is for validation"
            ),
            Warning::PreisachPlaneWide { h_max, reach, advised } => preisach_plane_wide(f, *h_max, *reach, *advised),
            Warning::NoUncertainty { why } => write!(f, "no parameter uncertainty: {why}"),
            Warning::TimeLimit { seconds } => write!(
                f,
                "the time limit of {seconds} s was reached: the result is the best found so far, not a converged fit"
            ),
            Warning::ModeAboveSomeFiles { natural_frequency_hz, files, nyquist_hz } => {
                mode_above_some_files(f, *natural_frequency_hz, files, *nyquist_hz)
            }
            Warning::ModeAboveNyquist { natural_frequency_hz, nyquist_hz, step_s, lowest_searched } => {
                mode_above_nyquist(f, *natural_frequency_hz, *nyquist_hz, *step_s, *lowest_searched)
            }
            Warning::Truncated { file, found, kept, kept_s, after_trim_start } => {
                let trimmed = if *after_trim_start { " after --trim-start" } else { "" };
                match kept_s {
                    Some(s) => write!(f, "{file}: {found} samples{trimmed}; using the first {kept} ({s:.3} s)"),
                    None => write!(f, "{file}: {found} points; using the first {kept}"),
                }?;
                write!(f, "; raise --max-samples to use more")
            }
            Warning::WeakLoop { max_magnetization_a_per_m, ms_floor_a_per_m } => write!(
                f,
                "the loop's largest |M| is {max_magnetization_a_per_m:.3e} A/m, below the smallest saturation \
                 magnetization the models hold ({ms_floor_a_per_m:.0e} A/m, for the ferromagnets this tool is made \
                 for): M_s is held there, and the fit follows the loop only as a loop far from saturation can; does \
                 the header name the file's unit? (M in kA/m under an A/m header reads 1000× too small; `M(kA/m)` \
                 converts)"
            ),
            Warning::AlphaAtLimit { alpha } => write!(
                f,
                "J–A's α = {alpha:.4e} ended at the model's limit |α| < 1 (the search moves α·M_s/(3a), which \
                 does not bound α when a is large against M_s): the model holds the fit there, not the loop; α \
                 scales as 1/M, so for a file whose M is known only up to a factor the limit moves with it"
            ),
            Warning::LoopFieldSmall { file, h_peak_a_per_m, m_peak_a_per_m } => {
                loop_field_small(f, file, *h_peak_a_per_m, *m_peak_a_per_m)
            }
            Warning::LoopClockwise { file, share } => loop_clockwise(f, file, *share),
            Warning::LoopOffCentre { file, centre_a_per_m, share, flux_density } => {
                let offset = if *flux_density {
                    format!("B offset by {:.4} T", centre_a_per_m * 4e-7 * std::f64::consts::PI)
                } else {
                    format!("M offset by {centre_a_per_m:.4e} A/m")
                };
                write!(
                    f,
                    "{file}: the field is symmetric but the loop is not centred ({offset}: {:.0} % of its half-swing): \
                     a ferromagnet's symmetric loop is, so it is most likely an integrator's offset or drift, which \
                     the loop fit does not remove; subtract it from the file and fit again",
                    share.abs() * 100.0
                )
            }
            Warning::FluxScaleAtBound { file, scale } => flux_scale_at_bound(f, file, *scale),
            Warning::GainsDisagree { file, gain, joint_nrmse, others_nrmse, doubted_from, pair } => match pair {
                None => gains_disagree(f, file, *gain, *joint_nrmse, *others_nrmse, *doubted_from),
                Some(other) => pair_gains_disagree(f, (other, file), *gain, *others_nrmse, *doubted_from),
            },
            Warning::DriveScaleOff { file, column, scale, rescaled, as_logged, pair } => {
                drive_scale_off(f, (file, pair.as_deref()), column, *scale, (*rescaled, *as_logged))
            }
            Warning::EffectsNotFitted { params, model, effects } => write!(
                f,
                "{params} was fitted as a model without `{}`, run here as `{model}`: those values are the start \
                 values the file was written with, never fitted to a recording, and the figures rest on them; fit \
                 `--model {model}` (from this set: `--params {params}`) to score that model",
                effects.join("`, `")
            ),
            Warning::UnfittedGain { file, params, gain } => write!(
                f,
                "{file} gives the command, not the current, so the model is driven through `amp.gain_a_per_v` = \
                 {gain} A/V, which {params} marks as not fitted (its files gave the current, so the gain never \
                 acted): the displacement's scale rests on a start value; fit on command-driven files, or set \
                 the rig amplifier's gain in [amp] and remove the mark"
            ),
            Warning::StrainScaleUnlikely { lambda_s, lo, hi, fields_in_kilo } => {
                strain_scale_unlikely(f, *lambda_s, *lo, *hi, fields_in_kilo)
            }
            Warning::Read(doubt) => write!(f, "{doubt}"),
            Warning::Data(doubt) => write!(f, "{doubt}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A start value is moved to the nearest end of its range, except a value a log scale cannot
    /// place (0, negative: a file's "no heating", "no creep"), which starts in the range's
    /// geometric middle: the warning must say which, not call the middle an end.
    #[test]
    fn a_moved_start_says_where_the_search_began() {
        let (lo, hi) = (1e-3, 0.6);
        let above = Warning::StartMoved { param: "aftereffect.fraction", given: 0.9, used: hi, lo, hi };
        assert!(above.to_string().contains("began at 6.0000e-1, that range's nearest end"), "{above}");
        let middle = (lo * hi).sqrt();
        let zero = Warning::StartMoved { param: "aftereffect.fraction", given: 0.0, used: middle, lo, hi };
        let text = zero.to_string();
        assert!(!text.contains("nearest end"), "{text}");
        assert!(text.contains("began at 2.4495e-2, the middle of that range"), "{text}");
    }

    /// A doubt about the data's unit comes before the search's and the statistics', whatever
    /// order the checks found them in; those of one weight keep theirs.
    #[test]
    fn warnings_are_listed_heaviest_first() {
        let correlated = |a| Warning::Correlated { a, b: "ja.alpha", rho: 0.99 };
        let unit =
            Warning::StrainScaleUnlikely { lambda_s: 1e-6, lo: 1e-5, hi: 1e-2, fields_in_kilo: vec![] };
        let edge = Warning::AtEdge { param: "ja.c", value: 0.0, lo: 0.0, hi: 0.95 };
        let found = [correlated("ja.a_a_per_m"), edge.clone(), correlated("ja.c"), unit.clone()];
        let listed = by_weight(&found);
        assert_eq!(listed, [&unit, &edge, &found[0], &found[2]]);
        assert!(Warning::Multivalued { ratio: 1.2 }.weight() < unit.weight());
    }

    /// What is said inside `heard` is collected in order, an inner `heard` keeps its own, and
    /// the outer collection carries on after it (a call that panics still restores it).
    #[test]
    fn heard_collects_what_is_said_on_its_thread_and_nests() {
        let ((inner, outer_after), said) = heard(|| {
            note("first");
            let ((), inner) = heard(|| warn(format_args!("inner {}", 2)));
            warn("after");
            let panicked = std::panic::catch_unwind(|| heard(|| panic!("in a heard call"))).is_err();
            note("still heard");
            (inner, panicked)
        });
        assert_eq!(inner, vec![Said::Warning("inner 2".into())]);
        assert!(outer_after);
        assert_eq!(
            said,
            vec![Said::Note("first".into()), Said::Warning("after".into()), Said::Note("still heard".into())]
        );
        assert_eq!(said[0].to_string(), "note: first");
        // Another thread's words are not this call's.
        let ((), said) = heard(|| std::thread::spawn(|| note("elsewhere")).join().unwrap());
        assert!(said.is_empty(), "{said:?}");
    }
}
