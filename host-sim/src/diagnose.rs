//! Diagnosis: fit the given structure, look at what it leaves unexplained, name the missing
//! physics, and prove it by refitting.
//!
//! 1. **Evidence** (a score test, per candidate effect): each missing effect, switched on
//!    weakly, changes the model output by a characteristic signature computed from the fitted
//!    model's own signals — a lag (eddy currents, amplifier, sensor delay) adds −τ·dy/dt;
//!    resonance adds −ÿ/ω_n²; hysteresis adds a branch-dependent term ∝ sign(dH/dt);
//!    saturation a cubic term in the field excursion; creep lowpass(y) − y; coil heating the
//!    accumulated ∫i² dt. The share of residual variance each signature explains (R², pooled
//!    over the files) is its evidence score. Lags share a first-order signature, so the evidence
//!    alone cannot tell eddy currents, amplifier and delay apart: the refit does.
//! 2. **Trends across files**: error against excitation frequency, amplitude and record length.
//! 3. **Refit**: the structure plus each candidate, identified again (warm start), scored on the
//!    validation files (fit files when there are none). The verdict is the candidate that is
//!    indicated and cuts the error at least [`MIN_CUT`]×; null when none does. When refits tie,
//!    the data cannot separate the effects: the diagnosis says so and names the stage nearest
//!    the drive.

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{bail, Result};
use model_core::effects::{Candidacy, Signature, Stage};
use model_core::{Effect, ModelSpec};
use rayon::prelude::*;
use serde::Serialize;

use crate::fit::{self, evaluate, simulate, FitOptions, FitResult, Simulation};
use crate::progress;
use crate::recording::Recording;

/// A candidate must cut the validation NRMSE at least this much to be the verdict.
pub const MIN_CUT: f64 = 1.5;
/// A candidate's signature must explain at least this share of the residual variance to count
/// as indicated (unless its refit cuts the error 3× or more).
pub const MIN_EVIDENCE_R2: f64 = 0.02;
/// Two candidates whose refits end within this factor of each other are not separated.
const SAME_CUT: f64 = 1.15;

/// Fewest samples per fit file for a verdict: the refits have up to about ten parameters, and
/// comparing them needs far more samples than parameters (20 per parameter).
pub const MIN_SAMPLES: usize = 200;

/// One candidate effect, as the JSON contract lists it.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// The effect (its name in JSON).
    pub effect: Effect,
    /// `displacement` (or `current`).
    pub channel: &'static str,
    /// Combined score in [0, 1]: evidence R² and the refit's error cut.
    pub score: f64,
    /// The evidence in words.
    pub evidence: String,
    /// Validation NRMSE of the given structure.
    pub nrmse_before: f64,
    /// Validation NRMSE with this effect added and refitted.
    pub nrmse_after: f64,
    /// Share of residual variance the effect's signature explains.
    pub evidence_r2: f64,
    /// Identified parameters of the refit.
    #[serde(skip)]
    pub refit: Option<FitResult>,
}

/// The whole diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// The structure as given.
    pub model: String,
    /// Its fit NRMSE (mean over fit files).
    pub nrmse_fit: f64,
    /// Its validation NRMSE, when validation files were given.
    pub nrmse_val: Option<f64>,
    /// Candidates, most likely first.
    pub candidates: Vec<Candidate>,
    /// The missing effect, or null.
    pub verdict: Option<Effect>,
    /// Effects the evidence could not separate from the verdict.
    pub undistinguished: Vec<Effect>,
    /// Residual whiteness, trends across files: findings in words.
    pub findings: Vec<String>,
    /// The fit of the given structure.
    #[serde(skip)]
    pub baseline: Option<FitResult>,
    /// `--time-limit` cut the work short: the baseline or some refits are the best found so
    /// far, and candidates not refitted in time are left out.
    #[serde(rename = "time_limit_reached")]
    pub time_limited: bool,
}

