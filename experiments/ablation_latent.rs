//! NeuroKin ablation: latent width 256, 512, 1024 and 2048 (paper Section V-C3).
//!
//! `cargo run --release --bin ablation_latent -- --help`

use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{ExperimentArgs, run_main};

/// NeuroKin ablation: latent width 256, 512, 1024 and 2048 (paper Section V-C3).
#[derive(Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    common: ExperimentArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| args.common.run("ablation_latent", "paper"))
}
