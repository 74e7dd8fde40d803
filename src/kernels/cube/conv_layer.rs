//! A convolution layer in training as our GPU operations take it (its weight, bias and
//! options), a type of burn's backend extension ([`super::extension::GpuKernelOps`]): what the
//! convolutions ([`super::convolution`]) and the extension's trait both name.

use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, ExtensionType};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};

/// A convolution layer in training: its weight `[c_out, c_in, k, k]`, bias and options.
#[derive(Clone, ExtensionType)]
#[extension_type(fusion)]
pub struct Conv2dLayer<B: Backend> {
    pub weight: FloatTensor<B>,
    pub bias: FloatTensor<B>,
    pub options: ConvOptions<2>,
}

/// A transposed convolution layer in training: its weight `[c_in, c_out, k, k]`, bias and
/// options.
#[derive(Clone, ExtensionType)]
#[extension_type(fusion)]
pub struct ConvTranspose2dLayer<B: Backend> {
    pub weight: FloatTensor<B>,
    pub bias: FloatTensor<B>,
    pub options: ConvTransposeOptions<2>,
}
