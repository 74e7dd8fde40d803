//! Train ResNeuroKin-D (silhouette + metric depth), evaluate it and write reports/resneurokin_d. Its paper preset needs a GPU to finish in minutes (--device wgpu); on a CPU use --steps for a shortened run.
//!
//! `cargo run --release --bin resneurokin_d -- --help`

use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{ExperimentArgs, run_main};

/// Train ResNeuroKin-D (silhouette + metric depth), evaluate it and write reports/resneurokin_d. Its paper preset needs a GPU to finish in minutes (--device wgpu); on a CPU use --steps for a shortened run.
#[derive(Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    common: ExperimentArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| args.common.run("resneurokin_d", "paper"))
}
