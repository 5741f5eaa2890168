//! Samples a sensor got wrong, found from the samples alone before any model runs: spikes and
//! dropouts (one sample or a short run off both its neighbours, at a file's ends too), a level
//! that steps where the drive does not (a probe re-zeroed or knocked), and a channel that stays
//! at one value while the drive moves (a sensor clipped at its range, a frozen converter). Each
//! would set or bend the NRMSE so that a wrong model scores as a right one.

use anyhow::Result;

use crate::columns::MAX_GAP_STEPS;
use crate::data_doubts::DataDoubt;
use crate::error::InRecording;
use crate::recording::Recording;
use crate::warning::Warning;

/// The channels a bad sample is looked for in: those a sensor measured (the command is what was
/// sent, and a drive may step in one sample).
const MEASURED: [&str; 4] = ["current_A", "displacement_um", "flux_density_T", "temperature_C"];

/// The measured channels that follow the drive (a level step or a stuck run is judged against
/// the drive's own moves).
const FOLLOWERS: [&str; 2] = ["displacement_um", "flux_density_T"];

/// A run this many times the local sample-to-sample change off both its neighbours is a spike or
/// a dropout: Gaussian noise reaches about 3 such changes, a square drive's step is off one
/// neighbour only, and a mode rung at a few samples a period changes as much around it.
pub const SPIKE_CHANGES: f64 = 20.0;

/// The samples either side whose changes give the local scale.
const SPIKE_WINDOW: usize = 32;

/// The local change is taken as at least this share of the channel's span (a noise-free channel
/// changes by nothing between some samples, and a least-significant bit is no spike).
const SPIKE_FLOOR_OF_SPAN: f64 = 1e-3;

/// Longest run of samples judged as one spike or dropout (a sensor over range, a lost packet of
/// a few samples); a square drive's half period is longer at ten samples a period and more, and
/// its steps are in the local change around.
pub const MAX_BAD_RUN: usize = 8;

/// How far back of a level step the drive's own step may be [samples]: a sensor delay and a
/// mode's rise put the displacement's step after the drive's.
const STEP_LOOKBACK: usize = 200;

/// A drive change this many times its local change is a step of the drive.
const DRIVE_STEP_CHANGES: f64 = 5.0;

/// Shortest run of one exact value, while the drive moves, said as a stuck or clipped channel.
const STUCK_RUN: usize = 10;

/// The share of its span the drive must cross during such a run (a rod moves by a tenth of its
/// stroke and more then, beyond any print resolution of a noise-free channel).
const STUCK_DRIVE_SHARE: f64 = 0.25;

/// How many of the other samples' spans a file's first or last sample must lie beyond their
/// range to be a spike: a simulated file's first sample may be the rod before the drive's first
/// value acted (a span or so off), a probe over range or a torn last line is far beyond.
const END_SPIKE_SPANS: f64 = 3.0;

/// A sample or short run far off its neighbours in a measured channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spike {
    /// Its first index in the recording as read.
    pub index: usize,
    /// How many samples it spans.
    pub samples: usize,
    /// Its first value.
    pub value: f64,
    /// The samples before and after it (the one neighbour twice at a file's end).
    pub neighbours: (f64, f64),
    /// The local sample-to-sample change it is measured against (the mean |Δ| around it).
    pub local_change: f64,
}

/// Smallest and largest of `x`.
fn bounds(x: &[f64]) -> (f64, f64) {
    x.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)))
}

/// The mean |Δ| of `x` within [`SPIKE_WINDOW`] of `from..to` (a run), without the changes into
/// and out of the run (a mean, not a median: a mode ringing after a step for a few samples amid
/// flat ones must count), at least `floor`.
fn local_change(x: &[f64], from: usize, to: usize, floor: f64) -> f64 {
    let n = x.len();
    let (lo, hi) = (from.saturating_sub(SPIKE_WINDOW), (to + SPIKE_WINDOW).min(n - 1));
    // Change j is x[j] → x[j + 1]; those into (from − 1) and out of (to − 1) the run are left out.
    let changes = (lo..hi).filter(|&j| j + 1 != from && j + 1 != to).map(|j| (x[j + 1] - x[j]).abs());
    let (sum, count) = changes.fold((0.0, 0usize), |(s, c), d| (s + d, c + 1));
    (sum / count.max(1) as f64).max(floor)
}

