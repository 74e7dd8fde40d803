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
use burn::backend::tensor::FloatTensor;
use burn::backend::{
    AutodiffBackend, Backend, Dispatch, Scalar, TensorMetadata, backend_extension,
};
use burn::nn::BatchNorm;
use burn::tensor::{Shape, Tensor};
use burn_cubecl::CubeBackend;
use burn::backend::fusion::custom::TensorSpec;

use super::batch_norm;

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

/// Operations that burn composes of many launches, as kernels of ours on a GPU.
#[backend_extension(Cube, Fusion, Autodiff)]
pub trait GpuKernelOps: Backend {
    /// A batch-norm layer's statistics in training: each channel's mean and biased variance
    /// of `x` `[N, C, ...]`, and the running statistics moved towards them by `momentum`.
    #[fusion(meta = |x, _rm, _rv, _momentum| (per_channel(x), per_channel(x), per_channel(x), per_channel(x)))]
    fn batch_norm_statistics(
        x: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        momentum: f64,
    ) -> (
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
    ) {
        let rank = x.shape().num_dims();
        let c = x.shape()[1];
        let flat = Shape::new([c, x.shape().num_elements() / c]);
        let by_channel = |t: FloatTensor<Self>| {
            Self::float_reshape(Self::float_swap_dims(t, 0, 1), flat.clone())
        };
        let mean = Self::float_mean_dim(by_channel(x.clone()), 1);
        let mean = Self::float_reshape(mean, Shape::new([c]));
        let centred = Self::float_sub(x, broadcast::<Self>(mean.clone(), rank));
        let var = Self::float_mean_dim(by_channel(Self::float_mul(centred.clone(), centred)), 1);
        let var = Self::float_reshape(var, Shape::new([c]));
        let moved = |r: FloatTensor<Self>, s: FloatTensor<Self>| {
            Self::float_add(
                Self::float_mul_scalar(r, Scalar::Float(1.0 - momentum)),
                Self::float_mul_scalar(s, Scalar::Float(momentum)),
            )
        };
        let running_mean = moved(running_mean, mean.clone());
        let running_var = moved(running_var, var.clone());
        (mean, var, running_mean, running_var)
    }

    /// Each channel's `Σ dy` and `Σ dy (x - mean)` (the backward pass's two sums).
    #[fusion(meta = |x, _dy, _mean| (per_channel(x), per_channel(x)))]
    fn batch_norm_grad_sums(
        x: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        mean: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let rank = x.shape().num_dims();
        let c = x.shape()[1];
        let flat = Shape::new([c, x.shape().num_elements() / c]);
        let by_channel = |t: FloatTensor<Self>| {
            Self::float_reshape(Self::float_swap_dims(t, 0, 1), flat.clone())
        };
        let centred = Self::float_sub(x, broadcast::<Self>(mean, rank));
        let sum_dy = Self::float_sum_dim(by_channel(dy.clone()), 1);
        let sum_dy_xc = Self::float_sum_dim(by_channel(Self::float_mul(dy, centred)), 1);
        (
            Self::float_reshape(sum_dy, Shape::new([c])),
            Self::float_reshape(sum_dy_xc, Shape::new([c])),
        )
    }

    /// A batch-norm layer in training: the output, and the new running mean and variance
    /// (burn's `BatchNorm::forward` in training, as one operation of the autodiff graph).
    #[fusion(default)]
    fn batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        epsilon: f64,
        momentum: f64,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        let (mean, var, running_mean, running_var) =
            Self::batch_norm_statistics(x.clone(), running_mean, running_var, momentum);
        let y = Self::batch_norm(x, gamma, beta, mean, var, epsilon);
        (y, running_mean, running_var)
    }
}

impl GpuKernelOps for CubeBackend {
    fn batch_norm_statistics(
        x: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        momentum: f64,
    ) -> (
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
        FloatTensor<Self>,
    ) {
        let [m, v, rm, rv] = batch_norm::launch_statistics(x, running_mean, running_var, momentum);
        (m, v, rm, rv)
    }

    fn batch_norm_grad_sums(
        x: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        mean: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let [s, p] = batch_norm::launch_grad_sums(x, dy, mean);
        (s, p)
    }
}

