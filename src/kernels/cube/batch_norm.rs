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

use burn::tensor::DType;
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

/// `(mean, variance, 1 / std, running mean, running variance)` of [`statistics`].
pub fn launch_statistics(
    x: CubeTensor,
    running_mean: CubeTensor,
    running_var: CubeTensor,
    epsilon: f64,
    momentum: f64,
) -> [CubeTensor; 5] {
    let (channels, plane) = layout(&x);
    let out = [(); 5].map(|_| empty_f32(&x, [channels]));
    statistics::launch(
        &x.client,
        CubeCount::new_1d(channels as u32),
        CubeDim::new_1d(BLOCK as u32),
        x.clone().into_tensor_arg(),
        contiguous(running_mean).into_tensor_arg(),
        contiguous(running_var).into_tensor_arg(),
        out[0].clone().into_tensor_arg(),
        out[1].clone().into_tensor_arg(),
        out[2].clone().into_tensor_arg(),
        out[3].clone().into_tensor_arg(),
        out[4].clone().into_tensor_arg(),
        channels as u32,
        plane as u32,
        epsilon as f32,
        momentum as f32,
        BLOCK,
    );
    out
}

/// The batch's statistics as the backward pass reads them, and the layer's tensors.
pub struct Saved {
    pub x: CubeTensor,
    /// The layer's output (after the ReLU where there is one).
    pub y: CubeTensor,
    pub dy: CubeTensor,
    pub mean: CubeTensor,
    pub inv_std: CubeTensor,
}

/// `(γ gradient, β gradient)` of [`grad_sums`].
pub fn launch_grad_sums(t: Saved, relu: bool) -> [CubeTensor; 2] {
    let (x, y, dy) = (t.x, t.y, t.dy);
    let (channels, plane) = layout(&x);
    let out = [(); 2].map(|_| empty_f32(&x, [channels]));
    grad_sums::launch(
        &x.client,
        CubeCount::new_1d(channels as u32),
        CubeDim::new_1d(BLOCK as u32),
        x.clone().into_tensor_arg(),
        y.into_tensor_arg(),
        dy.into_tensor_arg(),
        contiguous(t.mean).into_tensor_arg(),
        contiguous(t.inv_std).into_tensor_arg(),
        out[0].clone().into_tensor_arg(),
        out[1].clone().into_tensor_arg(),
        channels as u32,
        plane as u32,
        relu,
        BLOCK,
    );
    out
}

/// The input gradient of [`x_grad`].
pub fn launch_x_grad(
    t: Saved,
    gamma: CubeTensor,
    gamma_grad: CubeTensor,
    beta_grad: CubeTensor,
    relu: bool,
) -> CubeTensor {
    let (x, y, dy) = (t.x, t.y, t.dy);
    let (channels, plane) = layout(&x);
    let dx = empty_f32(&x, x.meta.shape().clone());
    let (cube_count, cube_dim) = elementwise(&x, x.meta.num_elements());
    x_grad::launch(
        &x.client,
        cube_count,
        cube_dim,
        x.clone().into_tensor_arg(),
        y.into_tensor_arg(),
        dy.into_tensor_arg(),
        contiguous(t.mean).into_tensor_arg(),
        contiguous(t.inv_std).into_tensor_arg(),
        contiguous(gamma).into_tensor_arg(),
        contiguous(gamma_grad).into_tensor_arg(),
        contiguous(beta_grad).into_tensor_arg(),
        dx.clone().into_tensor_arg(),
        channels as u32,
        plane as u32,
        relu,
    );
    dx
}
