//! Doubts about a recording's samples or physics that need no refusal (a refusal names its fix
//! and stops; these let the work go on and are listed first among a result's warnings): a
//! channel stuck while the drive moves, a scale or sign the model disagrees with, a loop run the
//! other way round, a delay counted at another rate, a validation file that repeats fit samples.

use std::fmt;

/// One such doubt ([`crate::fit::data_doubts`], [`crate::same_samples`]).
#[derive(Debug, Clone, PartialEq)]
pub enum DataDoubt {
    /// A validation file shares a stretch of samples with a fit file though its bytes differ (the
    /// fit file reprinted, shifted in time, cut: [`crate::same_samples`]).
    ValidationSharesFitSamples {
        /// The `--val` file.
        val: String,
        /// The fit file.
        fit: String,
        /// How many samples they share.
        samples: usize,
        /// The validation file's samples in all.
        val_samples: usize,
        /// Where the shared stretch begins in the validation file [s].
        val_from_s: f64,
        /// And in the fit file [s].
        fit_from_s: f64,
    },
    /// A channel that follows the drive stays at one exact value while the drive crosses a
    /// quarter of its span and more (or the measured current, clipped, while the displacement
    /// does) ([`crate::fit::data_doubts`]): a sensor clipped at its range
    /// or a frozen converter.
    StuckChannel {
        /// The recording.
        file: String,
        /// The channel.
        column: &'static str,
        /// The column it is judged against (the drive; the displacement for the current).
        drive: &'static str,
        /// The value it stays at (in its first such run).
        value: f64,
        /// Where its first such run begins [s].
        time_s: f64,
        /// How many such runs.
        runs: usize,
        /// Their samples in all.
        samples: usize,
        /// The value is the channel's largest or smallest (clipped, not frozen).
        at_range_end: bool,
    },
    /// The displacement spreads a hundred times more or less than the model's strain for the
    /// file's drive ([`crate::fit::data_doubts`]): a unit, a coil or a rod not the parameter set's.
    DisplacementScale {
        /// The recording.
        file: String,
        /// The drive column.
        drive: &'static str,
        /// The file's displacement spread (rms about its mean, past its first tenth) [µm].
        measured_um: f64,
        /// The model's, for the start parameters [µm].
        model_um: f64,
    },
    /// The file follows the model far better with its drive and its displacement both negated
    /// ([`crate::fit::data_doubts`]).
    BothNegated {
        /// The recording.
        file: String,
        /// The drive column.
        drive: &'static str,
        /// The displacement's variance share the model leaves unexplained as read (1 − ρ²).
        as_read: f64,
        /// The same with both columns negated.
        both: f64,
    },
    /// A recording's displacement loop against its drive runs the other way round from the
    /// model's ([`crate::fit::data_doubts`]): reverse time order, or a drive from another file.
    LoopReversed {
        /// The recording.
        file: String,
        /// The drive column.
        drive: &'static str,
        /// The file's loop area as a share of its box (positive: the displacement lags).
        area: f64,
        /// The model's.
        model_area: f64,
    },
    /// A sensor delay counted in the parameter set's `dt_s` follows the file far worse than
    /// the same count in the file's own step ([`crate::fit::data_doubts`]).
    DelayAtOtherRate {
        /// The recording.
        file: String,
        /// `delay_samples` as given.
        delay_samples: f64,
        /// The parameter set's `dt_s` [s] (as the file gives it).
        params_dt_s: f32,
        /// The file's step [s].
        step_s: f64,
        /// The displacement's variance share left unexplained as given (1 − ρ²).
        given: f64,
        /// The same with the delay counted in the file's step.
        at_step: f64,
    },
    /// A coil temperature that starts where a room's temperature in °F would
    /// ([`crate::fit::data_doubts`]).
    TemperatureLikeFahrenheit {
        /// The recording.
        file: String,
        /// `temperature_C`'s first value.
        first: f64,
    },
    /// A coil temperature that starts where a room's temperature in kelvin would
    /// ([`crate::fit::data_doubts`]).
    TemperatureLikeKelvin {
        /// The recording.
        file: String,
        /// `temperature_C`'s first value.
        first: f64,
    },
}

