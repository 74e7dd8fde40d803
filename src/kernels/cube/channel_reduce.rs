//! Sums by channel of `[N, C, ...]` tensors that fill a GPU: a layer's bias gradient, a batch
//! norm's statistics and its `γ` and `β` gradients. Two launches each:
//! 1. [`partial_sums`]: the `N·H·W` rows of every channel split into chunks, a workgroup a
//!    (tile of channels, chunk); each writes its sums to `partials` `[sums, chunks, C]`;
//! 2. a finishing kernel ([`finish_sums`], [`finish_statistics`], [`finish_grad_sums`]) sums
//!    each channel's chunks and derives what the layer needs.
//!
//! A workgroup of one launch a channel (what the kernels did before) runs 16 to 128 workgroups
//! on a GPU that holds thousands, each looping over `N·H·W` elements: at batch 256 on an H200
//! one bias gradient took 7.2 ms (issue 71). Here a launch has [`TARGET_WORKGROUPS`] or as many
//! as there are rows to give them.
//!
//! Reads are coalesced for the layouts the layers hand over: a channels-last view (a
//! convolution's output, channel stride 1) puts [`lanes`] consecutive channels on consecutive
//! units; a plain `[N, C, H, W]` tensor (pixel stride 1) puts every unit on consecutive pixels
//! of one channel. A tensor whose pixels are not one stride apart is copied first ([`flat`]).
//! The order of every sum is fixed (no atomics): the results do not depend on timing.
//!
//! The slow references are burn's own operations (the default bodies of
//! [`super::extension::GpuKernelOps`]), which `tests/gpu/kernels.rs` compares them with.

use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::multi_tensor::BLOCK;
use super::{contiguous, empty_f32, holds_f32, over_elements};

/// Workgroups a partial-sum launch aims at (as many as there are rows to give them): several
/// per multiprocessor of the largest GPUs (132 on an H100).
pub const TARGET_WORKGROUPS: usize = 2048;

/// Element `(n, c, p)` of an `[N, C, ...]` tensor whose pixels are one stride apart.
#[cube]
fn element(t: &Tensor<f32>, n: usize, c: usize, p: usize) -> f32 {
    let rank = t.rank();
    let mut offset = n * t.stride(0) + c * t.stride(1);
    if rank > 2 {
        offset += p * t.stride(rank - 1);
    }
    t[offset]
}

/// The gradient reaching a batch norm's normalisation: `dy`, or with a ReLU after the layer,
/// `dy` where its output `y` is positive.
#[cube]
pub fn reaching(dy: f32, y: f32, #[comptime] relu: bool) -> f32 {
    let mut g = dy;
    if relu {
        if y <= 0.0 {
            g = 0.0;
        }
    }
    g
}

/// What [`partial_sums`] sums, by channel `c`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Summand {
    /// `Σ a`: a bias gradient (`a` the output gradient).
    Plain,
    /// `Σ (a - a₀)` and `Σ (a - a₀)²`, shifted by the channel's first element `a₀`: the
    /// statistics of a batch norm's input `a` (the shift keeps the variance exact where the
    /// mean is large against the spread).
    Shifted,
    /// `Σ g` and `Σ g (a - mean)`, `g` [`reaching`] from `dy` (`d`) and the output `y`
    /// (`b`): a batch norm's `β` and `γ` gradients (before the `1/std`).
    BatchNormGrads { relu: bool },
}

impl Summand {
    fn sums(self) -> usize {
        match self {
            Summand::Plain => 1,
            _ => 2,
        }
    }

    /// The kernel's compile-time flags: `(shifted, grads, relu)`.
    fn flags(self) -> (bool, bool, bool) {
        match self {
            Summand::Plain => (false, false, false),
            Summand::Shifted => (true, false, false),
            Summand::BatchNormGrads { relu } => (false, true, relu),
        }
    }
}

