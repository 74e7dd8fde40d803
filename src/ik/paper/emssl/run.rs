//! One EMSSL run: exploration noise around the answers, the forward model asked where they
//! go, the model trained on those pairs, scored, stopped by its rule, then polished.

use burn::module::Module;
use burn::optim::ModuleOptimizer;
use burn::tensor::Device;
use nalgebra::Point3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use crate::core::error::{Error, Result};
use crate::ik::data::{DistanceErrors, IkData, JointOutput, distances, reach_errors};
use crate::ik::learning::{FitConfig, fit, fit_converged, joint_set, mse, predict, test_errors};
use crate::ik::mlp::Mlp;
use crate::sim::kinematics::KinematicChain;
use crate::train::{
    config::TrainConfig,
    convergence::{Convergence, Plateau},
};

use super::{
    EmsslConfig, EmsslIteration, StopRule,
    checkpoint::{EmsslCheckpoint, EmsslState},
};

/// Perturb `joints` (radians, each within its range of `ranges`) with Gaussian noise of standard deviation `sigma`
/// in normalised units (1 = the whole range), clamped to the range, or wrapped around it when
/// `wrap` (a whole-circle range under the wrapped output, where the ends are one pose).
pub(super) fn explore(
    joints: &mut [Vec<f64>],
    ranges: &[[f64; 2]],
    sigma: f64,
    seed: u64,
    wrap: bool,
) {
    if sigma <= 0.0 {
        return;
    }
    let noise = Normal::new(0.0, sigma).expect("finite sigma");
    let mut rng = StdRng::seed_from_u64(seed);
    for (v, &[lo, hi]) in joints.iter_mut().flat_map(|q| q.iter_mut().zip(ranges)) {
        let u = (*v - lo) / (hi - lo) + noise.sample(&mut rng);
        let u = if wrap {
            u.rem_euclid(1.0)
        } else {
            u.clamp(0.0, 1.0)
        };
        *v = lo + u * (hi - lo);
    }
}

/// Motor babbling: `n` joint vectors drawn uniformly from `ranges` (seeded) and where
/// `forward` takes them.
pub(super) fn babble(
    forward: &KinematicChain,
    n: usize,
    ranges: &[[f64; 2]],
    seed: u64,
) -> (Vec<Point3<f64>>, Vec<Vec<f64>>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let dof = forward.dof().min(ranges.len());
    let joints: Vec<Vec<f64>> = (0..n)
        .map(|_| crate::sim::trajectory::uniform_in(&mut rng, &ranges[..dof]))
        .collect();
    (forward.end_effector_batch(&joints), joints)
}

/// Mean absolute difference of two joint sets in normalised units.
pub(super) fn disagreement(a: &[Vec<f64>], b: &[Vec<f64>], ranges: &[[f64; 2]]) -> f64 {
    let n = a.iter().map(Vec::len).sum::<usize>().max(1);
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| {
            x.iter()
                .zip(y)
                .zip(ranges)
                .map(|((u, v), r)| (u - v).abs() / (r[1] - r[0]))
        })
        .sum::<f64>()
        / n as f64
}

/// What one EMSSL run works with: the devices, the forward model and the arm it is scored
/// on, the goals, the settings, and where it keeps its state.
pub(super) struct Run<'a> {
    pub(super) tdev: &'a Device,
    pub(super) forward: &'a KinematicChain,
    pub(super) arm: &'a KinematicChain,
    pub(super) data: &'a IkData,
    pub(super) fit_cfg: &'a FitConfig,
    pub(super) cfg: &'a EmsslConfig,
    pub(super) device: &'a Device,
    pub(super) checkpoint: Option<&'a EmsslCheckpoint>,
}

/// Where a run stands between iterations.
pub(super) struct Progress {
    model: Mlp,
    optim: ModuleOptimizer,
    curve: Vec<EmsslIteration>,
    /// The kept model (by the selection error), and the same on the training device for the
    /// polishing rounds.
    best: Option<Mlp>,
    best_trainable: Option<Mlp>,
    rule: StopRule,
    plateau: Option<Plateau>,
    finished: bool,
    /// The warm start's steps, counted in the first iteration's.
    warm_steps: usize,
    /// The pairs of the last `keep_iterations` iterations.
    kept: std::collections::VecDeque<(Vec<Point3<f64>>, Vec<Vec<f64>>)>,
    /// The answers for the desired positions (the next iteration samples around them) and
    /// the seconds their inference took.
    answers: Vec<Vec<f64>>,
    inference_seconds: f64,
}

