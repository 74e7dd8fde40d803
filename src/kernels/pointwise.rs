//! A layer's bias and ReLU on the CPU, forward and backward, in parallel.
//!
//! flex runs every elementwise operation on the calling thread. After each convolution of a
//! NeuroKin step (our kernels, on every thread) the bias add and the ReLU then ran on one
//! thread while the others waited: a few percent of a step on 2 threads, and a share that
//! grows with every thread added (Amdahl). Here they run over chunks on rayon's workers. The
//! values are those of burn's ops to the bit (an add, a comparison); the bias gradient sums
//! each channel in a fixed order (images, then pixels, in `f64`), whatever the thread count.
//! The tests compare values and gradients with burn's ops.

use rayon::prelude::*;

use crate::kernels::parallel_output::zeroed_in_parallel;

/// Elements per parallel chunk: a rayon job for at least this much work (below it, one
/// chunk, run on the calling thread).
const CHUNK: usize = 1 << 15;

/// `y[n, c, p] + bias[c]` for `y` `[batch, channels, plane]`.
pub fn add_bias(y: &[f32], bias: &[f32], plane: usize) -> Vec<f32> {
    let channels = bias.len();
    assert!(plane > 0 && y.len() % (channels * plane) == 0);
    // Whole planes per chunk, so each chunk's channels follow from its index.
    let planes_per_chunk = CHUNK.div_ceil(plane);
    zeroed_in_parallel(
        y.len(),
        planes_per_chunk * plane,
        || (),
        |_, index, out| {
            let first = index * planes_per_chunk;
            let src = &y[first * plane..first * plane + out.len()];
            for (k, (o, s)) in out
                .chunks_exact_mut(plane)
                .zip(src.chunks_exact(plane))
                .enumerate()
            {
                let b = bias[(first + k) % channels];
                for (o, &s) in o.iter_mut().zip(s) {
                    *o = s + b;
                }
            }
        },
    )
}

/// The bias gradient of [`add_bias`]: the sum of `grad` `[batch, channels, plane]` over images
/// and pixels, per channel.
pub fn bias_grad(grad: &[f32], channels: usize, plane: usize) -> Vec<f32> {
    assert!(channels > 0 && plane > 0 && grad.len() % (channels * plane) == 0);
    let batch = grad.len() / (channels * plane);
    (0..channels)
        .into_par_iter()
        .map(|c| {
            let mut sum = 0f64;
            for n in 0..batch {
                let p = &grad[(n * channels + c) * plane..][..plane];
                sum += p.iter().map(|&v| v as f64).sum::<f64>();
            }
            sum as f32
        })
        .collect()
}

/// `max(x, 0)`, NaN kept (as burn's and PyTorch's ReLU).
pub fn relu(x: &[f32]) -> Vec<f32> {
    zeroed_in_parallel(
        x.len(),
        CHUNK,
        || (),
        |_, index, out| {
            let src = &x[index * CHUNK..][..out.len()];
            for (o, &v) in out.iter_mut().zip(src) {
                *o = if v.is_nan() || v > 0.0 { v } else { 0.0 };
            }
        },
    )
}

/// The gradient of [`relu`] from its input `x`: `grad` where `x > 0` (or NaN), else 0.
pub fn relu_backward(x: &[f32], grad: &[f32]) -> Vec<f32> {
    assert_eq!(x.len(), grad.len());
    zeroed_in_parallel(
        x.len(),
        CHUNK,
        || (),
        |_, index, out| {
            let start = index * CHUNK;
            let (src, g) = (&x[start..][..out.len()], &grad[start..][..out.len()]);
            for ((o, &v), &g) in out.iter_mut().zip(src).zip(g) {
                *o = if v.is_nan() || v > 0.0 { g } else { 0.0 };
            }
        },
    )
}
