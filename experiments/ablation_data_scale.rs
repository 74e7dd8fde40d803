//! NeuroKin ablation: 400, 2,000 and 12,000 samples, one shared test set (paper Section VI-B).
//!
//! `cargo run --release --bin ablation_data_scale -- --help`

use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{ExperimentArgs, run_main};

/// NeuroKin ablation: 400, 2,000 and 12,000 samples, one shared test set (paper Section VI-B).
#[derive(Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    common: ExperimentArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| args.common.run("ablation_data_scale", "paper"))
}