/// The spikes and dropouts of `x`, first to last: runs of 1 to [`MAX_BAD_RUN`] samples beyond
/// both neighbours, on one side, by more than [`SPIKE_CHANGES`] local changes. A file's first or
/// last sample has one neighbour, which cannot tell a spike from a step: it is one only when it
/// also lies beyond the range of all the other samples by [`END_SPIKE_SPANS`] of their span.
pub fn spikes(x: &[f64]) -> Vec<Spike> {
    let n = x.len();
    if n < 5 {
        return Vec::new();
    }
    let (lo, hi) = bounds(x);
    let floor = SPIKE_FLOOR_OF_SPAN * (hi - lo);
    let mut found = Vec::new();
    let mut k = 1;
    while k < n - 1 {
        let run = (1..=MAX_BAD_RUN).take_while(|&len| k + len < n).find(|&len| {
            let (before, after) = (x[k - 1], x[k + len]);
            let (run_lo, run_hi) = bounds(&x[k..k + len]);
            let gap = (run_lo - before.max(after)).max(before.min(after) - run_hi);
            gap > SPIKE_CHANGES * floor && gap > SPIKE_CHANGES * local_change(x, k, k + len, floor)
        });
        match run {
            Some(len) => {
                found.push(Spike {
                    index: k,
                    samples: len,
                    value: x[k],
                    neighbours: (x[k - 1], x[k + len]),
                    local_change: local_change(x, k, k + len, floor),
                });
                k += len;
            }
            None => k += 1,
        }
    }
    for (end, next) in [(0, 1), (n - 1, n - 2)] {
        let rest = if end == 0 { &x[1..] } else { &x[..n - 1] };
        let (rest_lo, rest_hi) = bounds(rest);
        let beyond = (x[end] - rest_hi).max(rest_lo - x[end]);
        // The one change next to the end sample is left out of its local change.
        let local = local_change(x, end.max(1), end.max(1), floor);
        if beyond > (END_SPIKE_SPANS * (rest_hi - rest_lo)).max(SPIKE_CHANGES * local) {
            found.push(Spike {
                index: end,
                samples: 1,
                value: x[end],
                neighbours: (x[next], x[next]),
                local_change: local,
            });
        }
    }
    found.sort_by_key(|s| s.index);
    found
}

/// A measured channel with a spike or dropout (a probe over range, lost samples) is refused,
/// naming the row: one such sample sets the NRMSE's range (max − min), so a wrong model would
/// score as a right one. A file whose first row has no drive (`gma simulate`'s first sample:
/// the rig at rest, before the drive steps on) is not judged at that row.
pub fn check_samples(rec: &Recording) -> Result<()> {
    let at_rest = |name: &str| rec.column(name).and_then(|v| v.first()).is_some_and(|&v| v == 0.0);
    let first_row_at_rest = at_rest("current_A") || (rec.current_a.is_none() && at_rest("command_V"));
    for name in MEASURED {
        let Some(x) = rec.column(name) else { continue };
        let found: Vec<Spike> =
            spikes(x).into_iter().filter(|s| s.index != 0 || !first_row_at_rest).collect();
        let Some(s) = found.first() else { continue };
        return Err(InRecording::error(&rec.name, spike_message(rec, name, s, found.len() - 1)));
    }
    level_steps(rec)
}

