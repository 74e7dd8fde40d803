//! Adam, as burn's `Adam` computes it (no weight decay, no AMSGrad), each parameter's step in
//! one parallel pass on the CPU.
//!
//! burn's `Adam` runs a parameter's step as ten tensor operations, and flex runs each on the
//! calling thread: for NeuroKin's five million parameters, ten serial passes over 20 MB at
//! every step while the other threads wait (about a tenth of the main thread's time in
//! `bench_decoders` on 2 threads, a share that grows with the threads). Here one kernel
//! ([`crate::kernels::pointwise::adam`]) computes each element's new value and moments in
//! the order burn's operations do, so the parameters are burn's to the bit, and the state is
//! burn's `AdamState`: checkpoints written with either load into the other (tested). Off the
//! CPU the step is burn's own.

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::{
    AdamConfig, AdamState, AdaptiveMomentumState, GradientsParams, LearningRate, ModuleOptimizer,
};
use burn::tensor::{Device, Tensor};

use crate::kernels::cpu_extension::{adam_step, on_flex};
use crate::kernels::pointwise::AdamStep;

/// Adam with burn's defaults (β₁ 0.9, β₂ 0.999, ε 1e-5) and β₁ as given.
#[derive(Clone)]
pub struct Adam {
    beta_1: f32,
    beta_2: f32,
    epsilon: f32,
    /// burn's, for tensors off the CPU.
    reference: burn::optim::Adam,
}

impl Adam {
    pub fn new(beta_1: f32) -> Self {
        let (beta_2, epsilon) = (0.999, 1e-5);
        let reference = AdamConfig::new()
            .with_beta_1(beta_1)
            .with_beta_2(beta_2)
            .with_epsilon(epsilon)
            .build();
        Adam {
            beta_1,
            beta_2,
            epsilon,
            reference,
        }
    }
}

/// The optimizer every trainer uses: Adam with burn's defaults.
pub fn adam() -> ModuleOptimizer {
    adam_with_beta_1(0.9)
}

/// Adam with β₁ as given (0.5 for the conditional GAN, as its paper).
pub fn adam_with_beta_1(beta_1: f32) -> ModuleOptimizer {
    ModuleOptimizer::from(Adam::new(beta_1))
}

impl burn::optim::Optimizer for Adam {
    type State<const D: usize> = AdamState<D>;

    fn step<const D: usize>(
        &self,
        lr: LearningRate,
        tensor: Tensor<D>,
        grad: Tensor<D>,
        state: Option<Self::State<D>>,
    ) -> (Tensor<D>, Option<Self::State<D>>) {
        #[cfg(feature = "cube")]
        {
            if fused::gather_one(self, lr, &tensor, &grad, &state) {
                return (tensor, state);
            }
            if let Some(applied) = fused::apply_one(&tensor) {
                return applied;
            }
        }
        if !on_flex(&tensor) {
            return self.reference.step(lr, tensor, grad, state);
        }
        let (time, m, v) = match state {
            Some(s) => (
                s.momentum.time + 1,
                s.momentum.moment_1,
                s.momentum.moment_2,
            ),
            // m = v = 0 before the first step: 0·β + x is x, burn's first step to the bit.
            None => (1, grad.zeros_like(), grad.zeros_like()),
        };
        let step = AdamStep {
            beta_1: self.beta_1,
            beta_2: self.beta_2,
            epsilon: self.epsilon,
            time: time as i32,
            lr: lr as f32,
        };
        let [p, m, v] = adam_step(tensor, grad, m, v, step);
        let momentum = AdaptiveMomentumState::new(time, m, v);
        (p, Some(AdamState::new(momentum)))
    }

    fn to_device<const D: usize>(state: Self::State<D>, device: &Device) -> Self::State<D> {
        <burn::optim::Adam as burn::optim::Optimizer>::to_device(state, device)
    }
}

/// Scale all gradients so their global L2 norm is at most `max_norm` (PyTorch's
/// `clip_grad_norm_`), on the device: the norm is never read to the host, so a step that
/// clips waits for nothing. A non-finite norm leaves the gradients as they are (the loss
/// check stops such a run). Returns the norm before clipping, as a one-element tensor.
pub fn clip_global_norm<M: Module>(
    model: &M,
    grads: &mut GradientsParams,
    max_norm: f32,
) -> Option<Tensor<1>> {
    struct SquaredNorm<'a> {
        grads: &'a GradientsParams,
        sum: Option<Tensor<1>>,
    }
    impl ModuleVisitor for SquaredNorm<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if let Some(g) = self.grads.get::<D>(param.id) {
                let s = g.square().sum();
                self.sum = Some(match self.sum.take() {
                    Some(acc) => acc + s,
                    None => s,
                });
            }
        }
    }
    let mut v = SquaredNorm { grads, sum: None };
    model.visit(&mut v);
    let norm = v.sum?.sqrt();
    // max / (norm + 1e-6) where the norm is finite and above max, else 1: the same f32
    // arithmetic the host did when it read the norm.
    let clip = norm
        .clone()
        .is_finite()
        .bool_and(norm.clone().greater_elem(max_norm));
    let ratio = norm.zeros_like().add_scalar(max_norm) / norm.clone().add_scalar(1e-6f32);
    scale_gradients(model, grads, norm.ones_like().mask_where(clip, ratio));
    Some(norm)
}

/// Every gradient of `model`'s parameters in `grads` times `scale` (one value, on the device).
pub fn scale_gradients<M: Module>(model: &M, grads: &mut GradientsParams, scale: Tensor<1>) {
    struct Scale<'a> {
        grads: &'a mut GradientsParams,
        scale: Tensor<1>,
        ids: Vec<ParamId>,
    }
    impl ModuleVisitor for Scale<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if self.ids.contains(&param.id) {
                return;
            }
            if let Some(g) = self.grads.remove::<D>(param.id) {
                let scale = self.scale.clone().reshape([1usize; D]);
                self.grads.register(param.id, g * scale);
                self.ids.push(param.id);
            }
        }
    }
    model.visit(&mut Scale {
        grads,
        scale,
        ids: Vec::new(),
    });
}

/// One optimiser step of `model` with `grads`, the global gradient norm first clipped to
/// `clip` (PyTorch's `clip_grad_norm_`) where given: what every trainer calls.
///
/// On the CPU: [`clip_global_norm`], then `optim.step` (each parameter
/// on our parallel kernel, burn's numbers to the bit). On a GPU (feature `wgpu`), with our
/// [`Adam`]: the clipping and every parameter's update in a few launches
/// ([`crate::kernels::cube::multi_tensor`]: one for the norm, one per handful of parameters),
/// where burn's ops take about five a parameter. burn's `ModuleOptimizer` keeps the state
/// either way (its `AdamState`, so checkpoints load in both), in two passes over it: the first
/// gathers each parameter's tensor, gradient and moments without changing anything, the
/// fused kernels run over all of them, and the second hands each parameter its result.
pub fn step<M: Module>(
    optim: &mut ModuleOptimizer,
    lr: f64,
    model: M,
    grads: GradientsParams,
    clip: Option<f32>,
) -> M {
    #[cfg(feature = "cube")]
    if let Some(fused) = fused::gather(optim, lr, &model, &grads) {
        return fused.apply(optim, model, grads, clip);
    }
    let mut grads = grads;
    if let Some(max) = clip {
        clip_global_norm(&model, &mut grads, max);
    }
    optim.step(lr, model, grads)
}

#[cfg(feature = "cube")]
mod fused;
