use super::*;
use proptest::prelude::*;

const P: PreisachParams = PreisachParams {
    ms_a_per_m: 6.0e5,
    coercive_a_per_m: 5000.0,
    spread_a_per_m: 8000.0,
    interaction_spread_a_per_m: None,
    reversible_fraction: None,
    reversible_field_a_per_m: None,
    h_max_a_per_m: 60_000.0,
};

fn model() -> Preisach {
    Preisach::new(P).unwrap()
}

/// P with a reversible part (ρ 0.2, h_r 20 kA/m).
const P_REV: PreisachParams =
    PreisachParams { reversible_fraction: Some(0.2), reversible_field_a_per_m: Some(20_000.0), ..P };

fn drive(p: &Preisach, s: &mut PreisachState, path: &[f32], per_leg: usize) -> f32 {
    let mut m = p.output(s);
    let mut from = s.turning_points().last().copied().unwrap_or(-p.table().h_max_a_per_m());
    for &to in path {
        for n in 1..=per_leg {
            m = p.step(s, from + (to - from) * n as f32 / per_leg as f32);
        }
        from = to;
    }
    m
}

#[test]
fn saturates_at_plus_minus_ms_and_is_odd_symmetric() {
    let p = model();
    let mut s = PreisachState::default();
    assert!((p.output(&s) + P.ms_a_per_m).abs() < 1.0);
    assert!((p.step(&mut s, 1e9) - P.ms_a_per_m).abs() < 1.0);
    // Major loop: ascending branch at h equals minus the descending branch at −h.
    let mut up = PreisachState::default();
    let mut down = PreisachState::default();
    p.step(&mut down, P.h_max_a_per_m);
    for k in 0..=40 {
        let h = -30_000.0 + 1500.0 * k as f32;
        let m_up = p.step(&mut up, h);
        let mut d = down;
        let m_down = p.step(&mut d, -h);
        assert!((m_up + m_down).abs() < 1e-3 * P.ms_a_per_m, "h {h}: {m_up} vs {m_down}");
    }
}

/// The ascending major branch against a fine f64 integration of the same density:
/// M(h) = −M_s + 2 M_s · mass{β ≤ α ≤ h} / mass{β ≤ α} (the relays switched up so far).
#[test]
fn major_branch_matches_fine_integration_of_the_density() {
    let (hc, sigma) = (P.coercive_a_per_m as f64, P.spread_a_per_m as f64);
    let lorentz = |x: f64| 1.0 / (1.0 + x * x);
    major_branch_follows(P, |a, b| lorentz((a - hc) / sigma) * lorentz((b + hc) / sigma));
    // Narrow coercivity, wide interaction (the Terfenol-D shape).
    let (sigma, su) = (1500.0, 20_000.0);
    let q = PreisachParams { spread_a_per_m: sigma as f32, interaction_spread_a_per_m: Some(su as f32), ..P };
    major_branch_follows(q, |a, b| lorentz((0.5 * (a - b) - hc) / sigma) * lorentz(0.5 * (a + b) / su));
}

fn major_branch_follows(params: PreisachParams, mu: impl Fn(f64, f64) -> f64) {
    let p = Preisach::new(params).unwrap();
    let h_max = params.h_max_a_per_m as f64;
    let n = 800;
    let d = 2.0 * h_max / n as f64;
    // Column masses: mass with α in column i, β ≤ α.
    let mut col = vec![0.0f64; n];
    for (i, c) in col.iter_mut().enumerate() {
        let a = -h_max + (i as f64 + 0.5) * d;
        for j in 0..=i {
            let b = -h_max + (j as f64 + 0.5) * d;
            *c += mu(a, b) * if i == j { 0.5 } else { 1.0 };
        }
    }
    let total: f64 = col.iter().sum();
    let mut s = PreisachState::default();
    let mut worst = 0.0f64;
    for k in 0..=60 {
        let h = -30_000.0 + 1000.0 * k as f64;
        let m = p.step(&mut s, h as f32) as f64;
        let upto = ((h + h_max) / d) as usize;
        let reference = -1.0 + 2.0 * col[..upto].iter().sum::<f64>() / total;
        worst = worst.max((m / params.ms_a_per_m as f64 - reference).abs());
    }
    // The narrowest width is about two grid steps here (σ; 2σ along the coercivity axis of
    // the α–β grid); the interpolated table follows the continuous model to 3 %.
    assert!(worst < 0.035, "branch error {worst:.4} of M_s");
    eprintln!("major branch vs f64 integration: {:.3} % of M_s", worst * 100.0);
}

