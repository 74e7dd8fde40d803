//! Distal supervised learning (DSL; Jordan and Rumelhart 1992), a baseline of the EMSSL paper
//! (section IV-A): first learn a forward model network (normalised joints -> normalised
//! position) on the random data, then train the inverse model through it, frozen, by
//! minimising the distance between the learned forward model's output and the desired
//! position. Its accuracy is bounded by the forward model's: the inverse model learns to
//! satisfy the network, not the arm.

use burn::module::Module;
use burn::optim::AdamConfig;
use burn::tensor::Device;

use crate::error::Result;
use crate::ik_data::IkData;
use crate::inverse_learning::{FitConfig, fit_set, mse, row_set};
use crate::inverse_model::{InverseModelConfig, Mlp};
use crate::training::autodiff_device;

/// The forward model network and how long each phase trains.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DistalConfig {
    /// Hidden widths of the forward model (dof -> hidden -> 3, linear output).
    pub forward_hidden: Vec<usize>,
    pub forward_epochs: usize,
    pub inverse_epochs: usize,
}

/// What DSL learned.
pub struct DistalModels {
    pub inverse: Mlp,
    pub forward: Mlp,
    /// Mean distance (cm) between the forward model's prediction and the true position on the
    /// test joints.
    pub forward_test_cm: f64,
}

/// Learn the forward model, then the inverse model through it.
pub fn dsl(
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    cfg: &DistalConfig,
    device: &Device,
) -> Result<DistalModels> {
    let tdev = autodiff_device(device, fit_cfg.seed);
    let dof = data.joints[0].len();
    let train = data.train();
    let positions = data.position_rows(&data.positions[train.clone()]);
    // Phase 1: the forward model on (joints -> position) of the random data.
    let forward_cfg = InverseModelConfig {
        inputs: dof,
        hidden: cfg.forward_hidden.clone(),
        outputs: 3,
        sigmoid_output: false,
    };
    let set = row_set(
        data.joint_rows(&data.joints[train]),
        dof,
        positions.clone(),
        3,
        &tdev,
    );
    let (forward, _) = fit_set(
        forward_cfg.init(&tdev, fit_cfg.seed ^ 0xF0)?,
        AdamConfig::new().init(),
        &set,
        &FitConfig {
            epochs: cfg.forward_epochs,
            ..fit_cfg.clone()
        },
        "DSL forward model",
        mse,
    )?;
    let forward_test_cm = forward_test_error(&forward.valid(), data, device);
    // Phase 2: the inverse model through the frozen forward model: inputs and targets are the
    // desired positions.
    let frozen = forward.no_grad();
    let set = row_set(positions.clone(), 3, positions, 3, &tdev);
    let (inverse, _) = fit_set(
        model_cfg.init(&tdev, fit_cfg.seed)?,
        AdamConfig::new().init(),
        &set,
        &FitConfig {
            epochs: cfg.inverse_epochs,
            ..fit_cfg.clone()
        },
        "DSL inverse model",
        |m: &Mlp, b| {
            let [n, d, _, _] = b.targets[0].dims();
            (frozen.forward(m.forward(b.inputs.clone())) - b.targets[0].clone().reshape([n, d]))
                .square()
                .mean()
        },
    )?;
    Ok(DistalModels {
        inverse: inverse.valid(),
        forward: frozen.valid(),
        forward_test_cm,
    })
}

/// Mean distance (cm) between the forward model's predictions for the test joints and their
/// true positions.
fn forward_test_error(forward: &Mlp, data: &IkData, device: &Device) -> f64 {
    use burn::tensor::{Tensor, TensorData};
    let test = data.test();
    let dof = data.joints[0].len();
    let joints = data.joint_rows(&data.joints[test.clone()]);
    let n = test.len();
    let out = forward
        .forward(Tensor::from_data(TensorData::new(joints, [n, dof]), device))
        .into_data()
        .try_into_vec::<f32>()
        .expect("float");
    let total: f64 = data.positions[test]
        .iter()
        .zip(out.chunks(3))
        .map(|(p, v)| (data.position_from_normalised(v) - p).norm())
        .sum();
    100.0 * total / n.max(1) as f64
}
