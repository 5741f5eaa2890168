//! Parameter uncertainty after a displacement fit, from the Jacobian at the optimum (the fit
//! itself is not changed: this is analysis after it).
//!
//! Residuals r: every fit file's displacement residual (its offset re-solved, as the cost does)
//! and the current residual where the cost scores it, each block scaled by 1/(range·√n) so that
//! rᵀr = (number of blocks) × cost. λ_s is one more parameter of the Jacobian (the model run
//! with it, not re-solved), so it gets an uncertainty too; the per-file offsets are re-solved at
//! every evaluation, i.e. projected out. Parameters held fixed (`--fix`) are not in J.
//!
//! J by central differences in each parameter's search coordinate: ln θ for log-scaled
//! parameters (so σ is a relative uncertainty), θ for linear ones (step 10⁻³ of the range;
//! one-sided where a side cannot be run). The step actually applied is read back (parameters
//! are f32). Then, with N residuals, p parameters and F offsets:
//!
//! per block b (one file's displacement, or its current): s_b² = r_bᵀr_b / (n_b − dof_b) (dof_b:
//! its offset and its share n_b/N of the p parameters), ρ_b = its residuals' lag-1
//! autocorrelation, N_eff,b = n_b (1 − ρ_b)/(1 + ρ_b) (ρ_b ≤ 0: n_b), c_b = s_b² n_b / N_eff,b;
//!
//! C = A⁺ (Σ_b c_b J_bᵀJ_b) A⁺ with A = JᵀJ.
//!
//! With one block this is s² (JᵀJ)⁻¹ · N/N_eff; the sandwich is needed because the cost weights
//! each file by 1/range², not by its inverse noise variance (a small loop's scaled residuals are
//! noisier than a large one's).
//!
//! (JᵀJ)⁺ is taken through the SVD of J with unit-norm columns; singular values below
//! [`RANK_TOLERANCE`] × the largest are dropped and the parameters that take part in the dropped
//! directions are reported as not identifiable (no σ, no interval, no correlations).
//!
//! Intervals (95 %): θ ± 1.96 σ for linear parameters; θ·exp(±1.96 σ_ln) for log-scaled ones
//! (log-normal; their `std` is the delta-method θ·σ_ln); both clipped to the parameter's search
//! range, its physical range.

use anyhow::{bail, Result};
use model_core::{ActuatorParams, ModelSpec};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::fit::FreeParam;
use crate::fit::{residual_blocks, FitResult};
use crate::recording::Recording;
use crate::search::Bound;
use crate::simulation::{excursion_range, prepare, starting_from, Prepared};
use crate::warning::Warning;

/// Singular values of the column-normalised Jacobian below this fraction of the largest are
/// treated as zero: finite differences of an f32 model are not more accurate than that.
pub const RANK_TOLERANCE: f64 = 1e-4;

/// |ρ| above which a pair of parameters is warned about.
pub const CORRELATION_WARNING: f64 = 0.95;

/// Central-difference step in ln θ for log-scaled parameters.
const LOG_STEP: f64 = 1e-3;

/// Central-difference step for linear parameters, as a fraction of the searched range.
const LINEAR_STEP: f64 = 1e-3;

/// One parameter's estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamUncertainty {
    /// Its name and the range it was searched in.
    pub bound: Bound,
    /// The fitted value.
    pub value: f64,
    /// Standard deviation in the parameter's unit (None: not identifiable).
    pub std: Option<f64>,
    /// Standard deviation of ln θ (log-scaled parameters).
    pub std_ln: Option<f64>,
    /// 95 % interval.
    pub ci95: Option<(f64, f64)>,
    /// Which ends of the 95 % interval the search range cut off (lower, upper): there the
    /// interval says only that the data allow the whole rest of the range.
    pub ci95_clipped: (bool, bool),
}

impl ParamUncertainty {
    /// Words after the interval when the search range cut it off, e.g. " (lower end cut to the
    /// search range)"; empty when it did not.
    pub fn clipped_note(&self) -> &'static str {
        match self.ci95_clipped {
            (true, true) => " (both ends cut to the search range)",
            (true, false) => " (lower end cut to the search range)",
            (false, true) => " (upper end cut to the search range)",
            (false, false) => "",
        }
    }
}

