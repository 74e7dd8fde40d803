//! NeuroKin ablation: 400, 2,000 and 12,000 samples, one shared test set (paper Section VI-B).
//!
//! `cargo run --release --bin ablation_data_scale -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("ablation_data_scale", "paper")
}
