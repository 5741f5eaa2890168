//! The Jiles–Atherton law's incremental susceptibility and the state it is evaluated at,
//! checked against the published equations (evaluated here in f64, from the equations printed
//! in `JaVariant`'s documentation) and against the magnetization's own trajectory.

use model_core::magnetization::{JaParams, JaState, JaVariant, JilesAtherton};

/// Langevin function L(x) = coth x − 1/x and its slope L'(x) = 1/x² − 1/sinh² x, in f64.
fn langevin(x: f64) -> (f64, f64) {
    if x.abs() < 1e-3 {
        (x / 3.0 - x * x * x / 45.0, 1.0 / 3.0 - x * x / 15.0)
    } else {
        (1.0 / x.tanh() - 1.0 / x, 1.0 / (x * x) - 1.0 / x.sinh().powi(2))
    }
}

/// dM/dH of each variant's equation at field `h` with mean field seeded by `m_seed`,
/// magnetization `m` and irreversible magnetization `m_irr`, moving in direction `dir`; its
/// mean-field denominators floored at 0.05 (1 − αχ) and 0.05 k (k − αg) as the module says.
fn expected_susceptibility(p: &JaParams, h: f32, m_seed: f32, m: f32, m_irr: f32, dir: f64) -> f64 {
    let (ms, a, alpha, k, c) =
        (p.ms_a_per_m as f64, p.a_a_per_m as f64, p.alpha as f64, p.k_a_per_m as f64, p.c as f64);
    let (l, dl) = langevin((h as f64 + alpha * m_seed as f64) / a);
    let (man, dman) = (ms * l, ms / a * dl);
    let mean_field = |chi: f64| chi / (1.0 - alpha * chi).max(0.05);
    let pinned = |g: f64| g / (k - alpha * g).max(0.05 * k);
    match p.variant {
        JaVariant::Bulk => {
            let chi_irr = ((man - m_irr as f64) * dir).max(0.0) / k;
            mean_field(c * dman + (1.0 - c) * chi_irr)
        }
        JaVariant::Original1986 => {
            (1.0 - c) * pinned(((man - m_irr as f64) * dir).max(0.0)) + mean_field(c * dman)
        }
        JaVariant::Szewczyk => (pinned(((man - m as f64) * dir).max(0.0)) + c * dman) / (1.0 + c),
        JaVariant::Ungated1986 => ((pinned((man - m as f64) * dir) + c * dman) / (1.0 + c)).max(0.0),
    }
}

/// Both published parameter sets (α < 0 and α > 0) in every variant.
fn every_law() -> Vec<(JaParams, JilesAtherton)> {
    let mut laws = Vec::new();
    for base in [JaParams::TSMA_ROD1_002, JaParams::VIBRATOR_001] {
        for variant in JaVariant::ALL {
            let p = JaParams { variant, ..base };
            laws.push((p, JilesAtherton::new(p).unwrap()));
        }
    }
    laws
}

/// `state` builds what its documentation says: M_irr clamped to ±M_s and M = c M_an(h + αm) +
/// (1 − c) M_irr for the bulk and 1986 forms; M = M_irr = m (clamped) for the total forms.
#[test]
fn a_state_is_its_documented_magnetizations() {
    for (p, ja) in every_law() {
        let ms = p.ms_a_per_m;
        for (h, m, m_irr) in [(2_500.0, 1e5, -3e5), (-15_000.0, -2e5, 0.4 * ms), (0.0, 0.0, 2.0 * ms)] {
            let s = ja.state(h, m, m_irr);
            assert_eq!(s.h_a_per_m, h, "{p:?}");
            if p.variant.is_total_magnetization() {
                assert_eq!((s.m_a_per_m, s.m_irr_a_per_m), (m, m), "{p:?}");
            } else {
                let m_irr = m_irr.clamp(-ms, ms);
                let (l, _) = langevin((h as f64 + p.alpha as f64 * m as f64) / p.a_a_per_m as f64);
                let expected = p.c as f64 * ms as f64 * l + (1.0 - p.c as f64) * m_irr as f64;
                assert_eq!(s.m_irr_a_per_m, m_irr, "{p:?}");
                assert!((s.m_a_per_m as f64 - expected).abs() < 1e-5 * ms as f64, "{p:?}: {s:?}");
            }
        }
        // Beyond saturation the total forms' M is held at ±M_s too.
        let s = ja.state(0.0, -3.0 * ms, -3.0 * ms);
        assert!(s.m_a_per_m >= -ms && s.m_irr_a_per_m == -ms, "{p:?}: {s:?}");
    }
}