impl fmt::Display for DataDoubt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DataDoubt::ValidationSharesFitSamples { val, fit, samples, val_samples, val_from_s, fit_from_s } => write!(
                f,
                "{val} shares {samples} of its {val_samples} samples with the fit file {fit} (the drive and the \
                 displacement sample for sample, from time_s = {val_from_s} there and {fit_from_s} in {fit}): \
                 the fit file reprinted, shifted in time or cut, so its validation figure is {}a fit figure; \
                 validate on a recording the fit has not seen",
                if samples == val_samples { "" } else { "in part " }
            ),
            DataDoubt::StuckChannel { file, column, drive, value, time_s, runs, samples, at_range_end } => {
                let what = if *at_range_end {
                    "a sensor clipped at its range"
                } else {
                    "a frozen sensor or converter"
                };
                write!(
                    f,
                    "{file}: `{column}` stays at exactly {value} for {samples} samples in {runs} run(s) (the first \
                     from time_s = {time_s}) while `{drive}` crosses a quarter of its span and more: {what}, not \
                     the actuator; a fit follows those samples as if {}; record within the sensor's range, or \
                     cut those rows out (one file per part)",
                    if *column == "current_A" { "the coil's current stood still" } else { "the rod stood still" }
                )
            }
            DataDoubt::DisplacementScale { file, drive, measured_um, model_um } => {
                let (ratio, more) = if measured_um > model_um {
                    (measured_um / model_um, true)
                } else {
                    (model_um / measured_um, false)
                };
                // The readings a factor near a thousand or a million points at.
                let unit = if *drive == "current_A" { "A" } else { "V" };
                let hint = match (more, (ratio.log10() / 3.0).round() as i32) {
                    (true, k) if k >= 1 => format!(
                        ": is `{drive}` read in {unit} (a column read with `:m{unit}` reads 1000× small) and \
                         `displacement_um` in µm (a file in nm reads 1000× large; `--column \
                         displacement_um=HEADER:nm` converts)"
                    ),
                    (false, k) if k >= 1 => format!(
                        ": is `displacement_um` read in µm (a file in mm or m, or a column read with `:nm`, reads \
                         1000× small or more; `--column displacement_um=HEADER:mm` converts mm) and `{drive}` in \
                         {unit}"
                    ),
                    _ => String::new(),
                };
                write!(
                    f,
                    "{file}: the displacement's rms spread is {measured_um:.4e} µm, {ratio:.0}× {} the model's \
                     {model_um:.4e} µm for this `{drive}` and the start parameters{hint}; are `coil.turns_per_m` \
                     and `rod_length_m` this rig's?",
                    if more { "more than" } else { "less than" }
                )
            }
            DataDoubt::BothNegated { file, drive, as_read, both } => write!(
                f,
                "{file}: the displacement follows the model far better with it and `{drive}` both negated ({:.2} % \
                 of its variance unexplained, against {:.2} % as read): with a bias field the strain curves one \
                 way on the bias's side, and a probe and a current clamp both on backwards read like this; check \
                 both, and read them negated: `--column displacement_um=-displacement_um --column \
                 {drive}=-{drive}` (a column mapped with --column: put `-` before its HEADER)",
                100.0 * both,
                100.0 * as_read
            ),
            DataDoubt::LoopReversed { file, drive, area, model_area } => write!(
                f,
                "{file}: the displacement's loop against `{drive}` runs the other way round from the model's \
                 (signed area {area:+.3} of its box, the model's {model_area:+.3}): it leads the drive where \
                 hysteresis and every lag make it follow; are the rows in time order (a file reversed under a \
                 rising time column reads so), and are the drive and the displacement from the same run?"
            ),
            DataDoubt::DelayAtOtherRate { file, delay_samples, params_dt_s, step_s, given, at_step } => write!(
                f,
                "{file}: `delay_samples` = {delay_samples} counts periods of the parameter set's `dt_s` = \
                 {params_dt_s} s, {:.1} samples of this file (a step of {step_s:.4e} s); counted in this file's \
                 samples the model follows the displacement far better ({:.2} % of its variance unexplained, \
                 against {:.2} %): if the delay was meant in this file's samples, set `dt_s = {step_s:e}` in the \
                 parameter file (every command replaces `dt_s` by the file's step, but the delay keeps its time)",
                delay_samples * *params_dt_s as f64 / step_s,
                100.0 * at_step,
                100.0 * given
            ),
            DataDoubt::TemperatureLikeFahrenheit { file, first } => write!(
                f,
                "{file}: `temperature_C` starts at {first} °C, a hot coil before any drive, or a room at {:.1} °C \
                 logged in °F; if the column is in °F, read it so: `--column temperature_C=temperature_C:°F` \
                 (a column mapped with --column: give that mapping the unit `°F`); the coil heating's \
                 thermal resistance would otherwise come out 1.8× too large",
                (first - 32.0) * 5.0 / 9.0
            ),
            DataDoubt::TemperatureLikeKelvin { file, first } => write!(
                f,
                "{file}: `temperature_C` starts at {first} °C, a coil far above boiling before any drive, or a \
                 room at {:.1} °C logged in kelvin; if the column is in K, read it so: `--column \
                 temperature_C=temperature_C:K` (a column mapped with --column: give that mapping the unit `K`); \
                 the coil's ambient temperature would otherwise come out 273.15 °C too high",
                first - 273.15
            ),
        }
    }
}
