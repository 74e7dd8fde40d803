//! Table IV of the EMSSL paper: fast adaptation of the trained inverse model when every link
//! grows by 1, 3 or 5 cm (and, beyond the paper, when a link bends), by learned link
//! parameters or with the changed arm itself as the forward model, for the UR5 and arm4;
//! writes reports/emssl_adaptation.
//!
//! `cargo run --release --bin emssl_adaptation -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("emssl_adaptation", "paper")
}
