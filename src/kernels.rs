//! Our CPU kernels: convolution by im2col + GEMM, bilinear resize, the transposed
//! convolution layer, and the burn backend extension that puts them in the autodiff graph;
//! and (feature `wgpu`) our GPU kernels in CubeCL (`cube`). Each beside a slow reference that
//! a test compares it with.

pub mod bilinear_resize;
pub mod conv_gemm;
pub mod cpu_extension;
#[cfg(feature = "wgpu")]
pub mod cube;
pub mod linear;
pub mod parallel_output;
pub mod pointwise;
pub mod upconv;
