//! Table III and Figure 7 of the EMSSL paper: the time of one EMSSL sampling pass under batch
//! inference and a parallel forward model, against batch size and threads, and the inverse
//! model's arithmetic rate against the machine's peak; writes reports/emssl_sampling_speed.
//!
//! `cargo run --release --bin emssl_sampling_speed -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("emssl_sampling_speed", "paper")
}
