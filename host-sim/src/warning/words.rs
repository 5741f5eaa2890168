//! The longer warnings in words, one function each, so that [`super::Warning`]'s `Display`
//! stays a table of which words say which warning.

use std::fmt;

/// Sample periods from which on a time column may well be in ms read as seconds: 10 ms is
/// 100 Hz, where a rig logging an actuator's dynamics records at 1–100 kHz.
const SLOW_STEP_S: f64 = 0.01;

/// [`super::Warning::LoopClockwise`] in words.
pub(super) fn loop_clockwise(f: &mut fmt::Formatter<'_>, file: &str, share: f64) -> fmt::Result {
    write!(
        f,
        "{file}: the loop runs clockwise in the H–M plane (∮ M dH = +{:.0} % of its bounding box): a \
         ferromagnet's loop runs counterclockwise, its rising branch below the falling one; are the rows in \
         reverse time order? (the fit follows the file's order)",
        share * 100.0
    )
}

/// [`super::Warning::LoopFieldSmall`] in words.
pub(super) fn loop_field_small(f: &mut fmt::Formatter<'_>, file: &str, h: f64, m: f64) -> fmt::Result {
    write!(
        f,
        "{file}: M reaches {m:.3e} A/m at fields of at most {h:.3e} A/m (M/H = {:.0}): a Terfenol-D rod needs \
         tens of kA/m to come near saturation (M/H of 15–150 there), and only the softest magnets reach this; \
         if the file is a rod's, is H in kA/m under an A/m header? name the unit (`H [kA/m]` in the two-column \
         form) or write H in A/m (a fit's a and k come out in the file's field unit)",
        m / h
    )
}

