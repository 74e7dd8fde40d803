//! Learned inverse kinematics (the EMSSL paper). `method` is the IkMethod trait that Table II
//! runs; the methods are `drl` (direct regression), `emssl` (the paper's method), `dsl`
//! (distal supervised learning), `cgan` (conditional GAN), `flow` (a normalizing flow, many
//! solutions) and `dls` (damped least squares, numerical). Beneath them: the data (`data`),
//! the inverse MLP (`mlp`), the fitting they share (`learning`), link calibration and
//! EMSSL's batched sampling pass. `pose`: full-pose targets (position and orientation) solved
//! exactly by Levenberg-Marquardt within the joint limits; `targets`: random reachable ones
//! and their file.

pub mod calibration;
pub mod cgan;
pub mod collision;
pub mod data;
pub mod dls;
pub mod drl;
pub mod dsl;
pub mod emssl;
pub mod flow;
pub mod learning;
pub mod method;
pub mod mlp;
pub mod pose;
pub mod pose_model;
pub mod sampling_pass;
pub mod targets;
