//! Fitting a magnetization model of model-core (the same code the firmware runs) to a loop file,
//! along the file's own field path.

use anyhow::{bail, Result};
use model_core::magnetization::{
    Anhysteretic, AnhystereticParams, JaParams, JaState, JaVariant, JilesAtherton, LinearMagnetization,
    Preisach, PreisachParams, MAX_SUBSTEPS,
};
use model_core::{ActuatorParams, MagnetizationLaw, ModelSpec};

use crate::fit::StartScore;
use crate::loops::{clockwise, features, field_in_kilo, off_centre, LoopFile};
use crate::progress::Progress;
use crate::search::{minimize, Bound, Fidelity, Local, Plan, SearchOptions, Start};
use crate::warning::Warning;

/// The loop fit's search: two swarms (seeds `seed`, `seed + 1`), each best refined by a 5 % and
/// a 1 % simplex on every point.
const PLAN: Plan = Plan {
    particles: (10, 4),
    swarm_iters: 25.0,
    swarms: 2,
    simplex_iters_per_dim: 80.0,
    local_searches: 2,
    finalists: 2,
    local: &[Local::Simplex(0.05, Fidelity::Full), Local::Simplex(0.01, Fidelity::Full)],
    tolerance: (1e-7, 1e-20),
};

/// The magnetization model a loop fit identifies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LoopModel {
    /// M = a + bH.
    Linear,
    /// Langevin.
    Anhysteretic,
    /// Jiles–Atherton, in one of its variants.
    JilesAtherton(JaVariant),
    /// Preisach.
    Preisach,
}

/// |α| from which a J–A loop fit is said to be at the model's limit |α| < 1.
const ALPHA_LIMIT_WARNING: f64 = 0.999;

/// Largest saturation magnetization of any bulk material [A/m]: Fe–Co alloys, μ0 M_s ≈ 2.45 T.
/// The loop fit's M_s range ends here (or at 1.5× the file's largest |M| if a file exceeds it).
pub const MAX_SATURATION_A_PER_M: f64 = 1.95e6;

/// The J–A mean-field ratio α·M_s/(3a) the loop fit searches, instead of α: below 1 the
/// anhysteretic curve is single-valued (the physics limit, whatever the material's scale), and
/// down to −1 a negative α (002) may at most halve the initial susceptibility.
const MEAN_FIELD_RATIO: (f64, f64) = (-1.0, 0.99);

impl LoopModel {
    /// From a model spec (only the magnetization stage counts) and the parameter set that says
    /// which J–A variant.
    pub fn from_spec(spec: ModelSpec, params: &ActuatorParams) -> Result<Self> {
        if let Some(e) = spec.effects().find(|e| e.info().law.is_none()) {
            bail!(
                "a magnetization loop fits the magnetization stage only; `{e}` needs displacement recordings"
            );
        }
        Ok(match spec.law() {
            MagnetizationLaw::Linear => LoopModel::Linear,
            MagnetizationLaw::Anhysteretic => LoopModel::Anhysteretic,
            MagnetizationLaw::JilesAtherton => LoopModel::JilesAtherton(params.ja.variant),
            MagnetizationLaw::Preisach => LoopModel::Preisach,
        })
    }

    /// This model's parameters in a parameter set, in the order of its bounds (the inverse of
    /// [`LoopFit::apply_to`]).
    pub fn values_of(self, p: &ActuatorParams) -> Vec<f64> {
        let v: Vec<f32> = match self {
            LoopModel::Linear => vec![p.linear.offset_a_per_m, p.linear.susceptibility],
            LoopModel::Anhysteretic => vec![p.anhysteretic.ms_a_per_m, p.anhysteretic.a_a_per_m],
            LoopModel::JilesAtherton(_) => {
                let j = p.ja;
                vec![j.ms_a_per_m, j.a_a_per_m, j.alpha, j.k_a_per_m, j.c]
            }
            LoopModel::Preisach => {
                let q = p.preisach;
                let su = q.interaction_spread_a_per_m.unwrap_or(q.spread_a_per_m);
                vec![
                    q.ms_a_per_m,
                    q.coercive_a_per_m,
                    q.spread_a_per_m,
                    su,
                    q.h_max_a_per_m,
                    q.reversible_fraction_or_default(),
                    q.reversible_field_or_default(),
                ]
            }
        };
        v.into_iter().map(f64::from).collect()
    }