/// [`super::Warning::StrainScaleUnlikely`] in words: a field in kA/m is the likelier cause where the set
/// holds one, else the displacement's unit or the rod's length.
pub(super) fn strain_scale_unlikely(
    f: &mut fmt::Formatter<'_>,
    lambda_s: f64,
    lo: f64,
    hi: f64,
    fields_in_kilo: &[(&'static str, f64)],
) -> fmt::Result {
    write!(
        f,
        "`magnetostriction.lambda_s` = {lambda_s:.2e} is outside [{lo:.0e}, {hi:.0e}], the range of \
         magnetostrictive materials (Terfenol-D ≈ 1e-3)"
    )?;
    if fields_in_kilo.is_empty() {
        write!(
            f,
            ": is `displacement_um` in µm (`--column displacement_um=NAME:mm` converts mm, `:nm` nm) and \
             `rod_length_m` the rod's active length?"
        )
    } else {
        write!(f, ", fitted to a set that holds {}", crate::field_units::kilo_words(fields_in_kilo))
    }
}

/// [`super::Warning::ModeAboveSomeFiles`] in words.
pub(super) fn mode_above_some_files(
    f: &mut fmt::Formatter<'_>,
    natural_frequency_hz: f64,
    files: &[String],
    nyquist_hz: f64,
) -> fmt::Result {
    let (these, them, their) =
        if files.len() == 1 { ("this file", "it", "its") } else { ("these files", "them", "their") };
    write!(
        f,
        "`mech.natural_frequency_hz` = {natural_frequency_hz:.0} Hz lies above the Nyquist frequency of {} \
         ({}{nyquist_hz:.1} Hz), though not of the other files: {these} cannot show the mode, and a joint fit \
         may put it where {their} aliases fit best; fit without {them} and compare, or log {them} at 4× the \
         mode's frequency or faster",
        files.join(", "),
        if files.len() == 1 { "" } else { "at most " },
    )
}

/// [`super::Warning::ModeAboveNyquist`] in words.
pub(super) fn mode_above_nyquist(
    f: &mut fmt::Formatter<'_>,
    natural_frequency_hz: f64,
    nyquist_hz: f64,
    step_s: f64,
    lowest_searched: bool,
) -> fmt::Result {
    // Six significant digits: a step read off a time column is 0.10000000000000142 s.
    let step = format!("{:.5e}", step_s).parse::<f64>().unwrap_or(step_s);
    let at = format!("the recordings' Nyquist frequency ({nyquist_hz:.1} Hz, a sample every {step} s)");
    if lowest_searched {
        write!(
            f,
            "every mechanical mode the search tries (`mech.natural_frequency_hz` from \
             {natural_frequency_hz:.0} Hz) lies above {at}: no file can show one, so mechanical \
             dynamics cannot be judged"
        )?;
    } else {
        write!(
            f,
            "`mech.natural_frequency_hz` = {natural_frequency_hz:.0} Hz lies above {at}: no file can \
             show the mode, so the mechanics acts as a static gain and its frequency and damping are \
             not measured"
        )?;
    }
    if step_s >= SLOW_STEP_S {
        write!(
            f,
            "; a step this long is rare in an actuator recording: if `time_s` holds milliseconds, \
             read it as such (`--column time_s=time_s:ms`)"
        )?;
    }
    Ok(())
}

/// [`super::Warning::FluxScaleAtBound`] in words.
pub(super) fn flux_scale_at_bound(f: &mut fmt::Formatter<'_>, file: &str, scale: f64) -> fmt::Result {
    let (lo, hi) = crate::channels::FLUX_SCALE_RANGE;
    let why = if scale <= lo {
        "the flux density swings far less than the model's magnetization makes it: is \
         `flux_density_T` the rod's flux density B in T? A flux linkage N·A·B (V·s) must be divided \
         by the search coil's turns × area, and a coil much wider than the rod reads a share of its \
         flux"
    } else {
        "the flux density swings far more than the model's magnetization makes it: is \
         `flux_density_T` in T? A column in mT or G reads 1000× or 10 000× too large (`--column \
         flux_density_T=NAME:mT`, `:G` converts)"
    };
    write!(
        f,
        "{file}: the search coil's magnetization scale g = {scale} ended at an end of its range \
         [{lo}, {hi}] (B = μ0 (H + g M) + c): {why}; the other parameters may have bent to follow it"
    )
}

/// [`super::Warning::GainsDisagree`] in words.
pub(super) fn gains_disagree(
    f: &mut fmt::Formatter<'_>,
    file: &str,
    gain: f64,
    joint_nrmse: f64,
    (lo, hi): (f64, f64),
    doubted_from: f64,
) -> fmt::Result {
    let followed = if lo == hi {
        format!("{:.2} %", 100.0 * lo)
    } else {
        format!("{:.2}–{:.2} %", 100.0 * lo, 100.0 * hi)
    };
    write!(
        f,
        "{file}: its displacement spreads {gain:.3}× as far as the other files' rig makes it from its drive \
         (the model fitted without it, which follows them at {followed}, run on its drive from the \
         demagnetised rod); the joint fit follows it at {:.2} % only by bending every parameter: files of one \
         rig do not disagree so (doubted from {doubted_from}×). A probe gain or range not the others' (an amplifier range \
         switch, a sensitivity entered for another probe), a current clamp's range or a command in other units, \
         or a file of another rig reads like this; check its probe's and its drive's scales (if the probe is the \
         cause, divide its displacement by {gain:.3} and fit again) or fit it on its own. An effect the model lacks that acts on this file alone (a drive near a mode, hours of heating) \
         can read so too: `gma diagnose` tells",
        100.0 * joint_nrmse,
    )
}

/// [`super::Warning::GainsDisagree`] of two files in words: which of them is off, nothing tells.
pub(super) fn pair_gains_disagree(
    f: &mut fmt::Formatter<'_>,
    (first, second): (&str, &str),
    gain: f64,
    (first_own, second_own): (f64, f64),
    doubted_from: f64,
) -> fmt::Result {
    write!(
        f,
        "{first} and {second}: their displacement per unit drive disagrees by {gain:.3}× ({second}'s against \
         {first}'s, each file's model, fitted to it alone (at {:.2} % and {:.2} %), run on the other's drive from \
         the demagnetised rod, the two readings mirroring each other): files of one rig do not disagree so \
         (doubted from {doubted_from}×), and two files cannot tell which of them is off. A probe gain or range, \
         a current clamp's range or a command in other units in one of them, or files of two rigs, read like \
         this; check both files' probe and drive scales, or fit each on its own",
        100.0 * first_own,
        100.0 * second_own,
    )
}

/// [`super::Warning::DriveScaleOff`] in words (of two files, `pair` the other).
pub(super) fn drive_scale_off(
    f: &mut fmt::Formatter<'_>,
    (file, pair): (&str, Option<&str>),
    column: &str,
    scale: f64,
    (rescaled, as_logged): (f64, f64),
) -> fmt::Result {
    if let Some(other) = pair {
        return pair_drive_scales_disagree(f, (other, file), column, scale, (rescaled, as_logged));
    }
    write!(
        f,
        "{file}: the other files' rig (the model fitted without it, run on its drive from the start that \
         best explains it) follows its displacement far better with its {column} multiplied by {scale:.3} ({:.1} % of the \
         displacement's spread unexplained) than as logged at any probe gain ({:.1} %): its {column} reads at \
         another scale than the others' (a current clamp's or monitor's range, a shunt or gain entered for \
         another channel). Check that channel's scale (if it is the cause, multiply the column by {scale:.3} and \
         fit again) or fit the file on its own. An effect the model lacks that acts on this file alone (eddy \
         currents at a fast drive lower the field the rod sees) can read so too: `gma diagnose` tells",
        100.0 * rescaled,
        100.0 * as_logged,
    )
}

/// [`super::Warning::DriveScaleOff`] of two files in words: which of them is off, nothing tells.
fn pair_drive_scales_disagree(
    f: &mut fmt::Formatter<'_>,
    (first, second): (&str, &str),
    column: &str,
    scale: f64,
    (rescaled, as_logged): (f64, f64),
) -> fmt::Result {
    write!(
        f,
        "{first} and {second}: their {column} scales disagree by {scale:.3}× ({second}'s against {first}'s): a \
         model fitted to one file alone, run on the other's drive, follows that file's displacement far better \
         with its drive rescaled ({:.1} % of the spread unexplained) than as logged at any probe gain ({:.1} %), \
         and the reading the other way does not contradict it; two files cannot tell which of them is off. A current clamp's or monitor's range, or a shunt or gain entered for another channel, in one of \
         them reads like this; check both files' {column} scales, or fit each on its own",
        100.0 * rescaled,
        100.0 * as_logged,
    )
}

/// [`super::Warning::PreisachPlaneWide`] in words.
pub(super) fn preisach_plane_wide(
    f: &mut fmt::Formatter<'_>,
    h_max: f64,
    reach: f64,
    advised: f64,
) -> fmt::Result {
    let levels = model_core::magnetization::PREISACH_LEVELS;
    write!(
        f,
        "`preisach.h_max_a_per_m` = {h_max:.0} A/m is {:.1}× the largest field these recordings reach \
         ({reach:.0} A/m: coil.bias_a_per_m + coil.turns_per_m × the current): the relay plane's \
         {levels} levels step {:.0} A/m, most of them beyond the data; set it near {advised:.0} A/m \
         ({:.2}× that field) in the parameter file, or take it from a loop fit of the rod, which \
         identifies it",
        h_max / reach,
        2.0 * h_max / (levels - 1) as f64,
        advised / reach
    )
}
