//! Datasets rendered from `sim`: the self-modeling datasets (silhouettes, depth, angles) and
//! their NumPy `.npz` files.

pub mod dataset;
pub mod npz;