impl Run<'_> {
    fn desired(&self) -> &[Point3<f64>] {
        &self.data.positions[self.data.train()]
    }

    fn held_out(&self) -> &[Point3<f64>] {
        &self.data.positions[self.data.validation()]
    }

    fn predict(&self, model: &Mlp, positions: &[Point3<f64>]) -> Vec<Vec<f64>> {
        predict(
            model,
            self.data,
            positions,
            self.fit_cfg.inference_batch,
            self.device,
        )
    }

    /// The iterations, then the polishing rounds: the model to keep and the curve.
    pub(super) fn run(&self, model: Mlp) -> Result<(Mlp, Vec<EmsslIteration>)> {
        let mut p = self.start(model)?;
        let last_iteration = if p.finished {
            p.curve.len()
        } else {
            self.cfg.max_iterations
        };
        for iteration in p.curve.len() + 1..=last_iteration {
            let stop;
            (p, stop) = self.iteration(p, iteration)?;
            if stop {
                break;
            }
        }
        if self.cfg.polish_rounds > 0 {
            let start = p.best_trainable.unwrap_or(p.model);
            let (polished, more) = self.polish(start, &p.curve)?;
            p.curve.extend(more);
            return Ok((polished, p.curve));
        }
        let model = p.best.unwrap_or_else(|| p.model.valid());
        Ok((model, p.curve))
    }

    /// A fresh run (after its warm start of motor babbling, if any), or the checkpoint's.
    fn start(&self, model: Mlp) -> Result<Progress> {
        let (cfg, fit_cfg) = (self.cfg, self.fit_cfg);
        let mut p = Progress {
            model,
            optim: crate::train::adam::adam(),
            curve: Vec::new(),
            best: None,
            best_trainable: None,
            rule: StopRule::default(),
            plateau: cfg.lr_plateau.as_ref().map(|l| {
                Plateau::new(&Convergence {
                    max_epochs: cfg.max_iterations,
                    patience: usize::MAX,
                    lr_patience: l.patience,
                    lr_factor: l.factor,
                    min_improvement: 1e-3,
                    min_epochs: 0,
                })
            }),
            finished: false,
            warm_steps: 0,
            kept: Default::default(),
            answers: Vec::new(),
            inference_seconds: 0.0,
        };
        let resumed = self.checkpoint.and_then(|c| c.load().map(|s| (c, s)));
        let desired = self.desired();
        if cfg.warm_start_epochs > 0 && resumed.is_none() {
            p.warm_steps =
                TrainConfig::steps_for_epochs(cfg.warm_start_epochs, desired.len(), fit_cfg.batch);
            let (reached, tried) = babble(
                self.forward,
                desired.len(),
                &self.data.ranges,
                fit_cfg.seed ^ 0xBABB1E,
            );
            (p.model, p.optim) = fit(
                p.model,
                p.optim,
                self.data,
                &reached,
                &tried,
                &FitConfig {
                    epochs: cfg.warm_start_epochs,
                    ..fit_cfg.clone()
                },
                "EMSSL warm start (motor babbling)",
                self.tdev,
            )?;
        }
        if let Some((c, state)) = resumed {
            let load = |m: Mlp, file: &str| {
                m.try_load_file(c.path(file)).map_err(|e| {
                    crate::train::checkpoint::unreadable_checkpoint(&c.path(file), &c.dir, e)
                })
            };
            p.model = load(p.model.clone(), "model.bpk")?;
            p.optim = p.optim.load(c.path("optimizer.bpk")).map_err(|e| {
                crate::train::checkpoint::unreadable_checkpoint(&c.path("optimizer.bpk"), &c.dir, e)
            })?;
            if c.path("best.bpk").exists() {
                let b = load(p.model.clone(), "best.bpk")?;
                p.best = Some(b.valid());
                p.best_trainable = Some(b);
            }
            eprintln!(
                "EMSSL: continuing from iteration {} in {}",
                state.curve.len(),
                c.dir.display()
            );
            p.curve = state.curve;
            p.rule = state.rule;
            p.plateau = state.plateau;
            p.finished = state.finished;
        }
        // The answers for the desired positions: the first sampling pass, and after each
        // iteration both its agreement check and the next iteration's sampling.
        let t0 = std::time::Instant::now();
        p.answers = self.predict(&p.model.valid(), desired);
        p.inference_seconds = t0.elapsed().as_secs_f64();
        Ok(p)
    }

    /// One iteration: sample (the answers with exploration noise, through the forward
    /// model), train on the pairs, score, keep the best, checkpoint. Whether the stopping
    /// rule ends the run.
    fn iteration(&self, mut p: Progress, iteration: usize) -> Result<(Progress, bool)> {
        let (cfg, fit_cfg, data) = (self.cfg, self.fit_cfg, self.data);
        let wrap = p.model.joint_output() == JointOutput::Wrapped && data.full_circle();
        let decay = |rate: f64| rate.powi(iteration as i32 - 1);
        let sigma = (cfg.exploration * decay(cfg.exploration_decay)).max(cfg.exploration_floor);
        let learning_rate = fit_cfg.learning_rate
            * decay(cfg.learning_rate_decay)
            * p.plateau.as_ref().map_or(1.0, |l| l.scale);
        // Sampling: the batched inference (done at the end of the last iteration), the
        // exploration noise, then the forward model.
        let t0 = std::time::Instant::now();
        let mut tried = p.answers.clone();
        explore(
            &mut tried,
            &data.ranges,
            sigma,
            fit_cfg.seed ^ (iteration as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            wrap,
        );
        let reached = self.forward.end_effector_batch(&tried);
        let sampling_seconds = p.inference_seconds + t0.elapsed().as_secs_f64();
        p.kept.push_back((reached, tried));
        while p.kept.len() > cfg.keep_iterations.max(1) {
            p.kept.pop_front();
        }
        // Training on the self-generated pairs (reached -> joints tried).
        let t0 = std::time::Instant::now();
        let fit_iter = FitConfig {
            seed: fit_cfg.seed.wrapping_add(iteration as u64),
            learning_rate,
            ..fit_cfg.clone()
        };
        let (reached, tried): (Vec<Point3<f64>>, Vec<Vec<f64>>) = if p.kept.len() == 1 {
            p.kept[0].clone()
        } else {
            (
                p.kept.iter().flat_map(|k| k.0.iter().copied()).collect(),
                p.kept.iter().flat_map(|k| k.1.iter().cloned()).collect(),
            )
        };
        (p.model, p.optim) = fit(
            p.model,
            p.optim,
            data,
            &reached,
            &tried,
            &fit_iter,
            &format!("EMSSL iteration {iteration}"),
            self.tdev,
        )
        .map_err(|e| match (e, self.checkpoint) {
            // The fit inside an iteration keeps no checkpoint; the iterations do.
            (Error::Interrupted(_), Some(c)) => Error::Interrupted(format!(
                "EMSSL stopped during iteration {iteration}; its checkpoint after iteration {} \
                 is in {}: run the same command with `resume` to continue from there",
                iteration - 1,
                c.dir.display()
            )),
            (e, _) => e,
        })?;
        let training_seconds = t0.elapsed().as_secs_f64();
        let steps = TrainConfig::steps_for_epochs(fit_iter.epochs, reached.len(), fit_iter.batch)
            + std::mem::take(&mut p.warm_steps);
        let valid = p.model.valid();
        // The next sampling pass's inference, and the agreement check on it.
        let t0 = std::time::Instant::now();
        p.answers = self.predict(&valid, self.desired());
        p.inference_seconds = t0.elapsed().as_secs_f64();
        let point = EmsslIteration {
            iteration,
            exploration: sigma,
            learning_rate,
            sampling_seconds,
            training_seconds,
            forward_calls: 2 * self.desired().len() * iteration,
            steps,
            ..self.scored(&valid, &p.answers, true)
        };
        if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            eprintln!(
                "EMSSL iteration {iteration}: selection {:.4} cm, test {:.4} cm, lr {learning_rate:.2e}, noise {sigma:.4}",
                point.selection_cm(),
                point.test.mean_cm
            );
        }
        if let Some(l) = p.plateau.as_mut() {
            l.observe(point.selection_cm());
        }
        let (improved, stop) = p.rule.observe(&point, cfg);
        p.curve.push(point);
        if improved {
            p.best = Some(valid);
            if cfg.polish_rounds > 0 {
                p.best_trainable = Some(p.model.clone());
            }
        }
        if let Some(c) = self.checkpoint {
            c.save(
                &p.model,
                &p.optim,
                p.best.as_ref().filter(|_| improved),
                &EmsslState {
                    settings: c.settings.clone(),
                    curve: p.curve.clone(),
                    rule: p.rule.clone(),
                    plateau: p.plateau.clone(),
                    finished: stop,
                },
            )?;
        }
        Ok((p, stop))
    }

    /// `valid`'s scores, its `answers` for the desired positions given: the disagreement
    /// with its answers for where they reach, the reach errors on the training goals and (with
    /// `held_out_reach`) the held-out ones, and the test errors on the arm (the timing fields
    /// left zero).
    fn scored(&self, valid: &Mlp, answers: &[Vec<f64>], held_out_reach: bool) -> EmsslIteration {
        let (desired, held_out) = (self.desired(), self.held_out());
        let clean_reached = self.forward.end_effector_batch(answers);
        let back = self.predict(valid, &clean_reached);
        let validation_reach_cm = (held_out_reach && !held_out.is_empty()).then(|| {
            let q = self.predict(valid, held_out);
            DistanceErrors::from_metres(&reach_errors(self.forward, held_out, &q)).mean_cm
        });
        let batch = self.fit_cfg.inference_batch;
        let (test, _) = test_errors(valid, self.arm, self.data, batch, self.device);
        EmsslIteration {
            iteration: 0,
            exploration: 0.0,
            learning_rate: 0.0,
            test,
            train_reach_cm: DistanceErrors::from_metres(&distances(desired, &clean_reached))
                .mean_cm,
            validation_reach_cm,
            disagreement: disagreement(answers, &back, &self.data.ranges),
            sampling_seconds: 0.0,
            training_seconds: 0.0,
            forward_calls: 0,
            steps: 0,
        }
    }

    /// EMSSL's polishing rounds (see [`EmsslConfig::polish_rounds`]) from `model`, the kept
    /// model of the iterations in `curve`: the inference model to keep and the rounds' curve
    /// points (numbered after the iterations, exploration 0).
    fn polish(&self, model: Mlp, curve: &[EmsslIteration]) -> Result<(Mlp, Vec<EmsslIteration>)> {
        let (data, fit_cfg, forward) = (self.data, self.fit_cfg, self.forward);
        let (desired, held_out) = (self.desired(), self.held_out());
        let kept = curve
            .iter()
            .min_by(|a, b| a.selection_cm().total_cmp(&b.selection_cm()))
            .ok_or_else(|| crate::Error::Training("EMSSL: no iteration to polish".into()))?;
        let (mut best_cm, learning_rate) = (kept.selection_cm(), kept.learning_rate);
        // The selection error: the reach error on the validation goals, else the training goals.
        let goals = if held_out.is_empty() {
            desired
        } else {
            held_out
        };
        let reach_cm = |m: &Mlp| {
            let q = self.predict(m, goals);
            DistanceErrors::from_metres(&reach_errors(forward, goals, &q)).mean_cm
        };
        let mut model = model;
        let mut points = Vec::new();
        for round in 1..=self.cfg.polish_rounds {
            let iteration = curve.len() + round;
            let t0 = std::time::Instant::now();
            let answers = self.predict(&model.valid(), desired);
            let reached = forward.end_effector_batch(&answers);
            let set = joint_set(data, &reached, &answers, model.joint_output(), self.tdev);
            let sampling_seconds = t0.elapsed().as_secs_f64();
            let fit_round = FitConfig {
                learning_rate,
                seed: fit_cfg.seed.wrapping_add(iteration as u64),
                ..fit_cfg.clone()
            };
            let (polished, log) = fit_converged(
                model.clone(),
                &set,
                &fit_round,
                &Convergence::standard(),
                &format!("EMSSL polishing round {round}"),
                mse,
                reach_cm,
            )?;
            let valid = polished.valid();
            let clean = self.predict(&valid, desired);
            let point = EmsslIteration {
                iteration,
                learning_rate,
                validation_reach_cm: (!held_out.is_empty()).then_some(log.best_validation),
                sampling_seconds,
                training_seconds: log.seconds,
                forward_calls: curve.last().map_or(0, |c| c.forward_calls)
                    + 2 * desired.len() * round,
                steps: log.epochs * set.len().div_ceil(fit_round.batch),
                ..self.scored(&valid, &clean, false)
            };
            eprintln!(
                "EMSSL polishing round {round}: selection {:.4} cm (before {best_cm:.4}), test {:.4} cm, {}",
                point.selection_cm(),
                point.test.mean_cm,
                log.summary()
            );
            let better = point.selection_cm() < best_cm;
            points.push(point);
            if !better {
                break;
            }
            best_cm = points.last().expect("pushed").selection_cm();
            model = polished;
        }
        Ok((model.valid(), points))
    }
}
