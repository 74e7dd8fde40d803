//! Table II settled: EMSSL and DSL over seeds at +-90 degrees, DSL given EMSSL's optimiser
//! steps and DSL through the exact forward kinematics; writes reports/emssl_seeds.
//!
//! `cargo run --release --bin emssl_seeds -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("emssl_seeds", "paper")
}
