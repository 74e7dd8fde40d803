//! Answering targets: the flow's samples refined by Levenberg-Marquardt, and what a batch of
//! answers amounts to.

use burn::tensor::Device;

use crate::core::error::{Error, Result};
use crate::core::spread::Spread;
use crate::ik::flow::{Draws, sample_rows, sample_rows_from};
use crate::ik::solve::levenberg_marquardt::{
    Answering, Avoid, LmConfig, PoseSolution, PoseTarget, solve,
};
use crate::ik::solve::solver::IkSolver;
use crate::sim::kinematics::KinematicChain;

use super::LearnedIk;
use super::conditions::condition_rows;

/// The flow samples this many rows a batch (a block of targets between Ctrl-C checks).
const FLOW_BATCH: usize = 1024;

impl LearnedIk {
    /// How it answers unless told otherwise: its own Levenberg-Marquardt settings (the saved
    /// config's), stopped by Ctrl-C ([`crate::core::interrupt`]), nothing avoided.
    pub fn answering(&self) -> Answering<'_> {
        Answering::with(&self.saved.config.lm)
    }
}

impl IkSolver for LearnedIk {
    /// `k` answers per target: the flow's `k` samples, each refined by Levenberg-Marquardt
    /// (from random starts where it stalls), in target order, on the device it was loaded or
    /// trained on, answered as `how` says ([`LearnedIk::answering`]: its own): with its solver settings (a budget of random
    /// starts, tolerances), asking `how.stop` on the calling thread before each block of
    /// targets (a few thousand answers, well under a second: `true` ends it with
    /// [`Error::Interrupted`]; Python passes its own signal check), and where `how.avoid` is
    /// given (a collision check) counting an answer only where it accepts it
    /// ([`crate::ik::solve::levenberg_marquardt::solve`]). The answers are those of one pass over all targets: each
    /// block samples the flow with the seeds a single pass would use.
    fn solve(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        k: usize,
        how: &Answering,
    ) -> Result<Vec<Vec<PoseSolution>>> {
        use rayon::prelude::*;
        self.check_targets(targets)?;
        let device = &self.device;
        let Answering {
            lm: cfg,
            stop,
            avoid: valid,
        } = *how;
        let k = k.max(1);
        // Targets refined between two questions to `stop`: about 256 answers, a few
        // hundredths of a second on 2 cores where a hard target takes a millisecond (1,024 took
        // over a second with the cores shared three ways). The same with a collision check:
        // a block waits for its slowest target, and the few answers pushed apart are the slow
        // ones (blocks of 32 left a core idle for most of the time they took).
        let per_check = (256 / k).max(1);
        let ranges = &self.saved.ranges;
        let paths = chain.tip_paths();
        let mut answers: Vec<Vec<PoseSolution>> = Vec::with_capacity(targets.len());
        for (b, block) in targets.chunks(FLOW_BATCH).enumerate() {
            let first = b * FLOW_BATCH;
            let rows = condition_rows(&self.data, block, self.saved.config.position_only);
            let samples = sample_rows_from(
                &self.flow,
                &self.data,
                &rows,
                Draws {
                    k,
                    batch: FLOW_BATCH,
                    seed: 0x5EED,
                },
                b,
                device,
            );
            for (c, part) in block.chunks(per_check).enumerate() {
                how.go_on(answers.len(), targets.len())?;
                let offset = c * per_check;
                // Each sample refined on its own (the family of answers, not one), from random
                // starts where it stalls; the random starts differ between samples and targets.
                let solved: Vec<Vec<PoseSolution>> = part
                    .par_iter()
                    .enumerate()
                    .map(|(j, t)| {
                        // Ctrl-C skips the block's remaining targets (the block is then
                        // thrown away below): a stop within one target's time.
                        if crate::core::interrupt::requested() {
                            return Vec::new();
                        }
                        let (i, j) = (first + offset + j, offset + j);
                        (0..k)
                            .map(|s| {
                                let start = [samples[s][j].clone()];
                                let salt = (i * k + s) as u64;
                                solve(&paths, t, &start, ranges, cfg, salt, valid)
                            })
                            .collect()
                    })
                    .collect();
                if crate::core::interrupt::requested() {
                    return Err(Error::Interrupted(format!(
                        "stopped after {} of {} targets; nothing was written",
                        answers.len(),
                        targets.len()
                    )));
                }
                answers.extend(solved);
            }
        }
        if let Some(valid) = valid {
            self.retry_refused(chain, targets, cfg, device, valid, &mut answers);
            if stop() || crate::core::interrupt::requested() {
                return Err(Error::Interrupted(format!(
                    "stopped retrying the answers that collided ({} targets); nothing was written",
                    targets.len()
                )));
            }
        }
        Ok(answers)
    }
}

