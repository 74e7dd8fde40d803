//! Table I: every self-model of the registry on the same dataset, one row each, with the Pareto plot. The default preset (short) takes about 10 minutes on a 2-core CPU.
//!
//! `cargo run --release --bin table1 -- --help`

use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{ExperimentArgs, run_main};

/// Table I: every self-model of the registry on the same dataset, one row each, with the Pareto plot. The default preset (short) takes about 10 minutes on a 2-core CPU.
#[derive(Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    common: ExperimentArgs,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| args.common.run("table1", "short"))
}
