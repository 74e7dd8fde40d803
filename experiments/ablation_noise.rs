//! NeuroKin ablation: input noise sigma 0 against 0.01 (paper Section V-C1).
//!
//! `cargo run --release --bin ablation_noise -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("ablation_noise", "paper")
}
