//! Train ResNeuroKin-D (silhouette + metric depth), evaluate it and write reports/resneurokin_d. Its paper preset needs a GPU to finish in minutes (--device wgpu); on a CPU use --steps for a shortened run.
//!
//! `cargo run --release --bin resneurokin_d -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("resneurokin_d", "paper")
}
