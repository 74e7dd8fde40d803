//! Beyond one camera: NeuroKin camera-conditioned and multi-head on N cameras, tested on
//! cameras never trained on against FFKSM, K-3DGS and the view-blind bound; writes
//! reports/multiview.
//!
//! `cargo run --release --bin multiview -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("multiview", "paper")
}
