//! Bilinear resize of NCHW planes (PyTorch's `F.interpolate(mode="bilinear",
//! align_corners=False)`), forward and backward, separable, on the CPU.
//!
//! NeuroKin resizes its 30x30 features to 100x100 before the head. flex's kernel computes the
//! source coordinates in `f64` with `floor` per output pixel; here the taps are computed once per
//! call and the resize runs in two passes, along rows (a gather of two taps) and then along
//! columns (two whole rows blended, which vectorises). The backward pass runs the same two
//! passes transposed. Planes run in parallel; each plane's sums are in a fixed order, so the
//! result does not depend on the scheduling. The reference is burn's `interpolate` (see the
//! tests).

use crate::kernels::parallel_output::zeroed_in_parallel;

/// The two source indices and the weight of the second, for each output coordinate.
#[derive(Clone, Debug)]
struct Taps {
    lo: Vec<usize>,
    hi: Vec<usize>,
    frac: Vec<f32>,
}

impl Taps {
    /// `src = max((dst + 0.5) · in / out − 0.5, 0)`, `lo = floor(src)`, `hi = min(lo + 1, in − 1)`.
    fn new(input: usize, output: usize) -> Self {
        let scale = input as f32 / output as f32;
        let mut taps = Taps {
            lo: Vec::with_capacity(output),
            hi: Vec::with_capacity(output),
            frac: Vec::with_capacity(output),
        };
        for d in 0..output {
            let src = ((d as f32 + 0.5) * scale - 0.5).max(0.0);
            let lo = (src as usize).min(input - 1);
            taps.lo.push(lo);
            taps.hi.push((lo + 1).min(input - 1));
            taps.frac.push(src - lo as f32);
        }
        taps
    }
}

/// `x` `[planes, h, w]` -> `[planes, out_h, out_w]`.
pub fn resize(x: &[f32], planes: usize, input: [usize; 2], output: [usize; 2]) -> Vec<f32> {
    let [h, w] = input;
    let [oh, ow] = output;
    assert_eq!(x.len(), planes * h * w);
    let (ty, tx) = (Taps::new(h, oh), Taps::new(w, ow));
    zeroed_in_parallel(
        planes * oh * ow,
        oh * ow,
        || vec![0f32; h * ow],
        |rows, plane, out| {
            let x = &x[plane * h * w..(plane + 1) * h * w];
            // Rows: [h, w] -> [h, ow].
            for (row, src) in rows.chunks_exact_mut(ow).zip(x.chunks_exact(w)) {
                for (o, r) in row.iter_mut().enumerate() {
                    let f = tx.frac[o];
                    *r = src[tx.lo[o]] * (1.0 - f) + src[tx.hi[o]] * f;
                }
            }
            // Columns: [h, ow] -> [oh, ow].
            for (oy, dst) in out.chunks_exact_mut(ow).enumerate() {
                let f = ty.frac[oy];
                let a = &rows[ty.lo[oy] * ow..][..ow];
                let b = &rows[ty.hi[oy] * ow..][..ow];
                for ((d, &a), &b) in dst.iter_mut().zip(a).zip(b) {
                    *d = a * (1.0 - f) + b * f;
                }
            }
        },
    )
}

/// The gradient of [`resize`] with respect to its input: `grad` `[planes, out_h, out_w]` ->
/// `[planes, h, w]`.
pub fn resize_backward(
    grad: &[f32],
    planes: usize,
    input: [usize; 2],
    output: [usize; 2],
) -> Vec<f32> {
    let [h, w] = input;
    let [oh, ow] = output;
    assert_eq!(grad.len(), planes * oh * ow);
    let (ty, tx) = (Taps::new(h, oh), Taps::new(w, ow));
    zeroed_in_parallel(
        planes * h * w,
        h * w,
        || vec![0f32; h * ow],
        |rows, plane, dx| {
            let g = &grad[plane * oh * ow..(plane + 1) * oh * ow];
            rows.fill(0.0);
            // Columns, transposed: [oh, ow] -> [h, ow].
            for (oy, src) in g.chunks_exact(ow).enumerate() {
                let f = ty.frac[oy];
                for (r, &v) in rows[ty.lo[oy] * ow..][..ow].iter_mut().zip(src) {
                    *r += v * (1.0 - f);
                }
                for (r, &v) in rows[ty.hi[oy] * ow..][..ow].iter_mut().zip(src) {
                    *r += v * f;
                }
            }
            // Rows, transposed: [h, ow] -> [h, w].
            for (dst, row) in dx.chunks_exact_mut(w).zip(rows.chunks_exact(ow)) {
                for (o, &v) in row.iter().enumerate() {
                    let f = tx.frac[o];
                    dst[tx.lo[o]] += v * (1.0 - f);
                    dst[tx.hi[o]] += v * f;
                }
            }
        },
    )
}

