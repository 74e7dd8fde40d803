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

mod checkpoint;
pub mod iteration;
mod method;
mod run;

use burn::tensor::Device;

use crate::core::error::Result;
use crate::ik::data::IkData;
use crate::ik::learning::FitConfig;
use crate::ik::mlp::{InverseModelConfig, Mlp};
use crate::sim::kinematics::KinematicChain;
use crate::train::trainer::autodiff_device;

use checkpoint::EmsslCheckpoint;
use run::Run;

pub use iteration::EmsslIteration;
pub use method::EmsslMethod;

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

/// Embodied self-supervised learning (Algorithm 1) of an inverse model of `chain`, the forward
/// model, on the desired training positions of `data`, from a fresh network. Returns the model
/// of the iteration with the lowest reach error on the desired training positions
/// (self-supervised: the forward model and the goals, no test data) and the curve.
///
/// The disagreement alone cannot pick the model: a network that answers nearly the same
/// joints everywhere agrees with itself perfectly.
///
/// With `checkpoint` (a folder), its state is saved there after every iteration (model,
/// optimiser, best model, curve and the rules' state), and a run continues from it when it
/// holds a run of the same settings (the iteration cap aside: a run may be continued past its cap): a killed run
/// resumes to the same result. Runs that train on the pairs of more than one iteration
/// (`keep_iterations` > 1) are not checkpointed.
pub fn emssl(
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
