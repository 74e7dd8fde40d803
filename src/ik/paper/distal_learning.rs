//! Distal supervised learning (DSL; Jordan and Rumelhart 1992), a baseline of the EMSSL paper
//! (section IV-A): first learn a forward model network (normalised joints -> normalised
//! position) on the random data, then train the inverse model through it, frozen, by
//! minimising the distance between the learned forward model's output and the desired
//! position. Its accuracy is bounded by the forward model's: the inverse model learns to
//! satisfy the network, not the arm.
//!
//! With the fit's `converge` set, each phase trains until its validation error stops
//! improving: the forward model's distance error on the validation joints, then the inverse
//! model's distance error on the validation targets through the arm. Under the wrapped joint
//! output the forward model reads (cos, sin) per joint, which the inverse model writes.

use burn::module::Module;
use burn::tensor::Device;

use crate::core::error::Result;
use crate::ik::data::IkData;
use crate::ik::learning::{FitConfig, fit_converged, fit_set, mse, row_set, validation_cm};
use crate::ik::mlp::{InverseModelConfig, Mlp};
use crate::sim::kinematics::KinematicChain;
use crate::train::{batcher::Batch, convergence::ConvergenceLog, trainer::autodiff_device};

/// The forward model network and how long each phase trains.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DistalConfig {
    /// Hidden widths of the forward model (dof -> hidden -> 3, linear output).
    pub forward_hidden: Vec<usize>,
    pub forward_epochs: usize,
    pub inverse_epochs: usize,
    /// What the inverse model is trained through (absent in settings: the learned model).
    #[serde(default, skip_serializing_if = "DistalForward::is_learned")]
    pub forward: DistalForward,
    /// The inverse phase takes this many optimiser steps (rounded up to whole epochs; the best
    /// on the validation split kept, the rate cut on plateaus), whatever `converge` would
    /// stop at: a budget matched to another method's. `None`: `converge` or the fixed epochs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inverse_steps: Option<usize>,
}

impl DistalConfig {
    /// The inverse phase's fit over `samples` pairs: `fit_cfg`, or the matched budget.
    fn inverse_fit(&self, fit_cfg: &FitConfig, samples: usize) -> FitConfig {
        match self.inverse_steps {
            Some(steps) => FitConfig {
                converge: Some(crate::train::convergence::Convergence {
                    max_epochs: steps.div_ceil(samples.div_ceil(fit_cfg.batch).max(1)),
                    patience: usize::MAX,
                    ..fit_cfg
                        .converge
                        .clone()
                        .unwrap_or_else(crate::train::convergence::Convergence::standard)
                }),
                ..fit_cfg.clone()
            },
            None => fit_cfg.clone(),
        }
    }
}

/// The forward model DSL's inverse model learns through.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DistalForward {
    /// A network fit to the random data first (Jordan and Rumelhart; the paper's DSL).
    #[default]
    Learned,
    /// The arm's exact forward kinematics, differentiated in tensors
    /// ([`crate::sim::tensor_kinematics::TensorChain`]): DSL's ceiling, where the forward
    /// model makes no error (beyond the paper; sigmoid output only).
    Exact,
}

impl DistalForward {
    fn is_learned(&self) -> bool {
        *self == DistalForward::Learned
    }
}

/// What DSL learned.
pub struct DistalModels {
    pub inverse: Mlp,
    /// The learned forward model (`None` through the exact forward kinematics).
    pub forward: Option<Mlp>,
    /// Mean distance (cm) between the forward model's prediction and the true position on the
    /// test joints (0 through the exact forward kinematics).
    pub forward_test_cm: f64,
    /// The validation curves of the two phases, where they trained to convergence.
    pub forward_log: Option<ConvergenceLog>,
    pub inverse_log: Option<ConvergenceLog>,
}

