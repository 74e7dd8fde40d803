//! Our GPU kernels inside burn's autodiff graph: a burn backend extension, as
//! [`crate::kernels::cpu_extension`] is for the CPU.
//!
//! [`GpuKernelOps`] is routed through burn's `Dispatch` by `#[backend_extension]`: on burn's
//! CubeCL backend (`CubeBackend`) its methods launch our kernels; on the fusion backend that
//! wraps it on a GPU they are recorded as operations of their own (the kernels) or run as
//! their default bodies in burn's operations (which burn fuses); on `Autodiff` the layer is
//! one operation with a hand-written backward pass. The default bodies are the slow
//! references the tests compare the kernels with.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::autodiff::{Autodiff, NodeId};
use burn::backend::fusion::custom::TensorSpec;
use burn::backend::tensor::FloatTensor;
use burn::backend::{
    AutodiffBackend, Backend, Dispatch, Scalar, TensorMetadata, backend_extension,
};
use burn::nn::BatchNorm;
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Shape, Tensor};
use burn_cubecl::CubeBackend;

use super::{batch_norm, convolution, im2col, loss};

/// A `[channels]` tensor's spec for an `[N, C, ...]` input.
fn per_channel(x: &TensorSpec) -> TensorSpec {
    TensorSpec::new(Shape::new([x.shape[1]]), x.dtype)
}

/// `[C]` -> `[1, C, 1, ...]` of rank `rank`.
fn broadcast<B: Backend>(v: FloatTensor<B>, rank: usize) -> FloatTensor<B> {
    let c = v.shape()[0];
    let mut dims = vec![1; rank];
    dims[1] = c;
    B::float_reshape(v, Shape::from(dims))
}

/// `[N, C, ...]` -> `[C, N·...]`: a channel a row (burn's way to reduce by channel: a copy).
fn by_channel<B: Backend>(t: FloatTensor<B>) -> FloatTensor<B> {
    let c = t.shape()[1];
    let flat = Shape::new([c, t.shape().num_elements() / c]);
    B::float_reshape(B::float_swap_dims(t, 0, 1), flat)
}

/// `relu(x)` where `relu`, else `x`.
fn maybe_relu<B: Backend>(x: FloatTensor<B>, relu: bool) -> FloatTensor<B> {
    if relu { B::relu(x) } else { x }
}

/// The gradient reaching a batch norm's normalisation from `dy` (masked where a ReLU after
/// it gave 0).
fn reaching<B: Backend>(y: FloatTensor<B>, dy: FloatTensor<B>, relu: bool) -> FloatTensor<B> {
    if relu { B::relu_backward(y, dy) } else { dy }
}