/// Loops smaller than a grid cell follow Rayleigh's law, as the continuous density gives
/// them: near the diagonal E(α, β) ≈ ½ μ (α − β)², so a symmetric minor loop of amplitude
/// ΔH swings the relays by 2 E(H + ΔH, H − ΔH) ∝ ΔH² (4× for twice the amplitude) and
/// opens. Interpolating E itself linearly there made every such loop a closed straight line
/// with the slope of the whole cell: 8–16× the swing at these amplitudes.
#[test]
fn loops_smaller_than_a_grid_cell_follow_rayleigh() {
    let p = model();
    let (hc, sigma, h_max) = (P.coercive_a_per_m as f64, P.spread_a_per_m as f64, P.h_max_a_per_m as f64);
    let lorentz = |x: f64| 1.0 / (1.0 + x * x);
    let mu = |a: f64, b: f64| lorentz((a - hc) / sigma) * lorentz((b + hc) / sigma);
    // mass of the triangle lo ≤ β ≤ α ≤ hi (midpoint rule, n × n).
    let mass = |lo: f64, hi: f64, n: usize| {
        let d = (hi - lo) / n as f64;
        let mut m = 0.0;
        for i in 0..n {
            for j in 0..=i {
                let w = if i == j { 0.5 } else { 1.0 };
                m += w * mu(lo + (i as f64 + 0.5) * d, lo + (j as f64 + 0.5) * d) * d * d;
            }
        }
        m
    };
    let total = mass(-h_max, h_max, 1200);
    let step = 2.0 * h_max / (PREISACH_LEVELS - 1) as f64;
    // A bias at the centre of a cell, reached from positive saturation (descending branch).
    let bias = -h_max + step * 18.5;
    let swing = |dh: f64| {
        let mut s = p.demagnetized();
        drive(&p, &mut s, &[h_max as f32, bias as f32, (bias - dh) as f32], 40);
        let low = p.output(&s) as f64;
        let high = drive(&p, &mut s, &[(bias + dh) as f32], 40) as f64;
        // Back down the descending branch: half-way, M lies above the ascending branch's.
        let up_mid = {
            let mut t = s;
            drive(&p, &mut t, &[(bias - dh) as f32, bias as f32], 40) as f64
        };
        let down_mid = drive(&p, &mut s, &[bias as f32], 40) as f64;
        (high - low, down_mid - up_mid)
    };
    for dh in [step / 16.0, step / 8.0] {
        let (swing_model, opening) = swing(dh);
        let swing_true = 2.0 * P.ms_a_per_m as f64 * mass(bias - dh, bias + dh, 200) / total;
        let ratio = swing_model / swing_true;
        assert!((0.6..1.6).contains(&ratio), "ΔH {dh:.0}: swing {swing_model:.1} vs {swing_true:.1} A/m");
        assert!(opening > 0.0, "ΔH {dh:.0}: the loop does not open ({opening})");
    }
    let growth = swing(step / 8.0).0 / swing(step / 16.0).0;
    assert!((growth - 4.0).abs() < 0.2, "swing grows {growth:.2}× for twice the amplitude, not ∝ ΔH²");
}

/// The interaction spread slants the loop and leaves its width: the coercive field (M = 0 on
/// the ascending major branch) stays near h_c while the slope there falls.
#[test]
fn a_wider_interaction_spread_slants_the_loop_without_widening_it() {
    let branch = |su: f32| {
        let p = Preisach::new(PreisachParams {
            spread_a_per_m: 1500.0,
            interaction_spread_a_per_m: Some(su),
            ..P
        })
        .unwrap();
        let mut s = PreisachState::default();
        (0..=600).map(|k| -30_000.0 + 100.0 * k as f32).map(|h| (h, p.step(&mut s, h))).collect::<Vec<_>>()
    };
    let crossing = |b: &[(f32, f32)]| {
        let k = b.iter().position(|&(_, m)| m >= 0.0).unwrap();
        let ((h0, m0), (h1, m1)) = (b[k - 1], b[k]);
        let h = h0 + (h1 - h0) * (-m0) / (m1 - m0);
        (h, (m1 - m0) / (h1 - h0))
    };
    let (hc_narrow, slope_narrow) = crossing(&branch(5000.0));
    let (hc_wide, slope_wide) = crossing(&branch(30_000.0));
    for hc in [hc_narrow, hc_wide] {
        assert!((hc - P.coercive_a_per_m).abs() < 0.25 * P.coercive_a_per_m, "coercive field {hc}");
    }
    assert!(slope_narrow > 3.0 * slope_wide, "slopes {slope_narrow} vs {slope_wide}");
}

