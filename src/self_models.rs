//! The visual self-models of the self-modeling paper: a model maps joint angles to the
//! robot's silhouette (and depth) seen by a camera. The direct decoders (NeuroKin,
//! ResNeuroKin-D) and their run (`decoder_run`), FFKSM (an occupancy field, ray marched) and
//! K-3DGS (Gaussians on the links, splatted), LinkSplat (a direct decoder fed where each link is), and `result`, the row of Table I each reports. `device_equivalence` trains one on the CPU and
//! on a GPU and compares them; `step_counts` counts what a training step asks of a GPU.

pub mod camera_input;
pub mod data_spec;
pub mod device_equivalence;
pub mod ffksm;
pub mod harness;
pub mod k3dgs;
pub mod link_splat;
pub mod loading;
pub mod mean_silhouette;
pub mod model;
pub mod nearest_pose;
pub mod neurokin;
pub mod own_robot;
pub mod resneurokin_d;
pub mod result;
pub mod run_config;
pub mod saved;
#[cfg(feature = "cube")]
pub mod step_counts;
pub mod tree_encoder;
