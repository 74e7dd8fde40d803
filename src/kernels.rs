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

/// burn's `BatchNorm::forward`, then a ReLU where `relu`: on a GPU in training, two launches
/// forward and two backward (`cube::extension`); burn's own (and our ReLU) elsewhere.
pub fn batch_norm<const D: usize>(
    norm: &burn::nn::BatchNorm,
    x: burn::tensor::Tensor<D>,
    relu: bool,
) -> burn::tensor::Tensor<D> {
    #[cfg(feature = "wgpu")]
    if let Some(y) = cube::extension::batch_norm(norm, &x, relu) {
        return y;
    }
    let y = norm.forward(x);
    if relu { cpu_extension::relu(y) } else { y }
}
