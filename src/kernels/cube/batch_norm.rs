//! Batch normalisation in training (and the ReLU after it, where there is one), by channel:
//! two launches for the statistics (and the running statistics moved towards them), two for
//! the γ and β gradients, one for the input gradient, where burn's composition takes a layout copy
//! and two reductions forward, and two copies, four reductions and about six elementwise
//! launches backward (its `batch_norm_train` swaps the batch and channel axes and reshapes,
//! then reduces).
//!
//! The statistics and the parameter gradients are sums by channel in two launches each that
//! fill the GPU ([`super::channel_reduce`]); the layer's tensors `[N, C, ...]` of any strides
//! (a convolution's output is a channels-last view: read as it is, not copied).
//! The slow reference is the default body of [`super::extension::GpuKernelOps`]'s methods,
//! burn's own operations; `tests/gpu/kernels.rs` compares the two.

use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, ExtensionType};
use burn_cubecl::CubeBackend;
use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::channel_reduce::{
    Summand, finish_grad_sums, finish_grid, finish_statistics, flat, launch_partial_sums, reaching,
};
use super::multi_tensor::{BLOCK, at};
use super::{contiguous, elementwise, empty_f32, holds_f32, over_elements};

/// The input gradient, element by element:
/// `γ/std (g - Σg/M - (x - mean)/std · Σ g (x - mean)/std / M)`, `M` a channel's count.
#[cube(launch)]
// A GPU kernel takes its buffers and sizes as arguments (one launch, no host struct).
#[allow(clippy::too_many_arguments)]
pub fn x_grad(
    x: &Tensor<f32>,
    y: &Tensor<f32>,
    dy: &Tensor<f32>,
    mean: &Tensor<f32>,
    inv_std: &Tensor<f32>,
    gamma: &Tensor<f32>,
    gamma_grad: &Tensor<f32>,
    beta_grad: &Tensor<f32>,
    dx: &mut Tensor<f32>,
    channels: u32,
    plane: u32,
    #[comptime] relu: bool,
) {
    let k = ABSOLUTE_POS;
    if k < x.len() {
        let (channels, plane) = (channels as usize, plane as usize);
        let c = (k / plane) % channels;
        let count = f32::cast_from(x.len() / channels);
        let s = inv_std[c];
        let g = reaching(dy[at(dy, k)], y[at(y, k)], relu);
        let xhat = (x[at(x, k)] - mean[c]) * s;
        dx[k] = gamma[c] * s * (g - beta_grad[c] / count - xhat * gamma_grad[c] / count);
    }
}

/// `[channels, plane]` of an `[N, C, ...]` tensor.
fn layout(x: &CubeTensor) -> (usize, usize) {
    let dims = x.meta.shape();
    assert!(dims.len() >= 2 && holds_f32(x), "an f32 [N, C, ...] tensor");
    (dims[1], dims.iter().skip(2).product())
}

/// A batch-norm layer in training: `γ`, `β`, the running statistics, its `epsilon` and
/// `momentum`, and whether a ReLU follows it.
#[derive(Clone, ExtensionType)]
#[extension_type(fusion)]
pub struct Layer<B: Backend> {
    pub gamma: FloatTensor<B>,
    pub beta: FloatTensor<B>,
    pub running_mean: FloatTensor<B>,
    pub running_var: FloatTensor<B>,
    pub epsilon: f64,
    pub momentum: f64,
    pub relu: bool,
}

impl<B: Backend> Layer<B> {
    /// The same layer with each tensor mapped by `f` (onto an inner backend).
    pub fn map_inner<I: Backend>(self, f: impl Fn(FloatTensor<B>) -> FloatTensor<I>) -> Layer<I> {
        Layer {
            gamma: f(self.gamma),
            beta: f(self.beta),
            running_mean: f(self.running_mean),
            running_var: f(self.running_var),
            epsilon: self.epsilon,
            momentum: self.momentum,
            relu: self.relu,
        }
    }
}

/// A batch's statistics: each channel's mean, biased variance and `1 / sqrt(var + epsilon)`,
/// and the running statistics moved towards them.
#[derive(ExtensionType)]
#[extension_type(fusion)]
pub struct Statistics<B: Backend> {
    pub mean: FloatTensor<B>,
    pub var: FloatTensor<B>,
    pub inv_std: FloatTensor<B>,
    pub running_mean: FloatTensor<B>,
    pub running_var: FloatTensor<B>,
}

