//! NeRF-style positional encoding with log-spaced frequency bands (FFKSM, self-modeling paper
//! section IV-B; Hu et al. 2024).
//!
//! For an input `x` `[n, d]` and `bands` = L, the encoding is
//! `[x, sin(2⁰x), cos(2⁰x), sin(2¹x), cos(2¹x), …, sin(2^(L-1)x), cos(2^(L-1)x)]`, each term a
//! `d`-vector: `[n, d (1 + 2L)]`. The reimplementation's L = 5 maps a 3-D point to 33 values
//! and the two distal joint angles (radians) to 22; the original authors' L = 10 to 63 and 42.

use burn::tensor::Tensor;

/// Width of the encoding of a `d`-vector with `bands` bands: `d (1 + 2 bands)`.
pub fn encoded_width(d: usize, bands: usize) -> usize {
    d * (1 + 2 * bands)
}

/// Encode `x` `[n, d]` into `[n, d (1 + 2 bands)]` (see the module documentation).
pub fn encode(x: Tensor<2>, bands: usize) -> Tensor<2> {
    let mut terms = Vec::with_capacity(1 + 2 * bands);
    terms.push(x.clone());
    for k in 0..bands {
        let scaled = x.clone().mul_scalar((1u64 << k) as f32);
        terms.push(scaled.clone().sin());
        terms.push(scaled.cos());
    }
    Tensor::cat(terms, 1)
}

/// The slow reference of [`encode`] for one `d`-vector, in `f64`.
pub fn encode_reference(x: &[f64], bands: usize) -> Vec<f64> {
    let mut out = x.to_vec();
    for k in 0..bands {
        let f = (1u64 << k) as f64;
        out.extend(x.iter().map(|v| (f * v).sin()));
        out.extend(x.iter().map(|v| (f * v).cos()));
    }
    out
}

/// [`encode`] of one `d`-vector `x` on the host, in `f32`, into `out` (`d (1 + 2 bands)`
/// values): the layout the hand-written training step ([`crate::self_models::ffksm::dense_step`]) shares.
pub fn encode_into(x: &[f32], bands: usize, out: &mut [f32]) {
    let d = x.len();
    assert_eq!(out.len(), encoded_width(d, bands));
    out[..d].copy_from_slice(x);
    for k in 0..bands {
        let f = (1u64 << k) as f32;
        for (j, v) in x.iter().enumerate() {
            let (sin, cos) = (v * f).sin_cos();
            out[d * (1 + 2 * k) + j] = sin;
            out[d * (2 + 2 * k) + j] = cos;
        }
    }
}
