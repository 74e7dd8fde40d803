//! The decoders' convolutions on a GPU in training: each layer one operation of burn's autodiff
//! graph, forward and backward as matrix products around our [`im2col`](super::im2col)
//! kernels, where burn's run direct convolutions with layout copies around them.
//!
//! | layer | forward | backward |
//! |---|---|---|
//! | convolution `k × k` | im2col, `W · colsᵀ`, the bias (fused with the ReLU after it) | `dW = Σₙ dyₙ · colsₙ`, `dcols = dyᵀ W`, col2im, the bias by channel |
//! | convolution 1 × 1 | `W · x` | `dW = Σₙ dyₙ · xₙᵀ`, `dx = Wᵀ dy`, the bias by channel |
//! | transposed convolution | `xᵀ W`, col2im with the bias | im2col of `dy`, `dx = cols · Wᵀ`, `dW = Σₙ xₙ · colsₙ`, the bias by channel |
//!
//! Square kernels, equal strides and paddings, no dilation, groups or output padding; a layer
//! of another shape takes burn's own (`None` from [`conv2d`] and [`conv_transpose2d`]). A
//! batch whose columns would not fit one of the device's buffers, or whose products would need
//! more than 65,535 workgroups in a dimension, runs in slices ([`by_slices`]), in inference as
//! in training: burn's own layers failed there (`Cube count too big`). burn's are the slow
//! references, compared in `tests/gpu/kernels.rs`.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::autodiff::{Autodiff, NodeId};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, TensorMetadata};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Shape, Tensor};

pub use super::conv_layer::{Conv2dLayer, ConvTranspose2dLayer};
use super::extension::GpuKernelOps;
use super::im2col::{Fold, Patches};

/// A square kernel's geometry: its size, stride and padding.
#[derive(Debug, Clone, Copy)]
struct Geometry {
    kernel: usize,
    stride: usize,
    padding: usize,
}

impl Geometry {
    fn new(kernel: usize, stride: usize, padding: usize) -> Self {
        Geometry {
            kernel,
            stride,
            padding,
        }
    }

    /// A 1x1 kernel over every pixel: its columns are the input itself.
    fn pointwise(&self) -> bool {
        self.kernel == 1 && self.stride == 1 && self.padding == 0
    }

    /// Its patches over a grid of `grid`.
    fn patches(&self, grid: [usize; 2]) -> Patches {
        Patches {
            grid,
            kernel: self.kernel,
            stride: self.stride,
            padding: self.padding,
        }
    }

    /// The output size of a convolution over `hw`.
    fn conv_out(&self, hw: [usize; 2]) -> [usize; 2] {
        hw.map(|d| (d + 2 * self.padding - self.kernel) / self.stride + 1)
    }
}

/// `layer` over `x` in slices along the batch, joined (one slice where the batch fits): the
/// layer's result whatever the batch, in training too (burn differentiates the split and the
/// join). A slice's columns (`per_sample` floats a sample) fit one of `x`'s device buffers
/// (128 MiB on lavapipe), and no dispatch of its products has more than 65,535 workgroups in
/// a dimension (the batch is one).
fn by_slices(
    x: &Tensor<4>,
    per_sample: usize,
    layer: impl Fn(Tensor<4>) -> Tensor<4>,
) -> Tensor<4> {
    const MOST_WORKGROUPS: usize = 65_535;
    let max = super::max_buffer_bytes(&x.clone().inner()).unwrap_or(u64::MAX);
    let per = ((max / (per_sample.max(1) as u64 * 4)) as usize).clamp(1, MOST_WORKGROUPS);
    if x.dims()[0] <= per {
        return layer(x.clone());
    }
    Tensor::cat(x.clone().split(per, 0).into_iter().map(layer).collect(), 0)
}

