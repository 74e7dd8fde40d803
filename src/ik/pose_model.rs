//! A learned full-pose IK model people can keep and use: a conditional flow (IKFlow-style,
//! [`crate::ik::flow`]) conditioned on the target's position and orientation, trained on joint
//! samples drawn within the robot's limits, saved with the robot's fingerprint, joint names
//! and limits; answers refined to exact by Levenberg-Marquardt ([`crate::ik::pose`]).
//!
//! A saved model is a folder: `model.bpk` (the flow's weights), `model.json` ([`SavedModel`]:
//! the config, the robot as given and its fingerprint, joint names, ranges, the position
//! normalisation). The condition of a target: its position normalised per axis over the
//! training positions' bounds, then (unless the model is position-only) its unit quaternion
//! (w, x, y, z) with `w >= 0`.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use nalgebra::Point3;

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::input_file::{file_fnv, fnv};
use crate::core::preset::Preset;
use crate::core::spread::Spread;
use crate::ik::data::{IkData, IkDataConfig};
use crate::ik::flow::{FlowConfig, FlowIk, fit_flow, sample_rows, sample_rows_from};
use crate::ik::pose::{LmConfig, PoseSolution, PoseTarget, pose_error, solve};
use crate::sim::kinematics::KinematicChain;
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;

/// How a pose model is trained and answers.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseModelConfig {
    pub preset: String,
    /// Joint samples (drawn within the limits, narrowed to +-`range_deg`).
    pub data: IkDataConfig,
    pub flow: FlowConfig,
    /// Condition on the position only (the EMSSL paper's setting).
    pub position_only: bool,
    pub lm: LmConfig,
}

impl Preset for PoseModelConfig {
    /// 200,000 samples, the standard flow trained to a validation plateau or 100 epochs
    /// (about 25 s an epoch on 2 CPU cores).
    fn paper() -> Self {
        let mut flow = FlowConfig::standard();
        flow.fit.converge = Some(crate::train::convergence::Convergence {
            max_epochs: 100,
            ..crate::train::convergence::Convergence::standard()
        });
        PoseModelConfig {
            preset: "paper".into(),
            data: IkDataConfig {
                samples: 210_000,
                train: 200_000,
                range_deg: 180.0,
                seed: 0,
                validation: 5_000,
            },
            flow,
            position_only: false,
            lm: LmConfig::standard(),
        }
    }

    /// 3,000 samples, a small flow, 5 epochs: seconds.
    fn quick() -> Self {
        let mut flow = FlowConfig::standard();
        flow.couplings = 4;
        flow.hidden = vec![32, 32];
        flow.fit.epochs = 5;
        flow.fit.converge = None;
        PoseModelConfig {
            preset: "quick".into(),
            data: IkDataConfig {
                samples: 3_000,
                train: 2_900,
                range_deg: 180.0,
                seed: 0,
                validation: 0,
            },
            flow,
            position_only: false,
            lm: LmConfig::standard(),
        }
    }
}

/// What `model.json` holds.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SavedModel {
    pub config: PoseModelConfig,
    pub robot: RobotSpec,
    /// [`fingerprint`] of the robot's chain: a model answers only for the robot it learned.
    pub robot_fingerprint: String,
    pub joint_names: Vec<String>,
    /// The links whose poses a target gives, where there are several (`ik train --tips A,B`);
    /// empty for one tip (the robot's tip).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tips: Vec<String>,
    /// FNV-1a of `model.bpk` as saved: a damaged or replaced weights file is refused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights_fnv: Option<String>,
    /// Each joint's range (SI).
    pub ranges: Vec<[f64; 2]>,
    pub position_bounds: [[f64; 3]; 2],
    pub git_revision: String,
}

/// The largest joint value a saved model may state (SI: radians, metres).
const MAX_RANGE: f64 = 1e4;
/// The most iterations and random starts a saved model may ask of its solver per answer.
const MAX_ITERATIONS: usize = 100_000;
const MAX_STARTS: usize = 10_000;

