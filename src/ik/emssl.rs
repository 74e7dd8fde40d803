//! Embodied self-supervised learning (EMSSL, Algorithm 1 of the EMSSL paper, section III-A),
//! training the MLP of [`crate::ik::mlp`] through the shared training loop
//! ([`crate::ik::learning`]); [`EmsslMethod`]: EMSSL as a Table II method.
//!
//! - EMSSL never sees the random joints. Each iteration infers joints for every desired
//!   position in one batched pass, asks the forward model where the arm really goes, and trains
//!   the model to map those reached positions back to the joints that produced them: data it
//!   generated itself, always consistent (one joint vector per reached position). It stops when
//!   its answers for a desired position and for the position it actually reached agree (mean
//!   absolute difference of the normalised joints below `agreement`), or after
//!   `max_iterations`. The forward model is only called, never differentiated.
//!
//! ## What limits EMSSL (the study in `reports/emssl_study`, `crate::studies::emssl::study`)
//! On 22,000 UR5 goals (2,000 held out), the paper's network, one knob at a time from the
//! schedule Table II ran with at 3bc9f24 (learning rate and noise both times 0.9 per
//! iteration), test mean of the model the validation goals pick, +-90 / +-180 degrees:
//! - that baseline: 1.25 cm (iteration 27) / 9.83 cm (28);
//! - noise decaying by 0.8: 1.23 (17) / 9.67 (20): the same floor, reached 10 iterations sooner;
//! - learning rate annealed along a cosine within every iteration: 1.34 (20) / 11.50 (22);
//! - learning rate halved on plateaus (not decayed): 1.36 (26) / 8.48 (27);
//! - a warm start of 10 epochs of motor babbling: 1.36 (26) / 10.26 (25), from a lower start.
//!
//! Every setting falls to a floor near 1.2-1.4 cm at +-90 and then rises slowly as the noise
//! and the learning rate vanish, its tail first; the schedule moves the iteration of the
//! floor, not the floor. The remaining knobs (the combination, the wrapped output, batch 512, fewer
//! epochs, kept pairs) are rows the study has still to run (`emssl_study --resume`).

use burn::module::Module;
use burn::tensor::Device;
use nalgebra::Point3;

use crate::core::error::{Error, Result};
use crate::ik::data::{DistanceErrors, IkData, JointOutput, distances, reach_errors};
use crate::ik::mlp::{InverseModelConfig, Mlp};
use crate::sim::kinematics::KinematicChain;
use burn::optim::ModuleOptimizer;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use crate::ik::learning::{FitConfig, fit, fit_converged, joint_set, mse, predict, test_errors};

pub use crate::ik::emssl_iteration::EmsslIteration;
use crate::train::{
    config::TrainConfig,
    convergence::{Convergence, Plateau},
    trainer::autodiff_device,
};

/// EMSSL's schedule and stopping rule.
///
/// Algorithm 1 as printed starts from a random network and has no exploration. A random
/// network answers nearly the same joints for every target (its sigmoid outputs sit near 0.5),
/// so the first reached positions form a cloud a few millimetres wide around one point, and a
/// model fit to it is close to a constant, which is itself a fixed point of the algorithm
/// (measured on the UR5 at +-90 degrees: the paper's network stayed at 85 cm for 30
/// iterations). So, as goal babbling does (Rolf and Steil), Gaussian noise is added to the
/// answers before the forward model in the early iterations and decays geometrically; the
/// pairs stay exact (the joints tried and where they went). The learning rate decays too, and
/// one Adam optimiser serves the whole run.
///
/// The fields after `target_reach_cm` are the knobs of the study in `reports/emssl_study`
/// ([`crate::studies::emssl::study`]); their defaults are the schedule above.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EmsslConfig {
    pub max_iterations: usize,
    /// Stop when the disagreement (see [`EmsslIteration::disagreement`]) falls below this
    /// (the paper's rule) ...
    pub agreement: f64,
    /// ... or when the selection error ([`EmsslIteration::selection_cm`]) has not reached a
    /// new minimum for this many iterations.
    pub patience: usize,
    /// Exploration noise: standard deviation in normalised joint units ([0, 1] is the whole
    /// range) in iteration 1.
    pub exploration: f64,
    /// The noise and the learning rate are multiplied by these after each iteration.
    pub exploration_decay: f64,
    /// The noise never falls below this.
    #[serde(default)]
    pub exploration_floor: f64,
    pub learning_rate_decay: f64,
    /// Also stop once the reach error on the training goals is at most this (cm): fast
    /// adaptation's "back to where it was" rule. `None`: no such target.
    #[serde(default)]
    pub target_reach_cm: Option<f64>,
    /// Also reduce the learning rate on a plateau of the selection error: after `patience`
    /// iterations without a new best, multiply it by `factor` (and again after as many more).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lr_plateau: Option<LrPlateau>,
    /// Before the first iteration, fit the network this many epochs on motor babbling: as many
    /// random joint vectors as there are goals, drawn from the range and tried on the forward
    /// model (0: Algorithm 1's random network).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub warm_start_epochs: usize,
    /// Train each iteration on the pairs of the last this many iterations (1: Algorithm 1, its
    /// own pairs only).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub keep_iterations: usize,
    /// After the iterations, this many rounds of polishing: the kept model's noise-free pairs
    /// (positions its answers for the goals reach -> those answers) trained on to convergence
    /// ([`Convergence::standard`], stopped on the validation goals' reach error) at the kept
    /// iteration's learning rate; a round is kept only if it lowers that error (0: none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub polish_rounds: usize,
}

