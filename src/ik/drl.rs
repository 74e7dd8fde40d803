//! Direct regression learning (DRL) as a Table II method: the inverse MLP fitted on the random
//! (position, joints) samples ([`crate::ik::learning::drl`]).

use crate::core::error::Result;
use crate::ik::learning::{FitConfig, drl, predict};
use crate::ik::mlp::InverseModelConfig;

/// Direct regression (DRL) as a Table II method: `fit` (its epochs, or to convergence).
pub struct DrlMethod {
    pub name: String,
    pub model: InverseModelConfig,
    pub fit: FitConfig,
    /// The fixed schedule's epochs, reported where it does not train to convergence.
    pub fixed_epochs: usize,
}

impl crate::ik::method::IkMethod for DrlMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::method::settings_json(&(&self.model, &self.fit))
    }

    fn run(&self, task: &crate::ik::method::IkTask) -> Result<crate::ik::method::MethodOutput> {
        use crate::ik::method::{Answers, MethodOutput, ValidationRow, timed};
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