impl SavedModel {
    /// What a model written by `ik train` always satisfies; an edited or damaged file is
    /// refused with what is wrong rather than answering wrongly or failing inside the solver.
    pub fn check(&self) -> std::result::Result<(), String> {
        let dof = self.joint_names.len();
        if dof == 0 {
            return Err("it names no joints".into());
        }
        if self.ranges.len() != dof {
            return Err(format!(
                "it has {} joint ranges for {dof} joints",
                self.ranges.len()
            ));
        }
        if let Some(i) = (1..dof).find(|&i| self.joint_names[..i].contains(&self.joint_names[i])) {
            return Err(format!("joint \"{}\" is named twice", self.joint_names[i]));
        }
        if self.tips.len() == 1 {
            return Err(
                "it names one tip in \"tips\" (one tip is the robot's: leave it empty)".into(),
            );
        }
        if let Some(i) = (1..self.tips.len()).find(|&i| self.tips[..i].contains(&self.tips[i])) {
            return Err(format!("tip \"{}\" is named twice", self.tips[i]));
        }
        for (name, [lo, hi]) in self.joint_names.iter().zip(&self.ranges) {
            if !(lo.is_finite() && hi.is_finite() && lo.abs() <= MAX_RANGE && hi.abs() <= MAX_RANGE)
            {
                return Err(format!(
                    "joint \"{name}\" has the range [{lo:e}, {hi:e}], not finite numbers within +-{MAX_RANGE}"
                ));
            }
            if lo >= hi {
                // `ik train` never writes one: a joint without a range to sample is refused.
                return Err(format!(
                    "joint \"{name}\" has the range [{lo:e}, {hi:e}], {}",
                    if lo > hi { "inverted" } else { "empty" }
                ));
            }
        }
        let [lo, hi] = self.position_bounds;
        if (0..3).any(|k| !(lo[k].is_finite() && hi[k].is_finite() && lo[k] < hi[k])) {
            return Err(format!(
                "its position bounds {lo:?} .. {hi:?} are not finite, increasing intervals"
            ));
        }
        let flow = &self.config.flow;
        if !(1..=64).contains(&flow.couplings) {
            return Err(format!(
                "its flow has {} couplings (1 to 64)",
                flow.couplings
            ));
        }
        if flow.hidden.is_empty() || flow.hidden.iter().any(|&h| !(1..=8192).contains(&h)) {
            return Err(format!(
                "its flow's hidden widths {:?} are not 1 to 8192 each",
                flow.hidden
            ));
        }
        if !(flow.clamp > 0.0 && flow.clamp <= 100.0) {
            return Err(format!(
                "its flow's clamp {} is not in (0, 100]",
                flow.clamp
            ));
        }
        if !(1..=1000).contains(&flow.best_of) {
            return Err(format!("its best_of {} is not 1 to 1000", flow.best_of));
        }
        if !(1..=1_000_000).contains(&flow.fit.inference_batch) {
            return Err(format!(
                "its inference batch {} is not 1 to 1,000,000",
                flow.fit.inference_batch
            ));
        }
        let lm = &self.config.lm;
        if !(lm.tolerance_m > 0.0 && lm.tolerance_m.is_finite() && lm.tolerance_m < 1.0) {
            return Err(format!(
                "its position tolerance {} m is not between 0 and 1 m",
                lm.tolerance_m
            ));
        }
        if !(lm.tolerance_rad > 0.0 && lm.tolerance_rad < std::f64::consts::PI) {
            return Err(format!(
                "its rotation tolerance {} rad is not between 0 and pi",
                lm.tolerance_rad
            ));
        }
        lm.clone()
            .converging_to(1e3 * lm.convergence_m, lm.convergence_rad.to_degrees())
            .map_err(|e| format!("its convergence tolerance: {e}"))?;
        if !(1..=MAX_ITERATIONS).contains(&lm.max_iterations) {
            return Err(format!(
                "it asks {} iterations a start (1 to {MAX_ITERATIONS})",
                lm.max_iterations
            ));
        }
        if lm.random_starts > MAX_STARTS {
            return Err(format!(
                "it asks {} random starts (at most {MAX_STARTS})",
                lm.random_starts
            ));
        }
        Ok(())
    }
}

