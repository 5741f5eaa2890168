use super::*;

fn no_count(_: usize) {}

/// The normal equations from the upper triangle are nalgebra's `tr_mul`s bit for bit, so the
/// searches take the paths they took before (on columns of mixed scales and signs).
#[test]
fn normal_equations_are_tr_mul_bit_for_bit() {
    let (n, d) = (1001, 7);
    let x = |k: usize| ((k as f64 * 0.618_033_988_7).fract() - 0.5) * 10f64.powi((k % 9) as i32 - 4);
    let jac = nalgebra::DMatrix::from_fn(n, d, |i, j| x(i * d + j));
    let r = nalgebra::DVector::from_fn(n, |i, _| x(7 * i + 3));
    let (jtj, g) = normal_equations(&jac, &r);
    let (want_jtj, want_g) = (jac.tr_mul(&jac), jac.tr_mul(&r));
    let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(jtj.as_slice()), bits(want_jtj.as_slice()));
    assert_eq!(bits(g.as_slice()), bits(want_g.as_slice()));
}

/// Rosenbrock's valley as residuals (10·(y − x²), 1 − x) on x, y ∈ [−2, 2]: a curved,
/// badly scaled least-squares problem with its minimum at (1, 1), in the interior.
#[test]
fn levenberg_marquardt_follows_rosenbrocks_valley_to_its_minimum() {
    let to_xy = |u: &[f64]| (4.0 * u[0] - 2.0, 4.0 * u[1] - 2.0);
    let r = |u: &[f64]| {
        let (x, y) = to_xy(u);
        Some(vec![10.0 * (y - x * x), 1.0 - x])
    };
    // From (−1.2, 1), the classic start: the valley bends through x = 0 on the way.
    let u = levenberg_marquardt(&r, vec![0.2, 0.75], 40, None, &no_count);
    let (x, y) = to_xy(&u);
    assert!((x - 1.0).abs() < 1e-3 && (y - 1.0).abs() < 2e-3, "ended at ({x}, {y})");
}

/// A minimum outside the cube: the run must stop on the face, at the best point of the
/// face, not leave the cube or stall short of it (as clamping the full step does).
#[test]
fn levenberg_marquardt_stops_on_an_active_bound() {
    // Unconstrained minimum at u = (1.5, 0.3); on the face u₀ = 1 the best u₁ is 0.3 + 0.2·0.5.
    let r = |u: &[f64]| Some(vec![u[0] - 1.5, (u[1] - 0.3) - 0.2 * (u[0] - 1.5), 0.1 * (u[0] - 1.5)]);
    let u = levenberg_marquardt(&r, vec![0.2, 0.9], 20, None, &no_count);
    assert!(u.iter().all(|x| (0.0..=1.0).contains(x)), "left the cube: {u:?}");
    assert!((u[0] - 1.0).abs() < 1e-9, "u₀ = {} (should sit on the bound)", u[0]);
    assert!((u[1] - 0.2).abs() < 1e-4, "u₁ = {} (best on the face: 0.2)", u[1]);
}

/// Where the model cannot run (the residuals are `None`) the run keeps its last good point
/// and still descends where it can.
#[test]
fn levenberg_marquardt_steps_around_points_the_model_cannot_run() {
    // Minimum at u = (0.7, 0.7); the model "fails" for u₀ > 0.8.
    let r = |u: &[f64]| (u[0] <= 0.8).then(|| vec![u[0] - 0.7, 3.0 * (u[1] - 0.7)]);
    let u = levenberg_marquardt(&r, vec![0.1, 0.1], 20, None, &no_count);
    assert!((u[0] - 0.7).abs() < 1e-4 && (u[1] - 0.7).abs() < 1e-4, "ended at {u:?}");
}

