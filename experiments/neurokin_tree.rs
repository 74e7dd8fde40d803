//! Train NeuroKin with the kinematic-tree encoder (message passing down the robot's joints, at
//! the flat encoder's parameter count), evaluate it and write reports/neurokin_tree; for robots
//! of many joints (`--urdf ... --joints all`).
//!
//! `cargo run --release --bin neurokin_tree -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("neurokin_tree", "paper")
}
