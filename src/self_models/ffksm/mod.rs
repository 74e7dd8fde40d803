//! FFKSM, the occupancy-field self-model (self-modeling paper section IV-B; Hu, Lin, Lipson
//! 2024): training with the centre-crop curriculum, evaluation with both ray marchers, novel
//! views and depth. The logic behind the `ffksm` binary and FFKSM's rows of `table1`.
//!
//! Training (the reimplementation's code): one image per step, all its rays (10,000 for
//! 100x100) marched densely with stratified samples, plain MSE between the rendered pixels and
//! the silhouette (a robot-pixel weight is an option: the paper's text says 5, its code used
//! none), Adam 5e-4 for 8,000 steps, and for the first 500 steps only the central 50x50
//! pixels (the curriculum). The original authors' variant crops for 200 steps and restarts
//! with a fresh model when training collapses to an all-black image (their code restarted
//! when the validation loss stopped changing, which is what an all-black model does).
//!
//! A run writes into its folder what every self-model's does (one row per renderer: dense
//! marching and the accelerated marcher, the same trained model). The trained renderer also
//! measures itself ([`FfksmRenderer::comparison`]): evaluations per image, images/s, PSNR,
//! and the accelerated image's PSNR against the dense one; and novel views, cameras turned
//! about the vertical through the point they look at, against the simulator's images.

pub mod accelerated_marcher;
mod config;
pub mod dense_step;
pub mod encoding;
mod evaluation;
pub mod field;
pub mod grid;
pub mod marcher;
mod renderer;
mod self_model;
mod training;
pub mod virtual_frame;

pub use config::{
    CollapseRestart, Curriculum, DenseGradients, Ffksm, FfksmVariant, TrainMarcher, ffksm_run,
};
pub use evaluation::{NovelViewRow, RendererRow};
pub use renderer::{FfksmComparison, FfksmRenderer};
pub use training::{centre_crop, weighted_mse};