/// The diagnosis in words (`--json` gives the same as one object).
impl std::fmt::Display for Diagnosis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "model `{}`: fit NRMSE {:.3} %{}",
            self.model,
            self.nrmse_fit * 100.0,
            self.nrmse_val.map(|v| format!(", validation {:.3} %", v * 100.0)).unwrap_or_default()
        )?;
        for finding in &self.findings {
            writeln!(f, "  - {finding}")?;
        }
        writeln!(f, "  candidates (most likely first):")?;
        for c in &self.candidates {
            writeln!(
                f,
                "    {:22} score {:.2}  {:.2} % → {:.2} %  {}",
                c.effect,
                c.score,
                c.nrmse_before * 100.0,
                c.nrmse_after * 100.0,
                c.evidence
            )?;
        }
        match self.verdict {
            Some(v) => write!(
                f,
                "verdict: `{v}` is missing — try `--model {}+{}`",
                self.model,
                v.alias().unwrap_or(v.name())
            ),
            None => write!(f, "verdict: nothing significant is missing"),
        }
    }
}

/// The effects worth trying on top of `spec` for these files (the registry's candidacy).
pub fn candidates_for(spec: ModelSpec, files: &[Recording]) -> Vec<Effect> {
    let all_have_command = files.iter().all(|f| f.command_v.is_some());
    Effect::ALL
        .into_iter()
        .filter(|&e| !spec.has(e))
        .filter(|&e| match e.info().candidacy {
            Candidacy::Always => true,
            Candidacy::NeedsCommand => all_have_command,
            Candidacy::RefinesLaw => e.info().law.is_some_and(|l| l.refines(spec.law())),
            Candidacy::Never => false,
        })
        .collect()
}

/// Signals of one file under the baseline model, for the signatures.
struct Signals {
    residual: Vec<f64>,
    rate: Vec<f64>,
    accel: Vec<f64>,
    branch: Vec<f64>,
    cubic: Vec<f64>,
    creep: Vec<f64>,
    heat: Vec<f64>,
}

fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (x[b] - x[a]) / ((b - a).max(1) as f64 * dt)
        })
        .collect()
}

fn lowpass(x: &[f64], dt: f64, tau: f64) -> Vec<f64> {
    let p = (-dt / tau).exp();
    let mut y = x[0];
    x.iter()
        .map(|&v| {
            y = p * y + (1.0 - p) * v;
            y
        })
        .collect()
}

fn signals(rec: &Recording, sim: &Simulation, offset: f64) -> Signals {
    let dt = rec.dt_s();
    let meas = rec.displacement_um.as_deref().unwrap_or_default();
    let residual: Vec<f64> = meas.iter().zip(&sim.displacement_um).map(|(m, y)| m - y - offset).collect();
    let y = &sim.displacement_um;
    let rate = derivative(y, dt);
    let accel = derivative(&rate, dt);
    let h = &sim.field_a_per_m;
    let dh = derivative(h, dt);
    let hscale = dh.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    // Smooth sign of dH/dt: the branch the rod is on.
    let branch: Vec<f64> = dh.iter().map(|v| (v / (0.05 * hscale)).tanh()).collect();
    let hmean = h.iter().sum::<f64>() / h.len() as f64;
    let cubic: Vec<f64> = h.iter().map(|v| (v - hmean).powi(3)).collect();
    let creep = lowpass(y, dt, 0.05).iter().zip(y).map(|(l, v)| l - v).collect();
    let mut acc = 0.0;
    let heat = sim
        .current_a
        .iter()
        .map(|i| {
            acc += i * i * dt;
            acc
        })
        .collect();
    Signals { residual, rate, accel, branch, cubic, creep, heat }
}

/// R² of the least-squares fit of `r` by `a·f + b` (one regressor and a constant).
fn r2(r: &[f64], f: &[f64]) -> f64 {
    let n = r.len() as f64;
    let (mr, mf) = (r.iter().sum::<f64>() / n, f.iter().sum::<f64>() / n);
    let (mut sff, mut srf, mut srr) = (0.0, 0.0, 0.0);
    for (a, b) in r.iter().zip(f) {
        sff += (b - mf) * (b - mf);
        srf += (a - mr) * (b - mf);
        srr += (a - mr) * (a - mr);
    }
    if sff <= 0.0 || srr <= 0.0 {
        0.0
    } else {
        (srf * srf / (sff * srr)).clamp(0.0, 1.0)
    }
}

