//! NeuroKin ablation: 2, 4 and 6 transposed convolutions (paper Section V-C2).
//!
//! `cargo run --release --bin ablation_depth -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("ablation_depth", "paper")
}