/// The channel of this unit: `lanes` consecutive channels a workgroup along the grid's x.
#[cube]
fn unit_channel(#[comptime] lanes: usize) -> usize {
    CUBE_POS_X as usize * lanes + UNIT_POS as usize % lanes
}

/// Sums `shared[u]` over the units of a workgroup that share `u % lanes` (the rows of one
/// channel) into `shared[u % lanes]`, in a fixed order.
#[cube]
fn sum_rows(shared: &mut Shared<[f32]>, #[comptime] lanes: usize) {
    let u = UNIT_POS as usize;
    // A runtime value (halved in the loop), not a compile-time one.
    let mut active = CUBE_DIM as usize / comptime!(2 * lanes);
    sync_cube();
    while active > 0 {
        if u / lanes < active {
            let other = shared[u + active * lanes];
            shared[u] += other;
        }
        sync_cube();
        active /= 2;
    }
}

/// `partials[k, chunk, c]`: sum `k` of the [`Summand`] given by the flags over the rows
/// (`n`, pixel) of channel `c` in chunk `chunk` (the grid's y) of `chunks`. The grid's x is
/// the tile of `lanes` channels; a workgroup's units are `lanes` channels by `block / lanes`
/// rows. `a` (and for the gradients `b` = `y`, `d` = `dy`) are `[N, C, ...]` with pixels one
/// stride apart; `shift` per channel: the mean (gradients), unread otherwise.
#[cube(launch)]
// A GPU kernel takes its buffers and sizes as arguments (one launch, no host struct).
#[allow(clippy::too_many_arguments)]
pub fn partial_sums(
    a: &Tensor<f32>,
    b: &Tensor<f32>,
    d: &Tensor<f32>,
    shift: &Tensor<f32>,
    partials: &mut Tensor<f32>,
    #[comptime] shifted: bool,
    #[comptime] grads: bool,
    #[comptime] relu: bool,
    #[comptime] lanes: usize,
    #[comptime] block: usize,
) {
    let channels = a.shape(1);
    let plane = a.len() / (a.shape(0) * channels);
    let rows = a.shape(0) * plane;
    let chunks = CUBE_COUNT_Y as usize;
    let chunk = CUBE_POS_Y as usize;
    let u = UNIT_POS as usize;
    let c = unit_channel(lanes);
    let per_chunk = (rows + chunks - 1) / chunks;
    let mut end = (chunk + 1) * per_chunk;
    if end > rows {
        end = rows;
    }
    let mut first = 0.0;
    let mut second = 0.0;
    if c < channels {
        let mut s = 0.0;
        if shifted {
            s = element(a, 0, c, 0);
        }
        if grads {
            s = shift[c];
        }
        let mut r = chunk * per_chunk + u / lanes;
        while r < end {
            let (n, p) = (r / plane, r % plane);
            let x = element(a, n, c, p) - s;
            if grads {
                let g = reaching(element(d, n, c, p), element(b, n, c, p), relu);
                first += g;
                second += g * x;
            } else {
                first += x;
                if shifted {
                    second += x * x;
                }
            }
            r += comptime!(block / lanes);
        }
    }
    let mut shared = Shared::new_slice(block);
    shared[u] = first;
    sum_rows(&mut shared, lanes);
    if u < lanes && c < channels {
        partials[chunk * channels + c] = shared[u];
    }
    if shifted || grads {
        sync_cube();
        shared[u] = second;
        sum_rows(&mut shared, lanes);
        if u < lanes && c < channels {
            partials[(chunks + chunk) * channels + c] = shared[u];
        }
    }
}

/// Sum `k` of channel `c` over the chunks of `partials` `[sums, chunks, C]`, by a workgroup of
/// `lanes` channels by `block / lanes` chunks (every unit gets its channel's).
#[cube]
fn chunk_total(
    partials: &Tensor<f32>,
    k: usize,
    c: usize,
    #[comptime] lanes: usize,
    #[comptime] block: usize,
) -> f32 {
    let (chunks, channels) = (partials.shape(1), partials.shape(2));
    let u = UNIT_POS as usize;
    let mut acc = 0.0;
    if c < channels {
        let mut i = u / lanes;
        while i < chunks {
            acc += partials[(k * chunks + i) * channels + c];
            i += comptime!(block / lanes);
        }
    }
    let mut shared = Shared::new_slice(block);
    shared[u] = acc;
    sum_rows(&mut shared, lanes);
    let total = shared[u % lanes];
    sync_cube();
    total
}

