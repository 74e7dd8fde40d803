//! Learning the inverse kinematic model (EMSSL paper sections III-A and IV-A): direct
//! regression (DRL) and embodied self-supervised learning (EMSSL, Algorithm 1), both training
//! the MLP of [`crate::inverse_model`] through the shared training loop.
//!
//! - DRL fits (position -> joints) on the random data. On a redundant arm many joint vectors
//!   reach one position, and the regression averages them: the average of two solutions is
//!   usually not a solution. That is its known failure.
//! - EMSSL never sees the random joints. Each iteration infers joints for every desired
//!   position in one batched pass, asks the forward model where the arm really goes, and trains
//!   the model to map those reached positions back to the joints that produced them: data it
//!   generated itself, always consistent (one joint vector per reached position). It stops when
//!   its answers for a desired position and for the position it actually reached agree (mean
//!   absolute difference of the normalised joints below `agreement`), or after
//!   `max_iterations`. The forward model is only called, never differentiated.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Point3;

use crate::error::Result;
use crate::ik_data::{DistanceErrors, IkData, reach_errors};
use crate::inverse_model::{InverseModelConfig, Mlp};
use crate::kinematics::KinematicChain;
use crate::training::{TrainConfig, TrainSet, autodiff_device, train};

/// Optimisation of one fit.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitConfig {
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    pub inference_batch: usize,
    pub seed: u64,
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
        }
    }
}

/// Normalised positions `[n, 3]` of `positions`.
fn position_tensor(data: &IkData, positions: &[Point3<f64>], device: &Device) -> Tensor<2> {
    let v: Vec<f32> = positions
        .iter()
        .flat_map(|p| data.normalise_position(p))
        .collect();
    Tensor::from_data(TensorData::new(v, [positions.len(), 3]), device)
}

/// Train `model` to map `positions` to `joints` (radians) for `cfg.epochs` epochs.
pub fn fit(
    model: Mlp,
    data: &IkData,
    positions: &[Point3<f64>],
    joints: &[Vec<f64>],
    cfg: &FitConfig,
    label: &str,
    device: &Device,
) -> Result<Mlp> {
    let n = positions.len();
    let dof = joints.first().map_or(0, Vec::len);
    let targets: Vec<f32> = joints
        .iter()
        .flat_map(|q| data.normalise_joints(q))
        .collect();
    let set = TrainSet {
        inputs: position_tensor(data, positions, device),
        targets: vec![Tensor::from_data(
            TensorData::new(targets, [n, dof, 1, 1]),
            device,
        )],
    };
    let train_cfg = TrainConfig {
        steps: TrainConfig::steps_for_epochs(cfg.epochs, n, cfg.batch),
        batch: cfg.batch,
        learning_rate: cfg.learning_rate,
        grad_clip_norm: None,
        input_noise: 0.0,
        seed: cfg.seed,
        checkpoint_every: 0,
    };
    let (model, _) = train(model, &set, &train_cfg, None, label, |m: &Mlp, b| {
        let [bn, d, _, _] = b.targets[0].dims();
        (m.forward(b.inputs.clone()) - b.targets[0].clone().reshape([bn, d]))
            .square()
            .mean()
    })?;
    Ok(model)
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
        let q = model.forward(position_tensor(data, part, device));
        let [n, dof] = q.dims();
        let v = q.into_data().try_into_vec::<f32>().expect("float");
        for i in 0..n {
            out.push(data.joints_from_normalised(&v[i * dof..(i + 1) * dof]));
        }
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

/// Direct regression learning: fit (position -> joints) on the random training data.
pub fn drl(
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    device: &Device,
) -> Result<Mlp> {
    let tdev = autodiff_device(device, fit_cfg.seed);
    let model = model_cfg.init(&tdev, fit_cfg.seed)?;
    let train = data.train();
    let model = fit(
        model,
        data,
        &data.positions[train.clone()],
        &data.joints[train],
        fit_cfg,
        "DRL",
        &tdev,
    )?;
    Ok(model.valid())
}

/// EMSSL's stopping rule and iteration cap.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EmsslConfig {
    pub max_iterations: usize,
    /// Stop when the mean absolute difference of the normalised joints answered for the
    /// desired positions and for the positions reached falls below this.
    pub agreement: f64,
}

/// One EMSSL iteration, for the learning curve (Figure 6).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct EmsslIteration {
    pub iteration: usize,
    pub test_mean_cm: f64,
    pub test_median_cm: f64,
    /// Mean distance (cm) between the desired training positions and those reached.
    pub train_reach_cm: f64,
    /// Mean absolute difference of the normalised joints for desired and reached positions.
    pub disagreement: f64,
    pub seconds: f64,
}

/// Embodied self-supervised learning (Algorithm 1) of an inverse model of `chain`, the forward
/// model, on the desired training positions of `data`.
pub fn emssl(
    chain: &KinematicChain,
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    cfg: &EmsslConfig,
    device: &Device,
) -> Result<(Mlp, Vec<EmsslIteration>)> {
    let tdev = autodiff_device(device, fit_cfg.seed);
    let mut model = model_cfg.init(&tdev, fit_cfg.seed)?;
    let desired = &data.positions[data.train()];
    let mut curve = Vec::new();
    // The answers for the desired positions: the first sampling pass, and after each
    // iteration both its agreement check and the next iteration's sampling.
    let mut joints = predict(
        &model.valid(),
        data,
        desired,
        fit_cfg.inference_batch,
        device,
    );
    for iteration in 1..=cfg.max_iterations {
        let t0 = std::time::Instant::now();
        // Sampling: the batched inference above, then the forward model.
        let reached = chain.end_effector_batch(&joints);
        // Training on the self-generated pairs (reached -> joints).
        let fit_iter = FitConfig {
            seed: fit_cfg.seed.wrapping_add(iteration as u64),
            ..fit_cfg.clone()
        };
        model = fit(
            model,
            data,
            &reached,
            &joints,
            &fit_iter,
            &format!("EMSSL iteration {iteration}"),
            &tdev,
        )?;
        let valid = model.valid();
        let (test, _) = test_errors(&valid, chain, data, fit_cfg.inference_batch, device);
        // Agreement of the answers for desired and reached positions.
        let a = predict(&valid, data, desired, fit_cfg.inference_batch, device);
        let b = predict(&valid, data, &reached, fit_cfg.inference_batch, device);
        joints = a.clone();
        let span = data.range[1] - data.range[0];
        let disagreement = a
            .iter()
            .zip(&b)
            .flat_map(|(x, y)| x.iter().zip(y).map(|(u, v)| (u - v).abs() / span))
            .sum::<f64>()
            / (a.len() * a.first().map_or(1, Vec::len)).max(1) as f64;
        let train_reach_cm = 100.0
            * desired
                .iter()
                .zip(&reached)
                .map(|(d, r)| (d - r).norm())
                .sum::<f64>()
            / desired.len().max(1) as f64;
        curve.push(EmsslIteration {
            iteration,
            test_mean_cm: test.mean_cm,
            test_median_cm: test.median_cm,
            train_reach_cm,
            disagreement,
            seconds: t0.elapsed().as_secs_f64(),
        });
        if disagreement < cfg.agreement {
            break;
        }
    }
    Ok((model.valid(), curve))
}
