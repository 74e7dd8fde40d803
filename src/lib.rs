//! selfmodel: robots that learn models of themselves.
//!
//! A pure-Rust research framework on burn that reproduces and extends two papers: visual
//! self-models of a robot arm and learned inverse kinematics. This crate is the library:
//! robots, their simulator, datasets, GPU and CPU kernels, training, evaluation, the
//! self-models, pose from images and inverse kinematics. The studies that reproduce the papers
//! and their binaries are the `selfmodel-lab` crate (`lab/`, `experiments/`). See
//! `ARCHITECTURE.md`.

pub mod body;
pub mod core;
pub mod data;
pub mod eval;
pub mod ik;
pub mod kernels;
pub mod report;
pub mod self_models;
pub mod sim;
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
