//! Train NeuroKin (the notebook's architecture and the paper text's 64x64 variant), evaluate it and write reports/neurokin.
//!
//! `cargo run --release --bin neurokin -- --help`

use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{ExperimentArgs, run_main};

/// Train NeuroKin (the notebook's architecture and the paper text's 64x64 variant), evaluate it and write reports/neurokin.
#[derive(Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    common: ExperimentArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| args.common.run("neurokin", "paper"))
}
