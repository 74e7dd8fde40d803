//! Damage to the arm detected and localised from k images through NeuroKin trained on the
//! healthy arm; writes reports/damage.
//!
//! `cargo run --release --bin damage -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("damage", "paper")
}
