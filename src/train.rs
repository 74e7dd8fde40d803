//! The one training loop every model uses (seeded, Adam, clipping, checkpoints, progress, to
//! convergence on a validation score) and the losses.

pub mod losses;
pub mod trainer;