/// `sums[c]`: the chunks of [`partial_sums`] (`Plain`) added up.
#[cube(launch)]
pub fn finish_sums(
    partials: &Tensor<f32>,
    sums: &mut Tensor<f32>,
    #[comptime] lanes: usize,
    #[comptime] block: usize,
) {
    let c = unit_channel(lanes);
    let s = chunk_total(partials, 0, c, lanes, block);
    if (UNIT_POS as usize) < lanes && c < sums.len() {
        sums[c] = s;
    }
}

/// A batch's statistics from the chunks of [`partial_sums`] (`Shifted`, over `x`): each
/// channel's mean, biased variance and `1 / sqrt(var + epsilon)`, and the running statistics
/// moved towards them by `momentum` (as burn's `BatchNorm`: `r (1 - m) + s m`).
#[cube(launch)]
// A GPU kernel takes its buffers and sizes as arguments (one launch, no host struct).
#[allow(clippy::too_many_arguments)]
pub fn finish_statistics(
    x: &Tensor<f32>,
    partials: &Tensor<f32>,
    running_mean: &Tensor<f32>,
    running_var: &Tensor<f32>,
    mean: &mut Tensor<f32>,
    var: &mut Tensor<f32>,
    inv_std: &mut Tensor<f32>,
    running_mean_out: &mut Tensor<f32>,
    running_var_out: &mut Tensor<f32>,
    epsilon: f32,
    momentum: f32,
    #[comptime] lanes: usize,
    #[comptime] block: usize,
) {
    let channels = x.shape(1);
    let c = unit_channel(lanes);
    let s1 = chunk_total(partials, 0, c, lanes, block);
    let s2 = chunk_total(partials, 1, c, lanes, block);
    if (UNIT_POS as usize) < lanes && c < channels {
        let count = f32::cast_from(x.len() / channels);
        let d = s1 / count;
        let m = element(x, 0, c, 0) + d;
        let mut v = s2 / count - d * d;
        if v < 0.0 {
            v = 0.0;
        }
        mean[c] = m;
        var[c] = v;
        inv_std[c] = 1.0 / f32::sqrt(v + epsilon);
        running_mean_out[c] = running_mean[c] * (1.0 - momentum) + m * momentum;
        running_var_out[c] = running_var[c] * (1.0 - momentum) + v * momentum;
    }
}

/// A batch norm's `γ` and `β` gradients from the chunks of [`partial_sums`]
/// (`BatchNormGrads`): `Σ g (x - mean) / std` and `Σ g`.
#[cube(launch)]
pub fn finish_grad_sums(
    partials: &Tensor<f32>,
    inv_std: &Tensor<f32>,
    gamma_grad: &mut Tensor<f32>,
    beta_grad: &mut Tensor<f32>,
    #[comptime] lanes: usize,
    #[comptime] block: usize,
) {
    let c = unit_channel(lanes);
    let s = chunk_total(partials, 0, c, lanes, block);
    let p = chunk_total(partials, 1, c, lanes, block);
    if (UNIT_POS as usize) < lanes && c < beta_grad.len() {
        gamma_grad[c] = p * inv_std[c];
        beta_grad[c] = s;
    }
}

/// `t` where its pixels (the axes after the channel) are one stride apart, else a contiguous
/// copy: what [`partial_sums`] reads.
pub fn flat(t: CubeTensor) -> CubeTensor {
    let dims = t.meta.shape().clone();
    let strides = t.meta.strides().clone();
    let rank = dims.len();
    let one_stride = (2..rank.saturating_sub(1))
        .all(|d| dims[d + 1] == 1 || strides[d] == strides[d + 1] * dims[d + 1]);
    if one_stride { t } else { contiguous(t) }
}