    /// The search's parameter names and bounds, given the loop's field and magnetization scale.
    /// M_s lies between the largest measured |M| (less 10 % for noise) and the largest
    /// saturation of any material; J–A searches the mean-field ratio α·M_s/(3a) in
    /// [`MEAN_FIELD_RATIO`] instead of α, so no point of its box is multivalued. The field
    /// scales (a, k, the Preisach fields) span the data's range and the model's own limits.
    fn bounds(self, h_max: f64, m_max: f64) -> Vec<Bound> {
        // Within what the models accept (a weak sample's M_s below theirs is held at their floor,
        // a loop far from saturation, and said as a parameter at its range's end).
        let (ms_min, ms_max) = (f64::from(model_core::error::MS_MIN), f64::from(model_core::error::MS_MAX));
        let ms = Bound::log(
            "ms_a_per_m",
            (0.9 * m_max).clamp(ms_min, 0.5 * ms_max),
            MAX_SATURATION_A_PER_M.max(1.5 * m_max).min(ms_max),
        );
        let field = |name, lo: f64, hi: f64| Bound::log(name, lo.max(1.0), hi.max(10.0));
        match self {
            LoopModel::Linear => {
                vec![Bound::lin("offset_a_per_m", -m_max, m_max), Bound::log("susceptibility", 1e-3, 1e6)]
            }
            LoopModel::Anhysteretic => vec![ms, field("a_a_per_m", 1e-4 * h_max, 10.0 * h_max)],
            LoopModel::JilesAtherton(v) => vec![
                ms,
                field("a_a_per_m", 1e-4 * h_max, 10.0 * h_max),
                Bound::lin("mean_field_ratio", MEAN_FIELD_RATIO.0, MEAN_FIELD_RATIO.1),
                field("k_a_per_m", 1e-4 * h_max, 5.0 * h_max),
                // The total-magnetization form weighs reversibility by c/(1 + c): c near 1 is common.
                Bound::lin("c", 0.0, if v.is_total_magnetization() { 0.9999 } else { 0.99 }),
            ],
            LoopModel::Preisach => vec![
                ms,
                field("coercive_a_per_m", 1e-3 * h_max, 0.8 * h_max),
                field("spread_a_per_m", 1e-3 * h_max, 2.0 * h_max),
                field("interaction_spread_a_per_m", 1e-3 * h_max, 2.0 * h_max),
                // The relay plane's range is the field where the material saturates, which can lie
                // well inside the measured range (hard magnets): fitted, since the fixed grid's
                // resolution is 2·H_max/31 and a plane wider than needed blurs the switching.
                Bound::log("h_max_a_per_m", 0.2 * h_max, 1.05 * h_max),
                // The reversible part: what moves at once after a reversal (ferrites, soft steel).
                Bound::lin("reversible_fraction", 0.0, 0.9),
                field("reversible_field_a_per_m", 1e-3 * h_max, 2.0 * h_max),
            ],
        }
    }

    /// The model's parameters (as [`run`] takes them) from the search's: J–A's α from the ratio.
    fn model_values(self, v: &[f64]) -> Vec<f64> {
        match self {
            LoopModel::JilesAtherton(_) => vec![v[0], v[1], 3.0 * v[1] * v[2] / v[0], v[3], v[4]],
            _ => v.to_vec(),
        }
    }

    /// The search's parameters from the model's (the inverse of `model_values`).
    fn search_values(self, v: &[f64]) -> Vec<f64> {
        match self {
            LoopModel::JilesAtherton(_) => vec![v[0], v[1], v[2] * v[0] / (3.0 * v[1]), v[3], v[4]],
            _ => v.to_vec(),
        }
    }

