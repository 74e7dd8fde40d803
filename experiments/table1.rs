//! Table I: every self-model of the registry on the same dataset, one row each, with the Pareto plot. The default preset (short) took 247 s on a 2-core CPU.
//!
//! `cargo run --release --bin table1 -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("table1", "short")
}
