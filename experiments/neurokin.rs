//! Train NeuroKin (the notebook's architecture and the paper text's 64x64 variant), evaluate it and write reports/neurokin.
//!
//! `cargo run --release --bin neurokin -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("neurokin", "paper")
}
