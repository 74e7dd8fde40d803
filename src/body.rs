//! Reading the body from what the camera sees: a trained self-model run backwards. The
//! self-modeling paper names the uses (section VI: drift correction, calibration); Dr. Robot
//! and RoboPEPP recover joint angles from one image the same way, through a differentiable
//! renderer.
//!
//! - [`pose`]: joint angles from a silhouette, by gradient descent on the angles through the
//!   model ([`crate::self_models::model::Render::differentiable`]) from several starts.
//! - [`amortised`]: a small CNN trained on the self-model's own renderings that maps an image
//!   to angles in one pass, alone and as the start of the refinement.
//! - [`drift`]: constant encoder offsets from k images and the angles the encoders report.
//! - [`calibration`]: link lengths from images, through a self-model that hangs on the
//!   kinematic chain (K-3DGS), its joint origins fitted with the Gaussians frozen.
//! - [`damage`]: damage detected and localised from k images at commanded poses, by the
//!   residual between the self-model and what the camera sees.
//! - [`observations`]: the images these read, checked (size, empty silhouettes, NaN angles)
//!   and perturbed as a real camera would (flipped pixels, an occluder, a shift).
//!
//! Every fit here is the one training loop ([`crate::train::trainer::Trainer`]) with the
//! unknowns as the module's parameters and the model's weights frozen.

pub mod amortised;
pub mod calibration;
pub mod damage;
pub mod descent;
pub mod drift;
pub mod observations;
pub mod pose;
