//! Table II of the EMSSL paper: learned inverse kinematics (EMSSL, direct regression, distal
//! supervised learning, a conditional GAN) and a numerical solver, in two joint ranges; writes
//! reports/emssl_table2.
//!
//! `cargo run --release --bin emssl_table2 -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("emssl_table2", "paper")
}
