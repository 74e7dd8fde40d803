//! Learned inverse kinematics (the EMSSL paper): the data (`data`), the inverse MLP (`mlp`),
//! direct regression and EMSSL (`learning`), distal supervised learning (`dsl`), the
//! conditional GAN (`cgan`), the normalizing flow (`flow`), damped least squares (`dls`),
//! link calibration and EMSSL's batched sampling pass.

pub mod calibration;
pub mod cgan;
pub mod data;
pub mod dls;
pub mod dsl;
pub mod flow;
pub mod learning;
pub mod mlp;
pub mod sampling_pass;
