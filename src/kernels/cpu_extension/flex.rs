//! [`CpuKernelOps`] on the flex backend: the forward passes and gradients on our kernels
//! (im2col + GEMM convolutions, bilinear resize, fused pointwise ops and Adam).

use burn::backend::flex::FlexTensor;
use burn::backend::ops::{ActivationOps, FloatTensorOps, ModuleOps};
use burn::backend::{DType, Flex, TensorMetadata};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Shape, TensorData};

use crate::kernels::conv_gemm::{self, ConvGeometry, weight_grad};
use crate::kernels::{bilinear_resize, linear, pointwise};

use super::{
    CpuKernelOps, adam_step_composed, bilinear_options, conv_transpose2d_x_grad, conv2d_x_grad,
    kernel_supports,
};

/// `(data, [batch, channels, h, w])` of a contiguous f32 flex tensor.
fn f32_nchw(t: &FlexTensor) -> (FlexTensor, [usize; 4]) {
    let dims = t.shape().dims::<4>();
    (t.to_contiguous(), dims)
}

fn flex_tensor(values: Vec<f32>, dims: [usize; 4]) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, dims))
}

impl CpuKernelOps for Flex {
    fn conv2d_fast(x: FlexTensor, weight: FlexTensor, options: ConvOptions<2>) -> FlexTensor {
        if !kernel_supports(x.dtype(), &options.dilation, options.groups)
            || weight.dtype() != DType::F32
            || options.is_asymmetric()
        {
            return Self::conv2d(x, weight, None, options);
        }
        let (x, xd) = f32_nchw(&x);
        let (weight, wd) = f32_nchw(&weight);
        let g = ConvGeometry::conv(xd, wd, options.stride, options.padding_begin());
        let y = conv_gemm::forward(x.storage::<f32>(), weight.storage::<f32>(), &g);
        let [oh, ow] = g.output();
        flex_tensor(y, [xd[0], wd[0], oh, ow])
    }

    fn conv_transpose2d_fast(
        x: FlexTensor,
        weight: FlexTensor,
        options: ConvTransposeOptions<2>,
    ) -> FlexTensor {
        if !kernel_supports(x.dtype(), &options.dilation, options.groups)
            || weight.dtype() != DType::F32
            || options.padding_out != [0, 0]
        {
            return Self::conv_transpose2d(x, weight, None, options);
        }
        let (x, xd @ [batch, _, h, w]) = f32_nchw(&x);
        let (weight, wd @ [_, c_out, kh, kw]) = f32_nchw(&weight);
        let [s, p] = [options.stride, options.padding];
        let out = [
            (h - 1) * s[0] + kh - 2 * p[0],
            (w - 1) * s[1] + kw - 2 * p[1],
        ];
        let g = ConvGeometry::transposed(xd, wd, out, s, p);
        let y = conv_gemm::transpose(x.storage::<f32>(), weight.storage::<f32>(), &g);
        flex_tensor(y, [batch, c_out, out[0], out[1]])
    }

    fn conv2d_grads(
        x: FlexTensor,
        weight: FlexTensor,
        dy: FlexTensor,
        options: ConvOptions<2>,
        need: [bool; 2],
    ) -> (Option<FlexTensor>, Option<FlexTensor>) {
        (
            need[0].then(|| conv2d_x_grad::<Self>(x.clone(), weight.clone(), dy.clone(), &options)),
            need[1].then(|| conv2d_weight_grad(x, weight, dy, options)),
        )
    }

    fn conv_transpose2d_grads(
        x: FlexTensor,
        weight: FlexTensor,
        dy: FlexTensor,
        options: ConvTransposeOptions<2>,
        need: [bool; 2],
    ) -> (Option<FlexTensor>, Option<FlexTensor>) {
        if need == [true, true] {
            let (dx, dw) = conv_transpose2d_both_grads(x, weight, dy, options);
            return (Some(dx), Some(dw));
        }
        (
            need[0].then(|| conv_transpose2d_x_grad::<Self>(weight.clone(), dy.clone(), &options)),
            need[1].then(|| conv_transpose2d_weight_grad(x, weight, dy, options)),
        )
    }

    fn resize_bilinear_fast(x: FlexTensor, size: [usize; 2]) -> FlexTensor {
        if x.dtype() != DType::F32 {
            return Self::interpolate(x, size, bilinear_options());
        }
        let (x, [n, c, h, w]) = f32_nchw(&x);
        let y = bilinear_resize::resize(x.storage::<f32>(), n * c, [h, w], size);
        flex_tensor(y, [n, c, size[0], size[1]])
    }

