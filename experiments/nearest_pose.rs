//! The nearest-pose lookup table, a baseline of Table I: each test pose answered by the training images of the nearest training pose; writes reports/nearest_pose.
//!
//! `cargo run --release --bin nearest_pose -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("nearest_pose", "paper")
}