/// Operations that burn composes of many launches, as kernels of ours on a GPU.
#[backend_extension(Cube, Fusion, Autodiff)]
pub trait GpuKernelOps: Backend {
    /// A batch-norm layer's statistics in training: each channel's mean, biased variance and
    /// `1 / sqrt(var + epsilon)` over `x` `[N, C, ...]`, and the running statistics moved
    /// towards them by `momentum`.
    #[fusion(meta = |x, _rm, _rv, _epsilon, _momentum| {
        let c = per_channel(x);
        (c.clone(), c.clone(), c.clone(), c.clone(), c)
    })]
    fn batch_norm_statistics(
        x: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        epsilon: f64,
        momentum: f64,
    ) -> (
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
    ) {
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
            Scalar::Float(epsilon),
        )));
        let moved = |r: FloatTensor<Self>, s: FloatTensor<Self>| {
            Self::float_add(
                Self::float_mul_scalar(r, Scalar::Float(1.0 - momentum)),
                Self::float_mul_scalar(s, Scalar::Float(momentum)),
            )
        };
        let running_mean = moved(running_mean, mean.clone());
        let running_var = moved(running_var, var.clone());
        (mean, var, inv_std, running_mean, running_var)
    }

    /// A batch-norm layer's `γ` and `β` gradients from its input `x`, output `y` (after the
    /// ReLU where `relu`), output gradient `dy` and the batch's mean and `1 / std`.
    #[fusion(meta = |x, _y, _dy, _mean, _inv_std, _relu| (per_channel(x), per_channel(x)))]
    fn batch_norm_param_grads(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        mean: FloatTensor<Self>,
        inv_std: FloatTensor<Self>,
        relu: bool,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let rank = x.shape().num_dims();
        let c = x.shape()[1];
        let g = reaching::<Self>(y, dy, relu);
        let centred = Self::float_sub(x, broadcast::<Self>(mean, rank));
        let beta = Self::float_sum_dim(by_channel::<Self>(g.clone()), 1);
        let gx = Self::float_sum_dim(by_channel::<Self>(Self::float_mul(g, centred)), 1);
        let gamma = Self::float_mul(Self::float_reshape(gx, Shape::new([c])), inv_std);
        (gamma, Self::float_reshape(beta, Shape::new([c])))
    }

    /// A batch-norm layer's input gradient (see [`Self::batch_norm_param_grads`]; `gamma`,
    /// and the `γ` and `β` gradients it gave).
    #[fusion(dtype = x, shape = x)]
    // A backend operation takes its tensors as arguments (burn records each one for fusion).
    #[allow(clippy::too_many_arguments)]
    fn batch_norm_x_grad(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        mean: FloatTensor<Self>,
        inv_std: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        gamma_grad: FloatTensor<Self>,
        beta_grad: FloatTensor<Self>,
        relu: bool,
    ) -> FloatTensor<Self> {
        // γ/std (g - Σg/M - (x - mean)/std · Σ g (x - mean)/std / M).
        let rank = x.shape().num_dims();
        let count = (x.shape().num_elements() / x.shape()[1]) as f64;
        let c = |t| broadcast::<Self>(t, rank);
        let g = reaching::<Self>(y, dy, relu);
        let xhat = Self::float_mul(Self::float_sub(x, c(mean)), c(inv_std.clone()));
        let mean_g = Self::float_div_scalar(beta_grad, Scalar::Float(count));
        let projection = Self::float_div_scalar(gamma_grad, Scalar::Float(count));
        let dx = Self::float_sub(
            Self::float_sub(g, c(mean_g)),
            Self::float_mul(xhat, c(projection)),
        );
        Self::float_mul(dx, c(Self::float_mul(gamma, inv_std)))
    }

    /// The columns (im2col) of `t` `[N, C, H, W]` over a grid of `grid` patches:
    /// `[N, h·w, C·k·k]` (see `kernels::cube::im2col`).
    #[fusion(meta = |t, grid, kernel, _stride, _padding| {
        TensorSpec::new(
            Shape::new([t.shape[0], grid[0] * grid[1], t.shape[1] * kernel * kernel]),
            t.dtype,
        )
    })]
    fn im2col(
        t: FloatTensor<Self>,
        grid: [usize; 2],
        kernel: usize,
        stride: usize,
        padding: usize,
    ) -> FloatTensor<Self> {
        // Only the CubeCL kernel: the layers' references are burn's own convolutions and
        // their backward passes, which `tests/gpu/kernels.rs` compares them with.
        let _ = (t, grid, kernel, stride, padding);
        unreachable!("im2col runs on CubeCL devices only")
    }

    /// The image `out` `[N, C, H, W]` whose columns over a grid of `grid` patches are `cols`
    /// `[N, h·w, C·k·k]`, overlaps summed, plus `bias` `[C]` where `with_bias` (see
    /// `kernels::cube::im2col`).
    #[fusion(meta = |cols, _bias, _with_bias, _grid, out, _kernel, _stride, _padding| {
        TensorSpec::new(Shape::new(*out), cols.dtype)
    })]
    // A backend operation takes its tensors as arguments (burn records each one for fusion).
    #[allow(clippy::too_many_arguments)]
    fn col2im(
        cols: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        with_bias: bool,
        grid: [usize; 2],
        out: [usize; 4],
        kernel: usize,
        stride: usize,
        padding: usize,
    ) -> FloatTensor<Self> {
        // Only the CubeCL kernel (see `im2col`).
        let _ = (cols, bias, with_bias, grid, out, kernel, stride, padding);
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
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        Self::conv2d(x, weight, Some(bias), options)
    }

    /// A transposed convolution with bias as a matrix product and [`Self::col2im`],
    /// differentiated by [`Self::im2col`] and two matrix products (as [`Self::conv2d_train`]).
    #[fusion(default)]
    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        Self::conv_transpose2d(x, weight, Some(bias), options)
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

    /// A batch-norm layer in training (and the ReLU after it where `relu`): the output, and the
    /// new running mean and variance (burn's `BatchNorm::forward` in training, as one
    /// operation of the autodiff graph).
    #[fusion(default)]
    // A backend operation takes its tensors as arguments (burn records each one for fusion).
    #[allow(clippy::too_many_arguments)]
    fn batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        epsilon: f64,
        momentum: f64,
        relu: bool,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        let (mean, var, _, running_mean, running_var) =
            Self::batch_norm_statistics(x.clone(), running_mean, running_var, epsilon, momentum);
        let y = maybe_relu::<Self>(Self::batch_norm(x, gamma, beta, mean, var, epsilon), relu);
        (y, running_mean, running_var)
    }
}