fn one() -> usize {
    1
}
fn is_one(v: &usize) -> bool {
    *v == 1
}
fn is_zero(v: &usize) -> bool {
    *v == 0
}

/// Reduce-on-plateau of EMSSL's learning rate, counted in iterations.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LrPlateau {
    pub patience: usize,
    pub factor: f64,
}

impl EmsslConfig {
    /// Up to 200 iterations (the paper's Table I); noise 0.2 decaying by 0.9, learning rate
    /// decaying by 0.9 per iteration (ours); stop at agreement 0.002 or after 10 iterations
    /// without a new best reach error on the training goals.
    pub fn paper() -> Self {
        EmsslConfig {
            max_iterations: 200,
            agreement: 0.002,
            patience: 10,
            exploration: 0.2,
            exploration_decay: 0.9,
            exploration_floor: 0.0,
            learning_rate_decay: 0.9,
            target_reach_cm: None,
            lr_plateau: None,
            warm_start_epochs: 0,
            keep_iterations: 1,
            polish_rounds: 0,
        }
    }
}

/// EMSSL's stopping rule followed iteration by iteration: the agreement threshold, or
/// `patience` iterations without a new minimum of the selection error, or the reach error on
/// the training goals at or below the target, where one is set.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct StopRule {
    best_reach_cm: f64,
    since_best: usize,
}

impl Default for StopRule {
    fn default() -> Self {
        StopRule {
            best_reach_cm: f64::INFINITY,
            since_best: 0,
        }
    }
}

impl StopRule {
    /// Take in one iteration: `(whether it is the best so far, whether the rule stops now)`.
    pub fn observe(&mut self, it: &EmsslIteration, cfg: &EmsslConfig) -> (bool, bool) {
        let improved = it.selection_cm() < self.best_reach_cm;
        if improved {
            self.best_reach_cm = it.selection_cm();
            self.since_best = 0;
        } else {
            self.since_best += 1;
        }
        let stop = it.disagreement < cfg.agreement
            || self.since_best >= cfg.patience
            || cfg.target_reach_cm.is_some_and(|t| it.train_reach_cm <= t);
        (improved, stop)
    }
}

