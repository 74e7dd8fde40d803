//! What limits EMSSL: its schedule, exploration, warm start, batch, epochs per iteration, the
//! data each iteration trains on and the joint output, one knob at a time; writes
//! reports/emssl_study.
//!
//! `cargo run --release --bin emssl_study -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("emssl_study", "paper")
}
