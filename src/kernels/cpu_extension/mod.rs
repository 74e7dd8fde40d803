//! Our CPU kernels inside burn's autodiff graph: a burn backend extension.
//!
//! On the flex backend:
//! - [`conv2d`] and [`conv_transpose2d`] run forward and backward on [`crate::kernels::conv_gemm`]
//!   (im2col + GEMM): the forward passes, the input gradients (as forward convolutions) and
//!   the weight gradients, instead of burn-backend's defaults, whose weight gradient runs a
//!   convolution with the activations as its kernel and took most of a NeuroKin training step;
//! - [`resize_bilinear`] runs forward and backward on [`crate::kernels::bilinear_resize`].
//!
//! On every other device (wgpu, ndarray) they are burn's own ops, unchanged.
//!
//! The extension: a backend trait [`CpuKernelOps`] routed through burn's `Dispatch` by
//! `#[backend_extension]`; its flex implementation calls the kernels; its `Autodiff`
//! implementation holds the hand-written backward passes. The tests compare values and
//! gradients with burn's ops.

use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, DType, Dispatch, DispatchDevice, TensorMetadata, backend_extension};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions, InterpolateMode, InterpolateOptions};
use burn::tensor::{Shape, Tensor};

use crate::kernels::pointwise;

mod autodiff;
mod flex;

/// Convolutions with a backend-chosen weight gradient. The default bodies are burn's ops.
#[backend_extension(Flex, Autodiff)]
pub trait CpuKernelOps: Backend {
    /// `conv2d` without bias; its backward pass is [`Self::conv2d_grads`].
    fn conv2d_fast(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        Self::conv2d(x, weight, None, options)
    }

    /// `conv_transpose2d` without bias; its backward pass is [`Self::conv_transpose2d_grads`].
    fn conv_transpose2d_fast(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d(x, weight, None, options)
    }

    /// The gradients of `conv2d` for its input and its weight `[c_out, c_in, kh, kw]` from
    /// the output's gradient `dy`, each where `need` asks for it.
    fn conv2d_grads(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        options: ConvOptions<2>,
        need: [bool; 2],
    ) -> (Option<FloatTensor<Self>>, Option<FloatTensor<Self>>) {
        (
            need[0].then(|| conv2d_x_grad::<Self>(x.clone(), weight.clone(), dy.clone(), &options)),
            need[1].then(|| Self::conv2d_weight_backward(x, weight, dy, options)),
        )
    }

    /// The gradients of `conv_transpose2d` for its input and its weight
    /// `[c_in, c_out, kh, kw]` from the output's gradient `dy`, each where `need` asks for it.
    fn conv_transpose2d_grads(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
        need: [bool; 2],
    ) -> (Option<FloatTensor<Self>>, Option<FloatTensor<Self>>) {
        (
            need[0].then(|| conv_transpose2d_x_grad::<Self>(weight.clone(), dy.clone(), &options)),
            need[1].then(|| Self::conv_transpose2d_weight_backward(x, weight, dy, options)),
        )
    }

    /// Bilinear resize of `[batch, channels, h, w]` to `size`, align_corners false; its
    /// backward pass uses [`Self::resize_bilinear_backward`].
    fn resize_bilinear_fast(x: FloatTensor<Self>, size: [usize; 2]) -> FloatTensor<Self> {
        Self::interpolate(x, size, bilinear_options())
    }

    /// `y` `[batch, channels, h, w]` plus `bias` `[channels]`; its backward pass uses
    /// [`Self::bias_grad`].
    fn add_bias_fast(y: FloatTensor<Self>, bias: FloatTensor<Self>) -> FloatTensor<Self> {
        let c = bias.shape().dims::<1>()[0];
        Self::float_add(y, Self::float_reshape(bias, Shape::new([1, c, 1, 1])))
    }

    /// The gradient of [`Self::add_bias_fast`]'s bias: `grad` summed over images and pixels.
    fn bias_grad(grad: FloatTensor<Self>) -> FloatTensor<Self> {
        // As burn's autodiff reduces a broadcast add's gradient: the same sums, to the bit.
        let c = grad.shape().dims::<4>()[1];
        Self::float_reshape(Self::float_sum_dims(grad, &[0, 2, 3]), Shape::new([c]))
    }

    /// `x` `[m, k]` · `w` `[k, n]` (a linear layer's weight); its backward pass is burn's
    /// linear layer's.
    fn matmul_fast(x: FloatTensor<Self>, w: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::float_matmul(x, w)
    }