    fn resize_bilinear_backward(grad: FlexTensor, input: [usize; 4]) -> FlexTensor {
        if grad.dtype() != DType::F32 {
            let [_, _, oh, ow] = grad.shape().dims::<4>();
            let x = FlexTensor::zeros(Shape::new(input), DType::F32);
            return Self::interpolate_backward(x, grad, [oh, ow], bilinear_options());
        }
        let (g, [n, c, oh, ow]) = f32_nchw(&grad);
        let [_, _, h, w] = input;
        let dx = bilinear_resize::resize_backward(g.storage::<f32>(), n * c, [h, w], [oh, ow]);
        flex_tensor(dx, input)
    }

    fn add_bias_fast(y: FlexTensor, bias: FlexTensor) -> FlexTensor {
        if y.dtype() != DType::F32 || bias.dtype() != DType::F32 {
            let c = bias.shape().dims::<1>()[0];
            return Self::float_add(y, Self::float_reshape(bias, Shape::new([1, c, 1, 1])));
        }
        let (y, dims @ [_, _, h, w]) = f32_nchw(&y);
        let bias = bias.to_contiguous();
        let out = pointwise::add_bias(y.storage::<f32>(), bias.storage::<f32>(), h * w);
        flex_tensor(out, dims)
    }

    fn matmul_fast(x: FlexTensor, w: FlexTensor) -> FlexTensor {
        let ([m, k], [_, n]) = (x.shape().dims::<2>(), w.shape().dims::<2>());
        if x.dtype() != DType::F32 || w.dtype() != DType::F32 || !linear::by_columns_pays(m, k, n) {
            return Self::float_matmul(x, w);
        }
        let (x, w) = (x.to_contiguous(), w.to_contiguous());
        let y = linear::matmul_by_columns(x.storage::<f32>(), w.storage::<f32>(), m, k, n);
        FlexTensor::from_data(TensorData::new(y, [m, n]))
    }

    fn sigmoid_fast(x: FlexTensor) -> FlexTensor {
        if x.dtype() != DType::F32 {
            return Self::sigmoid(x);
        }
        let shape = x.shape();
        let x = x.to_contiguous();
        FlexTensor::from_data(TensorData::new(
            pointwise::sigmoid(x.storage::<f32>()),
            shape,
        ))
    }

    fn sigmoid_fast_backward(s: FlexTensor, grad: FlexTensor) -> FlexTensor {
        if s.dtype() != DType::F32 || grad.dtype() != DType::F32 {
            return Self::sigmoid_backward(s, grad);
        }
        let shape = s.shape();
        let (s, grad) = (s.to_contiguous(), grad.to_contiguous());
        let dx = pointwise::sigmoid_backward(s.storage::<f32>(), grad.storage::<f32>());
        FlexTensor::from_data(TensorData::new(dx, shape))
    }

    fn bce_with_logits_fast(z: FlexTensor, y: FlexTensor) -> FlexTensor {
        let shape = z.shape();
        let (z, y) = (z.to_contiguous(), y.to_contiguous());
        let each = pointwise::bce_with_logits_elements(z.storage::<f32>(), y.storage::<f32>());
        Self::float_mean(FlexTensor::from_data(TensorData::new(each, shape)))
    }

    fn bce_with_logits_grads(
        z: FlexTensor,
        y: FlexTensor,
        grad: FlexTensor,
    ) -> (FlexTensor, FlexTensor) {
        let shape = z.shape();
        let (z, y) = (z.to_contiguous(), y.to_contiguous());
        // burn's mean passes back `(1 / n) · grad`, the factor rounded to f32 first.
        let scale =
            (1.0 / shape.num_elements() as f64) as f32 * grad.to_contiguous().storage::<f32>()[0];
        let (z, y) = (z.storage::<f32>(), y.storage::<f32>());
        let dz = pointwise::bce_with_logits_z_grad(z, y, scale);
        let dy = pointwise::bce_with_logits_y_grad(z, scale);
        (
            FlexTensor::from_data(TensorData::new(dz, shape.clone())),
            FlexTensor::from_data(TensorData::new(dy, shape)),
        )
    }

