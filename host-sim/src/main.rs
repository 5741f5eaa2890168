//! `gma`: the model workbench for giant-magnetostrictive actuators.

mod simulate;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use model_core::mechanics::{MassSpringDamper, MechState, SecondOrderZoh};

#[derive(Parser)]
#[command(name = "gma", version, about = "Model workbench for giant-magnetostrictive (Terfenol-D) actuators")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate an actuator (a model-core chain) under a standard excitation and write a
    /// measurement CSV (time_s, [command_V,] current_A, displacement_um). Simulated data, for
    /// tests and demos.
    Simulate(simulate::SimulateArgs),
    /// Natural frequency, damping ratio and step response of the actuator mechanics
    /// (m ÿ + c ẏ + k y = F, 001 eq. 14–15), discretised exactly at the loop rate.
    Mechanics {
        /// Moving mass m [kg].
        #[arg(long, default_value_t = 0.1)]
        mass_kg: f32,
        /// Viscous damping c [N s/m].
        #[arg(long, default_value_t = 3000.0)]
        damping_n_s_per_m: f32,
        /// Stiffness k [N/m].
        #[arg(long, default_value_t = 9.9e6)]
        stiffness_n_per_m: f32,
        /// Sample rate [Hz] of the discretisation.
        #[arg(long, default_value_t = 10_000.0)]
        sample_rate_hz: f32,
        /// Step force [N] for the printed step response.
        #[arg(long, default_value_t = 100.0)]
        force_n: f32,
    },
}

fn main() -> std::process::ExitCode {
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("gma: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate(a) => simulate::run(&a),
        Command::Mechanics { mass_kg, damping_n_s_per_m, stiffness_n_per_m, sample_rate_hz, force_n } => {
            let p = MassSpringDamper { mass_kg, damping_n_s_per_m, stiffness_n_per_m };
            let zoh = SecondOrderZoh::new(p, 1.0 / sample_rate_hz).context("mechanics parameters")?;
            println!("natural frequency f_n = {:.1} Hz", p.natural_frequency_hz());
            println!("damping ratio     ζ   = {:.3}", p.damping_ratio());
            println!("static compliance     = {:.4e} m/N", 1.0 / stiffness_n_per_m);
            println!("time_s,displacement_um");
            let mut s = MechState::default();
            for n in 0..20 {
                let y = zoh.step(&mut s, force_n);
                println!("{:.6},{:.6}", (n + 1) as f32 / sample_rate_hz, y * 1e6);
            }
            Ok(())
        }
    }
}