/// Pooled evidence R² of `effect`'s signature over the files (variance-weighted mean).
fn evidence(effect: Effect, sigs: &[Signals]) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for s in sigs {
        let var = s.residual.iter().map(|v| v * v).sum::<f64>();
        let score = match effect.info().signature {
            Signature::Lag => r2(&s.residual, &s.rate),
            Signature::Resonance => r2(&s.residual, &s.accel).max(r2(&s.residual, &s.rate)),
            Signature::Branch => r2(&s.residual, &s.branch),
            Signature::Cubic => r2(&s.residual, &s.cubic),
            Signature::Creep => r2(&s.residual, &s.creep),
            Signature::Heating => r2(&s.residual, &s.heat),
            Signature::None => 0.0,
        };
        num += score * var;
        den += var;
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

fn signature_words(signature: Signature) -> &'static str {
    match signature {
        Signature::Lag => "the lag signature −dy/dt (shared by every lag: rod, amplifier, sensor)",
        Signature::Resonance => "the resonance signature −ÿ (and −dy/dt)",
        Signature::Branch => "the branch sign(dH/dt) (loop opening)",
        Signature::Cubic => "the cubic field excursion (H − H̄)³",
        Signature::Creep => "the creep signature lowpass(y) − y",
        Signature::Heating => "the accumulated coil heating ∫i² dt",
        Signature::None => "—",
    }
}

/// Dominant frequency of a drive (zero crossings of its AC part) [Hz] and its rms amplitude.
fn drive_stats(rec: &Recording) -> (f64, f64) {
    let u = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    let rms = (u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / u.len() as f64).sqrt();
    let crossings = u.windows(2).filter(|w| (w[0] - mean) * (w[1] - mean) < 0.0).count();
    (crossings as f64 / 2.0 / rec.duration_s().max(1e-12), rms)
}

/// Residual whiteness: share of autocorrelation lags 1–20 outside the 95 % band, pooled.
fn whiteness(sigs: &[Signals]) -> f64 {
    let mut outside = 0usize;
    let mut total = 0usize;
    for s in sigs {
        let r = &s.residual;
        let n = r.len();
        let m = r.iter().sum::<f64>() / n as f64;
        let c0: f64 = r.iter().map(|v| (v - m).powi(2)).sum();
        if c0 <= 0.0 {
            continue;
        }
        let band = 1.96 / (n as f64).sqrt();
        for lag in 1..=20.min(n - 1) {
            let c: f64 = (lag..n).map(|k| (r[k] - m) * (r[k - lag] - m)).sum();
            total += 1;
            if (c / c0).abs() > band {
                outside += 1;
            }
        }
    }
    outside as f64 / total.max(1) as f64
}

/// Direction reversals of `x`, ignoring wiggles below 10 % of its span (noise).
pub fn reversals(x: &[f64]) -> usize {
    let (lo, hi) = x.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let band = 0.1 * (hi - lo);
    let (mut n, mut dir, mut extreme) = (0, 0.0, x.first().copied().unwrap_or(0.0));
    for &v in x {
        let d = v - extreme;
        if dir == 0.0 {
            if d.abs() > band {
                dir = d.signum();
                extreme = v;
            }
        } else if d * dir > 0.0 {
            extreme = v;
        } else if -d * dir > band {
            n += 1;
            dir = -dir;
            extreme = v;
        }
    }
    n
}