#[test]
fn wiping_out_forgets_an_inner_loop() {
    let p = model();
    let mut a = PreisachState::default();
    let mut b = PreisachState::default();
    drive(&p, &mut a, &[20_000.0, -5000.0, 30_000.0], 50);
    drive(&p, &mut b, &[20_000.0, -5000.0, 12_000.0, 2000.0, 30_000.0], 50);
    // Passing 20 kA/m wiped (12, 2) kA/m and (20, −5) kA/m: same memory, same output.
    assert_eq!(a.turning_points(), b.turning_points());
    assert_eq!(p.output(&a), p.output(&b));
    assert_eq!(a.turning_points(), &[30_000.0]);
}

#[test]
fn minor_loops_between_the_same_extrema_are_congruent() {
    // Two different histories, then the same cycle between 5 and 15 kA/m: the minor loops
    // are translated copies (congruency property).
    let p = model();
    let mut a = PreisachState::default();
    let mut b = PreisachState::default();
    drive(&p, &mut a, &[40_000.0, 5000.0], 40);
    drive(&p, &mut b, &[25_000.0, -20_000.0, 20_000.0, 5000.0], 40);
    let (a0, b0) = (p.output(&a), p.output(&b));
    assert!((a0 - b0).abs() > 1e3, "histories should differ");
    for k in 0..=20 {
        let h = 5000.0 + 500.0 * k as f32;
        let da = p.step(&mut a, h) - a0;
        let db = p.step(&mut b, h) - b0;
        assert!((da - db).abs() < 1e-3 * P.ms_a_per_m, "ascending at {h}: {da} vs {db}");
    }
    for k in 0..=20 {
        let h = 15_000.0 - 500.0 * k as f32;
        let da = p.step(&mut a, h) - a0;
        let db = p.step(&mut b, h) - b0;
        assert!((da - db).abs() < 1e-3 * P.ms_a_per_m, "descending at {h}: {da} vs {db}");
    }
}

/// The relay plane's output with an unbounded memory (the test's oracle): the same
/// wiping-out rule and Everett sum, on a `Vec`.
fn unbounded_relay_output(t: &EverettTable, path: &[f32]) -> std::vec::Vec<f32> {
    let h_max = t.h_max_a_per_m();
    let mut pts: std::vec::Vec<f32> = std::vec::Vec::new();
    let mut out = std::vec::Vec::new();
    for &h in path {
        let n = pts.len();
        let rising = n % 2 == 1;
        if n > 0 && ((rising && h >= pts[n - 1]) || (!rising && h <= pts[n - 1])) {
            pts[n - 1] = h;
        } else {
            pts.push(h);
        }
        while pts.len() >= 3 {
            let n = pts.len();
            let is_max = n % 2 == 1;
            if (is_max && pts[n - 1] >= pts[n - 3]) || (!is_max && pts[n - 1] <= pts[n - 3]) {
                pts[n - 3] = pts[n - 1];
                pts.truncate(n - 2);
            } else {
                break;
            }
        }
        let (mut m_prev, mut up) = (-h_max, 0.0);
        for pair in pts.chunks(2) {
            let m_next = pair.get(1).copied().unwrap_or(pair[0]);
            up += t.everett(pair[0], m_prev) - t.everett(pair[0], m_next);
            m_prev = m_next;
        }
        out.push(2.0 * up - t.total());
    }
    out
}

/// Steps `p` (relays only) along `path`: its largest distance from an unbounded memory's
/// output [A/m] and the deepest its memory got.
fn against_unbounded_memory(p: &Preisach, path: &[f32]) -> (f32, usize) {
    let exact = unbounded_relay_output(p.table(), path);
    let mut s = PreisachState::default();
    let (mut worst, mut deepest) = (0.0_f32, 0);
    for (&h, &m_exact) in path.iter().zip(&exact) {
        let m = p.step(&mut s, h);
        deepest = deepest.max(s.turning_points().len());
        worst = worst.max((m - m_exact).abs());
    }
    (worst, deepest)
}