/// A trained model ready to answer.
pub struct PoseModel {
    pub saved: SavedModel,
    pub flow: FlowIk,
    /// The data's normalisations (joints and positions), rebuilt from `saved`.
    data: IkData,
}

/// A stable fingerprint of a chain (FNV-1a over its joints, limits and tip): the same robot
/// description gives the same string on every machine.
pub fn fingerprint(chain: &KinematicChain) -> String {
    let mut text = format!(
        "tip {} {:?};",
        chain.links[chain.tip_link], chain.tip_offset
    );
    let tips = chain.tips();
    if tips.len() > 1 {
        for (l, p) in tips {
            text += &format!("tips {} {:?};", chain.links[l], p);
        }
    }
    for j in &chain.joints {
        let (r, p, y) = j.origin.rotation.euler_angles();
        let t = j.origin.translation.vector;
        text += &format!(
            "{} {:?} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:?} {:?} {:?};",
            j.name,
            j.kind,
            t.x,
            t.y,
            t.z,
            r,
            p,
            y,
            j.axis.as_slice(),
            j.limits,
            j.mimic.map(|m| (m.leader, m.multiplier, m.offset))
        );
    }
    fnv(text.as_bytes())
}

/// The condition rows of `targets` (for each tip, its position normalised, then its
/// quaternion with `w >= 0`).
fn condition_rows(data: &IkData, targets: &[Vec<PoseTarget>], position_only: bool) -> Vec<f32> {
    let tips = targets.first().map_or(1, Vec::len);
    let mut rows = Vec::with_capacity(targets.len() * tips * 7);
    for t in targets.iter().flatten() {
        rows.extend(data.normalise_position(&t.position));
        if !position_only {
            let q = t
                .orientation
                .expect("a full-pose model's targets have orientations");
            let c = q.coords; // (x, y, z, w)
            let sign = if c.w < 0.0 { -1.0 } else { 1.0 };
            rows.extend([c.w, c.x, c.y, c.z].map(|v| (sign * v) as f32));
        }
    }
    rows
}

/// The condition width of a model: 3 or 7 values a tip.
fn condition_width(position_only: bool, tips: usize) -> usize {
    tips.max(1) * if position_only { 3 } else { 7 }
}

