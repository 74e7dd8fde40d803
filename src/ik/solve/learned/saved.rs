//! A saved model: what `model.json` holds and checks, the robot's fingerprint, writing a
//! trained model and loading it back (against the robot it was trained on).

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::input_file::file_fnv;
use crate::ik::data::IkData;
use crate::ik::flow::FlowIk;
use crate::sim::kinematics::KinematicChain;
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;

use super::conditions::condition_width;
use super::{LearnedIk, LearnedIkConfig};

/// What `model.json` holds.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SavedModel {
    pub config: LearnedIkConfig,
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
pub(super) const MAX_RANGE: f64 = 1e4;
/// The most iterations and random starts a saved model may ask of its solver per answer.
pub(super) const MAX_ITERATIONS: usize = 100_000;
pub(super) const MAX_STARTS: usize = 10_000;

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

impl SavedModel {
    /// What `model.json` will say of a model of `chain` (as `spec` names it) trained with
    /// `cfg` on `data`, answering for `tips`; the weights' hash is set when they are written.
    pub(super) fn describe(
        cfg: &LearnedIkConfig,
        spec: &RobotSpec,
        chain: &KinematicChain,
        tips: Vec<String>,
        data: &IkData,
    ) -> Self {
        // The solver's budget for the model's tips (one tip: the preset's).
        let mut config = cfg.clone();
        config.lm = config.lm.for_tips(tips.len());
        SavedModel {
            config,
            robot: spec.clone(),
            robot_fingerprint: chain.fingerprint(),
            joint_names: chain.joint_names(),
            tips: if tips.len() > 1 { tips } else { Vec::new() },
            weights_fnv: None,
            ranges: data.ranges.clone(),
            position_bounds: data.position_bounds,
            git_revision: crate::core::provenance::git_revision(),
        }
    }
}

/// Write a trained model into `dir`: `model.bpk`, `model.json` (`saved`, with the weights'
/// hash) and the validation curve; the training checkpoint is removed.
pub(super) fn save_model(
    dir: &Path,
    trained: &crate::ik::flow::TrainedFlow,
    mut saved: SavedModel,
    checkpoint: &Path,
) -> Result<SavedModel> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let weights = dir.join("model.bpk");
    crate::train::checkpoint::save_module(&trained.model, &weights)?;
    saved.weights_fnv = Some(file_fnv(&weights)?);
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

impl LearnedIk {
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
        Ok(LearnedIk {
            saved,
            flow,
            data,
            device: device.clone(),
        })
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
        let print = robot.chain.fingerprint();
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
}