#[test]
fn a_full_memory_merges_the_pair_that_changes_the_output_least() {
    // A shrinking oscillation whose minima rise faster than its maxima fall (a voltage-driven
    // chirp: the current's amplitude falls with frequency while its mean settles) nests a
    // new minor loop inside the last at every reversal, so the memory fills after
    // PREISACH_MEMORY / 2 cycles and merges from then on. Against an unbounded memory the
    // output stays within 0.5 % M_s (0.02 % measured with 48 points; 0.09 % with 16 on a
    // 14-cycle path). Dropping the innermost loop (the merge before) put M on the branch
    // from an older minimum at every reversal: 0.8 % M_s off on that path, jumps of up to
    // 28 kA/m on the independent rig's chirp.
    // Narrow coercivities and a wide interaction field, as fitted to the rig: M moves
    // little inside a small loop and much along an outer branch.
    let p = Preisach::new(PreisachParams {
        coercive_a_per_m: 2500.0,
        spread_a_per_m: 800.0,
        interaction_spread_a_per_m: Some(30_000.0),
        h_max_a_per_m: 80_000.0,
        ..P
    })
    .unwrap();
    let mut path = std::vec![20_000.0_f32];
    for cycle in 0..48 {
        let shrink = 0.92_f32.powi(cycle);
        for to in [20_000.0 + 4000.0 * shrink, 20_000.0 - 12_000.0 * shrink] {
            let from = *path.last().unwrap();
            path.extend((1..=50).map(|n| from + (to - from) * n as f32 / 50.0));
        }
    }
    let (worst, deepest) = against_unbounded_memory(&p, &path);
    assert_eq!(deepest, PREISACH_MEMORY, "the memory should have filled");
    assert!(
        worst < 5e-3 * P.ms_a_per_m,
        "{:.2} % M_s from the unbounded memory",
        100.0 * worst / P.ms_a_per_m
    );
}

#[test]
fn a_chirp_through_a_coil_stays_within_the_memory() {
    // A voltage-driven log chirp, 20 Hz–2.5 kHz in 0.4 s at 10 kHz, through a coil's L/R
    // (corner 300 Hz) about a bias: the current's amplitude falls with frequency, so each
    // reversal nests a loop inside the last — the independent rig's fit chirp. With 16
    // turning points the memory merged from the ninth cycle on and the complete `preisach`
    // structure fitted that file to 3.3 % and validated at 3.7 % (mean of four files); with
    // 48, 1.4 % and 3.1 % (64 and 192: 1.4 % and 3.05 %; `GMA_BUDGET_LAW=preisach` error
    // budget).
    // Measured here: 0.13 % M_s from an unbounded memory with 48, 0.91 % with 16.
    let p = Preisach::new(PreisachParams {
        coercive_a_per_m: 3000.0,
        spread_a_per_m: 1500.0,
        interaction_spread_a_per_m: Some(25_000.0),
        h_max_a_per_m: 80_000.0,
        ..P
    })
    .unwrap();
    let (rate, duration, f0, f1) = (10_000.0_f64, 0.4, 20.0_f64, 2500.0_f64);
    let k = (f1 / f0).ln() / duration;
    let lowpass = 1.0 - (-2.0 * core::f64::consts::PI * 300.0 / rate).exp();
    let mut current = 0.0;
    let path: std::vec::Vec<f32> = (0..(rate * duration) as usize)
        .map(|n| {
            let t = n as f64 / rate;
            let phase = 2.0 * core::f64::consts::PI * f0 * ((k * t).exp() - 1.0) / k;
            current += lowpass * (phase.sin() - current);
            (20_000.0 + 15_000.0 * current) as f32
        })
        .collect();
    let (worst, deepest) = against_unbounded_memory(&p, &path);
    assert_eq!(deepest, PREISACH_MEMORY, "the chirp should fill the memory");
    assert!(
        worst < 3e-3 * P.ms_a_per_m,
        "{:.2} % M_s from the unbounded memory",
        100.0 * worst / P.ms_a_per_m
    );
}

