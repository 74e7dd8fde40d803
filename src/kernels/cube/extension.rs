//! Our GPU kernels inside burn's autodiff graph: a burn backend extension, as
//! [`crate::kernels::cpu_extension`] is for the CPU.
//!
//! [`GpuKernelOps`] is routed through burn's `Dispatch` by `#[backend_extension]`: on burn's
//! CubeCL backend (`CubeBackend`) its methods launch our kernels; on the fusion backend that
//! wraps it on a GPU they are recorded as operations of their own (the kernels) or run as
//! their default bodies in burn's operations (which burn fuses); on `Autodiff` the layer is
//! one operation with a hand-written backward pass. The default bodies are the slow
//! references the tests compare the kernels with.

use burn::backend::fusion::custom::TensorSpec;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, Scalar, TensorMetadata, backend_extension};
use burn::nn::BatchNorm;
use burn::tensor::{Shape, Tensor};
use burn_cubecl::CubeBackend;

use super::batch_norm::{
    Layer, ParamGrads, ParamGradsMetadata, Saved, Statistics, StatisticsMetadata,
};
use super::conv_layer::{Conv2dLayer, ConvTranspose2dLayer};
use super::im2col::{Fold, Patches};
use super::{batch_norm, channel_reduce, im2col, loss};

/// A `[channels]` tensor's spec for an `[N, C, ...]` input.
pub(super) fn per_channel(x: &TensorSpec) -> TensorSpec {
    TensorSpec::new(Shape::new([x.shape[1]]), x.dtype)
}

/// `[C]` -> `[1, C, 1, ...]` of rank `rank`.
pub(super) fn broadcast<B: Backend>(v: FloatTensor<B>, rank: usize) -> FloatTensor<B> {
    let c = v.shape()[0];
    let mut dims = vec![1; rank];
    dims[1] = c;
    B::float_reshape(v, Shape::from(dims))
}

/// `[N, C, ...]` -> `[C, N·...]`: a channel a row (burn's way to reduce by channel: a copy).
pub(super) fn by_channel<B: Backend>(t: FloatTensor<B>) -> FloatTensor<B> {
    let c = t.shape()[1];
    let flat = Shape::new([c, t.shape().num_elements() / c]);
    B::float_reshape(B::float_swap_dims(t, 0, 1), flat)
}

/// `relu(x)` where `relu`, else `x`.
pub(super) fn maybe_relu<B: Backend>(x: FloatTensor<B>, relu: bool) -> FloatTensor<B> {
    if relu { B::relu(x) } else { x }
}

/// The gradient reaching a batch norm's normalisation from `dy` (masked where a ReLU after
/// it gave 0).
pub(super) fn reaching<B: Backend>(
    y: FloatTensor<B>,
    dy: FloatTensor<B>,
    relu: bool,
) -> FloatTensor<B> {
    if relu { B::relu_backward(y, dy) } else { dy }
}