/// Diagnoses `spec` on `fit_files` (scored on `val_files` when given).
pub fn diagnose(
    spec: ModelSpec,
    init: &model_core::ActuatorParams,
    fit_files: &[Recording],
    val_files: &[Recording],
    opts: FitOptions,
) -> Result<Diagnosis> {
    for rec in fit_files {
        let drive = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
        let n = reversals(drive);
        if n < 2 {
            bail!(
                "{}: the drive covers less than one cycle ({n} reversal{} in {:.1} ms): a diagnosis compares \
                 both branches of the loop, so record at least one full period of the excitation",
                rec.name,
                if n == 1 { "" } else { "s" },
                rec.duration_s() * 1e3
            );
        }
        if rec.len() < MIN_SAMPLES {
            bail!(
                "{}: {} samples; a diagnosis compares models with up to about ten parameters and needs at \
                 least {MIN_SAMPLES} samples per file",
                rec.name,
                rec.len()
            );
        }
    }
    progress::phase(opts.progress, &format!("diagnose: fitting the given model `{spec}`"));
    let base = fit::fit(spec, init, fit_files, opts)?;
    let mut time_limited = base.time_limited;
    let score_files = if val_files.is_empty() { fit_files } else { val_files };
    let before = evaluate(spec, &base.params, score_files)?.mean_nrmse();
    let nrmse_val = if val_files.is_empty() { None } else { Some(before) };

    // Evidence on the fit files' residuals.
    let evidence_phase =
        progress::Phase::start(opts.progress, "diagnose: residual evidence and trends across files", 0);
    let sigs: Vec<Signals> = fit_files
        .iter()
        .zip(&base.fit.files)
        .map(|(rec, sc)| Ok(signals(rec, &simulate(spec, &base.params, rec)?, sc.offset_um)))
        .collect::<Result<_>>()?;
    let mut findings = Vec::new();
    let white = whiteness(&sigs);
    findings.push(if white > 0.2 {
        format!(
            "residual is not white: {:.0} % of autocorrelation lags 1–20 lie outside the 95 % band (something systematic is left)",
            white * 100.0
        )
    } else {
        format!("residual is close to white: {:.0} % of lags 1–20 outside the 95 % band", white * 100.0)
    });
    let mut per_file: Vec<(f64, f64, f64, f64)> = Vec::new(); // freq, amplitude, duration, nrmse
    let all_files: Vec<&Recording> = fit_files.iter().chain(val_files).collect();
    let all_scores =
        evaluate(spec, &base.params, &all_files.iter().map(|r| (*r).clone()).collect::<Vec<_>>())?;
    for (rec, sc) in all_files.iter().zip(&all_scores.files) {
        let (f, a) = drive_stats(rec);
        per_file.push((f, a, rec.duration_s(), sc.nrmse));
    }
    let trend = |key: fn(&(f64, f64, f64, f64)) -> f64, what: &str, unit: &str| -> Option<String> {
        let mut v = per_file.clone();
        v.sort_by(|a, b| key(a).total_cmp(&key(b)));
        let (lo, hi) = (v.first()?, v.last()?);
        if key(hi) <= 1.5 * key(lo) {
            return None;
        }
        let ratio = hi.3 / lo.3.max(1e-12);
        (!(0.67..=1.5).contains(&ratio)).then(|| {
            format!(
                "error {} with {what}: {:.2} % at {:.3} {unit} → {:.2} % at {:.3} {unit}",
                if ratio > 1.0 { "grows" } else { "falls" },
                lo.3 * 100.0,
                key(lo),
                hi.3 * 100.0,
                key(hi)
            )
        })
    };
    findings.extend(trend(|r| r.0, "excitation frequency", "Hz"));
    findings.extend(trend(|r| r.1, "drive amplitude (rms)", "A or V"));
    findings.extend(trend(|r| r.2, "record length", "s"));
    evidence_phase.finish();

    // Refit every candidate (in parallel), warm-started from the baseline.
    let cands = candidates_for(spec, fit_files);
    let refit_opts = FitOptions { progress: false, ..opts };
    let refitting = progress::Phase::start(
        opts.progress,
        &format!("diagnose: refitting `{spec}` plus each of {} candidate effects", cands.len()),
        cands.len() as u64,
    );
    let done = AtomicUsize::new(0);
    // Per candidate: its refit and validation NRMSE, or None when the time limit left it out.
    type Refit = Option<Result<(FitResult, f64)>>;
    let results: Vec<(Effect, Refit)> = cands
        .par_iter()
        .map(|&e| {
            // Past the deadline a candidate is not refitted at all (and said so).
            if fit::time_left(opts.deadline).is_some_and(|t| t.is_zero()) {
                return (e, None);
            }
            let s2 = spec.with(e);
            // Warm start from the baseline, and from the engineer's start values: a baseline that
            // bent its parameters to mimic the missing effect can be a poor start.
            let r = fit::fit_from(s2, &[base.params, *init], fit_files, refit_opts)
                .and_then(|f| Ok((evaluate(s2, &f.params, score_files)?.mean_nrmse(), f)))
                .map(|(after, f)| (f, after));
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            let note = match &r {
                Ok((_, after)) => {
                    format!(
                        "diagnose: refit {k}/{} done: `+{}` {:.2} %",
                        cands.len(),
                        e.name(),
                        after * 100.0
                    )
                }
                Err(_) => String::new(),
            };
            refitting.step(&note);
            (e, Some(r))
        })
        .collect();
    refitting.finish();
    let mut candidates = Vec::new();
    let mut skipped = Vec::new();
    for (e, r) in results {
        let Some(r) = r else {
            skipped.push(e.name());
            continue;
        };
        if let Ok((f, _)) = &r {
            time_limited |= f.time_limited;
        }
        let r2 = evidence(e, &sigs);
        let (refit, after) = match r {
            Ok((f, after)) => (Some(f), after),
            Err(_) => (None, before),
        };
        let cut = if before > 0.0 && after > 0.0 { before / after } else { 1.0 };
        let evidence = format!(
            "{} explains {:.0} % of the residual variance; adding it and refitting takes the {} NRMSE from {:.2} % to {:.2} % ({:.1}× {})",
            signature_words(e.info().signature),
            r2 * 100.0,
            if val_files.is_empty() { "fit" } else { "validation" },
            before * 100.0,
            after * 100.0,
            if cut >= 1.0 { cut } else { 1.0 / cut },
            if cut >= 1.0 { "lower" } else { "higher" },
        );
        let score = (0.5 * r2 + 0.5 * (1.0 - after / before).max(0.0)).clamp(0.0, 1.0);
        candidates.push(Candidate {
            effect: e,
            channel: "displacement",
            score,
            evidence,
            nrmse_before: before,
            nrmse_after: after,
            evidence_r2: r2,
            refit,
        });
    }
    candidates.sort_by(|a, b| {
        a.nrmse_after.total_cmp(&b.nrmse_after).then(b.evidence_r2.total_cmp(&a.evidence_r2))
    });
    let mut verdict = None;
    let mut undistinguished = Vec::new();
    if let Some(best) = candidates.first().cloned() {
        let cut = best.nrmse_before / best.nrmse_after.max(1e-12);
        // Indicated: its signature explains part of the residual, or the refit is decisive.
        let indicated = best.evidence_r2 >= MIN_EVIDENCE_R2 || cut >= 3.0;
        if cut >= MIN_CUT && indicated {
            // Refits that end within SAME_CUT of the best are not separated by these data; name
            // the one nearest the drive in the chain (e.g. with only a command recorded, an
            // amplifier lag and an eddy-current lag are the same lag between command and field).
            let tied: Vec<usize> = (0..candidates.len())
                .filter(|&i| candidates[i].nrmse_after <= SAME_CUT * best.nrmse_after)
                .collect();
            let order = |e: Effect| Effect::ALL.iter().position(|x| *x == e).unwrap_or(usize::MAX);
            let chosen = tied.iter().copied().min_by_key(|&i| order(candidates[i].effect)).unwrap_or(0);
            let pick = candidates.remove(chosen);
            candidates.insert(0, pick);
            verdict = Some(candidates[0].effect);
            undistinguished = candidates[1..]
                .iter()
                .filter(|c| c.nrmse_after <= SAME_CUT * best.nrmse_after)
                .map(|c| c.effect)
                .collect();
            if !undistinguished.is_empty() {
                let hint = if candidates[0].effect.info().stage == Stage::Amplifier {
                    " (record `current_A` to tell the amplifier from the rod)"
                } else {
                    " (excite more frequencies or record more channels to separate them)"
                };
                findings.push(format!(
                    "the data do not separate `{}` from `{}`: their refits end within {:.0} % of each other; the verdict names the stage nearest the drive{hint}",
                    candidates[0].effect,
                    undistinguished.iter().map(|e| e.name()).collect::<Vec<_>>().join("`, `"),
                    (SAME_CUT - 1.0) * 100.0
                ));
            }
        } else if cut >= MIN_CUT {
            findings.push(format!(
                "`{}` cuts the error {cut:.1}× but its signature explains only {:.1} % of the residual: not indicated, no verdict",
                best.effect,
                best.evidence_r2 * 100.0
            ));
        } else {
            findings.push(format!(
                "no candidate cuts the error {MIN_CUT}× or more (best: `{}`, {:.2} % → {:.2} %): nothing missing is significant",
                best.effect,
                best.nrmse_before * 100.0,
                best.nrmse_after * 100.0
            ));
        }
    }
    if !skipped.is_empty() {
        time_limited = true;
        findings.push(format!(
            "--time-limit reached: `{}` not refitted; the verdict weighs only the candidates refitted in time",
            skipped.join("`, `")
        ));
    }
    Ok(Diagnosis {
        time_limited,
        model: spec.to_string(),
        nrmse_fit: base.fit.mean_nrmse(),
        nrmse_val,
        candidates,
        verdict,
        undistinguished,
        findings,
        baseline: Some(base),
    })
}
