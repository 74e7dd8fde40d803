//! Our CPU kernels: convolution by im2col + GEMM, bilinear resize, the transposed
//! convolution layer, and the burn backend extension that puts them in the autodiff graph;
//! and (feature `wgpu`) our GPU kernels in CubeCL (`cube`). Each beside a slow reference that
//! a test compares it with.

pub mod bilinear_resize;
pub mod conv_gemm;
pub mod cpu_extension;
#[cfg(feature = "cube")]
pub mod cube;
pub mod linear;
pub mod parallel_output;
pub mod pointwise;
pub mod upconv;

use burn::tensor::FloatDType;

/// burn's `BatchNorm::forward`, then a ReLU where `relu`: on a GPU in training, two launches
/// forward and two backward (`cube::extension`); burn's own (and our ReLU) elsewhere. An input
/// in a lower precision than the layer's (autocast, [`crate::train::precision`]) is normalised
/// in the layer's dtype and cast back.
pub fn batch_norm<const D: usize>(
    norm: &burn::nn::BatchNorm,
    x: burn::tensor::Tensor<D>,
    relu: bool,
) -> burn::tensor::Tensor<D> {
    let (dtype, own) = (x.dtype(), norm.gamma.val().dtype());
    if dtype != own {
        let (own, dtype): (FloatDType, FloatDType) = (own.into(), dtype.into());
        return batch_norm(norm, x.cast(own), relu).cast(dtype);
    }
    #[cfg(feature = "cube")]
    if let Some(y) = cube::extension::batch_norm(norm, &x, relu) {
        return y;
    }
    let y = norm.forward(x);
    if relu { cpu_extension::relu(y) } else { y }
}