/// The refusal of spike `s` in column `name`, with `more` others in the column.
fn spike_message(rec: &Recording, name: &str, s: &Spike, more: usize) -> String {
    let time = rec.time_s.get(s.index).copied().unwrap_or(f64::NAN);
    let more = match more {
        0 => String::new(),
        1 => " (1 more such run in this column)".to_string(),
        m => format!(" ({m} more such runs in this column)"),
    };
    let what =
        if s.samples == 1 { "an isolated spike or dropout" } else { "a run of spiked or dropped samples" };
    let fix = bad_rows_fix(s.samples);
    let (rows, off) = match (s.samples, s.index) {
        (1, 0) => {
            ("the first row".to_string(), format!("the next sample ({}) and all the others", s.neighbours.0))
        }
        (1, i) if i + 1 == rec.len() => {
            ("the last row".to_string(), format!("the sample before ({}) and all the others", s.neighbours.0))
        }
        (1, i) => (format!("the row at time_s = {time} (sample {i} as read)"), neighbours(s)),
        (m, i) => {
            (format!("the {m} rows from time_s = {time} (samples {i}–{} as read)", i + m - 1), neighbours(s))
        }
    };
    format!(
        "`{name}` = {} in {rows} stands off {off} by over {SPIKE_CHANGES}× the local sample-to-sample change \
         ({:.3e}): {what} (a sensor over range, a lost sample), not the actuator, and it would set the NRMSE's \
         range (max − min) so that a wrong model scores as a right one{more}; {fix}, and run again",
        s.value, s.local_change
    )
}

/// What to do about `rows` bad rows amid a file: rows removed leave a gap in the time axis,
/// which `--resample` bridges only up to [`MAX_GAP_STEPS`] steps, so longer runs are replaced or
/// the file split there (advice that ends in a refusal is no advice).
fn bad_rows_fix(rows: usize) -> String {
    let bridged = rows as f64 + 1.0 <= MAX_GAP_STEPS;
    match rows {
        1 => "replace the value with its neighbours' mean (or remove the row and read the file with \
              `--resample linear`, which bridges the gap)"
            .to_string(),
        _ if bridged => "replace those values with a straight line between their neighbours (or remove the rows \
                         and read the file with `--resample linear`, which bridges the gap)"
            .to_string(),
        _ => format!(
            "replace those values with a straight line between their neighbours, or split the file there into \
             two recordings (removing the rows alone leaves a gap of {} steps in the time axis, beyond the \
             {MAX_GAP_STEPS} that `--resample` bridges)",
            rows + 1
        ),
    }
}

/// "both neighbours (a and b)".
fn neighbours(s: &Spike) -> String {
    format!("both neighbours ({} and {})", s.neighbours.0, s.neighbours.1)
}

/// The drive column the followers are judged against: the measured current, else the command.
fn drive_of(rec: &Recording) -> Option<(&'static str, &[f64])> {
    rec.current_a.as_deref().map(|c| ("current_A", c)).or(rec.command_v.as_deref().map(|c| ("command_V", c)))
}

/// Whether the drive stepped within [`STEP_LOOKBACK`] samples before `k` (or one after): a
/// change beyond [`DRIVE_STEP_CHANGES`] of its local change (a sine's largest is π/2 of it).
fn drive_stepped_near(drive: &[f64], k: usize, floor: f64) -> bool {
    let (from, to) = (k.saturating_sub(STEP_LOOKBACK).max(1), (k + 2).min(drive.len()));
    let local = local_change(drive, from, to, floor);
    (from..to).any(|j| (drive[j] - drive[j - 1]).abs() > DRIVE_STEP_CHANGES * local)
}