/// A convolution with bias on a GPU, on our kernels (see the module's table): in training one
/// autodiff operation, in inference its forward pass; `None` where `x` is elsewhere or the
/// layer is not one they take.
pub fn conv2d(
    x: &Tensor<4>,
    weight: &Tensor<4>,
    bias: &Tensor<1>,
    options: &ConvOptions<2>,
) -> Option<Tensor<4>> {
    let [_, c_in, kh, kw] = weight.dims();
    let [(p0, p1), (p2, p3)] = options.padding;
    let plain = kh == kw
        && options.stride[0] == options.stride[1]
        && p0 == p1
        && p1 == p2
        && p2 == p3
        && options.dilation == [1, 1]
        && options.groups == 1;
    if !plain || !super::on_kernels(&x.clone().inner()) {
        return None;
    }
    let g = Geometry {
        kernel: kh,
        stride: options.stride[0],
        padding: p0,
    };
    let [_, _, h, w] = x.dims();
    let [oh, ow] = g.conv_out([h, w]);
    let per_sample = if g.pointwise() {
        0
    } else {
        oh * ow * c_in * kh * kw
    };
    let layer = Conv2dLayer {
        weight: weight.clone().into_dispatch(),
        bias: bias.clone().into_dispatch(),
        options: options.clone(),
    };
    let train = <Dispatch as GpuKernelOps>::conv2d_train;
    Some(through(x, per_sample, layer, train, |x, layer| {
        conv2d_forward::<Dispatch>(x, layer.weight, layer.bias, g).0
    }))
}

/// A transposed convolution with bias on a GPU, on our kernels (see the module's table): in
/// training one autodiff operation, in inference its forward pass; `None` where `x` is
/// elsewhere or the layer is not one they take.
pub fn conv_transpose2d(
    x: &Tensor<4>,
    weight: &Tensor<4>,
    bias: &Tensor<1>,
    options: &ConvTransposeOptions<2>,
) -> Option<Tensor<4>> {
    let [_, c_out, kh, kw] = weight.dims();
    let plain = kh == kw
        && options.stride[0] == options.stride[1]
        && options.padding[0] == options.padding[1]
        && options.padding_out == [0, 0]
        && options.dilation == [1, 1]
        && options.groups == 1;
    if !plain || !super::on_kernels(&x.clone().inner()) {
        return None;
    }
    // The columns `[N, Hi·Wi, c_out·k·k]`.
    let [_, _, h, w] = x.dims();
    let per_sample = h * w * c_out * kh * kw;
    let (stride, padding) = (options.stride[0], options.padding[0]);
    let layer = ConvTranspose2dLayer {
        weight: weight.clone().into_dispatch(),
        bias: bias.clone().into_dispatch(),
        options: options.clone(),
    };
    let train = <Dispatch as GpuKernelOps>::conv_transpose2d_train;
    Some(through(x, per_sample, layer, train, |x, layer| {
        conv_transpose2d_forward::<Dispatch>(x, layer.weight, layer.bias, stride, padding)
    }))
}

/// `x` through `layer` on our kernels, in slices along the batch ([`by_slices`]): its
/// training operation `train` where `x` trains, its forward pass `infer` elsewhere.
fn through<L: Clone>(
    x: &Tensor<4>,
    per_sample: usize,
    layer: L,
    train: fn(FloatTensor<Dispatch>, L) -> FloatTensor<Dispatch>,
    infer: impl Fn(FloatTensor<Dispatch>, L) -> FloatTensor<Dispatch>,
) -> Tensor<4> {
    let training = x.device().is_autodiff();
    by_slices(x, per_sample, |x| {
        let (x, layer) = (x.into_dispatch(), layer.clone());
        Tensor::from_dispatch(if training {
            train(x, layer)
        } else {
            infer(x, layer)
        })
    })
}

/// A convolution's forward pass (see the module's table) on any backend with our kernels:
/// the output, and the columns read transposed `[N, q, h·w]` (for a 1x1 kernel, `x` itself).
fn conv2d_forward<B: Backend + GpuKernelOps>(
    x: FloatTensor<B>,
    w: FloatTensor<B>,
    b: FloatTensor<B>,
    g: Geometry,
) -> (FloatTensor<B>, FloatTensor<B>) {
    let [n, c_in, h, wd] = x.shape().dims::<4>();
    let [c_out, _, k, _] = w.shape().dims::<4>();
    let [oh, ow] = g.conv_out([h, wd]);
    let cols_t = if g.pointwise() {
        B::float_reshape(x, Shape::new([n, c_in, h * wd]))
    } else {
        let cols = B::im2col(x, g.patches([oh, ow]));
        B::float_swap_dims(cols, 1, 2)
    };
    let wm = B::float_reshape(w, Shape::new([1, c_out, c_in * k * k]));
    let y = B::float_matmul(wm, cols_t.clone());
    // Shaped as the image before the bias: the sum then fuses with what follows (the ReLU),
    // where a reshape after it would stand between them.
    let y = B::float_reshape(y, Shape::new([n, c_out, oh, ow]));
    let y = B::float_add(y, B::float_reshape(b, Shape::new([1, c_out, 1, 1])));
    (y, cols_t)
}