impl LearnedIk {
    /// Where an answer is not exact once collisions are checked (every start it tried either
    /// missed or collided), try again from more of the flow's samples for that target: they
    /// keep to the poses it learned, where the random starts fold the robot onto itself.
    /// Only those targets pay for the extra samples. Ctrl-C ([`crate::core::interrupt`])
    /// ends it within a target; the caller then says so.
    fn retry_refused(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        cfg: &LmConfig,
        device: &Device,
        valid: &dyn Avoid,
        answers: &mut [Vec<PoseSolution>],
    ) {
        use rayon::prelude::*;
        /// Flow samples a refused answer starts again from.
        const RETRY_SAMPLES: usize = 256;
        let retry: Vec<usize> = (0..answers.len())
            .filter(|&i| answers[i].iter().any(|a| !a.exact(cfg)))
            .collect();
        if retry.is_empty() {
            return;
        }
        let sub: Vec<Vec<PoseTarget>> = retry.iter().map(|&i| targets[i].clone()).collect();
        let rows = condition_rows(&self.data, &sub, self.saved.config.position_only);
        let samples = sample_rows_from(
            &self.flow,
            &self.data,
            &rows,
            Draws {
                k: RETRY_SAMPLES,
                batch: FLOW_BATCH,
                seed: 0xC011,
            },
            0,
            device,
        );
        let only_samples = LmConfig {
            random_starts: 0,
            ..cfg.clone()
        };
        let paths = chain.tip_paths();
        let ranges = &self.saved.ranges;
        let better: Vec<Vec<(usize, PoseSolution)>> = retry
            .par_iter()
            .enumerate()
            .map(|(r, &i)| {
                if crate::core::interrupt::requested() {
                    return Vec::new();
                }
                let starts: Vec<Vec<f64>> = samples.iter().map(|s| s[r].clone()).collect();
                (answers[i].iter().enumerate())
                    .filter(|(_, a)| !a.exact(cfg))
                    .filter_map(|(s, a)| {
                        let salt = (i * answers[i].len() + s) as u64 ^ 0xC011;
                        let mut b = solve(
                            &paths,
                            &targets[i],
                            &starts,
                            ranges,
                            &only_samples,
                            salt,
                            Some(valid),
                        );
                        b.iterations += a.iterations;
                        b.starts += a.starts;
                        b.exact(cfg).then_some((s, b))
                    })
                    .collect()
            })
            .collect();
        for (&i, fixed) in retry.iter().zip(better) {
            for (s, b) in fixed {
                answers[i][s] = b;
            }
        }
    }

    /// The flow's own answers (one sample per target, no refinement).
    pub fn sample(&self, targets: &[Vec<PoseTarget>], device: &Device) -> Vec<Vec<f64>> {
        let rows = condition_rows(&self.data, targets, self.saved.config.position_only);
        sample_rows(
            &self.flow,
            &self.data,
            &rows,
            Draws {
                k: 1,
                batch: FLOW_BATCH,
                seed: 0x5EED,
            },
            device,
        )
        .pop()
        .unwrap_or_default()
    }

    /// Refuse targets this model cannot be conditioned on: one pose per tip it was trained
    /// for, each with an orientation unless the model is position-only.
    fn check_targets(&self, targets: &[Vec<PoseTarget>]) -> Result<()> {
        let tips = self.tips().len().max(1);
        if let Some((i, t)) = targets.iter().enumerate().find(|(_, t)| t.len() != tips) {
            return Err(Error::Config(format!(
                "target {i} gives {} poses; this model answers {tips} (one a tip: {})",
                t.len(),
                self.tips().join(", ")
            )));
        }
        let full = !self.saved.config.position_only;
        if let Some(i) = targets
            .iter()
            .position(|t| full && t.iter().any(|p| p.orientation.is_none()))
        {
            return Err(Error::Config(format!(
                "target {i} has no orientation, and this model answers full poses: give each tip's orientation, or train a position-only model"
            )));
        }
        Ok(())
    }