    /// The logistic sigmoid; its backward pass uses [`Self::sigmoid_fast_backward`].
    fn sigmoid_fast(x: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::sigmoid(x)
    }

    /// The gradient of [`Self::sigmoid_fast`] from its output `s`.
    fn sigmoid_fast_backward(s: FloatTensor<Self>, grad: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::sigmoid_backward(s, grad)
    }

    /// The mean binary cross-entropy of logits `z` against targets `y` (`[1]`); its backward
    /// pass uses [`Self::bce_with_logits_grads`].
    fn bce_with_logits_fast(z: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        let softplus =
            Self::float_log1p(Self::float_exp(Self::float_neg(Self::float_abs(z.clone()))));
        let hinge = Self::float_clamp_min(z.clone(), 0.0.into());
        let loss = Self::float_add(Self::float_sub(hinge, Self::float_mul(z, y)), softplus);
        Self::float_mean(loss)
    }

    /// The gradients of [`Self::bce_with_logits_fast`] for `z` and `y` from the upstream
    /// gradient `grad` (`[1]`): `(σ(z) − y) · grad / n` and `−z · grad / n`.
    fn bce_with_logits_grads(
        z: FloatTensor<Self>,
        y: FloatTensor<Self>,
        grad: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let shape = z.shape();
        let ones = Shape::from(vec![1; shape.num_dims()]);
        let scale = Self::float_mul_scalar(grad, (1.0 / shape.num_elements() as f64).into());
        let scale = Self::float_expand(Self::float_reshape(scale, ones), shape);
        let dz = Self::float_mul(Self::float_sub(Self::sigmoid(z.clone()), y), scale.clone());
        let dy = Self::float_mul(Self::float_neg(z), scale);
        (dz, dy)
    }

    /// One Adam step (burn's `Adam`, no weight decay, no AMSGrad) on a parameter `p` with
    /// gradient `g` and moments `m`, `v`: the new `(p, m, v)`. No autodiff (an optimizer step).
    fn adam_step(
        p: FloatTensor<Self>,
        g: FloatTensor<Self>,
        m: FloatTensor<Self>,
        v: FloatTensor<Self>,
        step: pointwise::AdamStep,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        adam_step_composed::<Self>(p, g, m, v, step)
    }

    /// ReLU; its backward pass uses [`Self::relu_fast_backward`].
    fn relu_fast(x: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::relu(x)
    }

    /// The gradient of [`Self::relu_fast`] from its input `x`.
    fn relu_fast_backward(x: FloatTensor<Self>, grad: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::relu_backward(x, grad)
    }

    /// Gradient of [`Self::resize_bilinear_fast`] for an input of shape `input`.
    fn resize_bilinear_backward(grad: FloatTensor<Self>, input: [usize; 4]) -> FloatTensor<Self> {
        let [_, _, oh, ow] = grad.shape().dims::<4>();
        let x = Self::float_zeros(
            Shape::new(input),
            &grad.device(),
            burn::tensor::FloatDType::F32,
        );
        Self::interpolate_backward(x, grad, [oh, ow], bilinear_options())
    }
}

fn bilinear_options() -> InterpolateOptions {
    let mut options = InterpolateOptions::new(InterpolateMode::Bilinear);
    options.align_corners = false;
    options
}

/// [`CpuKernelOps::adam_step`] as burn's `Adam` computes it, one tensor op after another.
fn adam_step_composed<B: Backend>(
    p: FloatTensor<B>,
    g: FloatTensor<B>,
    m: FloatTensor<B>,
    v: FloatTensor<B>,
    step: pointwise::AdamStep,
) -> (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>) {
    let (f1, f2) = (1.0 - step.beta_1, 1.0 - step.beta_2);
    let m = B::float_add(
        B::float_mul_scalar(m, step.beta_1.into()),
        B::float_mul_scalar(g.clone(), f1.into()),
    );
    let v = B::float_add(
        B::float_mul_scalar(v, step.beta_2.into()),
        B::float_mul_scalar(B::float_mul(g.clone(), g), f2.into()),
    );
    let bias_correction2_sqrt = (1.0 - step.beta_2.powi(step.time)).sqrt();
    let combined = bias_correction2_sqrt / (1.0 - step.beta_1.powi(step.time));
    let denominator = B::float_add_scalar(
        B::float_sqrt(v.clone()),
        (step.epsilon * bias_correction2_sqrt).into(),
    );
    let update = B::float_div(B::float_mul_scalar(m.clone(), combined.into()), denominator);
    let p = B::float_sub(p, B::float_mul_scalar(update, step.lr.into()));
    (p, m, v)
}

