//! [`CpuKernelOps`] inside burn's autodiff graph: each op's hand-written backward pass, its
//! inputs checkpointed where the backward pass reads them.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind, unary};
use burn::backend::autodiff::{Autodiff, NodeId};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, TensorMetadata};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};

use super::{CpuKernelOps, conv_transpose2d_x_grad, conv2d_x_grad};

impl<B: Backend + CpuKernelOps, C: CheckpointStrategy> CpuKernelOps for Autodiff<B, C> {
    fn conv2d_fast(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Conv2dFast;

        impl<B: Backend + CpuKernelOps> Backward<B, 2> for Conv2dFast {
            type State = (NodeId, NodeId, ConvOptions<2>);

            fn backward(
                self,
                ops: Ops<Self::State, 2>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let [node_x, node_weight] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                let (x_state, weight_state, options) = ops.state;
                let x = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(x_state);
                let weight =
                    checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(weight_state);
                if let Some(node) = node_x {
                    let g = conv2d_x_grad::<B>(x.clone(), weight.clone(), grad.clone(), &options);
                    grads.register::<B>(node.id, g);
                }
                if let Some(node) = node_weight {
                    grads.register::<B>(node.id, B::conv2d_weight_grad(x, weight, grad, options));
                }
            }
        }

        match Conv2dFast
            .prepare::<C>([x.node(), weight.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let x_state = prep.checkpoint(&x);
                let weight_state = prep.checkpoint(&weight);
                prep.finish(
                    (x_state, weight_state, options.clone()),
                    B::conv2d_fast(x.into_primitive(), weight.into_primitive(), options),
                )
            }
            OpsKind::UnTracked(prep) => prep.finish(B::conv2d_fast(
                x.into_primitive(),
                weight.into_primitive(),
                options,
            )),
        }
    }

    fn conv_transpose2d_fast(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct ConvTranspose2dFast;

        impl<B: Backend + CpuKernelOps> Backward<B, 2> for ConvTranspose2dFast {
            type State = (NodeId, NodeId, ConvTransposeOptions<2>);

            fn backward(
                self,
                ops: Ops<Self::State, 2>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let [node_x, node_weight] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                let (x_state, weight_state, options) = ops.state;
                let x = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(x_state);
                let weight =
                    checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(weight_state);
                match (node_x, node_weight) {
                    (Some(nx), Some(nw)) => {
                        let (dx, dw) = B::conv_transpose2d_grads(x, weight, grad, options);
                        grads.register::<B>(nx.id, dx);
                        grads.register::<B>(nw.id, dw);
                    }
                    (Some(node), None) => {
                        let g = conv_transpose2d_x_grad::<B>(weight, grad, &options);
                        grads.register::<B>(node.id, g);
                    }
                    (None, Some(node)) => {
                        let g = B::conv_transpose2d_weight_grad(x, weight, grad, options);
                        grads.register::<B>(node.id, g);
                    }
                    (None, None) => {}
                }
            }
        }

        match ConvTranspose2dFast
            .prepare::<C>([x.node(), weight.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let x_state = prep.checkpoint(&x);
                let weight_state = prep.checkpoint(&weight);
                prep.finish(
                    (x_state, weight_state, options.clone()),
                    B::conv_transpose2d_fast(x.into_primitive(), weight.into_primitive(), options),
                )
            }
            OpsKind::UnTracked(prep) => prep.finish(B::conv_transpose2d_fast(
                x.into_primitive(),
                weight.into_primitive(),
                options,
            )),
        }
    }

    fn resize_bilinear_fast(x: FloatTensor<Self>, size: [usize; 2]) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct ResizeBilinear;

