//! The mean binary cross-entropy of logits against targets, `max(z, 0) - z y + log(1 + e^-|z|)`
//! (PyTorch's `BCEWithLogitsLoss`): two launches forward (partial sums over workgroups, then
//! their sum over the count) and one backward (`(σ(z) - y) g / n`), where burn's composition
//! takes one fused launch, a reduction a dimension and three launches backward.
//!
//! The slow reference is `train::losses::bce_with_logits_composed`; `tests/gpu/kernels.rs`
//! compares the two.

use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::multi_tensor::{BLOCK, at, tree_sum};
use super::{elementwise, empty_f32, holds_f32, over_elements};

/// Workgroups of the forward pass's partial sums, at most: enough to fill the largest GPUs
/// (issue 71's guard asks 1,024 of a kernel over more than 2^20 elements).
const GROUPS: usize = 2048;

/// Element `k` (row-major over the shape) of `t`: read straight where `plain` (contiguous),
/// else through its strides ([`at`]).
#[cube]
fn read(t: &Tensor<f32>, k: usize, #[comptime] plain: bool) -> f32 {
    let mut i = k;
    if !plain {
        i = at(t, k);
    }
    t[i]
}

/// `partials[g]`: the sum of the element losses workgroup `g` visits (strided over all).
#[cube(launch)]
pub fn partial_sums(
    z: &Tensor<f32>,
    y: &Tensor<f32>,
    partials: &mut Tensor<f32>,
    #[comptime] plain: bool,
    #[comptime] block: usize,
) {
    let groups = CUBE_COUNT_X as usize;
    let mut acc = 0.0;
    let mut k = CUBE_POS_X as usize * block + UNIT_POS as usize;
    while k < z.len() {
        let zk = read(z, k, plain);
        let softplus = f32::log1p(f32::exp(-f32::abs(zk)));
        acc += f32::max(zk, 0.0) - zk * read(y, k, plain) + softplus;
        k += groups * block;
    }
    let mut shared = Shared::new_slice(block);
    shared[UNIT_POS as usize] = acc;
    let sum = tree_sum(&mut shared);
    if UNIT_POS == 0 {
        partials[CUBE_POS_X as usize] = sum;
    }
}

/// `loss[0] = Σ partials / count`, by one workgroup.
#[cube(launch)]
pub fn mean_of_partials(
    partials: &Tensor<f32>,
    loss: &mut Tensor<f32>,
    count: f32,
    #[comptime] block: usize,
) {
    let mut acc = 0.0;
    let mut k = UNIT_POS as usize;
    while k < partials.len() {
        acc += partials[k];
        k += block;
    }
    let mut shared = Shared::new_slice(block);
    shared[UNIT_POS as usize] = acc;
    let sum = tree_sum(&mut shared);
    if UNIT_POS == 0 {
        loss[0] = sum / count;
    }
}

/// `dz = (σ(z) - y) · grad[0] / count`, element by element (contiguous out).
#[cube(launch)]
pub fn logits_grad(
    z: &Tensor<f32>,
    y: &Tensor<f32>,
    grad: &Tensor<f32>,
    dz: &mut Tensor<f32>,
    count: f32,
    #[comptime] plain: bool,
) {
    let k = ABSOLUTE_POS;
    if k < z.len() {
        let s = 1.0 / (1.0 + f32::exp(-read(z, k, plain)));
        dz[k] = (s - read(y, k, plain)) * (grad[0] / count);
    }
}

/// The mean loss, a `[1]` tensor.
pub fn launch_mean(z: CubeTensor, y: CubeTensor) -> CubeTensor {
    assert!(holds_f32(&z) && holds_f32(&y), "f32 logits and targets");
    let n = z.meta.num_elements();
    let groups = n.div_ceil(BLOCK * 8).clamp(1, GROUPS);
    let partials = empty_f32(&z, [groups]);
    let plain = z.is_contiguous() && y.is_contiguous();
    over_elements(n, || {
        partial_sums::launch(
            &z.client,
            CubeCount::new_1d(groups as u32),
            CubeDim::new_1d(BLOCK as u32),
            z.clone().into_tensor_arg(),
            y.into_tensor_arg(),
            partials.clone().into_tensor_arg(),
            plain,
            BLOCK,
        )
    });
    let loss = empty_f32(&z, [1]);
    mean_of_partials::launch(
        &z.client,
        CubeCount::new_1d(1),
        CubeDim::new_1d(BLOCK as u32),
        partials.into_tensor_arg(),
        loss.clone().into_tensor_arg(),
        n as f32,
        BLOCK,
    );
    loss
}

/// The logits' gradient given the loss's `grad` (a `[1]` tensor).
pub fn launch_logits_grad(z: CubeTensor, y: CubeTensor, grad: CubeTensor) -> CubeTensor {
    let n = z.meta.num_elements();
    let dz = empty_f32(&z, z.meta.shape().clone());
    let (cube_count, cube_dim) = elementwise(&z, n);
    let plain = z.is_contiguous() && y.is_contiguous();
    over_elements(n, || {
        logits_grad::launch(
            &z.client,
            cube_count,
            cube_dim,
            z.clone().into_tensor_arg(),
            y.into_tensor_arg(),
            grad.into_tensor_arg(),
            dz.clone().into_tensor_arg(),
            n as f32,
            plain,
        )
    });
    dz
}