/// A user's own density (here a Gaussian in coercivity and interaction): saturation at the
/// given total, a table `new` accepts as it stands, a zero or infinite density refused.
#[test]
fn a_table_from_any_density() {
    let gauss = |a: f32, b: f32| {
        let (h, u) = (0.5 * (a - b) - 3000.0, 0.5 * (a + b));
        libm::expf(-(h * h) / (2.0 * 1500.0f32.powi(2)) - (u * u) / (2.0 * 20_000.0f32.powi(2)))
    };
    let t = EverettTable::from_density(8e4, 7.6e5, gauss).unwrap();
    assert!((t.total() - 7.6e5).abs() < 1e-4 * 7.6e5, "total {}", t.total());
    let revalidated = EverettTable::new(8e4, t.values()).unwrap();
    for (i, j) in [(31, 0), (20, 10), (16, 15), (5, 2)] {
        let (x, y) = (t.values()[i][j], revalidated.values()[i][j]);
        assert!((x - y).abs() <= 1e-5 * 7.6e5, "E[{i}][{j}]: {x} vs {y}");
    }
    let refused =
        Err(ParamError::OutOfRange("preisach density", "positive and finite somewhere in the relay plane"));
    assert_eq!(EverettTable::from_density(8e4, 7.6e5, |_, _| 0.0), refused);
    assert_eq!(EverettTable::from_density(8e4, 7.6e5, |_, _| f32::INFINITY), refused);
    assert!(EverettTable::from_density(0.0, 7.6e5, gauss).is_err());
}

#[test]
fn bad_tables_are_named() {
    let mut e = model().table().values();
    e[10][3] = f32::NAN;
    assert_eq!(EverettTable::new(8e4, e), Err(ParamError::NonFinite("preisach.everett")));
    let mut e = model().table().values();
    e[10][3] = e[10][4] * 1.5 + 1.0; // E must fall with β
    assert!(matches!(EverettTable::new(8e4, e), Err(ParamError::OutOfRange("preisach.everett", _))));
    let bad = PreisachParams { coercive_a_per_m: 9e4, ..P };
    assert!(matches!(Preisach::new(bad), Err(ParamError::OutOfRange("preisach.coercive_a_per_m", _))));
    for rho in [-0.1, 0.95, f32::NAN] {
        let bad = PreisachParams { reversible_fraction: Some(rho), ..P };
        assert!(matches!(Preisach::new(bad), Err(ParamError::OutOfRange("preisach.reversible_fraction", _))));
    }
    let bad = PreisachParams { reversible_field_a_per_m: Some(0.0), ..P_REV };
    assert!(Preisach::new(bad).is_err());
}

/// A table whose grid or output f32 cannot hold is refused by name: H_max subnormal (1e-40:
/// NaN), a total near f32::MAX (2e38: an infinite output), entries far beyond the total
/// (relay weights overflowing). At the bounds the output is finite.
#[test]
fn a_table_beyond_f32_is_refused_by_name() {
    // E(α_i, β_j) = total ((i − j)/(L − 1))²: a valid table, zero on the diagonal.
    let table = |total: f32| {
        let mut e = [[0.0f32; PREISACH_LEVELS]; PREISACH_LEVELS];
        for i in 0..PREISACH_LEVELS {
            for j in 0..i {
                let d = (i - j) as f32 / (PREISACH_LEVELS - 1) as f32;
                e[i][j] = total * d * d;
            }
        }
        e
    };
    let name = |h_max, e| EverettTable::new(h_max, e).err().map(|e| e.name());
    assert_eq!(name(1e-40, table(6e5)), Some("preisach.h_max_a_per_m"));
    assert_eq!(name(8e4, table(2e38)), Some("preisach.everett"));
    let mut overflowing = table(6e5);
    overflowing[20][3] = 3e38;
    overflowing[20][4] = -3e38;
    assert_eq!(name(8e4, overflowing), Some("preisach.everett"));
    for (h_max, total) in [(1.0, 1e3), (1e7, 1e7)] {
        let p = Preisach::from_table(EverettTable::new(h_max, table(total)).unwrap());
        let mut s = p.demagnetized();
        let m = [p.step(&mut s, 0.3 * h_max), p.step(&mut s, h_max), p.step(&mut s, -h_max)];
        assert!(m.iter().all(|m| m.is_finite() && m.abs() <= total), "{m:?}");
    }
}

