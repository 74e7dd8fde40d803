//! selfmodel: robots that learn models of themselves.
//!
//! A pure-Rust research framework on burn that reproduces and extends two papers: visual
//! self-models of a robot arm and learned inverse kinematics. This crate holds the library;
//! `experiments/` holds one thin binary per experiment. See `ARCHITECTURE.md`.

pub mod body;
pub mod cli;
pub mod core;
pub mod data;
pub mod eval;
pub mod ik;
pub mod kernels;
pub mod report;
pub mod self_models;
pub mod sim;
pub mod studies;
pub mod train;

// The types a user needs, from where they live.
pub use crate::core::error::{Error, Result};
pub use crate::core::preset::Preset;
pub use crate::data::dataset::{Dataset, DatasetConfig};
pub use crate::ik::data::{IkData, IkDataConfig};
pub use crate::self_models::{
    data_spec::DataSpec,
    model::{Render, SelfModel},
    run_config::SelfModelRun,
};
pub use crate::sim::robot::Robot;
pub use crate::sim::robots::{BuiltinRobot, RobotSpec};
pub use crate::studies::registry::{EXPERIMENTS, Experiment, RunOptions};

/// mimalloc instead of the system allocator: training allocates and frees buffers of tens of
/// megabytes every step, which glibc returns to the kernel and faults back in (page faults
/// and TLB shootdowns were ~12% of a NeuroKin training step in `perf`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;
