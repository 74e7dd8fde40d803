//! Fitting the inverse MLP of [`crate::ik::mlp`] (position -> joints) through the shared
//! training loop: the fit settings, the training sets, a fit for epochs or to convergence,
//! prediction and test errors. Direct regression ([`crate::ik::paper::direct_regression`]), EMSSL
//! ([`crate::ik::paper::emssl`]) and DSL's inverse model all fit this way.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Point3;

use crate::core::error::Result;
use crate::ik::data::{DistanceErrors, IkData, JointOutput, reach_errors};
use crate::ik::mlp::Mlp;
use crate::sim::kinematics::KinematicChain;
use burn::optim::ModuleOptimizer;

use crate::train::{
    batcher::{Batch, TrainSet},
    config::{LrSchedule, TrainConfig},
    convergence::{Convergence, ConvergenceLog, FitCheckpoint, train_to_convergence},
    trainer::Trainer,
};

/// Optimisation of one fit.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitConfig {
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    pub inference_batch: usize,
    pub seed: u64,
    /// Train until the validation error stops improving (`epochs` ignored) instead of a fixed
    /// number of epochs; needs a validation split. EMSSL's iterations ignore it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub converge: Option<Convergence>,
    /// Within one fit, the learning rate falls along a half cosine from `learning_rate` to 1%
    /// of it (each EMSSL iteration ends annealed); constant otherwise.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub cosine: bool,
    /// Where a run to convergence keeps its checkpoints (each network in a folder named
    /// after its label); none if absent. Not a setting: not written with the config.
    #[serde(skip)]
    pub checkpoint: Option<FitCheckpoint>,
}

impl FitConfig {
    /// The paper's Table I: Adam 1.5e-3, training batch 128, inference batch 512, 10 epochs.
    pub fn paper() -> Self {
        FitConfig {
            epochs: 10,
            batch: 128,
            learning_rate: 1.5e-3,
            inference_batch: 512,
            seed: 0,
            converge: None,
            cosine: false,
            checkpoint: None,
        }
    }

    /// Where the network `label` keeps its checkpoint, if this fit keeps any.
    pub fn checkpoint_for(&self, label: &str) -> Option<FitCheckpoint> {
        self.checkpoint.as_ref().map(|c| FitCheckpoint {
            dir: c.dir.join(crate::core::atomic_file::file_name(label)),
            settings: c.settings.clone(),
        })
    }

    /// The shared loop's config for `cfg.epochs` epochs over `samples` (no clipping, no input
    /// noise, no checkpoints).
    pub fn train_config(&self, samples: usize) -> TrainConfig {
        TrainConfig {
            precision: Default::default(),
            schedule: if self.cosine {
                LrSchedule::Cosine
            } else {
                LrSchedule::Constant
            },
            steps: TrainConfig::steps_for_epochs(self.epochs, samples, self.batch),
            batch: self.batch,
            learning_rate: self.learning_rate,
            grad_clip_norm: None,
            input_noise: 0.0,
            seed: self.seed,
            checkpoint_every: 0,
            log_every: 0,
        }
    }
}

/// Normalised positions `[n, 3]` of `positions`.
fn position_tensor(data: &IkData, positions: &[Point3<f64>], device: &Device) -> Tensor<2> {
    Tensor::from_data(
        TensorData::new(data.position_rows(positions), [positions.len(), 3]),
        device,
    )
}

/// The mean squared error between the model's outputs and the batch's targets.
pub fn mse(model: &Mlp, batch: &Batch) -> Tensor<1> {
    let [n, d, _, _] = batch.targets[0].dims();
    (model.forward(batch.inputs.clone()) - batch.targets[0].clone().reshape([n, d]))
        .square()
        .mean()
}

/// Rows of `width` values as a training set: `inputs` `[n, in_width]`, `targets`
/// `[n, out_width, 1, 1]` (the shared loop's layout).
pub fn row_set(
    inputs: Vec<f32>,
    in_width: usize,
    targets: Vec<f32>,
    out_width: usize,
    device: &Device,
) -> TrainSet {
    let n = inputs.len() / in_width.max(1);
    TrainSet {
        inputs: Tensor::from_data(TensorData::new(inputs, [n, in_width]), device),
        targets: vec![Tensor::from_data(
            TensorData::new(targets, [n, out_width, 1, 1]),
            device,
        )],
    }
}

