//! Train K-3DGS (Gaussians on the robot's kinematic chain), evaluate it, time culled against dense splatting, and write reports/k3dgs.
//!
//! `cargo run --release --bin k3dgs -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("k3dgs", "paper")
}