impl GpuKernelOps for CubeBackend {
    fn im2col(
        t: FloatTensor<Self>,
        grid: [usize; 2],
        kernel: usize,
        stride: usize,
        padding: usize,
    ) -> FloatTensor<Self> {
        im2col::launch_columns(t, grid, kernel, stride, padding)
    }

    fn channel_sums(t: FloatTensor<Self>) -> FloatTensor<Self> {
        im2col::launch_channel_sums(t)
    }

    fn col2im(
        cols: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        with_bias: bool,
        grid: [usize; 2],
        out: [usize; 4],
        kernel: usize,
        stride: usize,
        padding: usize,
    ) -> FloatTensor<Self> {
        let bias = with_bias.then_some(bias);
        im2col::launch_col2im(cols, bias, grid, out, kernel, stride, padding)
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

    fn batch_norm_statistics(
        x: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        epsilon: f64,
        momentum: f64,
    ) -> (
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
    ) {
        let [m, v, s, rm, rv] =
            batch_norm::launch_statistics(x, running_mean, running_var, epsilon, momentum);
        (m, v, s, rm, rv)
    }

    fn batch_norm_param_grads(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        mean: FloatTensor<Self>,
        inv_std: FloatTensor<Self>,
        relu: bool,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let saved = batch_norm::Saved {
            x,
            y,
            dy,
            mean,
            inv_std,
        };
        let [gamma, beta] = batch_norm::launch_grad_sums(saved, relu);
        (gamma, beta)
    }

    fn batch_norm_x_grad(
        x: FloatTensor<Self>,
        y: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        mean: FloatTensor<Self>,
        inv_std: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        gamma_grad: FloatTensor<Self>,
        beta_grad: FloatTensor<Self>,
        relu: bool,
    ) -> FloatTensor<Self> {
        let saved = batch_norm::Saved {
            x,
            y,
            dy,
            mean,
            inv_std,
        };
        batch_norm::launch_x_grad(saved, gamma, gamma_grad, beta_grad, relu)
    }
}

impl<B: Backend + GpuKernelOps, C: CheckpointStrategy> GpuKernelOps for Autodiff<B, C> {
    fn conv2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        convolution::conv2d_train::<B, C>(x, weight, bias, options)
    }

    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        convolution::conv_transpose2d_train::<B, C>(x, weight, bias, options)
    }

    fn bce_with_logits_mean(z: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct BceWithLogits;

        impl<B: Backend + GpuKernelOps> Backward<B, 1> for BceWithLogits {
            /// The logits and the targets (constants: their gradient is not asked for).
            type State = (NodeId, FloatTensor<B>);

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let [node_z] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                let (z_state, y) = ops.state;
                if let Some(node) = node_z {
                    let z = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(z_state);
                    grads.register::<B>(node.id, B::bce_with_logits_grad(z, y, grad));
                }
            }
        }

        // The targets are data: their gradient is not taken (a tracked target would be a bug).
        let y = y.into_primitive();
        match BceWithLogits
            .prepare::<C>([z.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let z_state = prep.checkpoint(&z);
                let loss = B::bce_with_logits_mean(z.into_primitive(), y.clone());
                prep.finish((z_state, y), loss)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::bce_with_logits_mean(z.into_primitive(), y)),
        }
    }

    fn batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        epsilon: f64,
        momentum: f64,
        relu: bool,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        #[derive(Debug)]
        struct BatchNormTrain;

        /// x, gamma, the output, the batch's mean and 1 / std, and whether a ReLU follows.
        type State<B> = (
            NodeId,
            NodeId,
            FloatTensor<B>,
            FloatTensor<B>,
            FloatTensor<B>,
            bool,
        );

        impl<B: Backend + GpuKernelOps> Backward<B, 3> for BatchNormTrain {
            type State = State<B>;

            fn backward(
                self,
                ops: Ops<Self::State, 3>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let [node_x, node_gamma, node_beta] = ops.parents;
                let dy = grads.consume::<B>(&ops.node);
                let (x_state, gamma_state, y, mean, inv_std, relu) = ops.state;
                let x = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(x_state);
                let gamma =
                    checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(gamma_state);
                let (gamma_grad, beta_grad) = B::batch_norm_param_grads(
                    x.clone(),
                    y.clone(),
                    dy.clone(),
                    mean.clone(),
                    inv_std.clone(),
                    relu,
                );
                if let Some(node) = node_x {
                    let dx = B::batch_norm_x_grad(
                        x,
                        y,
                        dy,
                        mean,
                        inv_std,
                        gamma,
                        gamma_grad.clone(),
                        beta_grad.clone(),
                        relu,
                    );
                    grads.register::<B>(node.id, dx);
                }
                if let Some(node) = node_gamma {
                    grads.register::<B>(node.id, gamma_grad);
                }
                if let Some(node) = node_beta {
                    grads.register::<B>(node.id, beta_grad);
                }
            }
        }

        let forward = |x: FloatTensor<B>, gamma, beta, rm, rv| {
            let (mean, var, inv_std, rm, rv) =
                B::batch_norm_statistics(x.clone(), rm, rv, epsilon, momentum);
            let y = B::batch_norm(x, gamma, beta, mean.clone(), var, epsilon);
            (maybe_relu::<B>(y, relu), mean, inv_std, rm, rv)
        };
        let constant = |t: FloatTensor<B>| <Self as AutodiffBackend>::from_inner(t);
        let (rm, rv) = (running_mean.into_primitive(), running_var.into_primitive());
        match BatchNormTrain
            .prepare::<C>([x.node(), gamma.node(), beta.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let x_state = prep.checkpoint(&x);
                let gamma_state = prep.checkpoint(&gamma);
                let (y, mean, inv_std, rm, rv) = forward(
                    x.into_primitive(),
                    gamma.into_primitive(),
                    beta.into_primitive(),
                    rm,
                    rv,
                );
                let state = (x_state, gamma_state, y.clone(), mean, inv_std, relu);
                let y = prep.finish(state, y);
                (y, constant(rm), constant(rv))
            }
            OpsKind::UnTracked(prep) => {
                let (y, _, _, rm, rv) = forward(
                    x.into_primitive(),
                    gamma.into_primitive(),
                    beta.into_primitive(),
                    rm,
                    rv,
                );
                (prep.finish(y), constant(rm), constant(rv))
            }
        }
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
    if !training || !super::is_lazy(&x.clone().inner()) {
        return None;
    }
    let device = x.device();
    // As burn's: `value_sync` (the mean over the threads that updated the state, one here:
    // burn's `RunningState` divides by their count, a launch a layer).
    let running_mean = norm.running_mean.value_sync().to_device(&device);
    let running_var = norm.running_var.value_sync().to_device(&device);
    let (y, rm, rv) = <Dispatch as GpuKernelOps>::batch_norm_train(
        x.clone().into_dispatch(),
        norm.gamma.val().into_dispatch(),
        norm.beta.val().into_dispatch(),
        running_mean.into_dispatch(),
        running_var.into_dispatch(),
        norm.epsilon,
        norm.momentum,
        relu,
    );
    let rm = Tensor::<1>::from_dispatch(rm);
    let rv = Tensor::<1>::from_dispatch(rv);
    norm.running_mean.update(rm.detach());
    norm.running_var.update(rv.detach());
    Some(Tensor::from_dispatch(y))
}

/// The mean binary cross-entropy of the logits `z` against the targets `y` on our kernels
/// where `z` is on a GPU; `None` elsewhere.
pub fn bce_with_logits<const D: usize>(z: &Tensor<D>, y: &Tensor<D>) -> Option<Tensor<1>> {
    let on_gpu = super::is_lazy(&z.clone().inner()) && super::is_lazy(&y.clone().inner());
    on_gpu.then(|| {
        Tensor::from_dispatch(<Dispatch as GpuKernelOps>::bce_with_logits_mean(
            z.clone().into_dispatch(),
            y.clone().into_dispatch(),
        ))
    })
}
