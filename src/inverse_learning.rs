//! Learning the inverse kinematic model (EMSSL paper sections III-A and IV-A): direct
//! regression (DRL) and embodied self-supervised learning (EMSSL, Algorithm 1), both training
//! the MLP of [`crate::inverse_model`] through the shared training loop.
//!
//! - DRL fits (position -> joints) on the random data. On a redundant arm many joint vectors
//!   reach one position, and the regression averages them: the average of two solutions is
//!   usually not a solution. That is its known failure.
//! - EMSSL never sees the random joints. Each iteration infers joints for every desired
//!   position in one batched pass, asks the forward model where the arm really goes, and trains
//!   the model to map those reached positions back to the joints that produced them: data it
//!   generated itself, always consistent (one joint vector per reached position). It stops when
//!   its answers for a desired position and for the position it actually reached agree (mean
//!   absolute difference of the normalised joints below `agreement`), or after
//!   `max_iterations`. The forward model is only called, never differentiated.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Point3;

use crate::error::Result;
use crate::ik_data::{DistanceErrors, IkData, distances, reach_errors};
use crate::inverse_model::{InverseModelConfig, Mlp};
use crate::kinematics::KinematicChain;
use burn::optim::{AdamConfig, ModuleOptimizer};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use crate::training::{Batch, TrainConfig, TrainSet, autodiff_device, train_continuing};

/// Optimisation of one fit.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitConfig {
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    pub inference_batch: usize,
    pub seed: u64,
}

impl FitConfig {
    /// The paper's Table I: Adam 1.5e-3, training batch 128, inference batch 512, 10 epochs.
    pub fn paper() -> Self {
        FitConfig {
            epochs: 10,
            batch: 128,
            learning_rate: 1.5e-3,
            inference_batch: 512,
            seed: 0,
        }
    }

    /// The shared loop's config for `cfg.epochs` epochs over `samples` (no clipping, no input
    /// noise, no checkpoints).
    pub fn train_config(&self, samples: usize) -> TrainConfig {
        TrainConfig {
            steps: TrainConfig::steps_for_epochs(self.epochs, samples, self.batch),
            batch: self.batch,
            learning_rate: self.learning_rate,
            grad_clip_norm: None,
            input_noise: 0.0,
            seed: self.seed,
            checkpoint_every: 0,
        }
    }
}

/// Normalised positions `[n, 3]` of `positions`.
fn position_tensor(data: &IkData, positions: &[Point3<f64>], device: &Device) -> Tensor<2> {
    Tensor::from_data(
        TensorData::new(data.position_rows(positions), [positions.len(), 3]),
        device,
    )
}

/// The mean squared error between the model's outputs and the batch's targets.
pub fn mse(model: &Mlp, batch: &Batch) -> Tensor<1> {
    let [n, d, _, _] = batch.targets[0].dims();
    (model.forward(batch.inputs.clone()) - batch.targets[0].clone().reshape([n, d]))
        .square()
        .mean()
}

/// Rows of `width` values as a training set: `inputs` `[n, in_width]`, `targets`
/// `[n, out_width, 1, 1]` (the shared loop's layout).
pub fn row_set(
    inputs: Vec<f32>,
    in_width: usize,
    targets: Vec<f32>,
    out_width: usize,
    device: &Device,
) -> TrainSet {
    let n = inputs.len() / in_width.max(1);
    TrainSet {
        inputs: Tensor::from_data(TensorData::new(inputs, [n, in_width]), device),
        targets: vec![Tensor::from_data(
            TensorData::new(targets, [n, out_width, 1, 1]),
            device,
        )],
    }
}

/// Train `model` on `set` with `loss` for `cfg.epochs` epochs, continuing from the optimiser
/// state `optim`, returned with the model.
pub fn fit_set(
    model: Mlp,
    optim: ModuleOptimizer,
    set: &TrainSet,
    cfg: &FitConfig,
    label: &str,
    loss: impl Fn(&Mlp, &Batch) -> Tensor<1>,
) -> Result<(Mlp, ModuleOptimizer)> {
    let train_cfg = cfg.train_config(set.len());
    struct NoHooks;
    impl crate::training::TrainHooks<Mlp> for NoHooks {}
    let (model, optim, _) = train_continuing(
        model,
        optim,
        set,
        &train_cfg,
        None,
        label,
        loss,
        &mut NoHooks,
    )?;
    Ok((model, optim))
}

