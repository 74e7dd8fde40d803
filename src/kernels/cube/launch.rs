//! Launching the multi-tensor kernels on burn's CubeCL tensors: contiguity, outputs, and the
//! tensors split into as many launches as the device's binding limit asks.

use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::multi_tensor::{self, AdamScalarsLaunch, BLOCK};
use super::{contiguous, elementwise, empty_f32, holds_f32, over_elements};
use crate::kernels::pointwise::AdamStep;

/// Workgroups a tensor's sum of squares is split over: enough that the largest tensor's
/// fill the GPU (a few thousand elements each), at least 8 and at most 512 (a smaller tensor's
/// spare workgroups find nothing to do and end at once).
fn groups(tensors: &[CubeTensor]) -> usize {
    let largest = tensors
        .iter()
        .map(|t| t.meta.num_elements())
        .max()
        .unwrap_or(0);
    largest.div_ceil(BLOCK * 16).clamp(8, 512)
}

/// Storage buffers one launch may bind: the device's limit, less one for the kernel's own
/// metadata.
fn max_bindings(t: &CubeTensor) -> usize {
    let limit = t.client.properties().hardware.max_bindings as usize;
    limit.saturating_sub(1).max(8)
}

fn f32_only(tensors: &[CubeTensor]) {
    assert!(
        tensors.iter().all(holds_f32),
        "the multi-tensor kernels take f32 tensors"
    );
}

/// The sum of squares of every element of `tensors`, `[1]`: partial sums over
/// [`groups`] workgroups a tensor, then one workgroup adds them up in a fixed order.
pub fn sum_of_squares(tensors: Vec<CubeTensor>) -> CubeTensor {
    assert!(!tensors.is_empty(), "the sum of squares of no tensor");
    f32_only(&tensors);
    let first = tensors[0].clone();
    let groups = groups(&tensors);
    let partials = empty_f32(&first, [tensors.len() * groups]);
    // Each launch binds its tensors (any strides) and the partials.
    let per_launch = max_bindings(&first) - 1;
    for (c, chunk) in tensors.chunks(per_launch).enumerate() {
        let mut seq = SequenceArg::<OwnedTensor<f32>>::new();
        for t in chunk {
            seq.push(t.clone().into_tensor_arg());
        }
        let elements = chunk.iter().map(|t| t.meta.num_elements()).sum();
        over_elements(elements, || {
            multi_tensor::sum_of_squares::launch(
                &first.client,
                CubeCount::new_2d(groups as u32, chunk.len() as u32),
                CubeDim::new_1d(BLOCK as u32),
                seq,
                partials.clone().into_tensor_arg(),
                (c * per_launch) as u32,
                BLOCK,
            )
        });
    }
    let total = empty_f32(&first, [1]);
    multi_tensor::sum_all::launch(
        &first.client,
        CubeCount::new_1d(1),
        CubeDim::new_1d(BLOCK as u32),
        partials.into_tensor_arg(),
        total.clone().into_tensor_arg(),
        BLOCK,
    );
    total
}

/// One Adam step of every parameter: `(params, grads, first moments, second moments)` in,
/// `(params, first moments, second moments)` out, as many parameters a launch as the device
/// binds. With `clip = Some((squared_norm, max))`, every gradient is first scaled by the global
/// norm's clipping factor (the squared norm from [`sum_of_squares`] over every gradient).
pub fn adam(
    params: Vec<CubeTensor>,
    grads: Vec<CubeTensor>,
    moment_1: Vec<CubeTensor>,
    moment_2: Vec<CubeTensor>,
    step: AdamStep,
    clip: Option<(CubeTensor, f32)>,
) -> Vec<[CubeTensor; 3]> {
    let n = params.len();
    assert!(n > 0 && grads.len() == n && moment_1.len() == n && moment_2.len() == n);
    f32_only(&params);
    f32_only(&grads);
    let first = params[0].clone();
    // Seven tensors a parameter, and the squared norm.
    let per_launch = ((max_bindings(&first) - 1) / 7).max(1);
    let (squared_norm, max_norm, clipping) = match clip {
        Some((p, max)) => (p, max, true),
        // A kernel argument is needed all the same: a tensor of its own (a buffer bound
        // twice in one launch is not allowed), never read.
        None => (empty_f32(&first, [1]), 0.0, false),
    };
    let bias_correction2_sqrt = (1.0 - step.beta_2.powi(step.time)).sqrt();
    let combined = bias_correction2_sqrt / (1.0 - step.beta_1.powi(step.time));
    let epsilon = step.epsilon * bias_correction2_sqrt;

    let contiguous_all =
        |v: Vec<CubeTensor>| -> Vec<CubeTensor> { v.into_iter().map(contiguous).collect() };
    // The gradients are read through their strides (a transposed weight gradient is not
    // copied); the parameters and moments are contiguous, as the outputs.
    let params = contiguous_all(params);
    let (moment_1, moment_2) = (contiguous_all(moment_1), contiguous_all(moment_2));
    let mut out = Vec::with_capacity(n);
    for start in (0..n).step_by(per_launch) {
        let end = (start + per_launch).min(n);
        let outs: Vec<[CubeTensor; 3]> = (start..end)
            .map(|i| {
                [&params[i], &moment_1[i], &moment_2[i]]
                    .map(|t| empty_f32(t, t.meta.shape().clone()))
            })
            .collect();
        let seq = |v: &[CubeTensor]| {
            let mut s = SequenceArg::<OwnedTensor<f32>>::new();
            for t in v {
                s.push(t.clone().into_tensor_arg());
            }
            s
        };
        let out_seq = |k: usize| {
            let mut s = SequenceArg::<OwnedTensor<f32>>::new();
            for o in &outs {
                s.push(o[k].clone().into_tensor_arg());
            }
            s
        };
        let elements: usize = (start..end).map(|i| params[i].meta.num_elements()).sum();
        let (cube_count, cube_dim) = elementwise(&first, elements);
        over_elements(elements, || {
            multi_tensor::adam::launch(
                &first.client,
                cube_count,
                cube_dim,
                seq(&params[start..end]),
                seq(&grads[start..end]),
                seq(&moment_1[start..end]),
                seq(&moment_2[start..end]),
                out_seq(0),
                out_seq(1),
                out_seq(2),
                squared_norm.clone().into_tensor_arg(),
                AdamScalarsLaunch::new(
                    step.lr,
                    step.beta_1,
                    step.beta_2,
                    combined,
                    epsilon,
                    max_norm,
                ),
                clipping,
            )
        });
        out.extend(outs);
    }
    out
}
