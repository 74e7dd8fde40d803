//! Kernels over many tensors at once (PyTorch's multi-tensor apply): the sum of squares of
//! every gradient of a step, and Adam's update of every parameter, each in one launch for as
//! many tensors as a kernel may bind, where burn runs a handful of launches per tensor.
//!
//! A kernel takes its tensors as a [`Sequence`] (unrolled at compile time: a kernel is
//! compiled once per count of tensors). Each thread finds its tensor by walking the
//! sequence's lengths; every tensor is contiguous (the host side makes sure).
//!
//! The slow references are burn's own operations: `train::adam` composes the same step from
//! them, and `tests/gpu/kernels.rs` compares the two on lavapipe.

use cubecl::prelude::*;

/// Threads in a workgroup of these kernels (a power of two: the tree sums halve it).
pub const BLOCK: usize = 256;

/// Sums `shared[0..CUBE_DIM]` into `shared[0]` (every unit takes part; `CUBE_DIM` a power of
/// two), in a fixed order: the result does not depend on timing.
#[cube]
pub fn tree_sum(shared: &mut Shared<[f32]>) -> f32 {
    sync_cube();
    let mut active = CUBE_DIM / 2;
    while active > 0 {
        if UNIT_POS < active {
            let other = shared[(UNIT_POS + active) as usize];
            shared[UNIT_POS as usize] += other;
        }
        sync_cube();
        active /= 2;
    }
    shared[0]
}

/// Where element `index` of `t` (counted in row-major order of its shape) lies in its buffer:
/// a tensor of any strides (a transposed or permuted view) is read without a copy.
#[cube]
pub fn at(t: &Tensor<f32>, index: usize) -> usize {
    let rank = t.rank();
    let mut rest = index;
    let mut offset = 0;
    for d in 0..rank {
        let dim = rank - 1 - d;
        let size = t.shape(dim);
        offset += (rest % size) * t.stride(dim);
        rest /= size;
    }
    offset
}

/// `partials[(first + t) * groups + g]`: the sum of squares of the elements of tensor `t`
/// that workgroup `g` of `groups` (the grid's x) visits; the grid's y is the tensor.
#[cube(launch)]
pub fn sum_of_squares(
    tensors: &Sequence<OwnedTensor<f32>>,
    partials: &mut Tensor<f32>,
    first: u32,
    #[comptime] block: usize,
) {
    let groups = CUBE_COUNT_X as usize;
    let tensor = CUBE_POS_Y as usize;
    let mut acc = 0.0;
    #[unroll]
    for i in 0..tensors.len() {
        if tensor == i {
            let x = &tensors[i];
            let mut k = CUBE_POS_X as usize * block + UNIT_POS as usize;
            while k < x.len() {
                let value = x.as_slice()[at(x, k)];
                acc += value * value;
                k += groups * block;
            }
        }
    }
    let mut shared = Shared::new_slice(block);
    shared[UNIT_POS as usize] = acc;
    let sum = tree_sum(&mut shared);
    if UNIT_POS == 0 {
        partials[(first as usize + tensor) * groups + CUBE_POS_X as usize] = sum;
    }
}

/// `total[0]`: the sum of every partial sum of [`sum_of_squares`] (one workgroup, a fixed
/// order): the squared global norm the clipping reads.
#[cube(launch)]
pub fn sum_all(partials: &Tensor<f32>, total: &mut Tensor<f32>, #[comptime] block: usize) {
    let mut shared = Shared::new_slice(block);
    let mut acc = 0.0;
    let mut k = UNIT_POS as usize;
    while k < partials.len() {
        acc += partials[k];
        k += block;
    }
    shared[UNIT_POS as usize] = acc;
    let sum = tree_sum(&mut shared);
    if UNIT_POS == 0 {
        total[0] = sum;
    }
}

/// Adam's scalars for one step, as burn's `Adam` derives them from its settings and the step.
#[derive(CubeLaunch, CubeType)]
pub struct AdamScalars {
    pub lr: f32,
    pub beta_1: f32,
    pub beta_2: f32,
    /// `(1 - β₂ᵗ)^½ / (1 - β₁ᵗ)`.
    pub combined: f32,
    /// `ε (1 - β₂ᵗ)^½`.
    pub epsilon: f32,
    /// The clipping threshold of the global gradient norm (read only when clipping).
    pub max_norm: f32,
}

/// The global-norm clipping factor from the squared norm `total[0]` ([`sum_all`]):
/// `max / (norm + 1e-6)` where the norm is finite and above `max`, else 1 (as
/// `train::adam::clip_global_norm`).
#[cube]
fn clip_scale(total: &Tensor<f32>, max_norm: f32) -> f32 {
    let norm = f32::sqrt(total[0]);
    let mut scale = 1.0;
    // NaN fails the comparison.
    if norm.is_inf() {
    } else if norm > max_norm {
        scale = max_norm / (norm + 1e-6);
    }
    scale
}

/// One Adam step of every tensor in the sequences (parameters, gradients, first and second
/// moments in; new parameters and moments out), each element as burn's `Adam` computes it.
/// The gradients may have any strides; the rest are contiguous.
/// With `clip`, each gradient is first scaled by the global-norm clipping factor of
/// `total` (the sum of squares of every gradient of the step, from [`sum_all`]).
#[cube(launch)]
// A GPU kernel takes its buffers and sizes as arguments (one launch, no host struct).
#[allow(clippy::too_many_arguments)]
pub fn adam(
    params: &Sequence<OwnedTensor<f32>>,
    grads: &Sequence<OwnedTensor<f32>>,
    moment_1: &Sequence<OwnedTensor<f32>>,
    moment_2: &Sequence<OwnedTensor<f32>>,
    params_out: &mut Sequence<OwnedTensor<f32>>,
    moment_1_out: &mut Sequence<OwnedTensor<f32>>,
    moment_2_out: &mut Sequence<OwnedTensor<f32>>,
    total: &Tensor<f32>,
    scalars: &AdamScalars,
    #[comptime] clip: bool,
) {
    let mut scale = 1.0;
    if clip {
        scale = clip_scale(total, scalars.max_norm);
    }
    let lr = scalars.lr;
    let beta_1 = scalars.beta_1;
    let beta_2 = scalars.beta_2;
    let combined = scalars.combined;
    let epsilon = scalars.epsilon;
    let mut offset = ABSOLUTE_POS;
    let mut done = false;
    #[unroll]
    for i in 0..params.len() {
        let n = params[i].as_slice().len();
        if !done {
            if offset < n {
                done = true;
                let g = grads[i].as_slice()[at(&grads[i], offset)] * scale;
                let m = moment_1[i].as_slice()[offset] * beta_1 + g * (1.0 - beta_1);
                let v = moment_2[i].as_slice()[offset] * beta_2 + g * g * (1.0 - beta_2);
                let update = m * combined / (f32::sqrt(v) + epsilon);
                let p = params[i].as_slice()[offset] - update * lr;
                params_out.index_mut(i).as_mut_slice()[offset] = p;
                moment_1_out.index_mut(i).as_mut_slice()[offset] = m;
                moment_2_out.index_mut(i).as_mut_slice()[offset] = v;
            } else {
                offset -= n;
            }
        }
    }
}
