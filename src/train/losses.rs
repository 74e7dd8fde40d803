//! Losses of the self-models, with PyTorch's semantics so the notebooks' numbers compare; in
//! f32 whatever dtype the network computed in (as autocast, [`super::precision`]).

use burn::tensor::Tensor;

use super::precision::widened;

/// Binary cross-entropy of probabilities `p` against targets `y` in [0, 1] (any equal shapes),
/// mean over all elements. `p` is clamped to [1e-7, 1 - 1e-7] before the logs (PyTorch's
/// `BCELoss` clamps the logs at -100 instead; in f32 a saturated sigmoid gives exactly 0,
/// whose log gradient would turn the step into NaN).
pub fn bce<const D: usize>(p: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    let (p, y) = (widened(p), widened(y));
    let p = p.clamp(1e-7, 1.0 - 1e-7);
    let log_p = p.clone().log();
    let log_1mp = p.neg().add_scalar(1.0).log();
    let per = y.clone() * log_p + y.neg().add_scalar(1.0) * log_1mp;
    per.mean().neg()
}

/// Binary cross-entropy of `sigmoid(z)` against `y`, computed stably from the logits `z`:
/// `max(z, 0) - z y + log(1 + exp(-|z|))`, mean over all elements. Equal to `sigmoid` followed
/// by PyTorch's `BCELoss` wherever that is finite. On the CPU, one parallel kernel forward and
/// one backward ([`crate::kernels::pointwise::bce_with_logits_elements`] and its gradient); on
/// a GPU two launches forward and one backward (`kernels::cube::loss`); the tests compare each
/// with [`bce_with_logits_composed`].
pub fn bce_with_logits<const D: usize>(z: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    let (z, y) = (widened(z), widened(y));
    if let Some(loss) = crate::kernels::cpu_extension::bce_with_logits(&z, &y) {
        return loss;
    }
    #[cfg(feature = "cube")]
    if let Some(loss) = crate::kernels::cube::extension::bce_with_logits(&z, &y) {
        return loss;
    }
    bce_with_logits_composed(z, y)
}

/// [`bce_with_logits`] as burn's elementwise ops (off the CPU, and the CPU kernel's reference).
pub fn bce_with_logits_composed<const D: usize>(z: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    let softplus = z.clone().abs().neg().exp().log1p();
    (z.clone().clamp_min(0.0) - z * y + softplus).mean()
}

/// Soft Dice loss `1 - (2 sum(p y) + 1) / (sum(p) + sum(y) + 1)` over the whole batch.
pub fn soft_dice<const D: usize>(p: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    let (p, y) = (widened(p), widened(y));
    let inter = (p.clone() * y.clone()).sum();
    let total = p.sum() + y.sum();
    inter
        .mul_scalar(2.0)
        .add_scalar(1.0)
        .div(total.add_scalar(1.0))
        .neg()
        .add_scalar(1.0)
}

/// Mean squared error.
pub fn mse<const D: usize>(p: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    (widened(p) - widened(y)).square().mean()
}

/// Mean absolute error.
pub fn l1<const D: usize>(p: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    (widened(p) - widened(y)).abs().mean()
}

/// Mean absolute error over the elements where `mask` is 1 (e.g. depth on robot pixels).
pub fn l1_masked<const D: usize>(p: Tensor<D>, y: Tensor<D>, mask: Tensor<D>) -> Tensor<1> {
    let (p, y, mask) = (widened(p), widened(y), widened(mask));
    let count = mask.clone().sum().clamp_min(1.0);
    ((p - y).abs() * mask).sum().div(count)
}