/// The whole search with a least-squares local run finds the minimum of a bounded,
/// log-scaled problem, and a plan without the residuals it needs is an error, not a panic.
#[test]
fn minimize_with_a_least_squares_run() {
    let bounds = [Bound::log("k", 1e-3, 1e3), Bound::lin("c", -5.0, 5.0)];
    let res = |_: &(), v: &[f64], _: Fidelity| Some(vec![v[0].ln() - 2.0_f64.ln(), v[1] - 1.5]);
    let cost = |c: &(), v: &[f64], f: Fidelity| res(c, v, f).map_or(1e9, |r| r.iter().map(|x| x * x).sum());
    let plan = Plan {
        particles: (8, 2),
        swarm_iters: 10.0,
        swarms: 1,
        simplex_iters_per_dim: 20.0,
        local_searches: 2,
        finalists: 1,
        local: &[Local::LeastSquares(Fidelity::Full)],
        tolerance: (1e-9, 1e-12),
    };
    let progress = Progress::new("test", 0, false);
    let found =
        minimize(&bounds, &cost, Some(&res), &(), &[], &plan, SearchOptions::default(), &progress).unwrap();
    assert!(
        (found.best[0] - 2.0).abs() < 1e-4 && (found.best[1] - 1.5).abs() < 1e-4,
        "found {:?}",
        found.best
    );
    let err =
        minimize(&bounds, &cost, None, &(), &[], &plan, SearchOptions::default(), &progress).unwrap_err();
    assert!(err.to_string().contains("residuals"), "{err}");
}

/// A start marked `always_refined` is refined even when two others rank above it: here it
/// sits on the shoulder of a narrow, deep well (a lightly damped mode's valley) and the
/// others in a broad, shallow basin.
#[test]
fn an_always_refined_start_is_refined_though_it_ranks_last() {
    let bounds = [Bound::lin("x", 0.0, 1.0)];
    let cost = |_: &(), v: &[f64], _: Fidelity| {
        let broad = 0.01 + (v[0] - 0.2).powi(2);
        broad.min(100.0 * (v[0] - 0.8137).powi(2))
    };
    let plan = Plan {
        particles: (1, 0),
        swarm_iters: 2.0,
        swarms: 0,
        simplex_iters_per_dim: 40.0,
        local_searches: 2,
        // Fewer finalists than seeds: the always-refined start must survive that cut too,
        // where it ranks last again.
        finalists: 1,
        local: &[Local::Simplex(0.02, Fidelity::Full)],
        tolerance: (1e-9, 1e-15),
    };
    let progress = Progress::new("test", 0, false);
    let run = |pinned: bool| {
        let start = |x: f64, always_refined| Start {
            values: vec![x],
            context: (),
            always_refined,
            simplex_holds: vec![],
        };
        let starts = [start(0.2, false), start(0.3, false), start(0.77, pinned)];
        minimize(&bounds, &cost, None, &(), &starts, &plan, SearchOptions::default(), &progress).unwrap()
    };
    // The shoulder costs 0.19, more than the broad basin's 0.01 and 0.02.
    let ranked_out = run(false);
    assert!((ranked_out.cost - 0.01).abs() < 1e-6, "{ranked_out:?}");
    let refined = run(true);
    assert!(refined.cost < 1e-8 && (refined.best[0] - 0.8137).abs() < 1e-4, "{refined:?}");
}

/// A start's held coordinate (a mode's frequency) is not moved by the simplex runs, while the
/// other coordinate travels to its optimum; least squares then polish both.
#[test]
fn a_starts_simplex_holds_keep_its_narrow_coordinate() {
    let bounds = [Bound::lin("x", 0.0, 1.0), Bound::lin("f", 0.0, 1.0)];
    let strayed = AtomicBool::new(false);
    // Context `true`: the always-refined start's runs.
    let res = |pinned: &bool, v: &[f64], _: Fidelity| {
        if *pinned && (v[1] - 0.8137).abs() > 0.02 {
            strayed.store(true, Ordering::Relaxed);
        }
        Some(vec![v[0] - 0.3, 100.0 * (v[1] - 0.8137)])
    };
    let cost = |c: &bool, v: &[f64], f: Fidelity| res(c, v, f).map_or(1e9, |r| r.iter().map(|x| x * x).sum());
    let plan = Plan {
        particles: (1, 0),
        swarm_iters: 2.0,
        swarms: 0,
        simplex_iters_per_dim: 40.0,
        local_searches: 1,
        finalists: 1,
        local: &[Local::Simplex(0.05, Fidelity::Full), Local::LeastSquares(Fidelity::Full)],
        tolerance: (1e-9, 1e-15),
    };
    let starts = [
        Start::new(vec![0.5, 0.5], false),
        Start { values: vec![0.8, 0.8137], context: true, always_refined: true, simplex_holds: vec![1] },
    ];
    let progress = Progress::new("test", 0, false);
    let found =
        minimize(&bounds, &cost, Some(&res), &false, &starts, &plan, SearchOptions::default(), &progress)
            .unwrap();
    assert!(found.cost < 1e-12, "{found:?}");
    assert!(!strayed.load(Ordering::Relaxed), "a simplex step moved the start's held coordinate");
}