/// Train `model` to map `positions` to `joints` (radians), normalised, by mean squared error.
#[allow(clippy::too_many_arguments)]
pub fn fit(
    model: Mlp,
    optim: ModuleOptimizer,
    data: &IkData,
    positions: &[Point3<f64>],
    joints: &[Vec<f64>],
    cfg: &FitConfig,
    label: &str,
    device: &Device,
) -> Result<(Mlp, ModuleOptimizer)> {
    let dof = joints.first().map_or(0, Vec::len);
    let set = row_set(
        data.position_rows(positions),
        3,
        data.joint_rows(joints),
        dof,
        device,
    );
    fit_set(model, optim, &set, cfg, label, mse)
}

/// Joints (radians) the model answers for `positions`, in batches of `batch`.
pub fn predict(
    model: &Mlp,
    data: &IkData,
    positions: &[Point3<f64>],
    batch: usize,
    device: &Device,
) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(positions.len());
    for part in positions.chunks(batch.max(1)) {
        let q = model.forward(position_tensor(data, part, device));
        let [n, dof] = q.dims();
        let v = q.into_data().try_into_vec::<f32>().expect("float");
        for i in 0..n {
            out.push(data.joints_from_normalised(&v[i * dof..(i + 1) * dof]));
        }
    }
    out
}

/// Distance errors of `model` on the test targets.
pub fn test_errors(
    model: &Mlp,
    chain: &KinematicChain,
    data: &IkData,
    batch: usize,
    device: &Device,
) -> (DistanceErrors, Vec<Vec<f64>>) {
    let targets = &data.positions[data.test()];
    let joints = predict(model, data, targets, batch, device);
    (
        DistanceErrors::from_metres(&reach_errors(chain, targets, &joints)),
        joints,
    )
}

/// Direct regression learning: fit (position -> joints) on the random training data.
pub fn drl(
    data: &IkData,
    model_cfg: &InverseModelConfig,
    fit_cfg: &FitConfig,
    device: &Device,
) -> Result<Mlp> {
    let tdev = autodiff_device(device, fit_cfg.seed);
    let model = model_cfg.init(&tdev, fit_cfg.seed)?;
    let train = data.train();
    let (model, _) = fit(
        model,
        AdamConfig::new().init(),
        data,
        &data.positions[train.clone()],
        &data.joints[train],
        fit_cfg,
        "DRL",
        &tdev,
    )?;
    Ok(model.valid())
}

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
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EmsslConfig {
    pub max_iterations: usize,
    /// Stop when the disagreement (see [`EmsslIteration::disagreement`]) falls below this
    /// (the paper's rule) ...
    pub agreement: f64,
    /// ... or when the reach error on the desired training positions
    /// ([`EmsslIteration::train_reach_cm`]) has not reached a new minimum for this many
    /// iterations.
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
        }
    }
}

/// One EMSSL iteration, for the learning curve (Figure 6).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct EmsslIteration {
    pub iteration: usize,
    /// Exploration noise and learning rate used in this iteration.
    pub exploration: f64,
    pub learning_rate: f64,
    /// Test distance errors after this iteration (evaluation only; never used to stop).
    pub test: DistanceErrors,
    /// Mean distance (cm) between the desired training positions and where the model's
    /// answers for them (without noise) take the arm.
    pub train_reach_cm: f64,
    /// Mean absolute difference (normalised joints) between the model's answers for the
    /// desired positions and its answers for the positions those answers reach: zero when
    /// the model is consistent with the arm (the paper's stopping rule).
    pub disagreement: f64,
    /// Seconds of the sampling phase (batched inference, noise, forward model) and of training.
    pub sampling_seconds: f64,
    pub training_seconds: f64,
    /// Forward-model calls so far (the sampling pass and the noise-free reach check of every
    /// iteration): with a real arm as the forward model, the moves it made.
    #[serde(default)]
    pub forward_calls: usize,
}