/// Train a model of `robot` (as `spec` names it) and save it into `dir`.
pub fn train(
    spec: &RobotSpec,
    robot: &Robot,
    cfg: &PoseModelConfig,
    dir: &Path,
    device: &Device,
) -> Result<PoseModel> {
    let chain = &robot.chain;
    let mut data = IkData::generate(chain, &cfg.data)?;
    let targets: Vec<Vec<PoseTarget>> = data.joints[data.train()]
        .iter()
        .map(|q| PoseTarget::of(chain, q))
        .collect();
    let tips = chain.tip_names();
    if tips.len() > 1 {
        // Several tips share one position normalisation: the box of all their positions.
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for t in targets.iter().flatten() {
            for k in 0..3 {
                lo[k] = lo[k].min(t.position[k]);
                hi[k] = hi[k].max(t.position[k]);
            }
        }
        data.position_bounds = [lo, hi];
    }
    let width = condition_width(cfg.position_only, tips.len());
    let validation: Vec<Vec<PoseTarget>> = data.joints[data.validation()]
        .iter()
        .map(|q| PoseTarget::of(chain, q))
        .collect();
    let val_rows = condition_rows(&data, &validation, cfg.position_only);
    let batch = cfg.flow.fit.inference_batch;
    // A run to convergence keeps a checkpoint after every epoch in `dir/checkpoint/`: the same
    // command, run again after a kill, continues from its last epoch to the same model.
    let checkpoint = dir.join("checkpoint");
    let mut flow_cfg = cfg.flow.clone();
    flow_cfg.fit.checkpoint = Some(crate::train::convergence::FitCheckpoint {
        dir: checkpoint.clone(),
        settings: serde_json::json!({ "config": cfg, "robot": fingerprint(chain) }),
    });
    let trained = fit_flow(
        &data,
        condition_rows(&data, &targets, cfg.position_only),
        width,
        &flow_cfg,
        device,
        |m: &FlowIk| {
            // One sample per validation target: its mean position error (cm).
            let q = sample_rows(m, &data, &val_rows, 1, batch, 0x7A1, device)
                .pop()
                .unwrap_or_default();
            let n = q.len().max(1) as f64;
            q.iter()
                .zip(&validation)
                .map(|(q, t)| 100.0 * pose_error(chain, q, t).0)
                .sum::<f64>()
                / n
        },
    )?;
    let fresh = !dir.exists() || dir.read_dir().is_ok_and(|mut d| d.next().is_none());
    let saved = save_model(
        dir,
        &trained,
        cfg,
        spec,
        chain,
        tips,
        &data,
        checkpoint.as_path(),
    );
    if saved.is_err() && fresh {
        // A run that could not save (a full disk) leaves no empty or partial folder.
        for name in ["model.bpk", "model.json", "validation_curve.csv"] {
            let _ = std::fs::remove_file(dir.join(name));
        }
        let _ = std::fs::remove_dir(dir);
    }
    let saved = saved?;
    Ok(PoseModel {
        saved,
        flow: trained.model,
        data,
    })
}

/// Write a trained model into `dir`: `model.bpk`, `model.json` (with the weights' hash) and
/// the validation curve; the training checkpoint is removed.
#[allow(clippy::too_many_arguments)]
fn save_model(
    dir: &Path,
    trained: &crate::ik::flow::TrainedFlow,
    cfg: &PoseModelConfig,
    spec: &RobotSpec,
    chain: &KinematicChain,
    tips: Vec<String>,
    data: &IkData,
    checkpoint: &Path,
) -> Result<SavedModel> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let weights = dir.join("model.bpk");
    crate::train::checkpoint::save_module(&trained.model, &weights)?;
    // The solver's budget for the model's tips (one tip: the preset's).
    let mut config = cfg.clone();
    config.lm = config.lm.for_tips(tips.len());
    let saved = SavedModel {
        config,
        robot: spec.clone(),
        robot_fingerprint: fingerprint(chain),
        joint_names: chain.joint_names(),
        tips: if tips.len() > 1 { tips } else { Vec::new() },
        weights_fnv: Some(file_fnv(&weights)?),
        ranges: data.ranges.clone(),
        position_bounds: data.position_bounds,
        git_revision: crate::core::provenance::git_revision(),
    };
    write_json(&dir.join("model.json"), &saved)?;
    if let Some(log) = &trained.log {
        // The flow's validation curve (mean position error of one sample, cm, per epoch).
        crate::report::table::write_csv(&dir.join("validation_curve.csv"), &log.curve)?;
    }
    if checkpoint.exists() {
        std::fs::remove_dir_all(checkpoint).map_err(|e| Error::io(checkpoint, e))?;
    }
    Ok(saved)
}

