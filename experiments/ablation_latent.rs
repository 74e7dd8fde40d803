//! NeuroKin ablation: latent width 256, 512, 1024 and 2048 (paper Section V-C3).
//!
//! `cargo run --release --bin ablation_latent -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("ablation_latent", "paper")
}
