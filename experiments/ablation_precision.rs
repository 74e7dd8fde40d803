//! NeuroKin trained in f32, bf16, f16 and flex32 (autocast): PSNR and speed of each precision.
//!
//! `cargo run --release --bin ablation_precision -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("ablation_precision", "paper")
}
