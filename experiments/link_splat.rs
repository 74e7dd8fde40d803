//! Train LinkSplat (a direct decoder that sees where each link is: anchors on every link
//! placed by forward kinematics, splatted with learned features, decoded by a CNN), evaluate
//! it and write reports/link_splat; for robots of many joints (`--urdf ... --joints all`).
//!
//! `cargo run --release --bin link_splat -- --help`

use std::process::ExitCode;

fn main() -> ExitCode {
    selfmodel_lab::cli::experiment_main("link_splat", "paper")
}