/// The reversible part: M = (1 − ρ) M_P + ρ M_s tanh(H/h_r) along any path; right after a
/// reversal the relays barely move (only the diagonal cells' linear interpolation), so
/// the reversible part gives most of the slope; far out the output goes on towards M_s;
/// ρ = 0 given explicitly is the relay plane bit for bit.
#[test]
fn the_reversible_part_adds_to_the_relays() {
    let (p, relays) = (Preisach::new(P_REV).unwrap(), model());
    let (rho, h_r, ms) = (0.2f64, 20_000.0f64, P.ms_a_per_m as f64);
    let (mut s, mut r) = (p.demagnetized(), relays.demagnetized());
    for h in [30_000.0, 10_000.0, 10_020.0, -45_000.0, 5000.0, -2000.0, 70_000.0] {
        let (m, m_relays) = (p.step(&mut s, h) as f64, relays.step(&mut r, h) as f64);
        let expected = (1.0 - rho) * m_relays + rho * ms * (h as f64 / h_r).tanh();
        assert!((m - expected).abs() < 1e-5 * ms, "at {h} A/m: {m} vs {expected}");
    }
    // The slope 20 A/m after a reversal at 10 kA/m: the reversible part's is
    // ρ M_s/h_r · sech²(H/h_r), and it is most of it.
    let (mut s, mut r) = (p.demagnetized(), relays.demagnetized());
    drive(&p, &mut s, &[30_000.0, 10_000.0], 50);
    drive(&relays, &mut r, &[30_000.0, 10_000.0], 50);
    let slope = |m: &Preisach, st: &mut PreisachState| {
        let m0 = m.output(st) as f64;
        (m.step(st, 10_020.0) as f64 - m0) / 20.0
    };
    let reversible = rho * ms / h_r / (10_000.0 / h_r).cosh().powi(2);
    let (total, of_relays) = (slope(&p, &mut s), slope(&relays, &mut r));
    assert!(of_relays < 0.5 * reversible, "relays' slope {of_relays}, reversible {reversible}");
    assert!((total - (1.0 - rho) * of_relays - reversible).abs() < 0.02 * reversible);
    // Beyond H_max the relays are saturated and the reversible part still rises.
    assert!((p.step(&mut s, 1e6) as f64 - ms).abs() < 1e-4 * ms);
    assert!(p.step(&mut s, 6e4) < p.step(&mut s, 8e4));
    let zero = Preisach::new(PreisachParams { reversible_fraction: Some(0.0), ..P }).unwrap();
    let (mut a, mut b) = (zero.demagnetized(), relays.demagnetized());
    for h in [12_000.0, -7000.0, 3000.0, 80_000.0, -1e5] {
        assert_eq!(zero.step(&mut a, h).to_bits(), relays.step(&mut b, h).to_bits());
    }
}

/// The evaluation the inverse uses instead of stepping a copy of the state gives the copy's
/// output bit for bit, but when the step would merge turning points (a full memory), and
/// then within the merge's own error; the pair sums kept between samples solve exactly as
/// sums made afresh from the points do. Along a decaying oscillation about a bias that fills
/// the memory, with saturation both ways (the resets), with and without the reversible
/// part. Every target the branch can reach is met to 10⁻⁵ M_s (to the merge's error in
/// the steps that merge).
#[test]
fn the_inverse_evaluates_as_a_step_would() {
    for params in [P, P_REV] {
        let p = Preisach::new(params).unwrap();
        let ms = params.ms_a_per_m;
        let (mut kept, mut fresh) = (p.demagnetized(), p.demagnetized());
        let (mut sums, mut fresh_sums) = (InverseCache::default(), InverseCache::default());
        let (mut merged, mut exact, mut worst_merged) = (0, 0, 0.0f32);
        let range = if params.reversible_fraction.is_some() { 6e4 + 4.0 * 2e4 } else { 6e4 };
        for n in 0..3000 {
            let target = if n % 700 == 650 {
                let side = if n % 1400 == 650 { 1.2 } else { -1.2 };
                side * ms
            } else {
                let decay = libm::expf(-(n % 700) as f32 / 250.0);
                ms * (0.15 + 0.8 * decay * libm::sinf(0.37 * n as f32))
            };
            let near = crate::math::within(kept.h, 1e5);
            for h in [-9e4, -2e4, -1.0, 0.0, 3e3, 1.7e4, 5.9e4, 9e4].map(|d: f32| d + 0.25 * near) {
                let (v, is_exact) = p.trial_output(&kept, &mut sums, h);
                let stepped = p.step(&mut { kept }, h);
                if is_exact {
                    assert_eq!(v.to_bits(), stepped.to_bits(), "sample {n}, field {h}");
                    exact += 1;
                } else {
                    worst_merged = worst_merged.max((v - stepped).abs());
                    merged += 1;
                }
            }
            let before = (kept, sums);
            fresh_sums.valid = 0; // the sums again from the points, the slope kept
            let a = p.field_for_with(&mut kept, &mut sums, target);
            let b = p.field_for_with(&mut fresh, &mut fresh_sums, target);
            assert_eq!(a.to_bits(), b.to_bits(), "sample {n}: field {a} vs {b}");
            assert_eq!(kept, fresh, "sample {n}");
            let got = p.output(&kept);
            let merging = !p.trial_output(&before.0, &mut { before.1 }, a).1;
            let tol = if merging { 3e-3 * ms } else { 1e-5 * ms };
            assert!(
                (got - target).abs() <= tol || a.abs() == range,
                "sample {n}: target {target}, got {got} at {a} A/m"
            );
        }
        assert!(merged > 100 && exact > 10_000, "{merged} merging trials, {exact} exact");
        assert!(worst_merged <= 3e-3 * ms, "a merge moved the output {worst_merged} A/m");
    }
}