/// A follower whose level steps (one change beyond [`SPIKE_CHANGES`] local changes, not back)
/// where the drive did not step is refused, naming the row: a probe re-zeroed or knocked during
/// the file, which no actuator model follows; one that comes back within [`STEP_LOOKBACK`]
/// samples is said as a run off range (too long for a spike). The first [`STEP_LOOKBACK`] samples
/// are not judged.
fn level_steps(rec: &Recording) -> Result<()> {
    let Some((drive_name, drive)) = drive_of(rec) else { return Ok(()) };
    let (drive_lo, drive_hi) = bounds(drive);
    let drive_floor = SPIKE_FLOOR_OF_SPAN * (drive_hi - drive_lo);
    for name in FOLLOWERS {
        let Some(x) = rec.column(name) else { continue };
        let n = x.len();
        if n < 5 || drive.len() != n {
            continue;
        }
        let (lo, hi) = bounds(x);
        let floor = SPIKE_FLOOR_OF_SPAN * (hi - lo);
        // The first samples may hold a start transient (a delay line filling at the rest value, a
        // mode settling): judged from the lookback's end on.
        for k in STEP_LOOKBACK..n {
            let jump = (x[k] - x[k - 1]).abs();
            if jump <= SPIKE_CHANGES * floor {
                continue;
            }
            // Beyond the mean change around it, a slow channel's level tells a run that comes
            // back; a step found only by the line it breaks (a fast channel) by a sharp return.
            let by_level = jump > SPIKE_CHANGES * local_change(x, k, k, floor);
            if !by_level && !breaks_line(x, k, floor) {
                continue;
            }
            if drive_stepped_near(drive, k, drive_floor) {
                continue;
            }
            let time = rec.time_s[k];
            let beyond = if by_level {
                format!("over {SPIKE_CHANGES}× its local sample-to-sample change")
            } else {
                format!("off the line of its neighbouring changes by over {SPIKE_CHANGES}× the local departure from one")
            };
            if let Some(rows) = comes_back(x, k, by_level) {
                let last = k + rows - 1;
                return Err(InRecording::error(
                    &rec.name,
                    format!(
                        "`{name}` jumps from {} to {} at time_s = {time} (sample {k} as read) and comes back \
                         after {rows} rows (samples {k}–{last}), {beyond}, while `{drive_name}` did not step: a sensor over range or lost samples, not the \
                         actuator, and it would set the NRMSE's range (max − min) so that a wrong model scores \
                         as a right one; {}, and run again",
                        x[k - 1],
                        x[k],
                        bad_rows_fix(rows)
                    ),
                ));
            }
            return Err(InRecording::error(
                &rec.name,
                format!(
                    "`{name}` steps from {} to {} at time_s = {time} (sample {k} as read), {beyond}, \
                     and stays there, while `{drive_name}` did not step in \
                     the {STEP_LOOKBACK} samples before: a sensor re-zeroed or knocked during the file, not the \
                     actuator; split the file at that row (two recordings), or remove the step (subtract it from \
                     the rows after), and run again",
                    x[k - 1],
                    x[k]
                ),
            ));
        }
    }
    Ok(())
}

/// How far `x`'s change into `k` stands off the line of its neighbouring changes:
/// Δ_k − (Δ_{k−1} + Δ_{k+1})/2, a third difference for a smooth channel, the step for a step.
fn line_gap(x: &[f64], k: usize) -> f64 {
    (x[k] - x[k - 1]) - 0.5 * ((x[k - 1] - x[k - 2]) + (x[k + 1] - x[k]))
}

/// A level step too small against the mean change around it (a quarter of the range where a
/// fast sine moves a fiftieth a sample) still breaks the line its neighbouring changes draw:
/// its [`line_gap`] is over 3× either neighbouring change (a corner, where the drive turns, is
/// at most one of them) and over [`SPIKE_CHANGES`] times the mean gap around it, without the
/// three it touches (at least `floor`).
fn breaks_line(x: &[f64], k: usize, floor: f64) -> bool {
    if k < 3 || k + 2 >= x.len() {
        return false;
    }
    let gap = line_gap(x, k).abs();
    if gap <= 3.0 * (x[k - 1] - x[k - 2]).abs().max((x[k + 1] - x[k]).abs()) {
        return false;
    }
    let (lo, hi) = (k.saturating_sub(SPIKE_WINDOW).max(2), (k + SPIKE_WINDOW).min(x.len() - 2));
    let around = (lo..=hi).filter(|&j| j + 1 < k || j > k + 1).map(|j| line_gap(x, j).abs());
    let (sum, count) = around.fold((0.0, 0usize), |(s, c), g| (s + g, c + 1));
    gap > SPIKE_CHANGES * (sum / count.max(1) as f64).max(floor)
}