/// The uncertainty of a fit's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// Per parameter, in the fit's order (λ_s first unless fixed).
    pub params: Vec<ParamUncertainty>,
    /// Correlation matrix, in the same order (NaN for a parameter that is not identifiable).
    pub correlation: Vec<Vec<f64>>,
    /// Residuals N.
    pub samples: usize,
    /// N_eff = N (1 − ρ₁)/(1 + ρ₁).
    pub effective_samples: f64,
    /// Lag-1 autocorrelation of the residuals.
    pub lag1_autocorrelation: f64,
    /// Largest over smallest singular value of the column-normalised Jacobian.
    pub condition: f64,
}

impl Uncertainty {
    /// Names of the parameters that are not identifiable.
    pub fn not_identifiable(&self) -> Vec<&'static str> {
        self.params.iter().filter(|p| p.std.is_none()).map(|p| p.bound.name).collect()
    }

    /// Doubts: parameters that are not identifiable, pairs with |ρ| > 0.95, parameters within
    /// 0.5 % of a search bound.
    pub fn warnings(&self) -> Vec<Warning> {
        let mut w = Vec::new();
        let lost = self.not_identifiable();
        if !lost.is_empty() {
            w.push(Warning::NotIdentifiable { params: lost, condition: self.condition });
        }
        for i in 0..self.params.len() {
            for j in 0..i {
                let rho = self.correlation[i][j];
                if rho.abs() > CORRELATION_WARNING {
                    w.push(Warning::Correlated {
                        a: self.params[j].bound.name,
                        b: self.params[i].bound.name,
                        rho,
                    });
                }
            }
        }
        for p in &self.params {
            if p.bound.at_edge(p.value) {
                w.push(Warning::AtEdge {
                    param: p.bound.name,
                    value: p.value,
                    lo: p.bound.lo,
                    hi: p.bound.hi,
                });
            }
        }
        w
    }
}

/// The search coordinate of a parameter: ln θ or θ.
fn coord(b: &Bound, v: f64) -> f64 {
    if b.log {
        v.ln()
    } else {
        v
    }
}

/// A parameter's std, std of ln θ, 95 % interval and which ends of it the search range cut
/// off, from σ in its search coordinate (None: not identifiable).
#[allow(clippy::type_complexity)]
fn interval(
    b: &Bound,
    value: f64,
    sd: Option<f64>,
) -> (Option<f64>, Option<f64>, Option<(f64, f64)>, (bool, bool)) {
    let (std, std_ln, raw) = match sd {
        None => return (None, None, None, (false, false)),
        Some(s) if b.log => (value * s, Some(s), (value * (-1.96 * s).exp(), value * (1.96 * s).exp())),
        Some(s) => (s, None, (value - 1.96 * s, value + 1.96 * s)),
    };
    // An interval never leaves the parameter's physical range (the search range): a ratio in
    // [0, 1) at 0 ± 0.16 has the interval [0, 0.32], not [−0.32, 0.32]. The ends it cut off are
    // marked: there the data do not bound the parameter, the range does.
    let ci95 = (raw.0.max(b.lo), raw.1.min(b.hi));
    (Some(std), std_ln, Some(ci95), (raw.0 < b.lo, raw.1 > b.hi))
}