/// What the backward pass reads: the layer's input, its output (after the ReLU where
/// `relu`), the output's gradient, and the batch's mean and `1 / std`.
#[derive(Clone, ExtensionType)]
#[extension_type(fusion)]
pub struct Saved<B: Backend> {
    pub x: FloatTensor<B>,
    pub y: FloatTensor<B>,
    pub dy: FloatTensor<B>,
    pub mean: FloatTensor<B>,
    pub inv_std: FloatTensor<B>,
    pub relu: bool,
}

/// The `γ` and `β` gradients.
#[derive(Clone, ExtensionType)]
#[extension_type(fusion)]
pub struct ParamGrads<B: Backend> {
    pub gamma: FloatTensor<B>,
    pub beta: FloatTensor<B>,
}

/// The statistics of `x` for `layer` ([`Summand::Shifted`] partial sums, then
/// [`finish_statistics`]).
pub fn launch_statistics(x: CubeTensor, layer: Layer<CubeBackend>) -> Statistics<CubeBackend> {
    let x = flat(x);
    let (channels, _) = layout(&x);
    let partials = launch_partial_sums(&x, None, None, None, Summand::Shifted);
    let [mean, var, inv_std, running_mean, running_var] =
        [(); 5].map(|_| empty_f32(&x, [channels]));
    let (lanes, count) = finish_grid(channels);
    finish_statistics::launch(
        &x.client,
        count,
        CubeDim::new_1d(BLOCK as u32),
        x.clone().into_tensor_arg(),
        partials.into_tensor_arg(),
        contiguous(layer.running_mean).into_tensor_arg(),
        contiguous(layer.running_var).into_tensor_arg(),
        mean.clone().into_tensor_arg(),
        var.clone().into_tensor_arg(),
        inv_std.clone().into_tensor_arg(),
        running_mean.clone().into_tensor_arg(),
        running_var.clone().into_tensor_arg(),
        layer.epsilon as f32,
        layer.momentum as f32,
        lanes,
        BLOCK,
    );
    Statistics {
        mean,
        var,
        inv_std,
        running_mean,
        running_var,
    }
}

/// The `γ` and `β` gradients ([`Summand::BatchNormGrads`] partial sums, then
/// [`finish_grad_sums`]).
pub fn launch_grad_sums(t: Saved<CubeBackend>) -> ParamGrads<CubeBackend> {
    let (x, y, dy) = (flat(t.x), flat(t.y), flat(t.dy));
    let (channels, _) = layout(&x);
    let mean = contiguous(t.mean);
    let what = Summand::BatchNormGrads { relu: t.relu };
    let partials = launch_partial_sums(&x, Some(&y), Some(&dy), Some(&mean), what);
    let [gamma, beta] = [(); 2].map(|_| empty_f32(&x, [channels]));
    let (lanes, count) = finish_grid(channels);
    finish_grad_sums::launch(
        &x.client,
        count,
        CubeDim::new_1d(BLOCK as u32),
        partials.into_tensor_arg(),
        contiguous(t.inv_std).into_tensor_arg(),
        gamma.clone().into_tensor_arg(),
        beta.clone().into_tensor_arg(),
        lanes,
        BLOCK,
    );
    ParamGrads { gamma, beta }
}

/// The input gradient of [`x_grad`], given the layer's `gamma` and its gradients.
pub fn launch_x_grad(
    t: Saved<CubeBackend>,
    gamma: CubeTensor,
    grads: ParamGrads<CubeBackend>,
) -> CubeTensor {
    let (channels, plane) = layout(&t.x);
    let dx = empty_f32(&t.x, t.x.meta.shape().clone());
    let (cube_count, cube_dim) = elementwise(&t.x, t.x.meta.num_elements());
    over_elements(t.x.meta.num_elements(), || {
        x_grad::launch(
            &t.x.client,
            cube_count,
            cube_dim,
            t.x.clone().into_tensor_arg(),
            t.y.into_tensor_arg(),
            t.dy.into_tensor_arg(),
            contiguous(t.mean).into_tensor_arg(),
            contiguous(t.inv_std).into_tensor_arg(),
            contiguous(gamma).into_tensor_arg(),
            contiguous(grads.gamma).into_tensor_arg(),
            contiguous(grads.beta).into_tensor_arg(),
            dx.clone().into_tensor_arg(),
            channels as u32,
            plane as u32,
            t.relu,
        )
    });
    dx
}