impl<B: Backend + GpuKernelOps, C: CheckpointStrategy> GpuKernelOps for Autodiff<B, C> {
    fn batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        running_mean: FloatTensor<Self>,
        running_var: FloatTensor<Self>,
        epsilon: f64,
        momentum: f64,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        #[derive(Debug)]
        struct BatchNormTrain;

        impl<B: Backend + GpuKernelOps> Backward<B, 3> for BatchNormTrain {
            /// x, gamma, the batch's mean and 1 / std.
            type State = (NodeId, NodeId, B::FloatTensorPrimitive, B::FloatTensorPrimitive);

            fn backward(
                self,
                ops: Ops<Self::State, 3>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let [node_x, node_gamma, node_beta] = ops.parents;
                let dy = grads.consume::<B>(&ops.node);
                let (x_state, gamma_state, mean, inv_std) = ops.state;
                let x = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(x_state);
                let gamma =
                    checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(gamma_state);
                let rank = x.shape().num_dims();
                let count = (x.shape().num_elements() / x.shape()[1]) as f64;
                let (sum_dy, sum_dy_xc) = B::batch_norm_grad_sums(x.clone(), dy.clone(), mean.clone());
                if let Some(node) = node_gamma {
                    grads.register::<B>(node.id, B::float_mul(sum_dy_xc.clone(), inv_std.clone()));
                }
                if let Some(node) = node_x {
                    // gamma / std (dy - mean(dy) - (x - mean) / std² · mean(dy (x - mean))).
                    let c = |t| broadcast::<B>(t, rank);
                    let scale = B::float_mul(gamma, inv_std.clone());
                    let mean_dy = B::float_div_scalar(sum_dy.clone(), Scalar::Float(count));
                    let projection = B::float_div_scalar(
                        B::float_mul(B::float_mul(sum_dy_xc, inv_std.clone()), inv_std),
                        Scalar::Float(count),
                    );
                    let centred = B::float_sub(x, c(mean));
                    let dx = B::float_sub(
                        B::float_sub(dy, c(mean_dy)),
                        B::float_mul(centred, c(projection)),
                    );
                    grads.register::<B>(node.id, B::float_mul(dx, c(scale)));
                }
                if let Some(node) = node_beta {
                    grads.register::<B>(node.id, sum_dy);
                }
            }
        }

        let forward = |x: FloatTensor<B>, gamma, beta, rm, rv| {
            let (mean, var, rm, rv) = B::batch_norm_statistics(x.clone(), rm, rv, momentum);
            let y = B::batch_norm(x, gamma, beta, mean.clone(), var.clone(), epsilon);
            let inv_std = B::float_recip(B::float_sqrt(B::float_add_scalar(
                var,
                Scalar::Float(epsilon),
            )));
            (y, mean, inv_std, rm, rv)
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
                let y = prep.finish((x_state, gamma_state, mean, inv_std), y);
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

/// burn's `BatchNorm::forward`, on our kernels where `x` is on a GPU and the layer trains
/// (the running statistics updated as burn updates them); burn's own elsewhere.
pub fn batch_norm<const D: usize>(norm: &BatchNorm, x: Tensor<D>) -> Tensor<D> {
    let training = x.device().is_autodiff() && norm.training.is_enabled();
    if !training || !super::is_lazy(&x.clone().inner()) {
        return norm.forward(x);
    }
    let device = x.device();
    let running_mean = norm.running_mean.value_sync().to_device(&device);
    let running_var = norm.running_var.value_sync().to_device(&device);
    let (y, rm, rv) = <Dispatch as GpuKernelOps>::batch_norm_train(
        x.into_dispatch(),
        norm.gamma.val().into_dispatch(),
        norm.beta.val().into_dispatch(),
        running_mean.into_dispatch(),
        running_var.into_dispatch(),
        norm.epsilon,
        norm.momentum,
    );
    let rm = Tensor::<1>::from_dispatch(rm);
    let rv = Tensor::<1>::from_dispatch(rv);
    norm.running_mean.update(rm.detach());
    norm.running_var.update(rv.detach());
    Tensor::from_dispatch(y)
}
