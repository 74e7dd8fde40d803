//! The GPU path on wgpu (lavapipe, Mesa's software Vulkan, in CI), in one test binary behind
//! the `wgpu` feature: `cargo test --release --features wgpu --test gpu -- --test-threads=1`.
//! - `kernels`: our CubeCL kernels (Adam, batch norm, the logit cross-entropy, convolutions)
//!   against burn's operations;
//! - `counts`: the kernel launches and host reads of a NeuroKin training step;
//! - `equivalence`: NeuroKin, K-3DGS and FFKSM trained on wgpu and on the CPU from one seed.
//!
//! One binary (one link of the GPU build, not three), run on one thread: `counts` counts every
//! launch of the process, and the NeuroKin tests share their shapes so that the kernels one
//! compiles and tunes (minutes on lavapipe) serve the other. CI runs the NeuroKin tests in one
//! process (`neurokin`) beside the rest in another (`--skip neurokin`), two cores, two
//! compilers.
#![cfg(feature = "wgpu")]

#[allow(dead_code)]
mod common;

#[path = "gpu/counts.rs"]
mod counts;
#[path = "gpu/equivalence.rs"]
mod equivalence;
#[path = "gpu/kernels.rs"]
mod kernels;