/// Operations that burn composes of many launches, as kernels of ours on a GPU.
#[backend_extension(Cube, Fusion, Autodiff)]
pub trait GpuKernelOps: Backend {
    /// A batch-norm `layer`'s statistics over `x` `[N, C, ...]` in training (see
    /// [`Statistics`]; `γ`, `β` and `relu` are not read).
    #[fusion(meta = |x, _layer| {
        let c = per_channel(x);
        StatisticsMetadata {
            mean: c.clone(),
            var: c.clone(),
            inv_std: c.clone(),
            running_mean: c.clone(),
            running_var: c,
        }
    })]
    fn batch_norm_statistics(
        x: FloatTensor<Self>,
        #[extension_type] layer: Layer<Self>,
    ) -> Statistics<Self> {
        let rank = x.shape().num_dims();
        let c = x.shape()[1];
        let mean = Self::float_mean_dim(by_channel::<Self>(x.clone()), 1);
        let mean = Self::float_reshape(mean, Shape::new([c]));
        let centred = Self::float_sub(x, broadcast::<Self>(mean.clone(), rank));
        let var = Self::float_mean_dim(
            by_channel::<Self>(Self::float_mul(centred.clone(), centred)),
            1,
        );
        let var = Self::float_reshape(var, Shape::new([c]));
        let inv_std = Self::float_recip(Self::float_sqrt(Self::float_add_scalar(
            var.clone(),
            Scalar::Float(layer.epsilon),
        )));
        let momentum = layer.momentum;
        let moved = |r: FloatTensor<Self>, s: FloatTensor<Self>| {
            Self::float_add(
                Self::float_mul_scalar(r, Scalar::Float(1.0 - momentum)),
                Self::float_mul_scalar(s, Scalar::Float(momentum)),
            )
        };
        Statistics {
            running_mean: moved(layer.running_mean, mean.clone()),
            running_var: moved(layer.running_var, var.clone()),
            mean,
            var,
            inv_std,
        }
    }

    /// A batch-norm layer's `γ` and `β` gradients from what its backward pass reads.
    #[fusion(meta = |saved| ParamGradsMetadata {
        gamma: per_channel(&saved.x),
        beta: per_channel(&saved.x),
    })]
    fn batch_norm_param_grads(#[extension_type] saved: Saved<Self>) -> ParamGrads<Self> {
        let rank = saved.x.shape().num_dims();
        let c = saved.x.shape()[1];
        let g = reaching::<Self>(saved.y, saved.dy, saved.relu);
        let centred = Self::float_sub(saved.x, broadcast::<Self>(saved.mean, rank));
        let beta = Self::float_sum_dim(by_channel::<Self>(g.clone()), 1);
        let gx = Self::float_sum_dim(by_channel::<Self>(Self::float_mul(g, centred)), 1);
        ParamGrads {
            gamma: Self::float_mul(Self::float_reshape(gx, Shape::new([c])), saved.inv_std),
            beta: Self::float_reshape(beta, Shape::new([c])),
        }
    }

    /// A batch-norm layer's input gradient from what its backward pass reads, its `gamma` and
    /// the `γ` and `β` gradients [`Self::batch_norm_param_grads`] gave.
    #[fusion(meta = |saved, _gamma, _grads| saved.x.clone())]
    fn batch_norm_x_grad(
        #[extension_type] saved: Saved<Self>,
        gamma: FloatTensor<Self>,
        #[extension_type] grads: ParamGrads<Self>,
    ) -> FloatTensor<Self> {
        // γ/std (g - Σg/M - (x - mean)/std · Σ g (x - mean)/std / M).
        let rank = saved.x.shape().num_dims();
        let count = (saved.x.shape().num_elements() / saved.x.shape()[1]) as f64;
        let c = |t| broadcast::<Self>(t, rank);
        let g = reaching::<Self>(saved.y, saved.dy, saved.relu);
        let centred = Self::float_sub(saved.x, c(saved.mean));
        let xhat = Self::float_mul(centred, c(saved.inv_std.clone()));
        let mean_g = Self::float_div_scalar(grads.beta, Scalar::Float(count));
        let projection = Self::float_div_scalar(grads.gamma, Scalar::Float(count));
        let dx = Self::float_sub(
            Self::float_sub(g, c(mean_g)),
            Self::float_mul(xhat, c(projection)),
        );
        Self::float_mul(dx, c(Self::float_mul(gamma, saved.inv_std)))
    }

    /// The columns (im2col) of `t` `[N, C, H, W]` over `patches`: `[N, h·w, C·k·k]` (see
    /// `kernels::cube::im2col`).
    #[fusion(meta = |t, patches| {
        let [h, w] = patches.grid;
        TensorSpec::new(Shape::new([t.shape[0], h * w, patches.width(t.shape[1])]), t.dtype)
    })]
    fn im2col(t: FloatTensor<Self>, patches: Patches) -> FloatTensor<Self> {
        // Only the CubeCL kernel: the layers' references are burn's own convolutions and
        // their backward passes, which `tests/gpu/kernels.rs` compares them with.
        let _ = (t, patches);
        unreachable!("im2col runs on CubeCL devices only")
    }

    /// The image `fold.out` `[N, C, H, W]` whose columns over `fold.patches` are `cols`
    /// `[N, h·w, C·k·k]`, overlaps summed, plus `bias` `[C]` where `fold.with_bias` (see
    /// `kernels::cube::im2col`).
    #[fusion(meta = |cols, _bias, fold| TensorSpec::new(Shape::new(fold.out), cols.dtype))]
    fn col2im(cols: FloatTensor<Self>, bias: FloatTensor<Self>, fold: Fold) -> FloatTensor<Self> {
        // Only the CubeCL kernel (see `im2col`).
        let _ = (cols, bias, fold);
        unreachable!("col2im runs on CubeCL devices only")
    }

    /// `Σ t[n, c, ...]` by channel: `[C]`.
    #[fusion(meta = |t| per_channel(t))]
    fn channel_sums(t: FloatTensor<Self>) -> FloatTensor<Self> {
        let c = t.shape()[1];
        Self::float_reshape(
            Self::float_sum_dim(by_channel::<Self>(t), 1),
            Shape::new([c]),
        )
    }

    /// A convolution with bias as [`Self::im2col`] and a matrix product (none for a 1x1
    /// kernel), differentiated by two products and [`Self::col2im`] (square kernels, equal
    /// strides and paddings, no dilation or groups; `kernels::cube::convolution`).
    #[fusion(default)]
    fn conv2d_train(
        x: FloatTensor<Self>,
        #[extension_type] layer: Conv2dLayer<Self>,
    ) -> FloatTensor<Self> {
        Self::conv2d(x, layer.weight, Some(layer.bias), layer.options)
    }

    /// A transposed convolution with bias as a matrix product and [`Self::col2im`],
    /// differentiated by [`Self::im2col`] and two matrix products (as [`Self::conv2d_train`]).
    #[fusion(default)]
    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        #[extension_type] layer: ConvTranspose2dLayer<Self>,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d(x, layer.weight, Some(layer.bias), layer.options)
    }

    /// The mean binary cross-entropy of the logits `z` against the targets `y`, a `[1]`
    /// tensor (differentiated in `z` by [`Self::bce_with_logits_grad`]).
    #[fusion(meta = |z, _y| TensorSpec::new(Shape::new([1]), z.dtype))]
    fn bce_with_logits_mean(z: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        let n = z.shape().num_elements();
        let softplus =
            Self::float_log1p(Self::float_exp(Self::float_neg(Self::float_abs(z.clone()))));
        let l = Self::float_add(
            Self::float_sub(
                Self::float_clamp_min(z.clone(), Scalar::Float(0.0)),
                Self::float_mul(z, y),
            ),
            softplus,
        );
        Self::float_mean(Self::float_reshape(l, Shape::new([n])))
    }

    /// The gradient of [`Self::bce_with_logits_mean`] in `z`, given the loss's gradient `grad`
    /// (`[1]`): `(σ(z) - y) grad / n`.
    #[fusion(dtype = z, shape = z)]
    fn bce_with_logits_grad(
        z: FloatTensor<Self>,
        y: FloatTensor<Self>,
        grad: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        let n = z.shape().num_elements() as f64;
        let rank = z.shape().num_dims();
        let g = Self::float_reshape(grad, Shape::from(vec![1; rank]));
        let d = Self::float_sub(Self::sigmoid(z), y);
        Self::float_mul(d, Self::float_div_scalar(g, Scalar::Float(n)))
    }

    /// A batch-norm `layer` in training (and the ReLU after it where it has one): the output,
    /// and the new running mean and variance (burn's `BatchNorm::forward` in training, as one
    /// operation of the autodiff graph).
    #[fusion(default)]
    fn batch_norm_train(
        x: FloatTensor<Self>,
        #[extension_type] layer: Layer<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        let (gamma, beta, epsilon, relu) = (
            layer.gamma.clone(),
            layer.beta.clone(),
            layer.epsilon,
            layer.relu,
        );
        let stats = Self::batch_norm_statistics(x.clone(), layer);
        let y = Self::batch_norm(x, gamma, beta, stats.mean, stats.var, epsilon);
        (
            maybe_relu::<Self>(y, relu),
            stats.running_mean,
            stats.running_var,
        )
    }
}