/// Learn the forward model, then the inverse model (`model_cfg`, whose output decides the
/// joint encoding) through it.
pub fn dsl(
    chain: &KinematicChain,
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    cfg: &DistalConfig,
    device: &Device,
) -> Result<DistalModels> {
    let tdev = autodiff_device(device, fit_cfg.seed);
    let dof = data.joints[0].len();
    let train = data.train();
    let inverse = model_cfg.init(&tdev, fit_cfg.seed)?;
    let output = inverse.joint_output();
    let positions = data.position_rows(&data.positions[train.clone()]);
    if cfg.forward == DistalForward::Exact {
        let inverse_set = row_set(positions.clone(), 3, positions, 3, &tdev);
        let fit = cfg.inverse_fit(fit_cfg, inverse_set.len());
        let (inverse, inverse_log) =
            inverse_through_arm(chain, data, inverse, &inverse_set, &fit, cfg, &tdev, device)?;
        return Ok(DistalModels {
            inverse,
            forward: None,
            forward_test_cm: 0.0,
            forward_log: None,
            inverse_log,
        });
    }
    // Phase 1: the forward model on (joints -> position) of the random data.
    let forward_cfg = InverseModelConfig {
        inputs: output.width(dof),
        hidden: cfg.forward_hidden.clone(),
        outputs: 3,
        sigmoid_output: false,
        unit_pairs: false,
    };
    let set = row_set(
        data.joint_rows_as(&data.joints[train], output),
        output.width(dof),
        positions.clone(),
        3,
        &tdev,
    );
    let forward = forward_cfg.init(&tdev, fit_cfg.seed ^ 0xF0)?;
    let (forward, forward_log) = match &fit_cfg.converge {
        Some(conv) => {
            let (m, log) = fit_converged(
                forward,
                &set,
                fit_cfg,
                conv,
                "DSL forward model",
                mse,
                |m| forward_error_cm(m, data, data.validation(), output, device),
            )?;
            (m, Some(log))
        }
        None => {
            let (m, _) = fit_set(
                forward,
                crate::train::adam::adam(),
                &set,
                &FitConfig {
                    epochs: cfg.forward_epochs,
                    ..fit_cfg.clone()
                },
                "DSL forward model",
                mse,
            )?;
            (m, None)
        }
    };
    let forward_test_cm = forward_error_cm(&forward.valid(), data, data.test(), output, device);
    // Phase 2: the inverse model through the frozen forward model: inputs and targets are the
    // desired positions.
    let frozen = forward.no_grad();
    let set = row_set(positions.clone(), 3, positions, 3, &tdev);
    let fit_cfg = &cfg.inverse_fit(fit_cfg, set.len());
    let through_forward = |m: &Mlp, b: &Batch| {
        let [n, d, _, _] = b.targets[0].dims();
        (frozen.forward(m.forward(b.inputs.clone())) - b.targets[0].clone().reshape([n, d]))
            .square()
            .mean()
    };
    let (inverse, inverse_log) = match &fit_cfg.converge {
        Some(conv) => {
            let (m, log) = fit_converged(
                inverse,
                &set,
                fit_cfg,
                conv,
                "DSL inverse model",
                through_forward,
                |m| validation_cm(m, chain, data, fit_cfg.inference_batch, device),
            )?;
            (m, Some(log))
        }
        None => {
            let (m, _) = fit_set(
                inverse,
                crate::train::adam::adam(),
                &set,
                &FitConfig {
                    epochs: cfg.inverse_epochs,
                    ..fit_cfg.clone()
                },
                "DSL inverse model",
                through_forward,
            )?;
            (m, None)
        }
    };
    Ok(DistalModels {
        inverse: inverse.valid(),
        forward: Some(frozen.valid()),
        forward_test_cm,
        forward_log,
        inverse_log,
    })
}

/// The inverse model trained through the arm's exact forward kinematics: its sigmoid outputs
/// mapped onto the joint ranges, the chain's differentiable forward kinematics, the position
/// normalised as the targets are; the loss is DSL's (squared distance in normalised position).
// Two devices (the training device with autodiff and the inference one) and the run's
// settings, each named at its one caller.
#[allow(clippy::too_many_arguments)]
fn inverse_through_arm(
    chain: &KinematicChain,
    data: &IkData,
    inverse: Mlp,
    set: &crate::train::batcher::TrainSet,
    fit_cfg: &FitConfig,
    cfg: &DistalConfig,
    tdev: &Device,
    device: &Device,
) -> Result<(Mlp, Option<ConvergenceLog>)> {
    use burn::tensor::{Tensor, TensorData};
    if inverse.joint_output() != crate::ik::data::JointOutput::Sigmoid {
        return Err(crate::Error::Config(
            "DSL through the exact forward kinematics takes the sigmoid joint output only".into(),
        ));
    }
    let arm = crate::sim::tensor_kinematics::TensorChain::new(chain);
    let row = |v: Vec<f32>| {
        let n = v.len();
        Tensor::<2>::from_data(TensorData::new(v, [1, n]), tdev)
    };
    let dof = data.ranges.len();
    let q_lo = row(data.ranges.iter().map(|r| r[0] as f32).collect());
    let q_span = row(data.ranges.iter().map(|r| (r[1] - r[0]) as f32).collect());
    let [p_lo, p_hi] = data.position_bounds;
    let p_lo_t = row(p_lo.iter().map(|&v| v as f32).collect());
    let p_span = row((0..3)
        .map(|k| (p_hi[k] - p_lo[k]).max(1e-9) as f32)
        .collect());
    let (r, t, tip) = arm.origin_rows();
    let joints = arm.joint_count();
    let origin_r = Tensor::<3>::from_data(TensorData::new(r, [joints, 3, 3]), tdev);
    let origin_t = Tensor::<2>::from_data(TensorData::new(t, [joints, 3]), tdev);
    let tip = row(tip.to_vec());
    let through_arm = |m: &Mlp, b: &Batch| {
        let [n, d, _, _] = b.targets[0].dims();
        let u = m.forward(b.inputs.clone());
        let q = u * q_span.clone().repeat_dim(0, n) + q_lo.clone().repeat_dim(0, n);
        debug_assert_eq!(q.dims()[1], dof);
        let p = arm.end_effector_with(q, origin_r.clone(), origin_t.clone(), tip.clone());
        let p = (p - p_lo_t.clone().repeat_dim(0, n)) / p_span.clone().repeat_dim(0, n);
        (p - b.targets[0].clone().reshape([n, d])).square().mean()
    };
    match &fit_cfg.converge {
        Some(conv) => {
            let (m, log) = fit_converged(
                inverse,
                set,
                fit_cfg,
                conv,
                "DSL inverse model (exact forward)",
                through_arm,
                |m| validation_cm(m, chain, data, fit_cfg.inference_batch, device),
            )?;
            Ok((m.valid(), Some(log)))
        }
        None => {
            let (m, _) = fit_set(
                inverse,
                crate::train::adam::adam(),
                set,
                &FitConfig {
                    epochs: cfg.inverse_epochs,
                    ..fit_cfg.clone()
                },
                "DSL inverse model (exact forward)",
                through_arm,
            )?;
            Ok((m.valid(), None))
        }
    }
}

