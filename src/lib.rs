//! selfmodel: robots that learn models of themselves.
//!
//! A pure-Rust research framework on burn that reproduces and extends two papers: visual
//! self-models of a robot arm and learned inverse kinematics. This crate holds the library;
//! `experiments/` holds one thin binary per experiment. See `ARCHITECTURE.md`.

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

pub use crate::core::error::{Error, Result};

/// mimalloc instead of the system allocator: training allocates and frees buffers of tens of
/// megabytes every step, which glibc returns to the kernel and faults back in (page faults
/// and TLB shootdowns were ~12% of a NeuroKin training step in `perf`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;