impl GpuKernelOps for CubeBackend {
    fn im2col(t: FloatTensor<Self>, patches: Patches) -> FloatTensor<Self> {
        im2col::launch_columns(t, patches)
    }

    fn channel_sums(t: FloatTensor<Self>) -> FloatTensor<Self> {
        channel_reduce::launch_channel_sums(t)
    }

    fn col2im(cols: FloatTensor<Self>, bias: FloatTensor<Self>, fold: Fold) -> FloatTensor<Self> {
        let bias = fold.with_bias.then_some(bias);
        im2col::launch_col2im(cols, bias, fold.patches, fold.out)
    }

    fn bce_with_logits_mean(z: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        loss::launch_mean(z, y)
    }

    fn bce_with_logits_grad(
        z: FloatTensor<Self>,
        y: FloatTensor<Self>,
        grad: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        loss::launch_logits_grad(z, y, grad)
    }

    fn batch_norm_statistics(x: FloatTensor<Self>, layer: Layer<Self>) -> Statistics<Self> {
        batch_norm::launch_statistics(x, layer)
    }

    fn batch_norm_param_grads(saved: Saved<Self>) -> ParamGrads<Self> {
        batch_norm::launch_grad_sums(saved)
    }

    fn batch_norm_x_grad(
        saved: Saved<Self>,
        gamma: FloatTensor<Self>,
        grads: ParamGrads<Self>,
    ) -> FloatTensor<Self> {
        batch_norm::launch_x_grad(saved, gamma, grads)
    }
}