/// The `[output, input]` matrix of a 1-D bilinear resize (align_corners false: PyTorch's
/// source coordinate `(o + 0.5) * input / output - 0.5`, clamped at 0).
pub fn resize_matrix(input: usize, output: usize) -> Vec<f32> {
    let mut m = vec![0.0f32; output * input];
    let scale = input as f64 / output as f64;
    for o in 0..output {
        let src = ((o as f64 + 0.5) * scale - 0.5).max(0.0);
        let i0 = (src.floor() as usize).min(input - 1);
        let i1 = (i0 + 1).min(input - 1);
        let l1 = (src - i0 as f64) as f32;
        m[o * input + i0] += 1.0 - l1;
        m[o * input + i1] += l1;
    }
    m
}

/// Bilinear resize of `[batch, channels, h, w]` to `size` as two matrix products
/// (`R_h · x · R_wᵀ`): any backend, differentiable wherever matmul is (burn's GPU backends
/// have no backward for bilinear `interpolate`). Tested against the CPU kernel. The two
/// matrices are built and uploaded once per device and shape ([`resize_matrices`]), not at
/// every call.
pub fn resize_matmul(x: burn::tensor::Tensor<4>, size: [usize; 2]) -> burn::tensor::Tensor<4> {
    let [b, c, h, w] = x.dims();
    // A batched product launches a workgroup column per matrix in the batch on a GPU, and a
    // dispatch takes at most 65,535 in a dimension: more images than that (4,096 of 16
    // channels) are resized a slice at a time (burn's naive product, which autotune tries,
    // failed there: `Cube count too big (4, 4, 65536)`).
    if b * c > MAX_BATCHED && b > 1 {
        let per = (MAX_BATCHED / c).max(1);
        let parts = x
            .split(per, 0)
            .into_iter()
            .map(|p| resize_matmul(p, size))
            .collect();
        return burn::tensor::Tensor::cat(parts, 0);
    }
    let (rh, rw_t) = resize_matrices(&x.device(), [h, w], size);
    // A lower precision's input (autocast) meets matrices of its own dtype.
    let (rh, rw_t) = if x.dtype() == rh.dtype() {
        (rh, rw_t)
    } else {
        let dtype: burn::tensor::FloatDType = x.dtype().into();
        (rh.cast(dtype), rw_t.cast(dtype))
    };
    let rows = x.matmul(rw_t.unsqueeze::<4>().expand([b, c, w, size[1]]));
    rh.unsqueeze::<4>().expand([b, c, size[0], h]).matmul(rows)
}

/// The most matrices one batched product of [`resize_matmul`] multiplies: a GPU dispatch's
/// limit of workgroups in a dimension.
const MAX_BATCHED: usize = 65_535;

/// `R_h` (`[size[0], h]`) and `R_wᵀ` (`[w, size[1]]`) on `device`, made once per device and
/// shape and kept for the process (a decoder resizes between the same shapes at every step).
fn resize_matrices(
    device: &burn::tensor::Device,
    input: [usize; 2],
    size: [usize; 2],
) -> (burn::tensor::Tensor<2>, burn::tensor::Tensor<2>) {
    use burn::tensor::{Tensor, TensorData};
    type Key = (burn::tensor::Device, [usize; 2], [usize; 2]);
    static CACHE: std::sync::Mutex<Vec<(Key, Tensor<2>, Tensor<2>)>> =
        std::sync::Mutex::new(Vec::new());
    let key = (device.clone(), input, size);
    let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, rh, rw_t)) = cache.iter().find(|(k, _, _)| *k == key) {
        return (rh.clone(), rw_t.clone());
    }
    let [h, w] = input;
    let rw_t: Tensor<2> = Tensor::<2>::from_data(
        TensorData::new(resize_matrix(w, size[1]), [size[1], w]),
        device,
    )
    .transpose();
    let rh: Tensor<2> = Tensor::from_data(
        TensorData::new(resize_matrix(h, size[0]), [size[0], h]),
        device,
    );
    cache.push((key, rh.clone(), rw_t.clone()));
    (rh, rw_t)
}