impl PoseModel {
    /// Load a saved model from `dir`.
    pub fn load(dir: &Path, device: &Device) -> Result<Self> {
        let json = dir.join("model.json");
        let text = crate::core::input_file::read_user_file(
            &json,
            "saved IK model",
            crate::core::input_file::MAX_JSON_BYTES,
        )?;
        let saved: SavedModel = serde_json::from_slice(&text).map_err(|e| {
            Error::data(
                &json,
                format!("not a saved IK model ({e}); make one with `ik train`"),
            )
        })?;
        saved.check().map_err(|e| {
            Error::data(&json, format!("{e}; train the model again with `ik train`"))
        })?;
        let dof = saved.joint_names.len();
        let width = condition_width(saved.config.position_only, saved.tips.len());
        let file = dir.join("model.bpk");
        let max = crate::core::input_file::MAX_WEIGHTS_BYTES;
        crate::core::input_file::check_user_file(&file, "weights file", max)?;
        if let Some(expected) = &saved.weights_fnv
            && file_fnv(&file)? != *expected
        {
            return Err(Error::data(
                &file,
                "differs from the weights saved with model.json (damaged or replaced); train the model again with `ik train`",
            ));
        }
        let flow = FlowIk::conditioned(&saved.config.flow, dof, width, device, 0)?
            .try_load_file(&file)
            .map_err(|e| {
                Error::data(
                    &file,
                    format!(
                        "the model's weights cannot be read ({e}); train it again with `ik train`"
                    ),
                )
            })?;
        // Weights that are not numbers answer NaN: refuse them here.
        let probe = flow.inverse(
            Tensor::<2>::zeros([1, dof], device),
            Tensor::<2>::zeros([1, width + 1], device),
        );
        let finite = probe.into_data().iter::<f32>().all(f32::is_finite);
        if !finite {
            return Err(Error::data(
                &file,
                "its weights are not finite numbers; train the model again with `ik train`",
            ));
        }
        let data = IkData {
            joints: Vec::new(),
            positions: Vec::new(),
            n_train: 0,
            n_validation: 0,
            ranges: saved.ranges.clone(),
            position_bounds: saved.position_bounds,
        };
        Ok(PoseModel { saved, flow, data })
    }

    /// [`Self::load`] with the robot description the model names, refused unless it is the
    /// robot the model learned ([`Self::check_robot`]): what answering needs.
    pub fn load_with_robot(dir: &Path, device: &Device) -> Result<(Self, Robot)> {
        let model = Self::load(dir, device)?;
        let robot = model.saved.robot.load_kinematics()?;
        model.check_robot(&robot)?;
        Ok((model, robot))
    }

    /// Refuse `robot` unless it is the robot the model learned: the same joints, named and
    /// ordered alike (the message shows both lists), and the same kinematics.
    pub fn check_robot(&self, robot: &Robot) -> Result<()> {
        let names = robot.chain.joint_names();
        if names != self.saved.joint_names {
            return Err(Error::Config(format!(
                "this model answers for the joints [{}] but the robot description has [{}]: train one for this description with `ik train`",
                self.saved.joint_names.join(", "),
                names.join(", ")
            )));
        }
        let print = fingerprint(&robot.chain);
        if print != self.saved.robot_fingerprint {
            return Err(Error::Config(format!(
                "this model was trained for another robot ({}, joints {}; fingerprint {} against {}): train one for this robot with `ik train`",
                self.saved.robot.label(),
                self.saved.joint_names.join(", "),
                self.saved.robot_fingerprint,
                print
            )));
        }
        Ok(())
    }

    /// `k` answers per target: the flow's `k` samples, each refined by Levenberg-Marquardt
    /// (from random starts where it stalls), in target order. Ctrl-C (the command line's
    /// [`crate::core::interrupt`]) ends it between blocks of targets with
    /// [`Error::Interrupted`].
    pub fn solve(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        k: usize,
        device: &Device,
    ) -> Result<Vec<Vec<PoseSolution>>> {
        self.solve_with(chain, targets, k, &self.saved.config.lm, device)
    }

    /// [`Self::solve`] with other solver settings (a budget of random starts, tolerances).
    pub fn solve_with(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        k: usize,
        cfg: &LmConfig,
        device: &Device,
    ) -> Result<Vec<Vec<PoseSolution>>> {
        let stop = crate::core::interrupt::requested;
        self.solve_until(chain, targets, k, cfg, device, &stop)
    }

