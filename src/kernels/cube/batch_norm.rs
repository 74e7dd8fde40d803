//! Batch normalisation in training, by channel: one launch for the statistics (and the running
//! statistics moved towards them), one for the gradient's two sums, where burn's composition
//! takes a layout copy and two reductions forward and two copies and four reductions backward
//! (its `batch_norm_train` swaps the batch and channel axes and reshapes, then reduces).
//!
//! A workgroup a channel; every tensor contiguous `[N, C, H, W]` (the host side makes sure).
//! The slow reference is the default body of [`super::extension::GpuKernelOps`]'s methods,
//! burn's own operations; `tests/gpu_kernels.rs` compares the two.

use burn::tensor::DType;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::ops::numeric::empty_device_dtype;
use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::multi_tensor::{BLOCK, tree_sum};

/// The sum over a channel `c` of `value(k)` for its elements `k` (batch-major), by the whole
/// workgroup; every unit gets it.
#[cube]
fn channel_sum(
    x: &Tensor<f32>,
    other: &Tensor<f32>,
    shift: f32,
    channels: usize,
    plane: usize,
    #[comptime] product: bool,
    #[comptime] block: usize,
) -> f32 {
    let c = CUBE_POS_X as usize;
    let count = x.len() / channels;
    let mut shared = Shared::new_slice(block);
    let mut acc = 0.0;
    let mut k = UNIT_POS as usize;
    while k < count {
        let at = ((k / plane) * channels + c) * plane + k % plane;
        if product {
            acc += other[at] * (x[at] - shift);
        } else {
            let d = x[at] - shift;
            acc += d * d;
        }
        k += block;
    }
    shared[UNIT_POS as usize] = acc;
    let sum = tree_sum(&mut shared);
    sync_cube();
    sum
}

/// Each channel's mean and biased variance, and the running statistics moved towards them by
/// `momentum` (as burn's `BatchNorm` does: `r (1 - m) + s m`).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn statistics(
    x: &Tensor<f32>,
    running_mean: &Tensor<f32>,
    running_var: &Tensor<f32>,
    mean: &mut Tensor<f32>,
    var: &mut Tensor<f32>,
    running_mean_out: &mut Tensor<f32>,
    running_var_out: &mut Tensor<f32>,
    channels: u32,
    plane: u32,
    momentum: f32,
    #[comptime] block: usize,
) {
    let (channels, plane) = (channels as usize, plane as usize);
    let c = CUBE_POS_X as usize;
    let count = f32::cast_from(x.len() / channels);
    let mut shared = Shared::new_slice(block);
    let mut acc = 0.0;
    let mut k = UNIT_POS as usize;
    let n = x.len() / channels;
    while k < n {
        acc += x[((k / plane) * channels + c) * plane + k % plane];
        k += block;
    }
    shared[UNIT_POS as usize] = acc;
    let m = tree_sum(&mut shared) / count;
    sync_cube();
    let v = channel_sum(x, x, m, channels, plane, false, block) / count;
    if UNIT_POS == 0 {
        mean[c] = m;
        var[c] = v;
        running_mean_out[c] = running_mean[c] * (1.0 - momentum) + m * momentum;
        running_var_out[c] = running_var[c] * (1.0 - momentum) + v * momentum;
    }
}

/// Each channel's `Σ dy` and `Σ dy (x - mean)`.
#[cube(launch)]
pub fn grad_sums(
    x: &Tensor<f32>,
    dy: &Tensor<f32>,
    mean: &Tensor<f32>,
    sum_dy: &mut Tensor<f32>,
    sum_dy_xc: &mut Tensor<f32>,
    channels: u32,
    plane: u32,
    #[comptime] block: usize,
) {
    let (channels, plane) = (channels as usize, plane as usize);
    let c = CUBE_POS_X as usize;
    let mut shared = Shared::new_slice(block);
    let mut acc = 0.0;
    let mut k = UNIT_POS as usize;
    let n = x.len() / channels;
    while k < n {
        acc += dy[((k / plane) * channels + c) * plane + k % plane];
        k += block;
    }
    shared[UNIT_POS as usize] = acc;
    let s = tree_sum(&mut shared);
    sync_cube();
    let p = channel_sum(x, dy, mean[c], channels, plane, true, block);
    if UNIT_POS == 0 {
        sum_dy[c] = s;
        sum_dy_xc[c] = p;
    }
}

fn contiguous(t: CubeTensor) -> CubeTensor {
    if t.is_contiguous() {
        t
    } else {
        into_contiguous(t)
    }
}

/// `[channels, plane]` of an `[N, C, ...]` tensor.
fn layout(x: &CubeTensor) -> (usize, usize) {
    let dims = x.meta.shape();
    assert!(dims.len() >= 2 && x.dtype == DType::F32, "an f32 [N, C, ...] tensor");
    (dims[1], dims.iter().skip(2).product())
}

fn channel_vector(x: &CubeTensor, channels: usize) -> CubeTensor {
    empty_device_dtype(x.client.clone(), x.device.clone(), [channels].into(), DType::F32)
}

/// `(mean, variance, running mean, running variance)` of [`statistics`].
pub fn launch_statistics(
    x: CubeTensor,
    running_mean: CubeTensor,
    running_var: CubeTensor,
    momentum: f64,
) -> [CubeTensor; 4] {
    let x = contiguous(x);
    let (channels, plane) = layout(&x);
    let out = [(); 4].map(|_| channel_vector(&x, channels));
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
        channels as u32,
        plane as u32,
        momentum as f32,
        BLOCK,
    );
    out
}

/// `(Σ dy, Σ dy (x - mean))` of [`grad_sums`].
pub fn launch_grad_sums(x: CubeTensor, dy: CubeTensor, mean: CubeTensor) -> [CubeTensor; 2] {
    let (x, dy) = (contiguous(x), contiguous(dy));
    let (channels, plane) = layout(&x);
    let out = [(); 2].map(|_| channel_vector(&x, channels));
    grad_sums::launch(
        &x.client,
        CubeCount::new_1d(channels as u32),
        CubeDim::new_1d(BLOCK as u32),
        x.clone().into_tensor_arg(),
        dy.into_tensor_arg(),
        contiguous(mean).into_tensor_arg(),
        out[0].clone().into_tensor_arg(),
        out[1].clone().into_tensor_arg(),
        channels as u32,
        plane as u32,
        BLOCK,
    );
    out
}
