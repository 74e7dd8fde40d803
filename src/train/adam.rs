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
        #[cfg(feature = "wgpu")]
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
    let scale = norm.ones_like().mask_where(clip, ratio);
    let mut s = Scale {
        grads,
        scale,
        ids: Vec::new(),
    };
    model.visit(&mut s);
    Some(norm)
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
    #[cfg(feature = "wgpu")]
    if let Some(fused) = fused::gather(optim, lr, &model, &grads) {
        return fused.apply(optim, lr, model, grads, clip);
    }
    let mut grads = grads;
    if let Some(max) = clip {
        clip_global_norm(&model, &mut grads, max);
    }
    optim.step(lr, model, grads)
}

#[cfg(feature = "wgpu")]
mod fused {
    //! The GPU path of [`super::step`]: gather, run the multi-tensor kernels, apply.

    use std::cell::RefCell;
    use std::collections::VecDeque;

    use burn::backend::DispatchAutodiffContext;
    use burn::module::{Module, ModuleVisitor, Param};
    use burn::optim::{AdamState, AdaptiveMomentumState, GradientsParams, ModuleOptimizer};
    use burn::tensor::{DType, Shape, Tensor};

    use crate::kernels::cube::{self, LazyTensor};
    use crate::kernels::pointwise::AdamStep;

    /// One parameter as the first pass finds it.
    pub(super) struct Gathered {
        step: AdamStep,
        param: LazyTensor,
        grad: LazyTensor,
        moment_1: LazyTensor,
        moment_2: LazyTensor,
        param_autodiff: DispatchAutodiffContext,
        state_autodiff: DispatchAutodiffContext,
    }

    /// One parameter's result, handed over in the second pass.
    pub(super) struct Applied {
        time: usize,
        shape: Shape,
        param: LazyTensor,
        moment_1: LazyTensor,
        moment_2: LazyTensor,
        param_autodiff: DispatchAutodiffContext,
        state_autodiff: DispatchAutodiffContext,
    }

    /// What [`super::Adam`]'s step does in each pass (off: its own step).
    #[derive(Default)]
    pub(super) enum Pass {
        #[default]
        Off,
        /// Record each parameter and return it unchanged; `None` once a parameter is not on a
        /// CubeCL device (the whole step then runs the ordinary way).
        Gather(Option<Vec<Gathered>>),
        Apply(VecDeque<Applied>),
    }

    thread_local! {
        pub(super) static PASS: RefCell<Pass> = RefCell::new(Pass::Off);
    }

    /// The first pass's part of [`super::Adam`]'s step: `true` when the pass took it.
    pub(super) fn gather_one<const D: usize>(
        adam: &super::Adam,
        lr: f64,
        tensor: &Tensor<D>,
        grad: &Tensor<D>,
        state: &Option<AdamState<D>>,
    ) -> bool {
        PASS.with(|pass| {
            let mut pass = pass.borrow_mut();
            let Pass::Gather(list) = &mut *pass else {
                return false;
            };
            let Some(gathered) = list.as_mut() else {
                return true;
            };
            if !cube::is_lazy(tensor) {
                *list = None;
                return true;
            }
            let (time, m, v) = match state {
                Some(s) => (
                    s.momentum.time + 1,
                    s.momentum.moment_1.clone(),
                    s.momentum.moment_2.clone(),
                ),
                None => (1, grad.zeros_like(), grad.zeros_like()),
            };
            let parts = (
                cube::lazy(tensor.clone()),
                cube::lazy(grad.clone()),
                cube::lazy(m),
                cube::lazy(v),
            );
            let (Ok((param, param_autodiff)), Ok((grad, state_autodiff)), Ok((m, _)), Ok((v, _))) =
                parts
            else {
                *list = None;
                return true;
            };
            if param.dtype != DType::F32 {
                *list = None;
                return true;
            }
            gathered.push(Gathered {
                step: AdamStep {
                    beta_1: adam.beta_1,
                    beta_2: adam.beta_2,
                    epsilon: adam.epsilon,
                    time: time as i32,
                    lr: lr as f32,
                },
                param,
                grad,
                moment_1: m,
                moment_2: v,
                param_autodiff,
                state_autodiff,
            });
            true
        })
    }

    /// The second pass's part of [`super::Adam`]'s step: this parameter's result.
    pub(super) fn apply_one<const D: usize>(
        tensor: &Tensor<D>,
    ) -> Option<(Tensor<D>, Option<AdamState<D>>)> {
        PASS.with(|pass| {
            let mut pass = pass.borrow_mut();
            let Pass::Apply(results) = &mut *pass else {
                return None;
            };
            let r = results
                .pop_front()
                .expect("the second pass meets the parameters of the first");
            assert_eq!(
                r.shape,
                tensor.shape(),
                "the second pass meets the parameters in the first's order"
            );
            let momentum = AdaptiveMomentumState::new(
                r.time,
                cube::tensor(r.moment_1, r.state_autodiff),
                cube::tensor(r.moment_2, r.state_autodiff),
            );
            Some((
                cube::tensor(r.param, r.param_autodiff),
                Some(AdamState::new(momentum)),
            ))
        })
    }

