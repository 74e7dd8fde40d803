//! Damped least squares from the home pose (every joint 0) as a Table II method: the
//! numerical solver a roboticist would reach for, beside the learned ones.

use crate::ik::solve::damped_least_squares::{DlsConfig, solve_batch, solver_detail};

/// DLS from the home pose (all joints 0) as a Table II method.
pub struct DlsFromHome {
    pub cfg: DlsConfig,
}

impl crate::ik::paper::method::IkMethod for DlsFromHome {
    fn name(&self) -> String {
        "DLS from home".into()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::paper::method::settings_json(&self.cfg)
    }

    fn run(
        &self,
        task: &crate::ik::paper::method::IkTask,
    ) -> crate::Result<crate::ik::paper::method::MethodOutput> {
        use crate::ik::paper::method::{Answers, MethodOutput, timed};
        let dof = task.chain.dof();
        let ranges = task.data.ranges.clone();
        let home = vec![vec![0.0; dof]; task.targets.len()];
        let mut solutions = Vec::new();
        let s = timed(&mut || {
            solutions = solve_batch(task.chain, task.targets, &home, &ranges, &self.cfg)
        });
        let mut a = Answers::new("DLS from home", Vec::new(), 0.0, s);
        a.detail = solver_detail(&solutions, &self.cfg, None);
        a.joints = solutions.into_iter().map(|x| x.joints).collect();
        Ok(MethodOutput {
            answers: vec![a],
            ..Default::default()
        })
    }
}
