//! `gma`: the model workbench for giant-magnetostrictive actuators (the command line lives in
//! `host_sim::cli`, one file per subcommand).

fn main() -> std::process::ExitCode {
    host_sim::cli::main()
}