/// The susceptibility is each variant's printed dM/dH, on both branches, at states above,
/// below and on either side of the anhysteretic curve (a sign flip or a dropped term in any
/// form, or a stale anhysteretic slope in the state, shows here).
#[test]
fn the_susceptibility_is_the_published_equation() {
    for (p, ja) in every_law() {
        let ms = p.ms_a_per_m;
        for h in [-40_000.0f32, -3_000.0, 0.0, 2_500.0, 15_000.0] {
            for m_irr in [-0.6 * ms, -0.1 * ms, 0.2 * ms, 0.7 * ms] {
                let m_seed = 0.5 * m_irr + 1e4;
                let s = ja.state(h, m_seed, m_irr);
                for dir in [1.0f32, -1.0] {
                    let got = ja.susceptibility(&s, dir) as f64;
                    let want =
                        expected_susceptibility(&p, h, m_seed, s.m_a_per_m, s.m_irr_a_per_m, dir as f64);
                    let tol = 1e-4 * want.abs() + 1e-5 * (ms / p.a_a_per_m) as f64;
                    assert!(
                        (got - want).abs() < tol,
                        "{p:?} at h = {h}, M_irr = {m_irr}, δ = {dir}: {got} against {want}"
                    );
                }
            }
        }
    }
}

/// Every variant at 002's rod parameters (α < 0) and with a mean field of the other sign (α =
/// 0.02: α·M_s/(3a) = 0.61, a single-valued anhysteretic, unlike 001's 2.4).
fn physical_laws() -> Vec<(JaParams, JilesAtherton)> {
    let mut laws = Vec::new();
    for alpha in [-0.035, 0.02] {
        for variant in JaVariant::ALL {
            let p = JaParams { variant, alpha, ..JaParams::TSMA_ROD1_002 };
            laws.push((p, JilesAtherton::new(p).unwrap()));
        }
    }
    laws
}

/// A state consistent with itself: the mean field seeded by the M it gives (a fixed point).
fn settled(ja: &JilesAtherton, s: JaState) -> JaState {
    (0..60).fold(s, |s, _| ja.state(s.h_a_per_m, s.m_a_per_m, s.m_irr_a_per_m))
}

/// The susceptibility is the slope the law then steps along: one small step of ±40 A/m from a
/// settled state on the initial curve and after a reversal moves M by χ·dh to within 2 %
/// (the 1986 form's reversible mean-field factor is first order only, so at α = 0 there).
#[test]
fn the_susceptibility_is_the_slope_of_the_trajectory() {
    for (p, _) in physical_laws() {
        let p = if p.variant == JaVariant::Original1986 { JaParams { alpha: 0.0, ..p } } else { p };
        let ja = JilesAtherton::new(p).unwrap();
        let mut s = JaState::default();
        for h in [4_000.0f32, 12_000.0, 20_000.0, 16_000.0, 9_000.0] {
            ja.step(&mut s, h);
            let start = settled(&ja, s);
            for dh in [40.0f32, -40.0] {
                let mut moved = start;
                let m = ja.step(&mut moved, h + dh);
                let slope = (m - start.m_a_per_m) / dh;
                let chi = ja.susceptibility(&start, dh.signum());
                assert!(
                    (slope - chi).abs() <= 0.02 * chi.abs() + 1e-3,
                    "{p:?} at {h} A/m, dh = {dh}: trajectory slope {slope}, susceptibility {chi}"
                );
            }
        }
    }
}

/// After a reversal the irreversible part switches off: on the rising initial curve the
/// rising slope exceeds the falling one (the δ_M gate), and neither is ever negative.
#[test]
fn the_rising_slope_exceeds_the_falling_one_on_the_initial_curve() {
    for (p, ja) in physical_laws() {
        let mut s = JaState::default();
        for n in 1..=20 {
            ja.step(&mut s, 1_000.0 * n as f32);
            let (up, down) = (ja.susceptibility(&s, 1.0), ja.susceptibility(&s, -1.0));
            assert!(
                down >= 0.0 && up > 1.05 * down,
                "{p:?} at {} A/m: rising {up}, falling {down}",
                s.h_a_per_m
            );
        }
    }
}

/// The total forms keep the anhysteretic curve of the state they stepped to: the susceptibility
/// at a stepped state is the one at the same state rebuilt from its field and magnetization.
/// (The bulk and 1986 forms keep the one at the predicted mean field, not at M.)
#[test]
fn a_stepped_state_caches_the_anhysteretic_slope_it_is_at() {
    for (p, ja) in physical_laws().into_iter().filter(|(p, _)| p.variant.is_total_magnetization()) {
        let mut s = JaState::default();
        for h in [7_000.0f32, 30_000.0, -8_000.0, 3_000.0] {
            ja.step(&mut s, h);
            let rebuilt = ja.state(s.h_a_per_m, s.m_a_per_m, s.m_irr_a_per_m);
            for dir in [1.0f32, -1.0] {
                let (got, want) = (ja.susceptibility(&s, dir), ja.susceptibility(&rebuilt, dir));
                assert!(
                    (got - want).abs() <= 1e-5 * want.abs() + 1e-4,
                    "{p:?} at {h} A/m, δ = {dir}: stepped {got}, rebuilt {want}"
                );
            }
        }
    }
}