/// EMSSL's stopping rule followed iteration by iteration: the agreement threshold, or
/// `patience` iterations without a new minimum of the reach error on the training goals, or
/// that reach error at or below the target, where one is set.
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
        let improved = it.train_reach_cm < self.best_reach_cm;
        if improved {
            self.best_reach_cm = it.train_reach_cm;
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

/// Perturb `joints` (radians, within `range`) with Gaussian noise of standard deviation `sigma`
/// in normalised units (1 = the whole range), clamped to the range.
fn explore(joints: &mut [Vec<f64>], range: [f64; 2], sigma: f64, seed: u64) {
    if sigma <= 0.0 {
        return;
    }
    let noise = Normal::new(0.0, sigma).expect("finite sigma");
    let mut rng = StdRng::seed_from_u64(seed);
    let [lo, hi] = range;
    for v in joints.iter_mut().flatten() {
        let u = (*v - lo) / (hi - lo) + noise.sample(&mut rng);
        *v = lo + u.clamp(0.0, 1.0) * (hi - lo);
    }
}

/// Mean absolute difference of two joint sets in normalised units.
fn disagreement(a: &[Vec<f64>], b: &[Vec<f64>], range: [f64; 2]) -> f64 {
    let span = range[1] - range[0];
    let n = a.iter().map(Vec::len).sum::<usize>().max(1);
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(u, v)| (u - v).abs() / span))
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
    let tdev = autodiff_device(device, fit_cfg.seed);
    let model = model_cfg.init(&tdev, fit_cfg.seed)?;
    emssl_from(model, &tdev, chain, chain, data, fit_cfg, cfg, device)
}

/// EMSSL iterations from `model` (on the autodiff device `tdev`; a trained inference model
/// comes back with `.train()`), with `forward` as the forward model, on the desired training
/// positions of `data`. The test errors are those of `arm`, the arm the answers are for (the
/// forward model itself, or the real arm when the forward model is a learned stand-in).
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
    let mut model = model;
    let mut optim = AdamConfig::new().init();
    let desired = &data.positions[data.train()];
    let mut curve: Vec<EmsslIteration> = Vec::new();
    let mut best: Option<Mlp> = None;
    let mut rule = StopRule::default();
    // The answers for the desired positions: the first sampling pass, and after each
    // iteration both its agreement check and the next iteration's sampling.
    let t0 = std::time::Instant::now();
    let mut answers = predict(
        &model.valid(),
        data,
        desired,
        fit_cfg.inference_batch,
        device,
    );
    let mut inference_seconds = t0.elapsed().as_secs_f64();
    for iteration in 1..=cfg.max_iterations {
        let decay = |rate: f64| rate.powi(iteration as i32 - 1);
        let sigma = (cfg.exploration * decay(cfg.exploration_decay)).max(cfg.exploration_floor);
        let learning_rate = fit_cfg.learning_rate * decay(cfg.learning_rate_decay);
        // Sampling: the batched inference (done at the end of the last iteration), the
        // exploration noise, then the forward model.
        let t0 = std::time::Instant::now();
        let mut tried = answers.clone();
        explore(
            &mut tried,
            data.range,
            sigma,
            fit_cfg.seed ^ (iteration as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        let reached = forward.end_effector_batch(&tried);
        let sampling_seconds = inference_seconds + t0.elapsed().as_secs_f64();
        // Training on the self-generated pairs (reached -> joints tried).
        let t0 = std::time::Instant::now();
        let fit_iter = FitConfig {
            seed: fit_cfg.seed.wrapping_add(iteration as u64),
            learning_rate,
            ..fit_cfg.clone()
        };
        (model, optim) = fit(
            model,
            optim,
            data,
            &reached,
            &tried,
            &fit_iter,
            &format!("EMSSL iteration {iteration}"),
            tdev,
        )?;
        let training_seconds = t0.elapsed().as_secs_f64();
        let valid = model.valid();
        // The next sampling pass's inference, and the agreement check on it.
        let t0 = std::time::Instant::now();
        answers = predict(&valid, data, desired, fit_cfg.inference_batch, device);
        inference_seconds = t0.elapsed().as_secs_f64();
        let clean_reached = forward.end_effector_batch(&answers);
        let back = predict(
            &valid,
            data,
            &clean_reached,
            fit_cfg.inference_batch,
            device,
        );
        let disagreement = disagreement(&answers, &back, data.range);
        let train_reach_cm =
            DistanceErrors::from_metres(&distances(desired, &clean_reached)).mean_cm;
        let (test, _) = test_errors(&valid, arm, data, fit_cfg.inference_batch, device);
        curve.push(EmsslIteration {
            iteration,
            exploration: sigma,
            learning_rate,
            test,
            train_reach_cm,
            disagreement,
            sampling_seconds,
            training_seconds,
            forward_calls: 2 * desired.len() * iteration,
        });
        let (improved, stop) = rule.observe(curve.last().expect("just pushed"), cfg);
        if improved {
            best = Some(valid);
        }
        if stop {
            break;
        }
    }
    let model = best.unwrap_or_else(|| model.valid());
    Ok((model, curve))
}