/// Train `model` on `set` with `loss` for `cfg.epochs` epochs, continuing from the optimiser
/// state `optim`, returned with the model.
pub fn fit_set(
    model: Mlp,
    optim: ModuleOptimizer,
    set: &TrainSet,
    cfg: &FitConfig,
    label: &str,
    loss: impl Fn(&Mlp, &Batch) -> Tensor<1>,
) -> Result<(Mlp, ModuleOptimizer)> {
    let train_cfg = cfg.train_config(set.len());
    let (model, optim, _) = Trainer::new(&train_cfg, label)
        .optimizer(optim)
        .run(model, set, loss)?;
    Ok((model, optim))
}

/// Train `model` to map `positions` to `joints` (radians), normalised, by mean squared error.
// The training's nouns (model, optimiser, data and its pairs, settings, label, device), each
// named at its callers; `fit_set` is the same on a prepared set.
#[allow(clippy::too_many_arguments)]
pub fn fit(
    model: Mlp,
    optim: ModuleOptimizer,
    data: &IkData,
    positions: &[Point3<f64>],
    joints: &[Vec<f64>],
    cfg: &FitConfig,
    label: &str,
    device: &Device,
) -> Result<(Mlp, ModuleOptimizer)> {
    let set = joint_set(data, positions, joints, model.joint_output(), device);
    fit_set(model, optim, &set, cfg, label, mse)
}

/// (position -> joints under `output`) pairs as a training set.
pub fn joint_set(
    data: &IkData,
    positions: &[Point3<f64>],
    joints: &[Vec<f64>],
    output: JointOutput,
    device: &Device,
) -> TrainSet {
    let dof = joints.first().map_or(0, Vec::len);
    row_set(
        data.position_rows(positions),
        3,
        data.joint_rows_as(joints, output),
        output.width(dof),
        device,
    )
}

/// Train `model` on `set` with `loss` until the validation error (`validate`, called with
/// the inference model) stops improving, from a fresh optimiser.
pub fn fit_converged(
    model: Mlp,
    set: &TrainSet,
    cfg: &FitConfig,
    conv: &Convergence,
    label: &str,
    loss: impl Fn(&Mlp, &Batch) -> Tensor<1>,
    mut validate: impl FnMut(&Mlp) -> f64,
) -> Result<(Mlp, ConvergenceLog)> {
    train_to_convergence(
        model,
        crate::train::adam::adam(),
        set,
        &cfg.train_config(set.len()),
        conv,
        label,
        loss,
        |m: &Mlp| validate(&m.valid()),
        cfg.checkpoint_for(label).as_ref(),
    )
}

/// Mean distance (cm) between the validation targets and where the model's answers take the
/// arm: what every inverse model stops on.
pub fn validation_cm(
    model: &Mlp,
    chain: &KinematicChain,
    data: &IkData,
    batch: usize,
    device: &Device,
) -> f64 {
    let targets = &data.positions[data.validation()];
    let joints = predict(model, data, targets, batch, device);
    DistanceErrors::from_metres(&reach_errors(chain, targets, &joints)).mean_cm
}

/// Joints (radians) the model answers for `positions`, in batches of `batch`.
pub fn predict(
    model: &Mlp,
    data: &IkData,
    positions: &[Point3<f64>],
    batch: usize,
    device: &Device,
) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(positions.len());
    for part in positions.chunks(batch.max(1)) {
        let output = model.joint_output();
        let q = model.forward(position_tensor(data, part, device));
        let [_, width] = q.dims();
        let v = q.into_data().try_into_vec::<f32>().expect("float");
        out.extend(v.chunks(width).map(|r| data.decode_joints(r, output)));
    }
    out
}

/// Distance errors of `model` on the test targets.
pub fn test_errors(
    model: &Mlp,
    chain: &KinematicChain,
    data: &IkData,
    batch: usize,
    device: &Device,
) -> (DistanceErrors, Vec<Vec<f64>>) {
    let targets = &data.positions[data.test()];
    let joints = predict(model, data, targets, batch, device);
    (
        DistanceErrors::from_metres(&reach_errors(chain, targets, &joints)),
        joints,
    )
}
