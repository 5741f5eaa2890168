//! `gma mechanics`: the actuator's mass–spring–damper, discretised exactly at the loop rate.

use anyhow::{bail, Context, Result};
use clap::Args;
use model_core::mechanics::{MassSpringDamper, MechState, SecondOrderZoh};
use serde_json::json;

/// Options of `gma mechanics`.
#[derive(Args)]
pub struct MechanicsArgs {
    /// Moving mass m [kg].
    #[arg(long, default_value_t = 0.1, value_parser = f32_as_typed)]
    pub mass_kg: f32,
    /// Viscous damping c [N s/m].
    #[arg(long, default_value_t = 3000.0, value_parser = f32_as_typed)]
    pub damping_n_s_per_m: f32,
    /// Stiffness k [N/m].
    #[arg(long, default_value_t = 9.9e6, value_parser = f32_as_typed)]
    pub stiffness_n_per_m: f32,
    /// Sample rate [Hz] of the discretisation.
    #[arg(long, default_value_t = 10_000.0, value_parser = f32_as_typed)]
    pub sample_rate_hz: f32,
    /// Step force [N] for the printed step response.
    #[arg(long, default_value_t = 100.0, value_parser = f32_as_typed)]
    pub force_n: f32,
    /// Print exactly one JSON object on stdout (the text goes to stderr).
    #[arg(long)]
    pub json: bool,
}

/// A number for an f32 option, refused as typed when beyond f32's range (parsed straight to f32,
/// 1e39 became inf and the refusal said "got inf").
fn f32_as_typed(s: &str) -> std::result::Result<f32, String> {
    let v: f64 = s.trim().parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && v.abs() > f64::from(f32::MAX) {
        return Err(format!("{s} is beyond single precision (at most 3.4e38 in magnitude)"));
    }
    Ok(v as f32)
}

/// Samples of the printed step response.
const STEP_SAMPLES: u32 = 20;

/// Runs `gma mechanics`.
pub fn run(a: &MechanicsArgs) -> Result<()> {
    for (name, v) in [
        ("--mass-kg", a.mass_kg),
        ("--stiffness-n-per-m", a.stiffness_n_per_m),
        ("--sample-rate-hz", a.sample_rate_hz),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} must be a positive number, got {v}");
        }
    }
    if !(a.damping_n_s_per_m.is_finite() && a.damping_n_s_per_m >= 0.0) {
        bail!("--damping-n-s-per-m must be ≥ 0, got {}", a.damping_n_s_per_m);
    }
    if !a.force_n.is_finite() {
        bail!("--force-n must be a finite number, got {}", a.force_n);
    }
    let p = MassSpringDamper {
        mass_kg: a.mass_kg,
        damping_n_s_per_m: a.damping_n_s_per_m,
        stiffness_n_per_m: a.stiffness_n_per_m,
    };
    let zoh = SecondOrderZoh::new(p, 1.0 / a.sample_rate_hz).context("mechanics parameters")?;
    // Within what a model's `mech` accepts at this sample rate (f_n, ζ and a step that decays in
    // f32): outside it the printed response would be rounding, not mechanics.
    let modal = model_core::chain::ModalMechanics {
        natural_frequency_hz: p.natural_frequency_hz() as f32,
        damping_ratio: p.damping_ratio() as f32,
    };
    if let Err(e) = modal.discretised(1.0 / a.sample_rate_hz) {
        bail!(
            "--mass-kg {:?}, --damping-n-s-per-m {:?}, --stiffness-n-per-m {:?} give f_n = {:.4e} Hz, ζ = {:.4e}, which the \
             discretised mechanics at {:?} Hz does not hold: {e}",
            a.mass_kg,
            a.damping_n_s_per_m,
            a.stiffness_n_per_m,
            modal.natural_frequency_hz,
            modal.damping_ratio,
            a.sample_rate_hz
        );
    }
    let j = a.json;
    let compliance_m_per_n = 1.0 / f64::from(a.stiffness_n_per_m);
    say!(j, "natural frequency f_n = {:.1} Hz", p.natural_frequency_hz());
    say!(j, "damping ratio     ζ   = {:.3}", p.damping_ratio());
    say!(j, "static compliance     = {compliance_m_per_n:.4e} m/N");
    say!(j, "time_s,displacement_um");
    // The rows as `gma` writes recordings: time with the decimals that resolve the sample period,
    // the displacement in its shortest single-precision form (a fixed 6 decimals printed 1e-7 s
    // steps and sub-pm displacements as 0).
    let decimals = crate::recording::time_decimals(1.0 / f64::from(a.sample_rate_hz));
    let mut s = MechState::default();
    let mut step = Vec::new();
    for n in 0..STEP_SAMPLES {
        let y_um = zoh.step(&mut s, a.force_n) * 1e6;
        let t_s = f64::from(n + 1) / f64::from(a.sample_rate_hz);
        say!(j, "{t_s:.decimals$},{y_um:?}");
        step.push(json!({"time_s": t_s, "displacement_um": stated(y_um)}));
    }
    if j {
        out!(
            "{}",
            json!({
                "natural_frequency_hz": p.natural_frequency_hz(),
                "damping_ratio": p.damping_ratio(),
                "static_compliance_m_per_n": compliance_m_per_n,
                "sample_rate_hz": stated(a.sample_rate_hz),
                "force_n": stated(a.force_n),
                "step_response": step,
            })
        );
    }
    Ok(())
}

/// A single-precision value as its shortest decimal (0.0002, not 0.00019999999494757503).
fn stated(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::from(v))
}
