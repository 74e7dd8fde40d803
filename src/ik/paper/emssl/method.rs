//! EMSSL as a Table II method.

use crate::core::error::Result;
use crate::ik::learning::{FitConfig, predict};
use crate::ik::mlp::InverseModelConfig;

use super::{EmsslConfig, emssl};

/// EMSSL as a Table II method: checkpointed in the task's files (a killed run continues), its
/// answers kept for the refinement that starts from them.
pub struct EmsslMethod {
    pub name: String,
    pub model: InverseModelConfig,
    pub fit: FitConfig,
    pub emssl: EmsslConfig,
}

impl crate::ik::paper::method::IkMethod for EmsslMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::paper::method::settings_json(&(&self.model, &self.fit, &self.emssl))
    }

    fn required(&self, task: &crate::ik::paper::method::IkTask) -> Vec<std::path::PathBuf> {
        vec![task.predictions_path(&self.name)]
    }

    fn run(
        &self,
        task: &crate::ik::paper::method::IkTask,
    ) -> Result<crate::ik::paper::method::MethodOutput> {
        use crate::ik::paper::method::{Answers, MethodOutput, ValidationRow, timed};
        let t = std::time::Instant::now();
        let checkpoint = task.file(&format!("{} checkpoint", self.name), "");
        let (model, curve) = emssl(
            task.chain,
            task.data,
            &self.model,
            &self.fit,
            &self.emssl,
            task.device,
            Some(&checkpoint),
        )?;
        let train_s = t.elapsed().as_secs_f64();
        let best = curve
            .iter()
            .min_by(|a, b| a.selection_cm().total_cmp(&b.selection_cm()))
            .ok_or_else(|| crate::Error::Training("EMSSL ran no iteration".into()))?;
        let mut joints = Vec::new();
        let solve_s = timed(&mut || {
            joints = predict(&model, task.data, task.targets, task.batch, task.device)
        });
        let mut a = Answers::new(&self.name, joints, train_s, solve_s);
        a.epochs = Some(curve.len());
        a.validation_cm = best.validation_reach_cm;
        a.detail = format!(
            "{} iterations run, the model of iteration {} kept (lowest reach error on the {} goals)",
            curve.len(),
            best.iteration,
            if best.validation_reach_cm.is_some() {
                "validation"
            } else {
                "training"
            }
        );
        let curves = curve
            .iter()
            .map(|c| ValidationRow {
                range_deg: task.range_deg,
                method: self.name.clone(),
                epoch: c.iteration,
                learning_rate: c.learning_rate,
                train_loss: c.train_reach_cm,
                validation_cm: c.selection_cm(),
                seconds: 0.0,
            })
            .collect();
        Ok(MethodOutput {
            answers: vec![a],
            curves,
            emssl_curve: curve,
        })
    }
}