/// The uncertainty of `res`'s continuous parameters on its fit files.
pub fn analyse(spec: ModelSpec, res: &FitResult, files: &[Recording]) -> Result<Uncertainty> {
    // Each file's initial magnetic state as the fit scored it: a nuisance parameter, so it gets
    // a column of its own and the parameters' covariance is the marginal one.
    let excursions: Vec<f64> = res.fit.files.iter().filter_map(|f| f.initial_excursion_a_per_m).collect();
    let excursions = if excursions.len() == files.len() { excursions } else { Vec::new() };
    let prep = starting_from(&prepare(spec, files)?, &excursions);
    let base = res.params;
    let blocks = residual_blocks(spec, &base, &prep)?;
    let r: Vec<f64> = blocks.iter().flat_map(|b| &b.1).copied().collect();
    let n = r.len();
    let free: &[FreeParam] = &res.free;
    let p = free.len();
    let offsets = prep.len();
    if p == 0 {
        bail!("every parameter is fixed: there is no uncertainty to estimate");
    }
    if n <= p + offsets + 1 {
        bail!(
            "{n} residuals for {p} parameters and {offsets} offsets: too few to estimate their uncertainty"
        );
    }
    let run = |f: &FreeParam, v: f64, prep: &[Prepared]| -> Option<(f64, Vec<f64>)> {
        let mut q = base;
        (f.set)(&mut q, v);
        let applied = coord(&f.bound, (f.get)(&q));
        let r = residual_blocks(spec, &q, prep).ok()?;
        let r: Vec<f64> = r.into_iter().flat_map(|b| b.1).collect();
        r.iter().all(|x| x.is_finite()).then_some((applied, r))
    };
    // Columns in parallel: dr/du by central differences (one-sided where a side cannot be run).
    let columns: Vec<Vec<f64>> = free
        .par_iter()
        .map(|f| {
            let v = (f.get)(&base);
            let u = coord(&f.bound, v);
            let (up, down) = if f.bound.log {
                (v * LOG_STEP.exp(), v * (-LOG_STEP).exp())
            } else {
                let h = LINEAR_STEP * (f.bound.hi - f.bound.lo);
                (v + h, v - h)
            };
            let plus = run(f, up, &prep);
            let minus = run(f, down, &prep);
            let centre = (u, r.clone());
            let (a, b) = match (plus, minus) {
                (Some(a), Some(b)) => (a, b),
                (Some(a), None) => (a, centre),
                (None, Some(b)) => (centre, b),
                (None, None) => return vec![0.0; n],
            };
            let du = a.0 - b.0;
            if du == 0.0 {
                return vec![0.0; n];
            }
            a.1.iter().zip(&b.1).map(|(x, y)| (x - y) / du).collect()
        })
        .collect();
    let nuisance = nuisance_columns(spec, &base, &prep, &excursions, n);
    let columns: Vec<Vec<f64>> = columns.into_iter().chain(nuisance).collect();
    // p parameters, then the nuisance columns; only the first p are reported.
    let (p_reported, p) = (p, columns.len());
    let j = DMatrix::from_fn(n, p, |i, k| columns[k][i]);
    let norms: Vec<f64> = (0..p).map(|k| j.column(k).norm()).collect();
    let js = DMatrix::from_fn(n, p, |i, k| if norms[k] > 0.0 { j[(i, k)] / norms[k] } else { 0.0 });
    let svd = js.clone().svd(false, true);
    let v_t = svd.v_t.as_ref().expect("V requested");
    let sigma_max = svd.singular_values.iter().fold(0.0f64, |a, &b| a.max(b));
    let sigma_min = svd.singular_values.iter().fold(f64::INFINITY, |a, &b| a.min(b));
    let condition = if sigma_min > 0.0 { sigma_max / sigma_min } else { f64::INFINITY };
    // (JsᵀJs)⁺ over the kept directions; parameters in a dropped direction are lost.
    let mut inv = DMatrix::<f64>::zeros(p, p);
    let mut lost = vec![false; p];
    for (k, &s) in svd.singular_values.iter().enumerate() {
        let row = v_t.row(k);
        if s > RANK_TOLERANCE * sigma_max {
            inv += row.transpose() * row / (s * s);
        } else {
            for (i, l) in lost.iter_mut().enumerate() {
                *l |= row[i].abs() > 0.1;
            }
        }
    }
    for (i, l) in lost.iter_mut().enumerate() {
        *l |= norms[i] == 0.0;
    }
    // Per block (file and channel): its residual variance and its correlation time τ_b, which
    // inflates its variance by N/N_eff = τ_b (the diagnosis counts independent samples the same
    // way: crate::spectral::effective_samples). The blocks' weights in the cost
    // are not their inverse noise variances, so the covariance is the sandwich
    // A⁺ (Σ_b s_b² τ_b J_bᵀ J_b) A⁺ with A = JᵀJ; with one block (or equal s_b² τ_b) it is
    // s² (JᵀJ)⁻¹ · N/N_eff. The pooled lag-1 autocorrelation is reported beside it.
    let mut meat = DMatrix::<f64>::zeros(p, p);
    let (mut start, mut effective, mut num, mut den) = (0, 0.0, 0.0, 0.0);
    for (solved, b) in &blocks {
        let nb = b.len();
        let ss: f64 = b.iter().map(|x| x * x).sum();
        num += b.windows(2).map(|w| w[0] * w[1]).sum::<f64>();
        den += ss;
        let n_eff = crate::spectral::effective_samples(b).max(1.0);
        let inflation = nb as f64 / n_eff;
        // Degrees of freedom: the block's closed-form unknowns (offset, flux scale and zero) and
        // its share of the parameters.
        let dof = *solved as f64 + p as f64 * nb as f64 / n as f64;
        let s2 = ss / (nb as f64 - dof).max(1.0);
        effective += n_eff;
        let jb = js.rows(start, nb);
        meat += (jb.transpose() * jb) * (s2 * inflation);
        start += nb;
    }
    let rho1 = if den > 0.0 { num / den } else { 0.0 };
    let sandwich = &inv * meat * &inv;
    let cov = DMatrix::from_fn(p, p, |a, b| {
        if lost[a] || lost[b] {
            f64::NAN
        } else {
            sandwich[(a, b)] / (norms[a] * norms[b])
        }
    });
    let p = p_reported;
    let params = free
        .iter()
        .enumerate()
        .map(|(k, f)| {
            // As reported in `params` (λ_s there is the closed form's f64, not its f32 copy).
            let value = res.identified.iter().find(|(n, _)| *n == f.name()).map_or((f.get)(&base), |x| x.1);
            let sd = cov[(k, k)].sqrt();
            let (std, std_ln, ci95, ci95_clipped) = interval(&f.bound, value, sd.is_finite().then_some(sd));
            ParamUncertainty { bound: f.bound, value, std, std_ln, ci95, ci95_clipped }
        })
        .collect();
    let correlation =
        (0..p).map(|a| (0..p).map(|b| cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt()).collect()).collect();
    Ok(Uncertainty {
        params,
        correlation,
        samples: n,
        effective_samples: effective,
        lag1_autocorrelation: rho1,
        condition,
    })
}

