//! Direct regression learning (DRL, EMSSL paper section IV-A): the inverse MLP fitted on the
//! random (position, joints) samples. On a redundant arm many joint vectors reach one
//! position, and the regression averages them: the average of two solutions is usually not a
//! solution. That is its known failure. [`DrlMethod`]: DRL as a Table II method.

use burn::module::Module;
use burn::tensor::Device;

use crate::core::error::Result;
use crate::ik::data::IkData;
use crate::ik::mlp::{InverseModelConfig, Mlp};
use crate::sim::kinematics::KinematicChain;

use crate::ik::learning::{FitConfig, fit, fit_converged, joint_set, mse, predict, validation_cm};
use crate::train::{convergence::ConvergenceLog, trainer::autodiff_device};

/// Direct regression learning: fit (position -> joints) on the random training data, for
/// `fit_cfg.epochs` or, with `fit_cfg.converge`, until the validation error (distance through
/// `chain`) stops improving. Returns the model and, when it trained to convergence, its log.
pub fn drl(
    chain: &KinematicChain,
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    device: &Device,
) -> Result<(Mlp, Option<ConvergenceLog>)> {
    let tdev = autodiff_device(device, fit_cfg.seed);
    let model = model_cfg.init(&tdev, fit_cfg.seed)?;
    let train = data.train();
    let (positions, joints) = (&data.positions[train.clone()], &data.joints[train]);
    if let Some(conv) = &fit_cfg.converge {
        let set = joint_set(data, positions, joints, model.joint_output(), &tdev);
        let (model, log) = fit_converged(model, &set, fit_cfg, conv, "DRL", mse, |m| {
            validation_cm(m, chain, data, fit_cfg.inference_batch, device)
        })?;
        return Ok((model.valid(), Some(log)));
    }
    let (model, _) = fit(
        model,
        crate::train::adam::adam(),
        data,
        positions,
        joints,
        fit_cfg,
        "DRL",
        &tdev,
    )?;
    Ok((model.valid(), None))
}

/// Direct regression (DRL) as a Table II method: `fit` (its epochs, or to convergence).
pub struct DrlMethod {
    pub name: String,
    pub model: InverseModelConfig,
    pub fit: FitConfig,
    /// The fixed schedule's epochs, reported where it does not train to convergence.
    pub fixed_epochs: usize,
}

impl crate::ik::paper::method::IkMethod for DrlMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::paper::method::settings_json(&(&self.model, &self.fit))
    }

    fn run(
        &self,
        task: &crate::ik::paper::method::IkTask,
    ) -> Result<crate::ik::paper::method::MethodOutput> {
        use crate::ik::paper::method::{Answers, MethodOutput, ValidationRow, timed};
        let t = std::time::Instant::now();
        let fit = task.checkpointed(&self.name, self.settings(), &self.fit);
        let (model, log) = drl(task.chain, task.data, &self.model, &fit, task.device)?;
        let train_s = t.elapsed().as_secs_f64();
        let mut joints = Vec::new();
        let solve_s = timed(&mut || {
            joints = predict(&model, task.data, task.targets, task.batch, task.device)
        });
        Ok(MethodOutput {
            answers: vec![
                Answers::new(&self.name, joints, train_s, solve_s)
                    .converged(&log, self.fixed_epochs),
            ],
            curves: log
                .iter()
                .flat_map(|l| ValidationRow::from_log(task.range_deg, &self.name, l))
                .collect(),
            emssl_curve: Vec::new(),
        })
    }
}