    fn adam_step(
        p: FlexTensor,
        g: FlexTensor,
        m: FlexTensor,
        v: FlexTensor,
        step: pointwise::AdamStep,
    ) -> (FlexTensor, FlexTensor, FlexTensor) {
        if [&p, &g, &m, &v].iter().any(|t| t.dtype() != DType::F32) {
            return adam_step_composed::<Self>(p, g, m, v, step);
        }
        let shape = p.shape();
        let [p, g, m, v] = [p, g, m, v].map(|t| t.to_contiguous());
        let [p, m, v] = pointwise::adam(
            p.storage::<f32>(),
            g.storage::<f32>(),
            m.storage::<f32>(),
            v.storage::<f32>(),
            step,
        )
        .map(|values| FlexTensor::from_data(TensorData::new(values, shape.clone())));
        (p, m, v)
    }

    fn relu_fast(x: FlexTensor) -> FlexTensor {
        if x.dtype() != DType::F32 {
            return Self::relu(x);
        }
        let shape = x.shape();
        let x = x.to_contiguous();
        FlexTensor::from_data(TensorData::new(pointwise::relu(x.storage::<f32>()), shape))
    }

    fn relu_fast_backward(x: FlexTensor, grad: FlexTensor) -> FlexTensor {
        if x.dtype() != DType::F32 || grad.dtype() != DType::F32 {
            return Self::relu_backward(x, grad);
        }
        let shape = x.shape();
        let (x, grad) = (x.to_contiguous(), grad.to_contiguous());
        let dx = pointwise::relu_backward(x.storage::<f32>(), grad.storage::<f32>());
        FlexTensor::from_data(TensorData::new(dx, shape))
    }
}

/// The gradient of `conv2d`'s weight `[c_out, c_in, kh, kw]` on our GEMM (burn's where the
/// kernel does not apply).
fn conv2d_weight_grad(
    x: FlexTensor,
    weight: FlexTensor,
    dy: FlexTensor,
    options: ConvOptions<2>,
) -> FlexTensor {
    if !kernel_supports(x.dtype(), &options.dilation, options.groups) || options.is_asymmetric() {
        return Flex::conv2d_weight_backward(x, weight, dy, options);
    }
    let (x, xd) = f32_nchw(&x);
    let (go, _) = f32_nchw(&dy);
    let wd = weight.shape().dims::<4>();
    let g = ConvGeometry::conv(xd, wd, options.stride, options.padding_begin());
    let dw = weight_grad(x.storage::<f32>(), go.storage::<f32>(), &g);
    flex_tensor(dw, wd)
}

/// The gradient of `conv_transpose2d`'s weight `[c_in, c_out, kh, kw]` on our GEMM.
fn conv_transpose2d_weight_grad(
    x: FlexTensor,
    weight: FlexTensor,
    dy: FlexTensor,
    options: ConvTransposeOptions<2>,
) -> FlexTensor {
    if !kernel_supports(x.dtype(), &options.dilation, options.groups) {
        return Flex::conv_transpose2d_weight_backward(x, weight, dy, options);
    }
    // The transposed convolution is the adjoint of `g`; `g`'s weight gradient with `x` as
    // the output gradient is ours.
    let (x, xd) = f32_nchw(&x);
    let (go, [_, _, oh, ow]) = f32_nchw(&dy);
    let wd = weight.shape().dims::<4>();
    let g = ConvGeometry::transposed(xd, wd, [oh, ow], options.stride, options.padding);
    let dw = weight_grad(go.storage::<f32>(), x.storage::<f32>(), &g);
    flex_tensor(dw, wd)
}

/// Both gradients of `conv_transpose2d`, `(input, weight)`, in one pass of our kernel.
fn conv_transpose2d_both_grads(
    x: FlexTensor,
    weight: FlexTensor,
    dy: FlexTensor,
    options: ConvTransposeOptions<2>,
) -> (FlexTensor, FlexTensor) {
    if !kernel_supports(x.dtype(), &options.dilation, options.groups)
        || weight.dtype() != DType::F32
        || options.padding_out != [0, 0]
    {
        let dx = Flex::conv_transpose2d_x_backward(weight.clone(), dy.clone(), options.clone());
        let dw = Flex::conv_transpose2d_weight_backward(x, weight, dy, options);
        return (dx, dw);
    }
    let (x, xd) = f32_nchw(&x);
    let (go, [_, _, oh, ow]) = f32_nchw(&dy);
    let (weight, wd) = f32_nchw(&weight);
    let g = ConvGeometry::transposed(xd, wd, [oh, ow], options.stride, options.padding);
    let (dx, dw) = conv_gemm::transpose_backward(
        x.storage::<f32>(),
        weight.storage::<f32>(),
        go.storage::<f32>(),
        &g,
    );
    (flex_tensor(dx, xd), flex_tensor(dw, wd))
}
