//! Batch normalisation in training (and the ReLU after it, where there is one), by channel:
//! one launch for the statistics (and the running statistics moved towards them), one for the
//! γ and β gradients, one for the input gradient, where burn's composition takes a layout copy
//! and two reductions forward, and two copies, four reductions and about six elementwise
//! launches backward (its `batch_norm_train` swaps the batch and channel axes and reshapes,
//! then reduces).
//!
//! A workgroup a channel; the layer's tensors `[N, C, ...]` of any strides (a convolution's
//! output is a channels-last view: read as it is, not copied).
//! The slow reference is the default body of [`super::extension::GpuKernelOps`]'s methods,
//! burn's own operations; `tests/gpu/kernels.rs` compares the two.

use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, ExtensionType};
use burn::tensor::DType;
use burn_cubecl::CubeBackend;
use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::multi_tensor::{BLOCK, at, tree_sum};
use super::{contiguous, elementwise, empty_f32};

/// `Σ (x - shift)` (or with `square`, `Σ (x - shift)²`) over channel `c` (the workgroup's) of
/// an `[N, C, ...]` tensor of any strides, by the whole workgroup; every unit gets it.
#[cube]
pub fn channel_total(
    x: &Tensor<f32>,
    shift: f32,
    channels: usize,
    plane: usize,
    #[comptime] square: bool,
    #[comptime] block: usize,
) -> f32 {
    let c = CUBE_POS_X as usize;
    let n = x.len() / channels;
    let mut shared = Shared::new_slice(block);
    let mut acc = 0.0;
    let mut k = UNIT_POS as usize;
    while k < n {
        let d = x[at(x, (k / plane * channels + c) * plane + k % plane)] - shift;
        if square {
            acc += d * d;
        } else {
            acc += d;
        }
        k += block;
    }
    shared[UNIT_POS as usize] = acc;
    let sum = tree_sum(&mut shared);
    sync_cube();
    sum
}

/// Each channel's mean, biased variance and `1 / sqrt(var + epsilon)`, and the running
/// statistics moved towards them by `momentum` (as burn's `BatchNorm` does: `r (1 - m) + s m`).
#[cube(launch)]
// A GPU kernel takes its buffers and sizes as arguments (one launch, no host struct).
#[allow(clippy::too_many_arguments)]
pub fn statistics(
    x: &Tensor<f32>,
    running_mean: &Tensor<f32>,
    running_var: &Tensor<f32>,
    mean: &mut Tensor<f32>,
    var: &mut Tensor<f32>,
    inv_std: &mut Tensor<f32>,
    running_mean_out: &mut Tensor<f32>,
    running_var_out: &mut Tensor<f32>,
    channels: u32,
    plane: u32,
    epsilon: f32,
    momentum: f32,
    #[comptime] block: usize,
) {
    let (channels, plane) = (channels as usize, plane as usize);
    let c = CUBE_POS_X as usize;
    let count = f32::cast_from(x.len() / channels);
    let m = channel_total(x, 0.0, channels, plane, false, block) / count;
    let v = channel_total(x, m, channels, plane, true, block) / count;
    if UNIT_POS == 0 {
        mean[c] = m;
        var[c] = v;
        inv_std[c] = 1.0 / f32::sqrt(v + epsilon);
        running_mean_out[c] = running_mean[c] * (1.0 - momentum) + m * momentum;
        running_var_out[c] = running_var[c] * (1.0 - momentum) + v * momentum;
    }
}

/// The gradient reaching the normalisation: `dy`, or with a ReLU after the layer, `dy` where
/// its output `y` is positive.
#[cube]
fn reaching(dy: f32, y: f32, #[comptime] relu: bool) -> f32 {
    let mut g = dy;
    if relu {
        if y <= 0.0 {
            g = 0.0;
        }
    }
    g
}

/// Each channel's `γ` and `β` gradients: `Σ g (x - mean) / std` and `Σ g`, with `g` the
/// gradient reaching the normalisation ([`reaching`]).
#[cube(launch)]
// A GPU kernel takes its buffers and sizes as arguments (one launch, no host struct).
#[allow(clippy::too_many_arguments)]
pub fn grad_sums(
    x: &Tensor<f32>,
    y: &Tensor<f32>,
    dy: &Tensor<f32>,
    mean: &Tensor<f32>,
    inv_std: &Tensor<f32>,
    gamma_grad: &mut Tensor<f32>,
    beta_grad: &mut Tensor<f32>,
    channels: u32,
    plane: u32,
    #[comptime] relu: bool,
    #[comptime] block: usize,
) {
    let (channels, plane) = (channels as usize, plane as usize);
    let c = CUBE_POS_X as usize;
    let m = mean[c];
    let mut shared = Shared::new_slice(block);
    let mut sum_g = 0.0;
    let mut sum_gx = 0.0;
    let mut k = UNIT_POS as usize;
    let n = x.len() / channels;
    while k < n {
        let i = (k / plane * channels + c) * plane + k % plane;
        let g = reaching(dy[at(dy, i)], y[at(y, i)], relu);
        sum_g += g;
        sum_gx += g * (x[at(x, i)] - m);
        k += block;
    }
    shared[UNIT_POS as usize] = sum_g;
    let s = tree_sum(&mut shared);
    sync_cube();
    shared[UNIT_POS as usize] = sum_gx;
    let p = tree_sum(&mut shared);
    if UNIT_POS == 0 {
        gamma_grad[c] = p * inv_std[c];
        beta_grad[c] = s;
    }
}

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
    assert!(
        dims.len() >= 2 && x.dtype == DType::F32,
        "an f32 [N, C, ...] tensor"
    );
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

/// [`statistics`] of `x` for `layer`.
pub fn launch_statistics(x: CubeTensor, layer: Layer<CubeBackend>) -> Statistics<CubeBackend> {
    let (channels, plane) = layout(&x);
    let [mean, var, inv_std, running_mean, running_var] =
        [(); 5].map(|_| empty_f32(&x, [channels]));
    statistics::launch(
        &x.client,
        CubeCount::new_1d(channels as u32),
        CubeDim::new_1d(BLOCK as u32),
        x.clone().into_tensor_arg(),
        contiguous(layer.running_mean).into_tensor_arg(),
        contiguous(layer.running_var).into_tensor_arg(),
        mean.clone().into_tensor_arg(),
        var.clone().into_tensor_arg(),
        inv_std.clone().into_tensor_arg(),
        running_mean.clone().into_tensor_arg(),
        running_var.clone().into_tensor_arg(),
        channels as u32,
        plane as u32,
        layer.epsilon as f32,
        layer.momentum as f32,
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

/// The `γ` and `β` gradients of [`grad_sums`].
pub fn launch_grad_sums(t: Saved<CubeBackend>) -> ParamGrads<CubeBackend> {
    let (channels, plane) = layout(&t.x);
    let [gamma, beta] = [(); 2].map(|_| empty_f32(&t.x, [channels]));
    grad_sums::launch(
        &t.x.client,
        CubeCount::new_1d(channels as u32),
        CubeDim::new_1d(BLOCK as u32),
        t.x.clone().into_tensor_arg(),
        t.y.into_tensor_arg(),
        t.dy.into_tensor_arg(),
        contiguous(t.mean).into_tensor_arg(),
        contiguous(t.inv_std).into_tensor_arg(),
        gamma.clone().into_tensor_arg(),
        beta.clone().into_tensor_arg(),
        channels as u32,
        plane as u32,
        t.relu,
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
    );
    dx
}
