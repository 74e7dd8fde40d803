//! NeuroKin ablation: 2, 4 and 6 transposed convolutions (paper Section V-C2).
//!
//! `cargo run --release --bin ablation_depth -- --help`

use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{ExperimentArgs, run_main};

/// NeuroKin ablation: 2, 4 and 6 transposed convolutions (paper Section V-C2).
#[derive(Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    common: ExperimentArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| args.common.run("ablation_depth", "paper"))
}
