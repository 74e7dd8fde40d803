//! Train FFKSM (the reimplementation and the original authors' model), render it densely and with the accelerated marcher, from novel views, and write reports/ffksm.
//!
//! `cargo run --release --bin ffksm -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("ffksm", "paper")
}