/// Units a workgroup puts on consecutive channels of `t` `[N, C, ...]`: up to 32 where channels
/// are adjacent in memory (channels last), else one (every unit on the pixels of one channel).
pub fn lanes(t: &CubeTensor) -> usize {
    let channels = t.meta.shape()[1];
    if t.meta.strides()[1] == 1 && channels > 1 {
        channels.next_power_of_two().min(32)
    } else {
        1
    }
}

/// The grid of [`partial_sums`] over `t` with `lanes` channels a workgroup: (channel tiles,
/// chunks), as many chunks as make [`TARGET_WORKGROUPS`] where there are rows enough (each
/// unit at least a few).
pub fn grid(t: &CubeTensor, lanes: usize) -> (usize, usize) {
    let dims = t.meta.shape();
    let channels = dims[1];
    let rows = t.meta.num_elements() / channels.max(1);
    let tiles = channels.div_ceil(lanes);
    let per_unit_row = BLOCK / lanes;
    let most = rows.div_ceil(per_unit_row * 4).max(1);
    (tiles, TARGET_WORKGROUPS.div_ceil(tiles).clamp(1, most))
}

/// The partial sums of `what` over `a` (`[N, C, ...]`, f32; `b`, `d` and `shift` for the
/// gradients, else `a` stands in): `[sums, chunks, C]`, and the `lanes` to finish them with.
pub fn launch_partial_sums(
    a: &CubeTensor,
    b: Option<&CubeTensor>,
    d: Option<&CubeTensor>,
    shift: Option<&CubeTensor>,
    what: Summand,
) -> CubeTensor {
    assert!(
        a.meta.shape().len() >= 2 && holds_f32(a),
        "an f32 [N, C, ...] tensor"
    );
    let channels = a.meta.shape()[1];
    let lanes = lanes(a);
    let (tiles, chunks) = grid(a, lanes);
    let partials = empty_f32(a, [what.sums(), chunks, channels]);
    // Unread stand-ins must still be distinct buffers from the output.
    let b = b.unwrap_or(a).clone();
    let d = d.unwrap_or(a).clone();
    let shift = shift.cloned().unwrap_or_else(|| empty_f32(a, [1]));
    let (shifted, grads, relu) = what.flags();
    over_elements(a.meta.num_elements(), || {
        partial_sums::launch(
            &a.client,
            CubeCount::new_2d(tiles as u32, chunks as u32),
            CubeDim::new_1d(BLOCK as u32),
            a.clone().into_tensor_arg(),
            b.into_tensor_arg(),
            d.into_tensor_arg(),
            shift.into_tensor_arg(),
            partials.clone().into_tensor_arg(),
            shifted,
            grads,
            relu,
            lanes,
            BLOCK,
        )
    });
    partials
}

/// The lanes and workgroups of a finishing kernel over `channels`.
pub fn finish_grid(channels: usize) -> (usize, CubeCount) {
    let lanes = channels.next_power_of_two().clamp(1, 32);
    (lanes, CubeCount::new_1d(channels.div_ceil(lanes) as u32))
}

/// `Σ t[n, c, ...]` by channel of `t` `[N, C, ...]` (any strides): a layer's bias gradient.
pub fn launch_channel_sums(t: CubeTensor) -> CubeTensor {
    let t = flat(t);
    let channels = t.meta.shape()[1];
    let partials = launch_partial_sums(&t, None, None, None, Summand::Plain);
    let sums = empty_f32(&t, [channels]);
    let (lanes, count) = finish_grid(channels);
    finish_sums::launch(
        &t.client,
        count,
        CubeDim::new_1d(BLOCK as u32),
        partials.into_tensor_arg(),
        sums.clone().into_tensor_arg(),
        lanes,
        BLOCK,
    );
    sums
}