    /// A start read off the loops' shape (search parameters), as Jiles, Thoelke & Devine (1992)
    /// seed J–A from measured loop features: M_s just above the largest |M|, the pinning k at
    /// the coercivity and a at the field of half the largest |M|, a middling mean-field ratio and
    /// reversibility. `None` for other models or loops that show no coercivity.
    fn start_from_features(self, files: &[LoopFile]) -> Option<Vec<f64>> {
        if !matches!(self, LoopModel::JilesAtherton(_)) {
            return None;
        }
        let f = files.first()?;
        let m = f.magnetization();
        let feat = features(&f.h, &m);
        let m_max = feat.max_magnetization_a_per_m;
        let h_half =
            f.h.iter()
                .zip(&m)
                .filter(|(_, m)| m.abs() >= 0.5 * m_max)
                .map(|(h, _)| h.abs())
                .fold(f64::INFINITY, f64::min);
        let hc = feat.coercivity_a_per_m;
        (hc.is_finite() && hc > 0.0 && h_half.is_finite() && h_half > 0.0)
            .then(|| vec![1.05 * m_max, h_half, 0.5, hc, 0.2])
    }

    /// The model's parameter names, in [`run`]'s order.
    fn names(self) -> &'static [&'static str] {
        match self {
            LoopModel::Linear => &["offset_a_per_m", "susceptibility"],
            LoopModel::Anhysteretic => &["ms_a_per_m", "a_a_per_m"],
            LoopModel::JilesAtherton(_) => &["ms_a_per_m", "a_a_per_m", "alpha", "k_a_per_m", "c"],
            LoopModel::Preisach => &[
                "ms_a_per_m",
                "coercive_a_per_m",
                "spread_a_per_m",
                "interaction_spread_a_per_m",
                "h_max_a_per_m",
                "reversible_fraction",
                "reversible_field_a_per_m",
            ],
        }
    }
}

/// Why a model run along a path is not a valid result.
#[derive(Debug, Clone, PartialEq)]
pub struct RunError(pub String);

/// The model's magnetization along the file's field path. The rod starts demagnetised at
/// H = 0, follows the initial curve to the first point, then the path; a closed path (ends
/// where it starts) is run twice and the second pass returned (the loop's steady state).
pub fn run(model: LoopModel, p: &[f64], h: &[f64], h_max: f64) -> Result<Vec<f64>, RunError> {
    let closed = (h[0] - h[h.len() - 1]).abs() <= 0.02 * h_max;
    let lead: Vec<f64> = (1..=50).map(|k| h[0] * k as f64 / 50.0).collect();
    let passes = if closed { 2 } else { 1 };
    let path = lead.iter().chain((0..passes).flat_map(|_| h.iter()));
    let mut out = Vec::with_capacity(lead.len() + passes * h.len());
    match model {
        LoopModel::Linear => {
            let lm =
                LinearMagnetization::new(p[0] as f32, p[1] as f32).map_err(|e| RunError(e.to_string()))?;
            out.extend(path.map(|&x| lm.magnetization(x as f32) as f64));
        }
        LoopModel::Anhysteretic => {
            let an =
                Anhysteretic::new(AnhystereticParams { ms_a_per_m: p[0] as f32, a_a_per_m: p[1] as f32 })
                    .map_err(|e| RunError(e.to_string()))?;
            out.extend(path.map(|&x| an.magnetization(x as f32) as f64));
        }
        LoopModel::JilesAtherton(variant) => {
            let jp = JaParams {
                ms_a_per_m: p[0] as f32,
                a_a_per_m: p[1] as f32,
                alpha: p[2] as f32,
                k_a_per_m: p[3] as f32,
                c: p[4] as f32,
                variant,
            };
            let ja = JilesAtherton::new(jp).map_err(|e| RunError(e.to_string()))?;
            let mut s = JaState::default();
            // A loop file's points are far apart next to a small a or k: step the field between
            // them in legs of at most a quarter of what one J–A call integrates to its accuracy
            // (the mean field can lengthen the effective step), so the sub-step cap never cuts
            // the integration short and no fit can profit from an unresolved loop.
            let leg = 0.25 * MAX_SUBSTEPS as f64 * ja.max_substep_a_per_m() as f64;
            let mut last = 0.0f64;
            out.extend(path.map(|&x| {
                let legs = ((x - last).abs() / leg).ceil().clamp(1.0, 1e6) as u32;
                for j in 1..legs {
                    ja.step(&mut s, (last + (x - last) * j as f64 / legs as f64) as f32);
                }
                last = x;
                ja.step(&mut s, x as f32) as f64
            }));
        }
        LoopModel::Preisach => {
            let pr = Preisach::new(PreisachParams {
                ms_a_per_m: p[0] as f32,
                coercive_a_per_m: p[1] as f32,
                spread_a_per_m: p[2] as f32,
                interaction_spread_a_per_m: Some(p[3] as f32),
                reversible_fraction: Some(p[5] as f32),
                reversible_field_a_per_m: Some(p[6] as f32),
                h_max_a_per_m: p[4] as f32,
            })
            .map_err(|e| RunError(e.to_string()))?;
            let mut s = pr.demagnetized();
            out.extend(path.map(|&x| pr.step(&mut s, x as f32) as f64));
        }
    }
    let tail = out.split_off(out.len() - h.len());
    if tail.iter().any(|v| !v.is_finite()) {
        return Err(RunError("the integration produced a non-finite magnetization".into()));
    }
    Ok(tail)
}

