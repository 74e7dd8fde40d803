//! The one training loop every model uses (seeded, Adam, clipping, checkpoints, progress, to
//! convergence on a validation score), the losses, and Elastic Weight Consolidation (a penalty
//! that keeps an old task while training a new one).

pub mod adam;
pub mod batcher;
pub mod checkpoint;
pub mod config;
pub mod convergence;
pub mod ewc;
pub mod hooks;
pub mod losses;
pub mod precision;
pub mod trainer;
