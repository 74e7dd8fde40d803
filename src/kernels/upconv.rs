//! A transposed 2-D convolution (PyTorch's `ConvTranspose2d`: its weight layout and initialisation).
//!
//! Weights have PyTorch's layout `[in_channels, out_channels, k, k]` and PyTorch's default
//! initialisation (uniform in +-1/sqrt(out_channels * k * k) for weight and bias), so the
//! decoders of the self-modeling paper can be checked against its notebooks.
//!
//! The layer exists (rather than burn's `ConvTranspose2d`) to own the decoders' hot spot. Its
//! forward pass is burn's GEMM + col2im `conv_transpose2d`; on flex its weight gradient runs on
//! [`crate::kernels::conv_gemm`] through [`crate::kernels::cpu_extension`], because burn's default weight
//! gradient (a convolution with the activations as its kernel) was the slow part. Measured on
//! the 2-core CPU (flex), rewrites of the layer in tensor ops were *slower*: the sub-pixel
//! form (one 2x2 convolution with 4x the output channels, phases interleaved) took 2-4x longer
//! forward and 1.1-3.7x longer forward+backward; stride 1 as a flipped-kernel convolution 2.2x
//! longer forward.

use burn::module::{Module, Param};
use burn::tensor::ops::ConvTransposeOptions;
use burn::tensor::{Device, Distribution, Tensor};

/// Shape of an [`UpConv`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct UpConvConfig {
    pub in_channels: usize,
    pub out_channels: usize,
    pub kernel: usize,
    pub stride: usize,
    pub padding: usize,
}

impl UpConvConfig {
    pub fn new(
        in_channels: usize,
        out_channels: usize,
        kernel: usize,
        stride: usize,
        padding: usize,
    ) -> Self {
        UpConvConfig {
            in_channels,
            out_channels,
            kernel,
            stride,
            padding,
        }
    }

    /// Build the layer, initialised like PyTorch's `ConvTranspose2d`.
    pub fn init(&self, device: &Device) -> UpConv {
        let k = self.kernel;
        let bound = 1.0 / ((self.out_channels * k * k) as f64).sqrt();
        let dist = Distribution::Uniform(-bound, bound);
        UpConv {
            weight: Param::from_tensor(Tensor::random(
                [self.in_channels, self.out_channels, k, k],
                dist,
                device,
            )),
            bias: Param::from_tensor(Tensor::random([self.out_channels], dist, device)),
            kernel: k,
            stride: self.stride,
            padding: self.padding,
        }
    }
}

/// A transposed convolution layer, `[batch, in, H, W]` ->
/// `[batch, out, (H - 1) * stride - 2 * padding + kernel, same for W]`.
#[derive(Module, Debug)]
pub struct UpConv {
    /// `[in_channels, out_channels, k, k]`.
    pub weight: Param<Tensor<4>>,
    /// `[out_channels]`.
    pub bias: Param<Tensor<1>>,
    #[module(skip)]
    pub kernel: usize,
    #[module(skip)]
    pub stride: usize,
    #[module(skip)]
    pub padding: usize,
}

impl UpConv {
    /// `[batch, in, H, W]` -> `[batch, out, H', W']`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let s = self.stride;
        let p = self.padding;
        crate::kernels::cpu_extension::conv_transpose2d(
            x,
            self.weight.val(),
            Some(self.bias.val()),
            ConvTransposeOptions::new([s, s], [p, p], [0, 0], [1, 1], 1),
        )
    }
}