/// A transposed convolution's forward pass (see the module's table) on any backend with our
/// kernels: the columns `xᵀ W` (one batched product, `x` read transposed in place), then
/// col2im with the bias.
fn conv_transpose2d_forward<B: Backend + GpuKernelOps>(
    x: FloatTensor<B>,
    w: FloatTensor<B>,
    b: FloatTensor<B>,
    stride: usize,
    padding: usize,
) -> FloatTensor<B> {
    let [n, c_in, in_h, in_w] = x.shape().dims::<4>();
    let [_, c_out, k, _] = w.shape().dims::<4>();
    let out_h = (in_h - 1) * stride + k - 2 * padding;
    let out_w = (in_w - 1) * stride + k - 2 * padding;
    let xt = B::float_swap_dims(
        B::float_reshape(x, Shape::new([n, c_in, in_h * in_w])),
        1,
        2,
    );
    let w = B::float_reshape(w, Shape::new([1, c_in, c_out * k * k]));
    let cols = B::float_matmul(xt, w);
    let patches = Geometry::new(k, stride, padding).patches([in_h, in_w]);
    let fold = Fold {
        out: [n, c_out, out_h, out_w],
        patches,
        with_bias: true,
    };
    B::col2im(cols, b, fold)
}

/// `GpuKernelOps::conv2d_train` on autodiff: the forward pass on the inner backend, and its
/// backward pass (see the module's table).
pub(super) fn conv2d_train<B: Backend + GpuKernelOps, C: CheckpointStrategy>(
    x: FloatTensor<Autodiff<B, C>>,
    layer: Conv2dLayer<Autodiff<B, C>>,
) -> FloatTensor<Autodiff<B, C>> {
    let Conv2dLayer {
        weight,
        bias,
        options,
    } = layer;
    #[derive(Debug)]
    struct Conv;

    /// The columns read transposed `[N, q, h·w]` (for a 1x1 kernel, `x` itself), the weight,
    /// the input's shape and the geometry.
    type State<B> = (FloatTensor<B>, NodeId, [usize; 4], Geometry);

    impl<B: Backend + GpuKernelOps> Backward<B, 3> for Conv {
        type State = State<B>;

        fn backward(
            self,
            ops: Ops<Self::State, 3>,
            grads: &mut Gradients,
            ckpt: &mut Checkpointer,
        ) {
            let [node_x, node_w, node_b] = ops.parents;
            let dy = grads.consume::<B>(&ops.node);
            let (cols_t, w_state, [n, c_in, h, w], g) = ops.state;
            let weight = ckpt.retrieve_node_output::<B::FloatTensorPrimitive>(w_state);
            let [c_out, _, k, _] = weight.shape().dims::<4>();
            let [_, _, oh, ow] = dy.shape().dims::<4>();
            let q = c_in * k * k;
            if let Some(node) = node_b {
                grads.register::<B>(node.id, B::channel_sums(dy.clone()));
            }
            let dy = B::float_reshape(dy, Shape::new([n, c_out, oh * ow]));
            let wm = B::float_reshape(weight.clone(), Shape::new([1, c_out, q]));
            if let Some(node) = node_w {
                // Σₙ [c_out, h·w] · [h·w, q].
                let cols = B::float_swap_dims(cols_t, 1, 2);
                let dw = B::float_sum_dim(B::float_matmul(dy.clone(), cols), 0);
                grads.register::<B>(node.id, B::float_reshape(dw, weight.shape()));
            }
            if let Some(node) = node_x {
                let dx = if g.pointwise() {
                    // Wᵀ [c_in, c_out] · dyₙ [c_out, h·w].
                    B::float_matmul(B::float_swap_dims(wm, 1, 2), dy)
                } else {
                    // dcols [N, h·w, q] = dyₙᵀ · W, folded back into the image.
                    let dcols = B::float_matmul(B::float_swap_dims(dy, 1, 2), wm);
                    let fold = Fold {
                        out: [n, c_in, h, w],
                        patches: g.patches([oh, ow]),
                        with_bias: false,
                    };
                    B::col2im(dcols, weight, fold)
                };
                grads.register::<B>(node.id, B::float_reshape(dx, Shape::new([n, c_in, h, w])));
            }
        }
    }

    let g = Geometry {
        kernel: weight.shape()[2],
        stride: options.stride[0],
        padding: options.padding[0].0,
    };
    let forward = |x, w, b| conv2d_forward::<B>(x, w, b, g);
    let x_shape = x.shape().dims::<4>();
    match Conv
        .prepare::<C>([x.node(), weight.node(), bias.node()])
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(mut prep) => {
            let w_state = prep.checkpoint(&weight);
            let (y, cols_t) = forward(
                x.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            );
            prep.finish((cols_t, w_state, x_shape, g), y)
        }
        OpsKind::UnTracked(prep) => prep.finish(
            forward(
                x.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            )
            .0,
        ),
    }
}