/// How many rows after `x` steps at `k` it comes back within [`STEP_LOOKBACK`] samples: a run
/// off range, not a level step. `by_level`: to its level before (within a quarter of the step),
/// which a slow channel's own moves do not reach; else (or also) by a change that breaks the
/// line of its neighbours the other way, by at least three quarters of the step's
/// ([`line_gap`]; the change after a step stands off by half of it, the way back by all).
fn comes_back(x: &[f64], k: usize, by_level: bool) -> Option<usize> {
    let (before, jump) = (x[k - 1], (x[k] - x[k - 1]).abs());
    let end = (k + STEP_LOOKBACK).min(x.len());
    let level = (k + 1..end).find(|&j| by_level && (x[j] - before).abs() < 0.25 * jump);
    let step_gap = line_gap(x, k);
    let sharp =
        (k + 2..end.min(x.len() - 1)).find(|&j| line_gap(x, j) * step_gap.signum() <= -0.75 * step_gap.abs());
    [level, sharp].into_iter().flatten().min().map(|j| j - k)
}

/// The runs of `x` at one exact value for [`STUCK_RUN`] samples and more while `reference`
/// crossed [`STUCK_DRIVE_SHARE`] of its span, or a tenth for a clip: a run at `x`'s range end
/// that `x` reached by a change under a twentieth of its span (a sensor saturating; a square
/// drive's level, reached by a step, is no clip). First run's index and value, runs, samples.
/// `clip_only`: only clips (a current clamp: the current stands still at a drive's hold).
fn stuck_runs(x: &[f64], reference: &[f64], clip_only: bool) -> Option<(usize, f64, usize, usize)> {
    let (lo, hi) = bounds(x);
    let (ref_lo, ref_hi) = bounds(reference);
    let (mut runs, mut samples, mut first) = (0usize, 0usize, None);
    let mut start = 0;
    for k in 1..=x.len() {
        if k < x.len() && x[k] == x[start] {
            continue;
        }
        let (r_lo, r_hi) = bounds(&reference[start..k]);
        let moved = |share: f64| r_hi - r_lo > share * (ref_hi - ref_lo);
        let clipped = (x[start] == lo || x[start] == hi)
            && start > 0
            && (x[start] - x[start - 1]).abs() < 0.05 * (hi - lo);
        // A clip's run, at a range end reached smoothly, needs only a tenth.
        let stuck = (!clip_only && moved(STUCK_DRIVE_SHARE)) || (clipped && moved(STUCK_DRIVE_SHARE / 2.5));
        if k - start >= STUCK_RUN && stuck {
            runs += 1;
            samples += k - start;
            first.get_or_insert((start, x[start]));
        }
        start = k;
    }
    first.map(|(at, value)| (at, value, runs, samples))
}

