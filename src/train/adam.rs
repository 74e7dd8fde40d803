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

use burn::optim::{AdamConfig, AdamState, AdaptiveMomentumState, LearningRate, ModuleOptimizer};
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