/// Mean distance (cm) between the forward model's predictions for the joints of the samples
/// `range` (written under `output`) and their true positions.
fn forward_error_cm(
    forward: &Mlp,
    data: &IkData,
    range: std::ops::Range<usize>,
    output: crate::ik::data::JointOutput,
    device: &Device,
) -> f64 {
    use burn::tensor::{Tensor, TensorData};
    let test = range;
    let width = output.width(data.joints[0].len());
    let joints = data.joint_rows_as(&data.joints[test.clone()], output);
    let n = test.len();
    let out = forward
        .forward(Tensor::from_data(
            TensorData::new(joints, [n, width]),
            device,
        ))
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

/// Distal supervised learning as a Table II method.
pub struct DslMethod {
    pub name: String,
    pub model: InverseModelConfig,
    pub fit: FitConfig,
    pub dsl: DistalConfig,
}

impl crate::ik::paper::method::IkMethod for DslMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::paper::method::settings_json(&(&self.model, &self.fit, &self.dsl))
    }

    fn run(
        &self,
        task: &crate::ik::paper::method::IkTask,
    ) -> Result<crate::ik::paper::method::MethodOutput> {
        use crate::ik::paper::method::{Answers, MethodOutput, ValidationRow, timed};
        let t = std::time::Instant::now();
        let fit = task.checkpointed(&self.name, self.settings(), &self.fit);
        let distal = dsl(
            task.chain,
            task.data,
            &self.model,
            &fit,
            &self.dsl,
            task.device,
        )?;
        // Counting the seconds before a restart from the checkpoint.
        let logged: f64 = [&distal.forward_log, &distal.inverse_log]
            .iter()
            .filter_map(|l| l.as_ref().map(|l| l.seconds))
            .sum();
        let train_s = t.elapsed().as_secs_f64().max(logged);
        let mut joints = Vec::new();
        let solve_s = timed(&mut || {
            joints = crate::ik::learning::predict(
                &distal.inverse,
                task.data,
                task.targets,
                task.batch,
                task.device,
            )
        });
        let mut a = Answers::new(&self.name, joints, train_s, solve_s)
            .converged(&distal.inverse_log, self.dsl.inverse_epochs);
        a.detail = match self.dsl.forward {
            DistalForward::Exact => {
                format!(
                    "inverse: {}; through the exact forward kinematics",
                    a.detail
                )
            }
            DistalForward::Learned => format!(
                "inverse: {}; forward model: {}, test error {:.2} cm",
                a.detail,
                distal
                    .forward_log
                    .as_ref()
                    .map_or(format!("{} epochs (fixed)", self.dsl.forward_epochs), |l| l
                        .summary()),
                distal.forward_test_cm
            ),
        };
        let forward_name = self.name.replacen("DSL", "DSL forward model", 1);
        let mut curves: Vec<ValidationRow> = distal
            .forward_log
            .iter()
            .flat_map(|l| ValidationRow::from_log(task.range_deg, &forward_name, l))
            .collect();
        curves.extend(
            distal
                .inverse_log
                .iter()
                .flat_map(|l| ValidationRow::from_log(task.range_deg, &self.name, l)),
        );
        Ok(MethodOutput {
            answers: vec![a],
            curves,
            emssl_curve: Vec::new(),
        })
    }
}