/// The runs of a follower at one exact value for [`STUCK_RUN`] samples and more while the drive
/// crossed [`STUCK_DRIVE_SHARE`] of its span, and of a measured current clipped at its range
/// end while the displacement crossed as much: a sensor clipped at its range or a frozen
/// converter. Said as a warning (the file may still be worth fitting where the channel moved).
pub fn stuck_channels(rec: &Recording) -> Vec<Warning> {
    let Some((drive_name, drive)) = drive_of(rec) else { return Vec::new() };
    // (channel, its values, the column it is judged against, that column's values, clip only)
    type Pair<'a> = (&'static str, &'a [f64], &'static str, &'a [f64], bool);
    let mut pairs: Vec<Pair> = FOLLOWERS
        .iter()
        .filter_map(|&name| rec.column(name).map(|x| (name, x.as_slice(), drive_name, drive, false)))
        .collect();
    if let (Some(i), Some(y)) = (rec.current_a.as_deref(), rec.displacement_um.as_deref()) {
        pairs.push(("current_A", i, "displacement_um", y, true));
    }
    let mut warnings = Vec::new();
    for (name, x, reference_name, reference, clip_only) in pairs {
        if x.len() != reference.len() || x.is_empty() {
            continue;
        }
        let (lo, hi) = bounds(x);
        if let Some((at, value, runs, samples)) = stuck_runs(x, reference, clip_only) {
            warnings.push(Warning::Data(DataDoubt::StuckChannel {
                file: rec.name.clone(),
                column: name,
                drive: reference_name,
                value,
                time_s: rec.time_s[at],
                runs,
                samples,
                at_range_end: value == lo || value == hi,
            }));
        }
    }
    warnings
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A noisy sine with an odd value somewhere (from a small deterministic generator).
    fn noisy_sine(n: usize, samples_per_period: f64, noise: f64) -> Vec<f64> {
        let mut state = 12345u64;
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..n)
            .map(|k| {
                let t = k as f64 / samples_per_period;
                20.0 + 15.0 * (2.0 * std::f64::consts::PI * t).sin()
                    + noise * (uniform() + uniform() + uniform())
            })
            .collect()
    }

    fn indices(found: &[Spike]) -> Vec<(usize, usize)> {
        found.iter().map(|s| (s.index, s.samples)).collect()
    }

    /// One over-range sample or one dropout to 0 in 10 000 is found at its index; the noisy
    /// recording without it, a sine sampled at a few samples a period, and a square wave whose
    /// steps are a sample long or ring for several samples are not.
    #[test]
    fn a_lone_spike_or_dropout_is_found_and_steps_and_noise_are_not() {
        let clean = noisy_sine(10_000, 50.0, 0.05);
        assert!(spikes(&clean).is_empty());
        // The dropout near a crest (k = 12.5 mod 50), where the signal is far from 0.
        for (at, bad) in [(5000, 9999.99), (5012, 0.0)] {
            let mut x = clean.clone();
            x[at] = bad;
            let found = spikes(&x);
            assert_eq!(indices(&found), vec![(at, 1)], "{bad}");
            assert_eq!(found[0].value, bad);
        }
        assert!(spikes(&noisy_sine(10_000, 4.0, 0.5)).is_empty());
        // A square drive: exact steps, then a displacement that rings after each (a mode at a
        // fifth of the sample rate, decaying over ~15 samples); a square at 1 kHz and 10 kHz
        // (five samples a half period).
        for half in [100, 5, 8] {
            let square: Vec<f64> = (0..4000).map(|k| if (k / half) % 2 == 0 { 0.0 } else { 2.0 }).collect();
            assert!(spikes(&square).is_empty(), "half period {half}: {:?}", spikes(&square).first());
        }
        let ringing: Vec<f64> = (0..4000)
            .map(|k| {
                let (level, since) = ((k / 100) % 2, (k % 100) as f64);
                let step = if level == 0 { -1.0 } else { 1.0 };
                let decay = (-since / 15.0).exp() * (2.0 * std::f64::consts::PI * since / 5.0).cos();
                10.0 * step * (1.0 - decay)
            })
            .collect();
        assert!(spikes(&ringing).is_empty(), "{:?}", spikes(&ringing).first());
    }

    /// Dropouts of 2 to 8 samples are one run each; a spike in the first or the last row is found
    /// as well, a first row that steps into the file's range is not.
    #[test]
    fn runs_and_end_rows_are_found() {
        let clean = noisy_sine(10_000, 50.0, 0.05);
        for len in [2, 3, 8] {
            let mut x = clean.clone();
            x[4012..4012 + len].fill(0.0);
            assert_eq!(indices(&spikes(&x)), vec![(4012, len)], "{len} samples");
        }
        for (at, bad) in [(0, 9999.0), (9999, -120.0), (9999, 9999.0)] {
            let mut x = clean.clone();
            x[at] = bad;
            assert_eq!(indices(&spikes(&x)), vec![(at, 1)], "{bad} at {at}");
        }
        // The rod before the drive's first value acted, a span off a sine offset to 20 ± 15.
        let mut x = clean.clone();
        x[0] = -30.0;
        assert!(spikes(&x).is_empty());
    }
}