/// rms(a − b) / (max − min of a).
pub(crate) fn nrmse(a: &[f64], b: &[f64]) -> f64 {
    crate::score::nrmse(a, b)
}

/// A loop fit's outcome.
#[derive(Debug, Clone)]
pub struct LoopFit {
    /// The model.
    pub model: LoopModel,
    /// Identified (name, value).
    pub params: Vec<(&'static str, f64)>,
    /// NRMSE per file on its own channel.
    pub nrmse: Vec<f64>,
    /// Objective evaluations.
    pub evaluations: usize,
    /// Doubts about the result; those that [`Warning::invalidates`] make it invalid (no
    /// parameter file may be written from it).
    pub warnings: Vec<Warning>,
    /// The search stopped at `--time-limit`: the best point so far.
    pub time_limited: bool,
    /// How the start values scored, and whether they were returned.
    pub start: StartScore,
}

impl LoopFit {
    /// The identified values in order.
    pub fn values(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.1).collect()
    }

    /// The parameter set with this fit's magnetization model written in (`M_s` also normalises
    /// the magnetostriction), to seed a displacement fit.
    pub fn apply_to(&self, base: &ActuatorParams) -> ActuatorParams {
        let mut p = *base;
        let v = self.values();
        match self.model {
            LoopModel::Linear => {
                p.linear.offset_a_per_m = v[0] as f32;
                p.linear.susceptibility = v[1] as f32;
            }
            LoopModel::Anhysteretic => {
                p.anhysteretic = AnhystereticParams { ms_a_per_m: v[0] as f32, a_a_per_m: v[1] as f32 };
            }
            LoopModel::JilesAtherton(variant) => {
                p.ja = JaParams {
                    ms_a_per_m: v[0] as f32,
                    a_a_per_m: v[1] as f32,
                    alpha: v[2] as f32,
                    k_a_per_m: v[3] as f32,
                    c: v[4] as f32,
                    variant,
                };
            }
            LoopModel::Preisach => {
                p.preisach.ms_a_per_m = v[0] as f32;
                p.preisach.coercive_a_per_m = v[1] as f32;
                p.preisach.spread_a_per_m = v[2] as f32;
                p.preisach.interaction_spread_a_per_m = Some(v[3] as f32);
                p.preisach.h_max_a_per_m = v[4] as f32;
                p.preisach.reversible_fraction = Some(v[5] as f32);
                p.preisach.reversible_field_a_per_m = Some(v[6] as f32);
            }
        }
        // One rod, one M_s: every table that holds it (model-core refuses a set whose strain's
        // M_s is not its law's, and the file may go on to another law, `diagnose --laws`).
        if self.model != LoopModel::Linear {
            let ms = v[0] as f32;
            p.ja.ms_a_per_m = ms;
            p.anhysteretic.ms_a_per_m = ms;
            p.preisach.ms_a_per_m = ms;
            p.magnetostriction.ms_a_per_m = ms;
        }
        p
    }
}

