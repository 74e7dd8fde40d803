//! [`GpuKernelOps`] on burn's `Autodiff` backend: each layer one operation of the autodiff
//! graph with a hand-written backward pass (the convolutions' in [`super::convolution`]).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::autodiff::{Autodiff, NodeId};
use burn::backend::tensor::FloatTensor;
use burn::backend::{AutodiffBackend, Backend};

use super::batch_norm::{Layer, Saved};
use super::conv_layer::{Conv2dLayer, ConvTranspose2dLayer};
use super::convolution;
use super::extension::{GpuKernelOps, maybe_relu};

impl<B: Backend + GpuKernelOps, C: CheckpointStrategy> GpuKernelOps for Autodiff<B, C> {
    fn conv2d_train(x: FloatTensor<Self>, layer: Conv2dLayer<Self>) -> FloatTensor<Self> {
        convolution::conv2d_train::<B, C>(x, layer)
    }

    fn conv_transpose2d_train(
        x: FloatTensor<Self>,
        layer: ConvTranspose2dLayer<Self>,
    ) -> FloatTensor<Self> {
        convolution::conv_transpose2d_train::<B, C>(x, layer)
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
        layer: Layer<Self>,
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
                let saved = Saved {
                    x,
                    y,
                    dy,
                    mean,
                    inv_std,
                    relu,
                };
                let param_grads = B::batch_norm_param_grads(saved.clone());
                if let Some(node) = node_x {
                    let dx = B::batch_norm_x_grad(saved, gamma, param_grads.clone());
                    grads.register::<B>(node.id, dx);
                }
                if let Some(node) = node_gamma {
                    grads.register::<B>(node.id, param_grads.gamma);
                }
                if let Some(node) = node_beta {
                    grads.register::<B>(node.id, param_grads.beta);
                }
            }
        }

        // The layer on the inner backend (the running statistics are constants).
        let inner = |x: FloatTensor<Self>| x.into_primitive();
        let nodes = [x.node(), layer.gamma.node(), layer.beta.node()];
        let relu = layer.relu;
        let constant = |t: FloatTensor<B>| <Self as AutodiffBackend>::from_inner(t);
        let forward = |x: FloatTensor<B>, layer: Layer<B>| {
            let (gamma, beta, epsilon) = (layer.gamma.clone(), layer.beta.clone(), layer.epsilon);
            let stats = B::batch_norm_statistics(x.clone(), layer);
            let y = B::batch_norm(
                x,
                gamma,
                beta,
                stats.mean.clone(),
                stats.var.clone(),
                epsilon,
            );
            (maybe_relu::<B>(y, relu), stats)
        };
        match BatchNormTrain
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let x_state = prep.checkpoint(&x);
                let gamma_state = prep.checkpoint(&layer.gamma);
                let (y, stats) = forward(inner(x), layer.map_inner(inner));
                let state = (
                    x_state,
                    gamma_state,
                    y.clone(),
                    stats.mean,
                    stats.inv_std,
                    relu,
                );
                let y = prep.finish(state, y);
                (y, constant(stats.running_mean), constant(stats.running_var))
            }
            OpsKind::UnTracked(prep) => {
                let (y, stats) = forward(inner(x), layer.map_inner(inner));
                (
                    prep.finish(y),
                    constant(stats.running_mean),
                    constant(stats.running_var),
                )
            }
        }
    }
}