/// The Jacobian's columns of each file's initial magnetic state (a nuisance parameter), by
/// central differences of `n` residuals about `base`.
fn nuisance_columns(
    spec: ModelSpec,
    base: &ActuatorParams,
    prep: &[Prepared],
    excursions: &[f64],
    n: usize,
) -> Vec<Vec<f64>> {
    let h = LINEAR_STEP * 2.0 * excursion_range(spec, base);
    (0..excursions.len())
        .into_par_iter()
        .map(|i| {
            let shifted = |dx: f64| -> Option<Vec<f64>> {
                let mut x = excursions.to_vec();
                x[i] += dx;
                let r = residual_blocks(spec, base, &starting_from(prep, &x)).ok()?;
                let r: Vec<f64> = r.into_iter().flat_map(|b| b.1).collect();
                r.iter().all(|v| v.is_finite()).then_some(r)
            };
            match (shifted(h), shifted(-h)) {
                (Some(a), Some(b)) => a.iter().zip(&b).map(|(x, y)| (x - y) / (2.0 * h)).collect(),
                _ => vec![0.0; n],
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interval_the_search_range_cuts_says_which_end() {
        // A ratio in [0, 1) at 0.1 ± 0.1: the lower end −0.096 is cut to 0 and said to be.
        let ratio = Bound::lin("ja.c", 0.0, 1.0);
        let (std, _, ci, clipped) = interval(&ratio, 0.1, Some(0.1));
        assert_eq!(std, Some(0.1));
        assert_eq!(ci, Some((0.0, 0.1 + 0.196)));
        assert_eq!(clipped, (true, false));
        // Inside the range: nothing cut, nothing said.
        let (_, _, ci, clipped) = interval(&ratio, 0.5, Some(0.1));
        assert!((ci.unwrap().0 - 0.304).abs() < 1e-12 && (ci.unwrap().1 - 0.696).abs() < 1e-12);
        assert_eq!(clipped, (false, false));
        // Log scale, σ_ln = 1 near the top of [1e-6, 1e-3]: the upper end 2.6e-3 is cut.
        let tau = Bound { name: "eddy_tau_s", lo: 1e-6, hi: 1e-3, log: true, swarm_holds: None };
        let (std, std_ln, ci, clipped) = interval(&tau, 3.5e-4, Some(1.0));
        assert_eq!((std, std_ln), (Some(3.5e-4), Some(1.0)));
        assert_eq!(ci.unwrap().1, 1e-3);
        assert_eq!(clipped, (false, true));
        let p = ParamUncertainty { bound: tau, value: 3.5e-4, std, std_ln, ci95: ci, ci95_clipped: clipped };
        assert_eq!(p.clipped_note(), " (upper end cut to the search range)");
        // Not identifiable: no interval, nothing cut.
        assert_eq!(interval(&tau, 3.5e-4, None), (None, None, None, (false, false)));
    }
}
