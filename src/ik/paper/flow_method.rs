//! The flow ([`crate::ik::flow`]) as a Table II method: one sample and the best of
//! `best_of`, its trained model kept for EMSSL + DLS's restarts.

use crate::core::error::{Error, Result};
use crate::ik::flow::{Draws, FlowConfig, best_of, diversity, sample, train_flow};

/// The flow as a Table II method: one sample and the best of `cfg.best_of`; its model is kept
/// in the task's files (`flow_model.bpk`) for the restarts of EMSSL + DLS.
pub struct FlowMethod {
    pub cfg: FlowConfig,
}

impl FlowMethod {
    /// Where the trained flow is kept.
    pub fn model_file(task: &crate::ik::paper::method::IkTask) -> std::path::PathBuf {
        task.file("flow_model", "bpk")
    }
}

impl crate::ik::paper::method::IkMethod for FlowMethod {
    fn name(&self) -> String {
        "Flow IK".into()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::paper::method::settings_json(&self.cfg)
    }

    fn required(&self, task: &crate::ik::paper::method::IkTask) -> Vec<std::path::PathBuf> {
        vec![Self::model_file(task)]
    }

    fn run(
        &self,
        task: &crate::ik::paper::method::IkTask,
    ) -> Result<crate::ik::paper::method::MethodOutput> {
        use crate::ik::paper::method::{Answers, MethodOutput, ValidationRow, timed};
        let cfg = &self.cfg;
        let t = std::time::Instant::now();
        let cfg = &FlowConfig {
            fit: task.checkpointed(&self.name(), self.settings(), &cfg.fit),
            ..cfg.clone()
        };
        let trained = train_flow(task.chain, task.data, cfg, task.device)?;
        // Counting the seconds before a restart from the checkpoint.
        let train_s = t
            .elapsed()
            .as_secs_f64()
            .max(trained.log.as_ref().map_or(0.0, |l| l.seconds));
        let file = Self::model_file(task);
        if let Some(parent) = file.parent() {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        crate::train::checkpoint::save_module(&trained.model, &file)?;
        let seed = cfg.fit.seed ^ 0x5EED;
        let draw = |k: usize| {
            sample(
                &trained.model,
                task.data,
                task.targets,
                Draws {
                    k,
                    batch: task.batch,
                    seed,
                },
                task.device,
            )
        };
        let k = cfg.best_of;
        let mut one = Vec::new();
        let solve_1 = timed(&mut || one = draw(1));
        let mut samples = Vec::new();
        let solve_k = timed(&mut || samples = draw(k));
        let t = std::time::Instant::now();
        let best = best_of(task.chain, task.targets, &samples);
        let pick_s = t.elapsed().as_secs_f64();
        let one = Answers::new("Flow IK", one.pop().expect("one sample"), train_s, solve_1)
            .converged(&trained.log, cfg.fit.epochs);
        let mut best = Answers::new(
            &format!("Flow IK best of {k}"),
            best,
            train_s,
            solve_k + pick_s,
        );
        best.diversity_rad = Some(diversity(&samples));
        best.detail = format!("the sample of {k} the forward model puts closest");
        Ok(MethodOutput {
            answers: vec![one, best],
            curves: trained
                .log
                .iter()
                .flat_map(|l| ValidationRow::from_log(task.range_deg, "Flow IK", l))
                .collect(),
            emssl_curve: Vec::new(),
        })
    }
}
