//! selfmodel: robots that learn models of themselves.
//!
//! A pure-Rust research framework on burn that reproduces and extends two papers: visual
//! self-models of a robot arm and learned inverse kinematics. This crate holds the library;
//! `experiments/` holds one thin binary per experiment. See `ARCHITECTURE.md`.

pub mod ablations;
pub mod accelerated_marcher;
pub mod arm4;
pub mod arm_change;
pub mod atomic_file;
pub mod bilinear_resize;
pub mod bvh;
pub mod camera;
pub mod cli;
pub mod compute_peak;
pub mod conditional_gan;
pub mod conv_gemm;
pub mod cpu_extension;
pub mod dataset;
pub mod decoder_bench;
pub mod decoder_experiment;
pub mod device;
pub mod dh_robot;
pub mod distal_learning;
pub mod emssl_learning_curve;
pub mod emssl_study;
pub mod error;
pub mod evaluation;
pub mod experiments;
pub mod fast_adaptation;
pub mod ffksm;
pub mod ffksm_step_bench;
pub mod field_gradients;
pub mod figures;
pub mod flow_ik;
pub mod gaussian_splatting;
pub mod ik_comparison;
pub mod ik_data;
pub mod inference_speed;
pub mod inverse_learning;
pub mod inverse_model;
pub mod k3dgs;
pub mod kinematic_gaussians;
pub mod kinematics;
pub mod link_calibration;
pub mod losses;
pub mod mesh_fidelity;
pub mod metrics;
pub mod model_result;
pub mod neurokin;
pub mod npz;
pub mod numerical_ik;
pub mod occupancy_field;
pub mod occupancy_grid;
pub mod positional_encoding;
pub mod preset;
pub mod preview;
pub mod primitive_fit;
pub mod ray_caster;
pub mod ray_marcher;
pub mod report;
pub mod resneurokin_d;
pub mod robot;
pub mod sampling_pass;
pub mod sampling_speed;
pub mod shape;
pub mod stl_mesh;
pub mod table1;
pub mod tensor_kinematics;
pub mod training;
pub mod trajectory;
pub mod upconv;
pub mod urdf_loader;
pub mod virtual_frame;

pub use error::{Error, Result};

/// mimalloc instead of the system allocator: training allocates and frees buffers of tens of
/// megabytes every step, which glibc returns to the kernel and faults back in (page faults
/// and TLB shootdowns were ~12% of a NeuroKin training step in `perf`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;