        impl<B: Backend + CpuKernelOps> Backward<B, 1> for ResizeBilinear {
            type State = [usize; 4];

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let input = ops.state;
                unary::<B, _>(ops.parents, ops.node, grads, |grad| {
                    B::resize_bilinear_backward(grad, input)
                });
            }
        }

        let input = x.shape().dims::<4>();
        match ResizeBilinear
            .prepare::<C>([x.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                prep.finish(input, B::resize_bilinear_fast(x.into_primitive(), size))
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::resize_bilinear_fast(x.into_primitive(), size))
            }
        }
    }

    fn add_bias_fast(y: FloatTensor<Self>, bias: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct AddBias;

        impl<B: Backend + CpuKernelOps> Backward<B, 2> for AddBias {
            type State = ();

            fn backward(
                self,
                ops: Ops<Self::State, 2>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let [node_y, node_bias] = ops.parents;
                let grad = grads.consume::<B>(&ops.node);
                if let Some(node) = node_bias {
                    grads.register::<B>(node.id, B::bias_grad(grad.clone()));
                }
                if let Some(node) = node_y {
                    grads.register::<B>(node.id, grad);
                }
            }
        }

        AddBias
            .prepare::<C>([y.node(), bias.node()])
            .compute_bound()
            .stateless(B::add_bias_fast(y.into_primitive(), bias.into_primitive()))
    }

    fn matmul_fast(x: FloatTensor<Self>, w: FloatTensor<Self>) -> FloatTensor<Self> {
        two_inputs::<B, C>(x, w, B::matmul_fast, |x, w, grad, [need_x, need_w]| {
            [
                need_x.then(|| B::linear_x_backward(w, grad.clone())),
                need_w.then(|| B::linear_weight_backward(x, grad)),
            ]
        })
    }

    fn sigmoid_fast(x: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Sigmoid;

        impl<B: Backend + CpuKernelOps> Backward<B, 1> for Sigmoid {
            type State = B::FloatTensorPrimitive;

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                _checkpointer: &mut Checkpointer,
            ) {
                let s = ops.state;
                unary::<B, _>(ops.parents, ops.node, grads, |grad| {
                    B::sigmoid_fast_backward(s, grad)
                });
            }
        }

        match Sigmoid.prepare::<C>([x.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let s = B::sigmoid_fast(x.into_primitive());
                prep.finish(s.clone(), s)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::sigmoid_fast(x.into_primitive())),
        }
    }

    fn bce_with_logits_fast(z: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        two_inputs::<B, C>(z, y, B::bce_with_logits_fast, |z, y, grad, need| {
            let (dz, dy) = B::bce_with_logits_grads(z, y, grad);
            [need[0].then_some(dz), need[1].then_some(dy)]
        })
    }

    fn relu_fast(x: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Relu;

        impl<B: Backend + CpuKernelOps> Backward<B, 1> for Relu {
            type State = NodeId;

            fn backward(
                self,
                ops: Ops<Self::State, 1>,
                grads: &mut Gradients,
                checkpointer: &mut Checkpointer,
            ) {
                let x = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(ops.state);
                unary::<B, _>(ops.parents, ops.node, grads, |grad| {
                    B::relu_fast_backward(x, grad)
                });
            }
        }

        match Relu.prepare::<C>([x.node()]).compute_bound().stateful() {
            OpsKind::Tracked(mut prep) => {
                let state = prep.checkpoint(&x);
                prep.finish(state, B::relu_fast(x.into_primitive()))
            }
            OpsKind::UnTracked(prep) => prep.finish(B::relu_fast(x.into_primitive())),
        }
    }
}

/// The gradients of a two-input op from both inputs and the output's gradient, each where
/// `need` says its input is tracked.
type TwoInputGrads<B> =
    fn(FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, [bool; 2]) -> [Option<FloatTensor<B>>; 2];

/// A two-input op in the autodiff graph whose backward pass reads both inputs: `forward` on
/// the inner backend, both inputs checkpointed, `grads` in the backward pass.
fn two_inputs<B: Backend, C: CheckpointStrategy>(
    a: FloatTensor<Autodiff<B, C>>,
    b: FloatTensor<Autodiff<B, C>>,
    forward: fn(FloatTensor<B>, FloatTensor<B>) -> FloatTensor<B>,
    grads: TwoInputGrads<B>,
) -> FloatTensor<Autodiff<B, C>> {
    #[derive(Debug)]
    struct TwoInputs<B: Backend>(TwoInputGrads<B>);

    impl<B: Backend> Backward<B, 2> for TwoInputs<B> {
        type State = (NodeId, NodeId);

        fn backward(
            self,
            ops: Ops<Self::State, 2>,
            gradients: &mut Gradients,
            checkpointer: &mut Checkpointer,
        ) {
            let grad = gradients.consume::<B>(&ops.node);
            let a = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(ops.state.0);
            let b = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(ops.state.1);
            let need = ops.parents.each_ref().map(Option::is_some);
            for (node, g) in ops.parents.into_iter().zip((self.0)(a, b, grad, need)) {
                if let (Some(node), Some(g)) = (node, g) {
                    gradients.register::<B>(node.id, g);
                }
            }
        }
    }

    match TwoInputs(grads)
        .prepare::<C>([a.node(), b.node()])
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(mut prep) => {
            let state = (prep.checkpoint(&a), prep.checkpoint(&b));
            prep.finish(state, forward(a.into_primitive(), b.into_primitive()))
        }
        OpsKind::UnTracked(prep) => prep.finish(forward(a.into_primitive(), b.into_primitive())),
    }
}