    pub fn position_only(&self) -> bool {
        self.saved.config.position_only
    }

    pub fn dof(&self) -> usize {
        self.saved.joint_names.len()
    }

    /// The tips a target row gives poses of (empty: the one tip, columns `x,y,z,...`).
    pub fn tips(&self) -> &[String] {
        &self.saved.tips
    }
}

/// What a batch of answers amounts to (one entry of `answers` per target, its k answers).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SolveStats {
    pub targets: usize,
    /// Targets with at least one exact answer (every joint is inside its limits by
    /// construction; `outside_limits` counts the answers that are not, as a check).
    pub exact_targets: usize,
    pub exact_answers: usize,
    /// Mean over targets of the distinct exact answers (more than 0.1 rad apart in a joint).
    pub distinct_mean: f64,
    /// Share of targets (%) with at least 5 distinct exact answers.
    pub distinct_5_pct: f64,
    /// Mean Levenberg-Marquardt iterations and starts per answer.
    pub iterations_mean: f64,
    pub starts_mean: f64,
    pub outside_limits: usize,
    /// The answers' pose errors, every answer (exact or not): position (mm) and rotation
    /// (degrees), the largest over the tips of each.
    pub position_mm: Spread,
    pub rotation_deg: Spread,
}

impl SolveStats {
    pub fn of(answers: &[Vec<PoseSolution>], cfg: &LmConfig, ranges: &[[f64; 2]]) -> Self {
        let (mut exact_targets, mut exact_answers, mut families, mut five) = (0, 0, 0, 0);
        let (mut iterations, mut starts, mut n, mut outside) = (0, 0, 0, 0);
        for sols in answers {
            let exact: Vec<&[f64]> = sols
                .iter()
                .filter(|a| a.exact(cfg))
                .map(|a| a.joints.as_slice())
                .collect();
            exact_answers += exact.len();
            exact_targets += usize::from(!exact.is_empty());
            let d = distinct(&exact, 0.1);
            families += d;
            five += usize::from(d >= 5);
            for a in sols {
                iterations += a.iterations;
                starts += a.starts;
                n += 1;
                outside += usize::from(!crate::sim::kinematics::within(&a.joints, ranges, 1e-12));
            }
        }
        let t = answers.len().max(1) as f64;
        SolveStats {
            targets: answers.len(),
            exact_targets,
            exact_answers,
            distinct_mean: families as f64 / t,
            distinct_5_pct: 100.0 * five as f64 / t,
            iterations_mean: iterations as f64 / n.max(1) as f64,
            starts_mean: starts as f64 / n.max(1) as f64,
            outside_limits: outside,
            position_mm: Spread::of(answers.iter().flatten().map(|a| 1e3 * a.position_error_m)),
            rotation_deg: Spread::of(
                answers
                    .iter()
                    .flatten()
                    .map(|a| a.rotation_error_rad.to_degrees()),
            ),
        }
    }

    /// Share of targets solved exactly (%).
    pub fn exact_pct(&self) -> f64 {
        100.0 * self.exact_targets as f64 / self.targets.max(1) as f64
    }

    /// The answers' precision in words: `pose error median/p98/max 0.0001/0.0002/0.0004 mm,
    /// ... degrees`.
    pub fn precision(&self) -> String {
        format!(
            "pose error median/p98/max {} mm, {} degrees",
            self.position_mm.short(2),
            self.rotation_deg.short(2)
        )
    }
}

/// Joint vectors more than `apart` (rad) apart in some joint, counted greedily.
pub fn distinct(solutions: &[&[f64]], apart: f64) -> usize {
    let mut kept: Vec<&[f64]> = Vec::new();
    for s in solutions {
        if kept
            .iter()
            .all(|k| k.iter().zip(s.iter()).any(|(a, b)| (a - b).abs() > apart))
        {
            kept.push(s);
        }
    }
    kept.len()
}