fn kernel_supports(dtype: DType, dilation: &[usize; 2], groups: usize) -> bool {
    dtype == DType::F32 && *dilation == [1, 1] && groups == 1
}

/// The input gradient of a convolution. With stride 1 and symmetric padding `p` it is the
/// forward convolution of the output gradient with the kernel flipped in space and its
/// channel axes swapped, padded by `k − 1 − p` (our im2col + GEMM forward kernel, faster than the
/// transposed convolution burn's default uses); otherwise burn's default.
fn conv2d_x_grad<B: Backend + CpuKernelOps>(
    x: FloatTensor<B>,
    weight: FloatTensor<B>,
    grad: FloatTensor<B>,
    options: &ConvOptions<2>,
) -> FloatTensor<B> {
    let [_, _, kh, kw] = weight.shape().dims::<4>();
    let [ph, pw] = options.padding_begin();
    let plain = options.stride == [1, 1]
        && options.dilation == [1, 1]
        && options.groups == 1
        && !options.is_asymmetric()
        && ph < kh
        && pw < kw;
    if !plain {
        return B::conv2d_x_backward(x, weight, grad, options.clone());
    }
    let flipped = B::float_flip(B::float_swap_dims(weight, 0, 1), &[2, 3]);
    let options = ConvOptions::new([1, 1], [kh - 1 - ph, kw - 1 - pw], [1, 1], 1);
    B::conv2d_fast(grad, flipped, options)
}

/// The input gradient of a transposed convolution: the forward convolution of the output
/// gradient with the same kernel, stride and padding (burn's default does the same through
/// `conv2d`; here through [`CpuKernelOps::conv2d_fast`]).
fn conv_transpose2d_x_grad<B: Backend + CpuKernelOps>(
    weight: FloatTensor<B>,
    grad: FloatTensor<B>,
    options: &ConvTransposeOptions<2>,
) -> FloatTensor<B> {
    if options.padding_out != [0, 0] || options.dilation != [1, 1] || options.groups != 1 {
        return B::conv_transpose2d_x_backward(weight, grad, options.clone());
    }
    let conv = ConvOptions::new(options.stride, options.padding, [1, 1], 1);
    B::conv2d_fast(grad, weight, conv)
}

/// Whether `x` is an f32 tensor on the flex backend (with or without autodiff): what our
/// kernels take; other dtypes (`precision`) run on burn's ops.
pub fn on_flex<const D: usize>(x: &Tensor<D>) -> bool {
    x.dtype() == DType::F32
        && matches!(
            x.device().without_autodiff().as_dispatch(),
            DispatchDevice::Flex(_)
        )
}

/// `[c_out]` -> broadcast over `[batch, c_out, H, W]` (`y` on flex: on our kernel).
fn add_bias(y: Tensor<4>, bias: Option<Tensor<1>>) -> Tensor<4> {
    match bias {
        Some(b) => Tensor::from_dispatch(<Dispatch as CpuKernelOps>::add_bias_fast(
            y.into_dispatch(),
            b.into_dispatch(),
        )),
        None => y,
    }
}

/// A burn `Linear` layer's forward pass on `[batch, d_input]`, its product on
/// [`linear::matmul_by_columns`] when `x` is on flex and has few rows.
pub fn linear_layer(layer: &burn::nn::Linear, x: Tensor<2>) -> Tensor<2> {
    if !on_flex(&x) {
        return layer.forward(x);
    }
    let y = Tensor::<2>::from_dispatch(<Dispatch as CpuKernelOps>::matmul_fast(
        x.into_dispatch(),
        layer.weight.val().into_dispatch(),
    ));
    match &layer.bias {
        Some(b) => y + b.val().unsqueeze_dim(0),
        None => y,
    }
}

/// burn's `sigmoid`, on our parallel kernel when `x` is on flex.
pub fn sigmoid<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    if !on_flex(&x) {
        return burn::tensor::activation::sigmoid(x);
    }
    Tensor::from_dispatch(<Dispatch as CpuKernelOps>::sigmoid_fast(x.into_dispatch()))
}

