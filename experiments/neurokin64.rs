//! Train NeuroKin-64, the paper text's 64x64 variant (MSE), evaluate it and write reports/neurokin64. On the clean data it collapses to an empty image (a documented negative result, kept out of Table I); with --paper-compatible it trains.
//!
//! `cargo run --release --bin neurokin64 -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("neurokin64", "paper")
}
