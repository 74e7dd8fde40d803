//! Read the body from images through the trained self-model: joint angles from a silhouette
//! and encoder drift from k images; writes reports/body_from_image.
//!
//! `cargo run --release --bin body_from_image -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("body_from_image", "paper")
}
