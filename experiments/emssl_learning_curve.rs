//! Figure 6 of the EMSSL paper: EMSSL's test error against iteration; writes
//! reports/emssl_learning_curve.
//!
//! `cargo run --release --bin emssl_learning_curve -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("emssl_learning_curve", "paper")
}