/// The mean binary cross-entropy of the logits `z` against the targets `y` on our kernel
/// (forward and backward in one pass each); `None` when `z` is not on flex.
pub fn bce_with_logits<const D: usize>(z: &Tensor<D>, y: &Tensor<D>) -> Option<Tensor<1>> {
    on_flex(z).then(|| {
        Tensor::from_dispatch(<Dispatch as CpuKernelOps>::bce_with_logits_fast(
            z.clone().into_dispatch(),
            y.clone().into_dispatch(),
        ))
    })
}

/// One Adam step, `[p, m, v]` after it: on our parallel kernel on flex (see
/// [`crate::train::adam`], which sends other devices to burn's own `Adam`), else as burn's
/// `Adam` composes it.
pub fn adam_step<const D: usize>(
    p: Tensor<D>,
    g: Tensor<D>,
    m: Tensor<D>,
    v: Tensor<D>,
    step: pointwise::AdamStep,
) -> [Tensor<D>; 3] {
    let (p, m, v) = <Dispatch as CpuKernelOps>::adam_step(
        p.into_dispatch(),
        g.into_dispatch(),
        m.into_dispatch(),
        v.into_dispatch(),
        step,
    );
    [p, m, v].map(Tensor::from_dispatch)
}

/// burn's `relu`, on our parallel kernel when `x` is on flex.
pub fn relu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    if !on_flex(&x) {
        return burn::tensor::activation::relu(x);
    }
    Tensor::from_dispatch(<Dispatch as CpuKernelOps>::relu_fast(x.into_dispatch()))
}

/// burn's `conv2d`, with the weight gradient on our kernel when `x` is on flex.
pub fn conv2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
) -> Tensor<4> {
    if !on_flex(&x) {
        #[cfg(feature = "cube")]
        if let Some(b) = &bias
            && let Some(y) = crate::kernels::cube::convolution::conv2d(&x, &weight, b, &options)
        {
            return y;
        }
        return burn::tensor::module::conv2d(x, weight, bias, options);
    }
    let y =
        <Dispatch as CpuKernelOps>::conv2d_fast(x.into_dispatch(), weight.into_dispatch(), options);
    add_bias(Tensor::from_dispatch(y), bias)
}

/// burn's `conv_transpose2d`, with the weight gradient on our kernel when `x` is on flex.
pub fn conv_transpose2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvTransposeOptions<2>,
) -> Tensor<4> {
    if !on_flex(&x) {
        #[cfg(feature = "cube")]
        if let Some(b) = &bias
            && let Some(y) =
                crate::kernels::cube::convolution::conv_transpose2d(&x, &weight, b, &options)
        {
            return y;
        }
        return burn::tensor::module::conv_transpose2d(x, weight, bias, options);
    }
    let y = <Dispatch as CpuKernelOps>::conv_transpose2d_fast(
        x.into_dispatch(),
        weight.into_dispatch(),
        options,
    );
    add_bias(Tensor::from_dispatch(y), bias)
}

/// A burn `Conv2d` layer's forward pass through [`conv2d`] (its own `forward` for `Same`
/// padding, which may be asymmetric).
pub fn conv2d_layer(layer: &burn::nn::conv::Conv2d, x: Tensor<4>) -> Tensor<4> {
    use burn::nn::PaddingConfig2d;
    let padding = match layer.padding {
        PaddingConfig2d::Valid => [(0, 0), (0, 0)],
        PaddingConfig2d::Explicit(top, left, bottom, right) => [(top, bottom), (left, right)],
        PaddingConfig2d::Same => return layer.forward(x),
    };
    let options =
        ConvOptions::new_with_padding(layer.stride, padding, layer.dilation, layer.groups);
    conv2d(
        x,
        layer.weight.val(),
        layer.bias.as_ref().map(|b| b.val()),
        options,
    )
}

/// Bilinear resize of `[batch, channels, h, w]` to `size` (align_corners false, PyTorch's
/// `F.interpolate(..., mode="bilinear")`), on our kernel when `x` is on flex.
pub fn resize_bilinear(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    if !on_flex(&x) {
        // Off the CPU: two matrix products (burn's GPU backends cannot differentiate
        // bilinear `interpolate`).
        return crate::kernels::bilinear_resize::resize_matmul(x, size);
    }
    let y = <Dispatch as CpuKernelOps>::resize_bilinear_fast(x.into_dispatch(), size);
    Tensor::from_dispatch(y)
}