    /// A copy of the gradients of `model`'s parameters (`GradientsParams` is not `Clone`).
    fn copy_grads<M: Module>(model: &M, grads: &GradientsParams) -> GradientsParams {
        struct Copy<'a> {
            from: &'a GradientsParams,
            to: GradientsParams,
        }
        impl ModuleVisitor for Copy<'_> {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                if let Some(g) = self.from.get::<D>(param.id) {
                    self.to.register(param.id, g);
                }
            }
        }
        let mut c = Copy {
            from: grads,
            to: GradientsParams::new(),
        };
        model.visit(&mut c);
        c.to
    }

    /// Every parameter of a step, gathered by the first pass.
    pub(super) struct Fused(Vec<Gathered>);

    /// The first pass: `None` where the step cannot be fused (a parameter off a CubeCL device,
    /// not f32, or an optimiser other than our Adam).
    pub(super) fn gather<M: Module>(
        optim: &mut ModuleOptimizer,
        lr: f64,
        model: &M,
        grads: &GradientsParams,
    ) -> Option<Fused> {
        if grads.is_empty() {
            return None;
        }
        let copy = copy_grads(model, grads);
        let expected = copy.len();
        PASS.with(|p| *p.borrow_mut() = Pass::Gather(Some(Vec::new())));
        // Each parameter comes back unchanged with its state: the step is a walk.
        let walked = optim.step(lr, model.clone(), copy);
        drop(walked);
        let pass = PASS.with(|p| std::mem::take(&mut *p.borrow_mut()));
        match pass {
            Pass::Gather(Some(list)) if !list.is_empty() && list.len() == expected => {
                Some(Fused(list))
            }
            _ => None,
        }
    }

    impl Fused {
        /// Run the kernels over every parameter, then the second pass hands out the results.
        pub(super) fn apply<M: Module>(
            self,
            optim: &mut ModuleOptimizer,
            lr: f64,
            model: M,
            grads: GradientsParams,
            clip: Option<f32>,
        ) -> M {
            let list = self.0;
            let partials = clip.map(|max| {
                let grads: Vec<LazyTensor> = list.iter().map(|g| g.grad.clone()).collect();
                let n = grads.len() * cube::launch::GROUPS;
                let out = cube::run_lazily(
                    "sum_of_squares",
                    grads,
                    &[(Shape::new([n]), DType::F32)],
                    |tensors| vec![cube::launch::sum_of_squares(tensors)],
                );
                (out.into_iter().next().expect("one output"), max)
            });
            let mut results = VecDeque::with_capacity(list.len());
            // Parameters with the same step (all of them, unless the learning rate differs
            // between parameters or some restarted) run together.
            let mut rest = list.into_iter().peekable();
            while let Some(first) = rest.next() {
                let mut group = vec![first];
                while let Some(next) = rest.peek() {
                    let s = (&next.step, &group[0].step);
                    if s.0.time == s.1.time && s.0.lr == s.1.lr {
                        group.push(rest.next().expect("peeked"));
                    } else {
                        break;
                    }
                }
                results.extend(run_group(group, partials.clone()));
            }
            PASS.with(|p| *p.borrow_mut() = Pass::Apply(results));
            let model = optim.step(lr, model, grads);
            let pass = PASS.with(|p| std::mem::take(&mut *p.borrow_mut()));
            if let Pass::Apply(left) = pass {
                assert!(left.is_empty(), "every result of the first pass is applied");
            }
            model
        }
    }

    /// Adam over a group of parameters with the same step, as one recorded operation.
    fn run_group(group: Vec<Gathered>, clip: Option<(LazyTensor, f32)>) -> Vec<Applied> {
        let n = group.len();
        let step = group[0].step;
        let mut inputs = Vec::with_capacity(4 * n + 1);
        let mut outputs = Vec::with_capacity(3 * n);
        for k in 0..4 {
            for g in &group {
                inputs.push(
                    match k {
                        0 => &g.param,
                        1 => &g.grad,
                        2 => &g.moment_1,
                        _ => &g.moment_2,
                    }
                    .clone(),
                );
            }
        }
        for k in 0..3 {
            for g in &group {
                let t = match k {
                    0 => &g.param,
                    1 => &g.moment_1,
                    _ => &g.moment_2,
                };
                outputs.push((t.shape.clone(), t.dtype));
            }
        }
        let max_norm = clip.as_ref().map(|c| c.1);
        if let Some((partials, _)) = clip {
            inputs.push(partials);
        }
        let out = cube::run_lazily("adam", inputs, &outputs, move |mut tensors| {
            let partials = max_norm.map(|max| (tensors.pop().expect("the partials"), max));
            let mut parts = tensors.chunks(n).map(|c| c.to_vec());
            let (p, g, m, v) = (
                parts.next().expect("params"),
                parts.next().expect("grads"),
                parts.next().expect("first moments"),
                parts.next().expect("second moments"),
            );
            let results = cube::launch::adam(p, g, m, v, step, partials);
            let mut flat = Vec::with_capacity(3 * n);
            for k in 0..3 {
                flat.extend(results.iter().map(|r| r[k].clone()));
            }
            flat
        });
        let mut out = out.into_iter();
        let mut params: Vec<LazyTensor> = (&mut out).take(n).collect();
        let mut m: Vec<LazyTensor> = (&mut out).take(n).collect();
        let mut v: Vec<LazyTensor> = out.collect();
        group
            .into_iter()
            .rev()
            .map(|g| Applied {
                time: step.time as usize,
                shape: g.param.shape.clone(),
                param: params.pop().expect("n params"),
                moment_1: m.pop().expect("n moments"),
                moment_2: v.pop().expect("n moments"),
                param_autodiff: g.param_autodiff,
                state_autodiff: g.state_autodiff,
            })
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect()
    }
}