/// Why J–A values cannot be used: α·M_s/(3a) ≥ 1 (the anhysteretic is multivalued).
fn multivalued(model: LoopModel, v: &[f64]) -> Option<f64> {
    // Only J–A has a mean field (the other laws have fewer values: index them only for J–A).
    let LoopModel::JilesAtherton(_) = model else { return None };
    let ratio = v[2] * v[0] / (3.0 * v[1]);
    (ratio >= 1.0).then_some(ratio)
}

/// Mean NRMSE over `files` of the model at `values` (its own parameters), or why it cannot run.
fn mean_nrmse(
    model: LoopModel,
    values: &[f64],
    files: &[LoopFile],
    h_max: f64,
) -> Result<Vec<f64>, RunError> {
    files
        .iter()
        .map(|f| run(model, values, &f.h, h_max).map(|m| nrmse(&f.value, &f.channel_from_m(&m))))
        .collect()
}

/// Fits `model` to the loops jointly, starting from (and never ending worse than) the model's
/// parameters in `start`.
pub fn fit(
    model: LoopModel,
    files: &[LoopFile],
    start: &ActuatorParams,
    opts: SearchOptions,
) -> Result<LoopFit> {
    fit_shown(model, files, start, opts, false)
}

/// As [`fit`], showing its progress on stderr when `show` (a bar on a terminal, else a line
/// every 5 s: a fit on a long loop takes minutes).
pub fn fit_shown(
    model: LoopModel,
    files: &[LoopFile],
    start: &ActuatorParams,
    opts: SearchOptions,
    show: bool,
) -> Result<LoopFit> {
    let h_max = files.iter().flat_map(|f| f.h.iter()).fold(0.0f64, |a, v| a.max(v.abs()));
    let m_max = files.iter().flat_map(|f| f.magnetization()).fold(0.0f64, |a, v| a.max(v.abs()));
    if !(h_max > 0.0 && m_max > 0.0) {
        bail!("the loop has no field or no magnetization excursion");
    }
    let bounds = model.bounds(h_max, m_max);
    // Through no more points than parameters any law passes, whatever the material.
    let points: usize = files.iter().map(|f| f.h.len()).sum();
    if points <= bounds.len() {
        bail!(
            "{points} loop points in all ({}) for the {} parameters of the law: a fit through no more points than \
             parameters is not determined by them; give the whole loop (both branches, tens of points or more), \
             or raise --max-samples if it cut the file",
            files.iter().map(|f| format!("{}: {}", f.name, f.h.len())).collect::<Vec<_>>().join(", "),
            bounds.len()
        );
    }
    let targets: Vec<Vec<f64>> = files.iter().map(|f| f.value.clone()).collect();
    let cost = |_: &(), v: &[f64], _: Fidelity| -> f64 {
        let p = model.model_values(v);
        let mut sum = 0.0;
        for (f, t) in files.iter().zip(&targets) {
            match run(model, &p, &f.h, h_max) {
                Ok(m) => {
                    let e = nrmse(t, &f.channel_from_m(&m));
                    sum += e * e;
                }
                Err(_) => return 10.0,
            }
        }
        let c = sum / files.len() as f64;
        if c.is_finite() {
            c
        } else {
            f64::MAX / 4.0
        }
    };
    // The start: scored as given; the search starts from it clamped into the box.
    let start_values = model.values_of(start);
    let start_score = match multivalued(model, &start_values) {
        Some(ratio) => Err(format!(
            "α·M_s/(3a) = {ratio:.2} ≥ 1: the anhysteretic curve is multivalued there, not a valid J–A model"
        )),
        None => mean_nrmse(model, &start_values, files, h_max).map_err(|e| e.0),
    };
    let mut starts: Vec<Start<()>> = match &start_score {
        Ok(_) => vec![Start::new(model.search_values(&start_values), ())],
        Err(_) => Vec::new(),
    };
    starts.extend(model.start_from_features(files).map(|values| Start::new(values, ())));
    // The bar's length: both swarms, then each local search's simplex runs (at most).
    let d = bounds.len() as u64;
    let swarm_iters = ((PLAN.swarm_iters * opts.effort).round() as u64).max(2);
    let simplex = ((PLAN.simplex_iters_per_dim * d as f64 * opts.effort).round() as u64).max(20);
    let planned =
        PLAN.swarms as u64 * (PLAN.particles.0 + PLAN.particles.1 * d as usize) as u64 * (swarm_iters + 1)
            + PLAN.local_searches as u64 * PLAN.local.len() as u64 * simplex;
    let progress = Progress::new(&format!("loop fit ({points} points)"), planned, show);
    let found = minimize(&bounds, &cost, None, &(), &starts, &PLAN, opts, &progress)?;
    progress.finish_and_clear();
    // As a parameter set holds them (f32), and as the model runs them: what is reported is what
    // `--params-out` writes, at the NRMSE it was scored at.
    let mut best: Vec<f64> = model.model_values(&found.best).iter().map(|&v| v as f32 as f64).collect();
    let mut warnings = Vec::new();
    let mut per_file = Vec::new();
    for f in files {
        match run(model, &best, &f.h, h_max) {
            Ok(m) => per_file.push(nrmse(&f.value, &f.channel_from_m(&m))),
            Err(RunError(e)) => {
                warnings.push(Warning::IntegrationFailed { file: f.name.clone(), why: e });
                per_file.push(f64::NAN);
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let mut kept = false;
    if let Ok(start_nrmse) = &start_score {
        let found_mean = mean(&per_file);
        if found_mean.is_nan() || found_mean > mean(start_nrmse) {
            kept = true;
            best = start_values.clone();
            per_file = start_nrmse.clone();
            warnings.retain(|w| !matches!(w, Warning::IntegrationFailed { .. }));
            warnings.push(Warning::StartKept { start_nrmse: mean(start_nrmse), found_nrmse: found_mean });
        }
    }
    let params: Vec<(&'static str, f64)> = model.names().iter().copied().zip(best.iter().copied()).collect();
    if !kept {
        for (b, v) in bounds.iter().zip(&found.best) {
            if b.at_edge(*v) {
                // The search's own coordinate for J–A's α, said as the ratio it is.
                let param = if b.name == "mean_field_ratio" { "α·M_s/(3a)" } else { b.name };
                warnings.push(Warning::AtEdge { param, value: *v, lo: b.lo, hi: b.hi });
                if b.name == "mean_field_ratio" && *v > 0.0 {
                    warnings.push(Warning::SquarerThanJa { ratio: *v });
                }
            }
        }
        // J–A's α is not searched (its ratio is), but the model holds it in (−1, 1): a fit
        // pressed against that limit is held by it, not by the loop.
        if let (LoopModel::JilesAtherton(_), Some(&alpha)) = (model, best.get(2)) {
            if alpha.abs() >= ALPHA_LIMIT_WARNING {
                warnings.push(Warning::AlphaAtLimit { alpha });
            }
        }
    }
    // A loop whose largest |M| is below the smallest M_s the models hold.
    let ms_floor = f64::from(model_core::error::MS_MIN);
    if m_max < ms_floor && !matches!(model, LoopModel::Linear) {
        warnings.push(Warning::WeakLoop { max_magnetization_a_per_m: m_max, ms_floor_a_per_m: ms_floor });
    }
    if let Some(ratio) = multivalued(model, &best) {
        warnings.push(Warning::Multivalued { ratio });
    }
    // First: an offset explains the edge and squareness warnings it causes.
    let doubts = files.iter().filter_map(field_in_kilo);
    warnings.splice(
        0..0,
        doubts.chain(files.iter().filter_map(off_centre)).chain(files.iter().filter_map(clockwise)),
    );
    let start = match start_score {
        Ok(e) => StartScore { nrmse: Some(mean(&e)), kept, refused: None, seen_mode: None },
        Err(why) => StartScore { nrmse: None, kept: false, refused: Some(why), seen_mode: None },
    };
    Ok(LoopFit {
        model,
        params,
        nrmse: per_file,
        evaluations: found.evaluations,
        warnings,
        time_limited: found.time_limited,
        start,
    })
}
