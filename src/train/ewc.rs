//! Elastic Weight Consolidation (Kirkpatrick et al., PNAS 2017): learning a new task while
//! keeping an old one, by a quadratic penalty that holds each weight near its old value in
//! proportion to how much the old task's loss depends on it: `lambda / 2 * sum_i F_i (w_i -
//! w*_i)^2`, with `F` the diagonal of the Fisher information at the old weights `w*`.
//!
//! `F` is the empirical Fisher of one image: the old task's loss per image (as the trainer
//! computes it) has gradients `g_s`, and `F = E[g_s^2]`. It is estimated from mini-batches:
//! a batch of `B` images has the gradient `g_B = mean_s g_s`; at the old optimum the `g_s` have
//! mean ~0 and are independent, so `E[g_B^2] = E[g_s^2] / B`, and `F = B * mean(g_B^2)` over
//! the batches drawn. (Without the factor `B` the penalty is `B` times weaker than its `lambda`
//! says.) With `F` per image, `lambda = 1` weighs the old task's mean loss, in the quadratic
//! approximation `F` gives of it, as much as the new task's; where one image's loss is a mean
//! over many correlated outputs (a silhouette's pixels), the empirical Fisher underestimates
//! the curvature by up to the number of outputs, so useful values of `lambda` run far above 1:
//! sweep it.

use std::collections::HashMap;

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::tensor::{Tensor, TensorData};

use crate::train::batcher::{Batch, Batcher, TrainSet};
use crate::train::config::TrainConfig;

/// The old weights and their Fisher information, per parameter (flattened, on the device
/// without autodiff: constants that join no step's graph, uploaded once).
pub struct Ewc {
    anchors: HashMap<ParamId, (Tensor<1>, Tensor<1>)>,
    /// The anchored model's device.
    device: burn::tensor::Device,
    pub lambda: f64,
}

impl Ewc {
    /// The Fisher diagonal of `model` (on an autodiff device) from `batches` batches of
    /// `data` (drawn as `cfg` draws them) under `loss`, and `model`'s weights as the anchor.
    pub fn new<M: Module>(
        model: &M,
        data: &TrainSet,
        cfg: &TrainConfig,
        batches: usize,
        loss: impl Fn(&M, &Batch) -> Tensor<1>,
        lambda: f64,
    ) -> crate::core::error::Result<Self> {
        struct Squares<'a> {
            grads: &'a GradientsParams,
            sums: &'a mut HashMap<ParamId, TensorData>,
        }
        impl ModuleVisitor for Squares<'_> {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                if let Some(g) = self.grads.get::<D>(param.id) {
                    let n = g.shape().num_elements();
                    let sq: Vec<f32> = g
                        .square()
                        .reshape([n])
                        .into_data()
                        .convert::<f32>()
                        .try_into_vec::<f32>()
                        .expect("float gradients");
                    let entry = self
                        .sums
                        .entry(param.id)
                        .or_insert_with(|| TensorData::new(vec![0f32; n], [n]));
                    let acc: Vec<f32> = entry
                        .try_to_vec::<f32>()
                        .expect("float")
                        .iter()
                        .zip(&sq)
                        .map(|(a, b)| a + b)
                        .collect();
                    *entry = TensorData::new(acc, [n]);
                }
            }
        }
        struct Anchor<'a> {
            fisher: &'a HashMap<ParamId, TensorData>,
            scale: f32,
            out: HashMap<ParamId, (Tensor<1>, Tensor<1>)>,
            device: Option<burn::tensor::Device>,
        }
        impl ModuleVisitor for Anchor<'_> {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                if let Some(f) = self.fisher.get(&param.id) {
                    let w = param.val();
                    self.device.get_or_insert_with(|| w.device());
                    let n = w.shape().num_elements();
                    let device = w.device();
                    let old = w.reshape([n]).detach().without_autodiff();
                    let fisher: Vec<f32> = f
                        .try_to_vec::<f32>()
                        .expect("float")
                        .iter()
                        .map(|v| v * self.scale)
                        .collect();
                    let fisher = Tensor::<1>::from_data(TensorData::new(fisher, [n]), &device)
                        .without_autodiff();
                    self.out.insert(param.id, (old, fisher));
                }
            }
        }
        let batcher = Batcher::new(data, cfg);
        let mut sums = HashMap::new();
        let batches = batches.max(1);
        for step in 0..batches {
            let l = loss(model, &batcher.batch(step));
            let grads = GradientsParams::from_grads(l.backward(), model);
            model.visit(&mut Squares {
                grads: &grads,
                sums: &mut sums,
            });
        }
        let mut anchor = Anchor {
            fisher: &sums,
            scale: cfg.batch.max(1) as f32 / batches as f32,
            out: HashMap::new(),
            device: None,
        };
        model.visit(&mut anchor);
        let Some(device) = anchor.device.filter(|_| !anchor.out.is_empty()) else {
            return Err(crate::core::error::Error::Training(
                "EWC: the old task's loss has a gradient for no parameter of the model".into(),
            ));
        };
        Ok(Ewc {
            anchors: anchor.out,
            device,
            lambda,
        })
    }

    /// `lambda / 2 * sum F (w - w*)^2` for `model`'s weights (differentiable in them); 0 at
    /// the old weights.
    pub fn penalty<M: Module>(&self, model: &M) -> Tensor<1> {
        struct Sum<'a> {
            anchors: &'a HashMap<ParamId, (Tensor<1>, Tensor<1>)>,
            total: Option<Tensor<1>>,
        }
        impl ModuleVisitor for Sum<'_> {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                if let Some((old, fisher)) = self.anchors.get(&param.id) {
                    let w = param.val();
                    let n = w.shape().num_elements();
                    let d = w.reshape([n]) - old.clone();
                    let term = (fisher.clone() * d.square()).sum();
                    self.total = Some(match self.total.take() {
                        Some(t) => t + term,
                        None => term,
                    });
                }
            }
        }
        let mut sum = Sum {
            anchors: &self.anchors,
            total: None,
        };
        model.visit(&mut sum);
        match sum.total {
            Some(t) => t.mul_scalar(0.5 * self.lambda),
            // Another model than the one anchored: nothing to hold.
            None => Tensor::zeros([1], &self.device),
        }
    }

    /// Parameters anchored.
    pub fn len(&self) -> usize {
        self.anchors.len()
    }

    pub fn is_empty(&self) -> bool {
        self.anchors.is_empty()
    }
}