    /// [`Self::solve_with`], asking `stop` on the calling thread before each block of targets
    /// (a few thousand answers, well under a second): `true` ends it with
    /// [`Error::Interrupted`] (Python passes its own signal check). The answers are those of
    /// one pass over all targets: each block samples the flow with the seeds a single pass
    /// would use.
    pub fn solve_until(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        k: usize,
        cfg: &LmConfig,
        device: &Device,
        stop: &dyn Fn() -> bool,
    ) -> Result<Vec<Vec<PoseSolution>>> {
        use rayon::prelude::*;
        /// The flow samples this many rows a batch (a block here).
        const FLOW_BATCH: usize = 1024;
        let k = k.max(1);
        // Targets refined between two questions to `stop`: about 4,096 answers.
        let per_check = (4096 / k).max(1);
        let ranges = &self.saved.ranges;
        let paths = chain.tip_paths();
        let mut answers: Vec<Vec<PoseSolution>> = Vec::with_capacity(targets.len());
        for (b, block) in targets.chunks(FLOW_BATCH).enumerate() {
            let first = b * FLOW_BATCH;
            let rows = condition_rows(&self.data, block, self.saved.config.position_only);
            let samples = sample_rows_from(
                &self.flow, &self.data, &rows, k, FLOW_BATCH, 0x5EED, b, device,
            );
            for (c, part) in block.chunks(per_check).enumerate() {
                if stop() {
                    return Err(Error::Interrupted(format!(
                        "stopped after {} of {} targets; nothing was written",
                        answers.len(),
                        targets.len()
                    )));
                }
                let offset = c * per_check;
                // Each sample refined on its own (the family of answers, not one), from random
                // starts where it stalls; the random starts differ between samples and targets.
                let solved: Vec<Vec<PoseSolution>> = part
                    .par_iter()
                    .enumerate()
                    .map(|(j, t)| {
                        let (i, j) = (first + offset + j, offset + j);
                        (0..k)
                            .map(|s| {
                                let start = [samples[s][j].clone()];
                                solve(&paths, t, &start, ranges, cfg, (i * k + s) as u64)
                            })
                            .collect()
                    })
                    .collect();
                answers.extend(solved);
            }
        }
        Ok(answers)
    }

