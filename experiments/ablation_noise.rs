//! NeuroKin ablation: input noise sigma 0 against 0.01 (paper Section V-C1).
//!
//! `cargo run --release --bin ablation_noise -- --help`

use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{ExperimentArgs, run_main};

/// NeuroKin ablation: input noise sigma 0 against 0.01 (paper Section V-C1).
#[derive(Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    common: ExperimentArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| args.common.run("ablation_noise", "paper"))
}