/// Every target a move from a state can reach, the inverse meets to 10⁻⁵ M_s within 20
/// evaluations: two-move paths over a grid from one range end to the other, with and without
/// the reversible part (and one with a narrow h_r, whose steep tanh a secant creeps along).
/// Measured: at most 16 (14, 15, 13 per set; 16 for −599 112 A/m after a saturating move).
/// The secant without its halving rule took 23 on the grid and 46 there, and, cut at 40,
/// stopped 0.49 % M_s short of it (found by review).
#[test]
fn the_inverse_meets_every_reachable_target() {
    let narrow = PreisachParams {
        reversible_fraction: Some(0.3),
        reversible_field_a_per_m: Some(2000.0),
        interaction_spread_a_per_m: Some(10_000.0),
        ..P
    };
    for params in [P, P_REV, narrow] {
        let p = Preisach::new(params).unwrap();
        let ms = params.ms_a_per_m;
        let grid: std::vec::Vec<f32> = (0..=24).map(|k| -2.0e5 + 4.0e5 * k as f32 / 24.0).collect();
        let mut most = 0;
        for &a in &grid {
            for &b in &grid {
                let mut s = p.demagnetized();
                p.step(&mut s, a);
                let target = p.step(&mut { s }, b);
                let (_, evaluations) = p.solve_field(&s, &mut p.inverse_cache(&s), target);
                most = most.max(evaluations);
                p.field_for(&mut s, target);
                let got = p.output(&s);
                assert!((got - target).abs() <= 1e-5 * ms, "{a} then {b}: target {target}, got {got}");
            }
        }
        assert!(most <= 20, "a solve took {most} evaluations");
    }
    let p = Preisach::new(P_REV).unwrap();
    let mut s = p.demagnetized();
    p.field_for(&mut s, 1.3 * P.ms_a_per_m);
    let (_, evaluations) = p.solve_field(&s, &mut p.inverse_cache(&s), -599_111.56);
    assert!(evaluations <= 20, "{evaluations} evaluations");
    p.field_for(&mut s, -599_111.56);
    assert!((p.output(&s) + 599_111.56).abs() <= 1e-5 * P.ms_a_per_m, "got {}", p.output(&s));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    /// Output bounded by ±M_s, finite, and the inverse finds the field again, with
    /// and without the reversible part.
    #[test]
    fn bounded_and_invertible(
        path in proptest::collection::vec(-2.0e5f32..2.0e5, 1..40),
        reversible in proptest::bool::ANY,
    ) {
        let p = Preisach::new(if reversible { P_REV } else { P }).unwrap();
        let mut s = p.demagnetized();
        for &h in &path {
            let m = p.step(&mut s, h);
            prop_assert!(m.is_finite() && m.abs() <= P.ms_a_per_m * 1.0001);
        }
        // Inverse: from a copy of the state before the last move, find the field for m.
        let mut before = p.demagnetized();
        for &h in &path[..path.len() - 1] {
            p.step(&mut before, h);
        }
        let target = p.output(&s);
        let mut inv = before;
        let h = p.field_for(&mut inv, target);
        prop_assert!((p.output(&inv) - target).abs() <= 1e-5 * P.ms_a_per_m,
            "target {} got {} (h {} vs {})", target, p.output(&inv), h, path[path.len() - 1]);
    }
}
