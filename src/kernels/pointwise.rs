//! Elementwise steps of a training step on the CPU, forward and backward, in parallel: a
//! layer's bias and ReLU, the sigmoid, the binary cross-entropy on logits, and Adam's update.
//!
//! flex runs every elementwise operation on the calling thread. After each convolution of a
//! NeuroKin step (our kernels, on every thread) the bias add and the ReLU then ran on one
//! thread while the others waited, and the loss (nine elementwise operations forward, more
//! backward) too: a few percent of a step on 2 threads each, a share that grows with every
//! thread added (Amdahl). Here they run over chunks on rayon's workers, each element computed
//! as burn's ops compute it, so values and gradients are burn's to the bit (the tests compare
//! them bit for bit) and a run gives the numbers it gave before; the sums (the bias gradient,
//! the loss's mean) stay flex's own.

use rayon::prelude::*;

use crate::kernels::parallel_output::{self, zeroed_in_parallel};

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

/// `max(x, 0)`, NaN kept (as burn's and PyTorch's ReLU).
pub fn relu(x: &[f32]) -> Vec<f32> {
    map(x, |v| if v.is_nan() || v > 0.0 { v } else { 0.0 })
}

/// The gradient of [`relu`] from its input `x`: `grad` where `x > 0` (or NaN), else 0.
pub fn relu_backward(x: &[f32], grad: &[f32]) -> Vec<f32> {
    zip_map(x, grad, |v, g| if v.is_nan() || v > 0.0 { g } else { 0.0 })
}

/// The logistic sigmoid as flex computes it (`1 / (1 + e^-x)` for `x >= 0`, `e^x / (1 + e^x)`
/// below), so that the values are flex's to the bit.
fn logistic(v: f32) -> f32 {
    if v >= 0.0 {
        1.0 / (1.0 + (-v).exp())
    } else {
        let e = v.exp();
        e / (1.0 + e)
    }
}

/// `out[i] = f(a[i], b[i])` over chunks in parallel.
fn zip_map(a: &[f32], b: &[f32], f: impl Fn(f32, f32) -> f32 + Sync + Send) -> Vec<f32> {
    assert_eq!(a.len(), b.len());
    zeroed_in_parallel(
        a.len(),
        CHUNK,
        || (),
        |_, index, out| {
            let start = index * CHUNK;
            let (a, b) = (&a[start..][..out.len()], &b[start..][..out.len()]);
            for ((o, &a), &b) in out.iter_mut().zip(a).zip(b) {
                *o = f(a, b);
            }
        },
    )
}

/// `out[i] = f(a[i])` over chunks in parallel.
fn map(a: &[f32], f: impl Fn(f32) -> f32 + Sync + Send) -> Vec<f32> {
    zeroed_in_parallel(
        a.len(),
        CHUNK,
        || (),
        |_, index, out| {
            let a = &a[index * CHUNK..][..out.len()];
            for (o, &a) in out.iter_mut().zip(a) {
                *o = f(a);
            }
        },
    )
}

/// The logistic sigmoid, flex's values to the bit.
pub fn sigmoid(x: &[f32]) -> Vec<f32> {
    map(x, logistic)
}

/// The gradient of [`sigmoid`] from its output `s`: `grad · s · (1 − s)`.
pub fn sigmoid_backward(s: &[f32], grad: &[f32]) -> Vec<f32> {
    zip_map(s, grad, |s, g| g * s * (1.0 - s))
}

/// The binary cross-entropy of each logit `z` against its target `y`,
/// `(max(z, 0) − z·y) + ln(1 + e^−|z|)` (stable for any `z`), each element as burn's
/// composition of flex's ops computes it (its mean is then flex's own).
pub fn bce_with_logits_elements(z: &[f32], y: &[f32]) -> Vec<f32> {
    zip_map(z, y, |z, y| {
        let hinge = if z < 0.0 { 0.0 } else { z };
        (hinge - z * y) + (-z.abs()).exp().ln_1p()
    })
}

/// The gradient of the mean of [`bce_with_logits_elements`] for `z`, from `g` = the upstream
/// gradient times `1 / len` (as burn's mean passes it back): `σ(z) − y` times `g`, computed as
/// burn's autodiff differentiates the composition (the three paths through `z`, added in the
/// order it adds them), so the values are its own to the bit.
pub fn bce_with_logits_z_grad(z: &[f32], y: &[f32], g: f32) -> Vec<f32> {
    zip_map(z, y, |z, y| {
        let u = (-z.abs()).exp();
        let through_softplus = -((g * (1.0 / (u + 1.0))) * u);
        let sign = if z > 0.0 {
            1.0
        } else if z < 0.0 {
            -1.0
        } else {
            0.0
        };
        let through_hinge = if z < 0.0 { 0.0 } else { g };
        ((-g) * y + through_softplus * sign) + through_hinge
    })
}

/// The same gradient for `y`: `−g · z`.
pub fn bce_with_logits_y_grad(z: &[f32], g: f32) -> Vec<f32> {
    map(z, |z| (-g) * z)
}

/// One Adam step's constants (burn's `Adam`, no weight decay, no AMSGrad).
#[derive(Clone, Copy, Debug)]
pub struct AdamStep {
    pub beta_1: f32,
    pub beta_2: f32,
    pub epsilon: f32,
    /// The step's number, from 1.
    pub time: i32,
    pub lr: f32,
}

/// One Adam step on a parameter `p` with gradient `g` and moments `m`, `v` (zeros before the
/// first step): the new `(p, m, v)`, each element computed in the order of burn's `Adam` (its
/// tensor ops one after the other), so the values are burn's to the bit.
pub fn adam(p: &[f32], g: &[f32], m: &[f32], v: &[f32], s: AdamStep) -> [Vec<f32>; 3] {
    let n = p.len();
    assert!(g.len() == n && m.len() == n && v.len() == n);
    let (f1, f2) = (1.0 - s.beta_1, 1.0 - s.beta_2);
    let bias_correction2_sqrt = (1.0 - s.beta_2.powi(s.time)).sqrt();
    let combined = bias_correction2_sqrt / (1.0 - s.beta_1.powi(s.time));
    let eps = s.epsilon * bias_correction2_sqrt;
    let mut out = [0usize; 3].map(|_| parallel_output::zeros(n));
    let [p_out, m_out, v_out] = &mut out;
    p_out
        .par_chunks_mut(CHUNK)
        .zip(m_out.par_chunks_mut(CHUNK))
        .zip(v_out.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(chunk, ((po, mo), vo))| {
            let start = chunk * CHUNK;
            let range = start..start + po.len();
            let (p, g, m, v) = (
                &p[range.clone()],
                &g[range.clone()],
                &m[range.clone()],
                &v[range],
            );
            for i in 0..po.len() {
                let m = m[i] * s.beta_1 + g[i] * f1;
                let v = v[i] * s.beta_2 + (g[i] * g[i]) * f2;
                let update = (m * combined) / (v.sqrt() + eps);
                po[i] = p[i] - update * s.lr;
                mo[i] = m;
                vo[i] = v;
            }
        });
    out
}