/// Perturb `joints` (radians, each within its range of `ranges`) with Gaussian noise of standard deviation `sigma`
/// in normalised units (1 = the whole range), clamped to the range, or wrapped around it when
/// `wrap` (a whole-circle range under the wrapped output, where the ends are one pose).
fn explore(joints: &mut [Vec<f64>], ranges: &[[f64; 2]], sigma: f64, seed: u64, wrap: bool) {
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
fn babble(
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
fn disagreement(a: &[Vec<f64>], b: &[Vec<f64>], ranges: &[[f64; 2]]) -> f64 {
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

/// Embodied self-supervised learning (Algorithm 1) of an inverse model of `chain`, the forward
/// model, on the desired training positions of `data`, from a fresh network. Returns the model
/// of the iteration with the lowest reach error on the desired training positions
/// (self-supervised: the forward model and the goals, no test data) and the curve.
///
/// The disagreement alone cannot pick the model: a network that answers nearly the same
/// joints everywhere agrees with itself perfectly.
pub fn emssl(
    chain: &KinematicChain,
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    cfg: &EmsslConfig,
    device: &Device,
) -> Result<(Mlp, Vec<EmsslIteration>)> {
    emssl_checkpointed(chain, data, model_cfg, fit_cfg, cfg, device, None)
}

/// [`emssl`] saving its state after every iteration in `checkpoint` (model, optimiser, best
/// model, curve and the rules' state) and continuing from it when it holds a run of the same
/// settings (the iteration cap aside: a run may be continued past its cap): a killed run
/// resumes to the same result. Runs that train on the pairs of more than one iteration
/// (`keep_iterations` > 1) are not checkpointed.
pub fn emssl_checkpointed(
    chain: &KinematicChain,
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    cfg: &EmsslConfig,
    device: &Device,
    checkpoint: Option<&std::path::Path>,
) -> Result<(Mlp, Vec<EmsslIteration>)> {
    let tdev = autodiff_device(device, fit_cfg.seed);
    let model = model_cfg.init(&tdev, fit_cfg.seed)?;
    let plan = checkpoint
        .filter(|_| cfg.keep_iterations <= 1)
        .map(|dir| EmsslCheckpoint {
            dir: dir.to_path_buf(),
            settings: serde_json::json!({
                "model": model_cfg,
                "fit": fit_cfg,
                // A run may be continued with a higher cap, and polished once finished.
                "emssl": EmsslConfig {
                    max_iterations: 0,
                    polish_rounds: 0,
                    ..cfg.clone()
                },
                "goals": data.train().len(),
                "range": data.range_record(),
            }),
        });
    Run {
        tdev: &tdev,
        forward: chain,
        arm: chain,
        data,
        fit_cfg,
        cfg,
        device,
        checkpoint: plan.as_ref(),
    }
    .run(model)
}

/// Where an EMSSL run keeps its state, and the settings it must match to continue.
struct EmsslCheckpoint {
    dir: std::path::PathBuf,
    settings: serde_json::Value,
}

/// What an EMSSL checkpoint's `state.json` holds besides the weights.
#[derive(serde::Serialize, serde::Deserialize)]
struct EmsslState {
    settings: serde_json::Value,
    curve: Vec<EmsslIteration>,
    rule: StopRule,
    plateau: Option<Plateau>,
    /// Whether the stopping rule has ended the run (its best model is final).
    finished: bool,
}

impl EmsslCheckpoint {
    fn path(&self, file: &str) -> std::path::PathBuf {
        self.dir.join(file)
    }

    /// The saved state, if it was made with the same settings.
    fn load(&self) -> Option<EmsslState> {
        if !(self.path("model.bpk").exists() && self.path("optimizer.bpk").exists()) {
            return None;
        }
        let text = std::fs::read_to_string(self.path("state.json")).ok()?;
        serde_json::from_str::<EmsslState>(&text)
            .ok()
            .filter(|s| s.settings == self.settings)
    }

    fn save(
        &self,
        model: &Mlp,
        optim: &ModuleOptimizer,
        best: Option<&Mlp>,
        state: &EmsslState,
    ) -> Result<()> {
        std::fs::create_dir_all(&self.dir).map_err(|e| crate::Error::io(&self.dir, e))?;
        crate::train::checkpoint::save_module(model, &self.path("model.bpk"))?;
        crate::train::checkpoint::save_renamed(&self.path("optimizer.bpk"), |t| optim.save(t))?;
        if let Some(b) = best {
            crate::train::checkpoint::save_module(b, &self.path("best.bpk"))?;
        }
        crate::core::atomic_file::write_json(&self.path("state.json"), state)
    }
}

/// EMSSL iterations from `model` (on the autodiff device `tdev`; a trained inference model
/// comes back with `.train()`), with `forward` as the forward model, on the desired training
/// positions of `data`. The test errors are those of `arm`, the arm the answers are for (the
/// forward model itself, or the real arm when the forward model is a learned stand-in).
// The paper's nouns as arguments (callers name each); inside, one `Run` holds them.
#[allow(clippy::too_many_arguments)]
pub fn emssl_from(
    model: Mlp,
    tdev: &Device,
    forward: &KinematicChain,
    arm: &KinematicChain,
    data: &IkData,
    fit_cfg: &FitConfig,
    cfg: &EmsslConfig,
    device: &Device,
) -> Result<(Mlp, Vec<EmsslIteration>)> {
    Run {
        tdev,
        forward,
        arm,
        data,
        fit_cfg,
        cfg,
        device,
        checkpoint: None,
    }
    .run(model)
}

/// What one EMSSL run works with: the devices, the forward model and the arm it is scored
/// on, the goals, the settings, and where it keeps its state.
struct Run<'a> {
    tdev: &'a Device,
    forward: &'a KinematicChain,
    arm: &'a KinematicChain,
    data: &'a IkData,
    fit_cfg: &'a FitConfig,
    cfg: &'a EmsslConfig,
    device: &'a Device,
    checkpoint: Option<&'a EmsslCheckpoint>,
}

/// Where a run stands between iterations.
struct Progress {
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
    fn run(&self, model: Mlp) -> Result<(Mlp, Vec<EmsslIteration>)> {
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
                 is in {}: run the same command with --resume to continue from there",
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

/// EMSSL as a Table II method: checkpointed in the task's files (a killed run continues), its
/// answers kept for the refinement that starts from them.
pub struct EmsslMethod {
    pub name: String,
    pub model: InverseModelConfig,
    pub fit: FitConfig,
    pub emssl: EmsslConfig,
}

impl crate::ik::method::IkMethod for EmsslMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::method::settings_json(&(&self.model, &self.fit, &self.emssl))
    }

    fn required(&self, task: &crate::ik::method::IkTask) -> Vec<std::path::PathBuf> {
        vec![task.predictions_path(&self.name)]
    }

    fn run(&self, task: &crate::ik::method::IkTask) -> Result<crate::ik::method::MethodOutput> {
        use crate::ik::method::{Answers, MethodOutput, ValidationRow, timed};
        let t = std::time::Instant::now();
        let checkpoint = task.file(&format!("{} checkpoint", self.name), "");
        let (model, curve) = emssl_checkpointed(
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
