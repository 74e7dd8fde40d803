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

use super::CpuKernelOps;

impl<B: Backend + CpuKernelOps, C: CheckpointStrategy> CpuKernelOps for Autodiff<B, C> {
    fn conv2d_fast(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        two_inputs::<B, C, _>(x, weight, options, B::conv2d_fast, B::conv2d_grads)
    }

    fn conv_transpose2d_fast(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self> {
        two_inputs::<B, C, _>(
            x,
            weight,
            options,
            B::conv_transpose2d_fast,
            B::conv_transpose2d_grads,
        )
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
        two_inputs::<B, C, _>(
            x,
            w,
            (),
            |x, w, ()| B::matmul_fast(x, w),
            |x, w, grad, (), need| {
                (
                    need[0].then(|| B::linear_x_backward(w, grad.clone())),
                    need[1].then(|| B::linear_weight_backward(x, grad)),
                )
            },
        )
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
        let forward = |z, y, ()| B::bce_with_logits_fast(z, y);
        two_inputs::<B, C, _>(z, y, (), forward, |z, y, grad, (), need| {
            let (dz, dy) = B::bce_with_logits_grads(z, y, grad);
            (need[0].then_some(dz), need[1].then_some(dy))
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

/// The gradients of a two-input op from both inputs, the output's gradient and the op's
/// `options`, each where `need` says its input is tracked.
type TwoInputGrads<B, S> = fn(
    FloatTensor<B>,
    FloatTensor<B>,
    FloatTensor<B>,
    S,
    [bool; 2],
) -> (Option<FloatTensor<B>>, Option<FloatTensor<B>>);

/// A two-input op in the autodiff graph whose backward pass reads both inputs: `forward` on
/// the inner backend with `options` (a convolution's; `()` for none), both inputs
/// checkpointed, `grads` in the backward pass.
fn two_inputs<B: Backend, C: CheckpointStrategy, S>(
    a: FloatTensor<Autodiff<B, C>>,
    b: FloatTensor<Autodiff<B, C>>,
    options: S,
    forward: fn(FloatTensor<B>, FloatTensor<B>, S) -> FloatTensor<B>,
    grads: TwoInputGrads<B, S>,
) -> FloatTensor<Autodiff<B, C>>
where
    S: Clone + std::fmt::Debug + Send + 'static,
{
    #[derive(Debug)]
    struct TwoInputs<B: Backend, S>(TwoInputGrads<B, S>);

    impl<B: Backend, S: Clone + std::fmt::Debug + Send + 'static> Backward<B, 2> for TwoInputs<B, S> {
        type State = (NodeId, NodeId, S);

        fn backward(
            self,
            ops: Ops<Self::State, 2>,
            gradients: &mut Gradients,
            checkpointer: &mut Checkpointer,
        ) {
            let grad = gradients.consume::<B>(&ops.node);
            let (a, b, options) = ops.state;
            let a = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(a);
            let b = checkpointer.retrieve_node_output::<B::FloatTensorPrimitive>(b);
            let need = ops.parents.each_ref().map(Option::is_some);
            let (da, db) = (self.0)(a, b, grad, options, need);
            for (node, g) in ops.parents.into_iter().zip([da, db]) {
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
            let state = (prep.checkpoint(&a), prep.checkpoint(&b), options.clone());
            prep.finish(
                state,
                forward(a.into_primitive(), b.into_primitive(), options),
            )
        }
        OpsKind::UnTracked(prep) => {
            prep.finish(forward(a.into_primitive(), b.into_primitive(), options))
        }
    }
}
