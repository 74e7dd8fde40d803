//! The GPU path of [`super::step`]: gather every parameter in a first pass over burn's
//! `ModuleOptimizer` (each comes back unchanged), run the multi-tensor kernels over all of
//! them, and hand each parameter its result in a second pass.

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

/// Every parameter of a step, gathered by the first pass at the learning rate `lr` (the
/// second pass walks the optimiser at the same one).
pub(super) struct Fused {
    list: Vec<Gathered>,
    lr: f64,
}

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
            Some(Fused { list, lr })
        }
        _ => None,
    }
}

impl Fused {
    /// Run the kernels over every parameter, then the second pass hands out the results.
    pub(super) fn apply<M: Module>(
        self,
        optim: &mut ModuleOptimizer,
        model: M,
        grads: GradientsParams,
        clip: Option<f32>,
    ) -> M {
        let Fused { list, lr } = self;
        let squared_norm = clip.map(|max| {
            let grads: Vec<LazyTensor> = list.iter().map(|g| g.grad.clone()).collect();
            let out = cube::run_lazily(
                "sum_of_squares",
                grads,
                &[(Shape::new([1]), DType::F32)],
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
            results.extend(run_group(group, squared_norm.clone()));
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
    if let Some((squared_norm, _)) = clip {
        inputs.push(squared_norm);
    }
    let out = cube::run_lazily("adam", inputs, &outputs, move |mut tensors| {
        let squared_norm = max_norm.map(|max| (tensors.pop().expect("the squared norm"), max));
        let mut parts = tensors.chunks(n).map(|c| c.to_vec());
        let (p, g, m, v) = (
            parts.next().expect("params"),
            parts.next().expect("grads"),
            parts.next().expect("first moments"),
            parts.next().expect("second moments"),
        );
        let results = cube::launch::adam(p, g, m, v, step, squared_norm);
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