    /// The flow's own answers (one sample per target, no refinement).
    pub fn sample(&self, targets: &[Vec<PoseTarget>], device: &Device) -> Vec<Vec<f64>> {
        let rows = condition_rows(&self.data, targets, self.saved.config.position_only);
        sample_rows(&self.flow, &self.data, &rows, 1, 1024, 0x5EED, device)
            .pop()
            .unwrap_or_default()
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

/// The CSV columns of a joint vector: the joints' names, or `q1..qN` where two share a name
/// or a name is one of `taken` (the file's other columns).
pub fn joint_columns(names: &[String], taken: &[&str]) -> Vec<String> {
    let clash = names.iter().enumerate().any(|(i, n)| {
        n.is_empty()
            || n.contains([',', '"', '\n'])
            || taken.contains(&n.as_str())
            || names[..i].contains(n)
    });
    if clash {
        (1..=names.len()).map(|i| format!("q{i}")).collect()
    } else {
        names.to_vec()
    }
}

/// The columns of a target: `x,y,z,qw,qx,qy,qz` (`x,y,z` when `position_only`) for one tip,
/// each prefixed with its tip's name (`A.x,...,B.x,...`) for several.
pub fn target_columns(tips: &[String], position_only: bool) -> Vec<String> {
    let axes: &[&str] = if position_only {
        &["x", "y", "z"]
    } else {
        &["x", "y", "z", "qw", "qx", "qy", "qz"]
    };
    if tips.is_empty() {
        return axes.iter().map(|a| a.to_string()).collect();
    }
    tips.iter()
        .flat_map(|t| axes.iter().map(move |a| format!("{t}.{a}")))
        .collect()
}

/// One target from its values in [`target_columns`] order (finite numbers): an error (what
/// is wrong, for the caller to place) for a position beyond [`MAX_TARGET_COORDINATE`] or a
/// quaternion that is not of unit norm. The one check of every way targets come in (a CSV
/// file, the Python package).
pub fn target_from_values(
    v: &[f64],
    position_only: bool,
    tips: &[String],
) -> std::result::Result<Vec<PoseTarget>, String> {
    let per_tip = if position_only { 3 } else { 7 };
    let want = per_tip * tips.len().max(1);
    if v.len() != want {
        return Err(format!("{} values where a target has {want}", v.len()));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("{x} is not a finite number"));
    }
    let mut row = Vec::with_capacity(v.len() / per_tip);
    for (t, v) in v.chunks(per_tip).enumerate() {
        let position = Point3::new(v[0], v[1], v[2]);
        if position.coords.amax() > MAX_TARGET_COORDINATE {
            return Err(format!(
                "the position ({}, {}, {}) lies more than {MAX_TARGET_COORDINATE} m from the robot's origin: give targets in metres",
                v[0], v[1], v[2]
            ));
        }
        let orientation = if position_only {
            None
        } else {
            let q = nalgebra::Quaternion::new(v[3], v[4], v[5], v[6]);
            let norm = q.norm();
            if !(0.9..=1.1).contains(&norm) {
                let of = tips.get(t).map_or(String::new(), |n| format!(" of {n}"));
                return Err(format!(
                    "the quaternion{of} (qw, qx, qy, qz) has norm {norm:.4}, not 1"
                ));
            }
            Some(nalgebra::UnitQuaternion::from_quaternion(q))
        };
        row.push(PoseTarget {
            position,
            orientation,
        });
    }
    Ok(row)
}

/// The farthest a target may lie from the robot's origin along an axis (m): far beyond any
/// robot's reach, near enough that it stays finite in the network's single precision.
pub const MAX_TARGET_COORDINATE: f64 = 1e3;

/// A target file's rows: [`target_columns`] (metres; a header names the columns, others are
/// ignored). A bad row fails naming its line.
pub fn read_targets(
    path: &Path,
    position_only: bool,
    tips: &[String],
) -> Result<Vec<Vec<PoseTarget>>> {
    let bad = |msg: String| Error::data(path, msg);
    let max = crate::core::input_file::MAX_TABLE_BYTES;
    crate::core::input_file::check_user_file(path, "targets file", max)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(file);
    let header = reader
        .headers()
        .map_err(|e| bad(format!("line 1: {e}")))?
        .clone();
    let need = target_columns(tips, position_only);
    if let Some(n) = need
        .iter()
        .find(|n| header.iter().filter(|h| h == n).count() > 1)
    {
        return Err(bad(format!(
            "line 1: the column \"{n}\" appears twice; keep one"
        )));
    }
    let cols: Vec<usize> = need
        .iter()
        .map(|n| {
            header.iter().position(|h| h == n).ok_or_else(|| {
                bad(format!(
                    "line 1: no column \"{n}\" (the header must name {}{})",
                    need.join(","),
                    if position_only {
                        ""
                    } else {
                        "; a position-only model takes x,y,z"
                    }
                ))
            })
        })
        .collect::<Result<_>>()?;
    let mut out = Vec::new();
    for (i, rec) in reader.records().enumerate() {
        let line = i + 2;
        if i % crate::core::interrupt::ROWS_BETWEEN_CHECKS == 0 {
            crate::core::interrupt::check(|| {
                format!("stopped reading {} at line {line}", path.display())
            })?;
        }
        let rec = rec.map_err(|e| bad(format!("line {line}: {e}")))?;
        let v: Vec<f64> = cols
            .iter()
            .map(|&c| {
                let cell = rec.get(c).unwrap_or("");
                cell.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(format!("line {line}: \"{cell}\" is not a finite number")))
            })
            .collect::<Result<_>>()?;
        let row = target_from_values(&v, position_only, tips)
            .map_err(|e| bad(format!("line {line}: {e}")))?;
        out.push(row);
    }
    if out.is_empty() {
        return Err(bad("no targets (a header and at least one row)".into()));
    }
    Ok(out)
}