/// burn's `BatchNorm::forward` then a ReLU where `relu`, on our kernels where `x` is on a GPU
/// and the layer trains (the running statistics updated as burn updates them); `None`
/// elsewhere.
pub fn batch_norm<const D: usize>(
    norm: &BatchNorm,
    x: &Tensor<D>,
    relu: bool,
) -> Option<Tensor<D>> {
    let training = x.device().is_autodiff() && norm.training.is_enabled();
    if !training || !super::on_kernels(&x.clone().inner()) {
        return None;
    }
    let device = x.device();
    // As burn's: `value_sync` (the mean over the threads that updated the state, one here:
    // burn's `RunningState` divides by their count, a launch a layer).
    let running_mean = norm.running_mean.value_sync().to_device(&device);
    let running_var = norm.running_var.value_sync().to_device(&device);
    let layer = Layer {
        gamma: norm.gamma.val().into_dispatch(),
        beta: norm.beta.val().into_dispatch(),
        running_mean: running_mean.into_dispatch(),
        running_var: running_var.into_dispatch(),
        epsilon: norm.epsilon,
        momentum: norm.momentum,
        relu,
    };
    let (y, rm, rv) =
        <Dispatch as GpuKernelOps>::batch_norm_train(x.clone().into_dispatch(), layer);
    let rm = Tensor::<1>::from_dispatch(rm);
    let rv = Tensor::<1>::from_dispatch(rv);
    norm.running_mean.update(rm.detach());
    norm.running_var.update(rv.detach());
    Some(Tensor::from_dispatch(y))
}

/// The mean binary cross-entropy of the logits `z` against the targets `y` on our kernels
/// where `z` is on a GPU; `None` elsewhere.
pub fn bce_with_logits<const D: usize>(z: &Tensor<D>, y: &Tensor<D>) -> Option<Tensor<1>> {
    let on_gpu = super::on_kernels(&z.clone().inner()) && super::on_kernels(&y.clone().inner());
    on_gpu.then(|| {
        Tensor::from_dispatch(<Dispatch as GpuKernelOps>::bce_with_logits_mean(
            z.clone().into_dispatch(),
            y.clone().into_dispatch(),
        ))
    })
}
