//! The best constant image (the mean training silhouette), the floor of Table I; writes reports/mean_silhouette.
//!
//! `cargo run --release --bin mean_silhouette -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("mean_silhouette", "paper")
}