/// `GpuKernelOps::conv_transpose2d_train` on autodiff: the forward pass on the inner backend,
/// and its backward pass (see the module's table).
pub(super) fn conv_transpose2d_train<B: Backend + GpuKernelOps, C: CheckpointStrategy>(
    x: FloatTensor<Autodiff<B, C>>,
    layer: ConvTranspose2dLayer<Autodiff<B, C>>,
) -> FloatTensor<Autodiff<B, C>> {
    let ConvTranspose2dLayer {
        weight,
        bias,
        options,
    } = layer;
    #[derive(Debug)]
    struct ConvTranspose;

    impl<B: Backend + GpuKernelOps> Backward<B, 3> for ConvTranspose {
        /// x, the weight, and the stride and padding.
        type State = (NodeId, NodeId, usize, usize);

        fn backward(
            self,
            ops: Ops<Self::State, 3>,
            grads: &mut Gradients,
            checkpointer: &mut Checkpointer,
        ) {
            let [node_x, node_w, node_b] = ops.parents;
            let dy = grads.consume::<B>(&ops.node);
            let (x_state, w_state, stride, padding) = ops.state;
            let x = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(x_state);
            let w = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(w_state);
            let [n, c_in, in_h, in_w] = x.shape().dims::<4>();
            let [_, c_out, k, _] = w.shape().dims::<4>();
            let q = c_out * k * k;
            if let Some(node) = node_b {
                grads.register::<B>(node.id, B::channel_sums(dy.clone()));
            }
            let patches = Geometry::new(k, stride, padding).patches([in_h, in_w]);
            let cols = B::im2col(dy, patches);
            if let Some(node) = node_x {
                // [N·Hi·Wi, q] · [q, c_in], channels last, seen as [N, c_in, Hi, Wi].
                let flat = B::float_reshape(cols.clone(), Shape::new([n * in_h * in_w, q]));
                let wt = B::float_transpose(B::float_reshape(w.clone(), Shape::new([c_in, q])));
                let dx = B::float_matmul(flat, wt);
                let dx = B::float_reshape(dx, Shape::new([n, in_h, in_w, c_in]));
                grads.register::<B>(node.id, B::float_permute(dx, &[0, 3, 1, 2]));
            }
            if let Some(node) = node_w {
                // Σₙ [c_in, Hi·Wi] · [Hi·Wi, q].
                let xs = B::float_reshape(x, Shape::new([n, c_in, in_h * in_w]));
                let dw = B::float_sum_dim(B::float_matmul(xs, cols), 0);
                grads.register::<B>(node.id, B::float_reshape(dw, w.shape()));
            }
        }
    }

    let (stride, padding) = (options.stride[0], options.padding[0]);
    let forward = |x, w, b| conv_transpose2d_forward::<B>(x, w, b, stride, padding);
    match ConvTranspose
        .prepare::<C>([x.node(), weight.node(), bias.node()])
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(mut prep) => {
            let x_state = prep.checkpoint(&x);
            let w_state = prep.checkpoint(&weight);
            let y = forward(
                x.into_primitive(),
                weight.into_primitive(),
                bias.into_primitive(),
            );
            prep.finish((x_state, w_state, stride, padding), y)
        }
        OpsKind::UnTracked(prep) => prep.finish(forward(
            x.into_primitive(),
            weight.into_primitive(),
            bias.into_primitive(),
        )),
    }
}
