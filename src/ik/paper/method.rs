//! The IkMethod trait: what Table II runs. A method trains on the random training samples (or,
//! self-supervised, only on their positions and the forward model) and answers the test
//! targets in batches; it hands back its answers (one or more rows: one sample, the best of
//! k), its validation curve and, for EMSSL, its iteration curve. A new method is one type
//! implementing [`IkMethod`] and one line in Table II's list (`studies::emssl::table2`).

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use nalgebra::Point3;

use crate::core::error::Result;
use crate::ik::data::IkData;
use crate::ik::paper::emssl::iteration::EmsslIteration;
use crate::sim::kinematics::KinematicChain;
use crate::train::convergence::ConvergenceLog;

/// What a method works with in one joint range.
pub struct IkTask<'a> {
    /// The arm (the forward model: called, never differentiated, by the self-supervised
    /// methods).
    pub chain: &'a KinematicChain,
    pub data: &'a IkData,
    /// The test targets to answer.
    pub targets: &'a [Point3<f64>],
    pub device: &'a Device,
    /// Targets per inference batch.
    pub batch: usize,
    pub range_deg: f64,
    /// Where methods keep files (checkpoints, a model later steps read): `units/<range>/`.
    pub files: &'a Path,
    /// Where every method's answers are written: `predictions_<range>/`.
    pub predictions: &'a Path,
}

impl IkTask<'_> {
    /// A file of `files` named after `name` ("EMSSL checkpoint" -> `emssl_checkpoint`),
    /// with `extension` (none if empty).
    pub fn file(&self, name: &str, extension: &str) -> PathBuf {
        self.files.join(file_name(name)).with_extension(extension)
    }

    /// `fit` keeping checkpoints in this task's files (`<name> checkpoint/`, a folder per
    /// network), valid only for `settings` (the method's) in this range: a killed run
    /// continues from its last epoch.
    pub fn checkpointed(
        &self,
        name: &str,
        settings: serde_json::Value,
        fit: &crate::ik::learning::FitConfig,
    ) -> crate::ik::learning::FitConfig {
        crate::ik::learning::FitConfig {
            checkpoint: Some(crate::train::convergence::FitCheckpoint {
                dir: self.file(&format!("{name} checkpoint"), ""),
                settings: serde_json::json!({
                    "method": settings,
                    "range_deg": self.range_deg,
                    "samples": self.data.positions.len(),
                }),
            }),
            ..fit.clone()
        }
    }

    /// Where the answers of the row `method` are written.
    pub fn predictions_path(&self, method: &str) -> PathBuf {
        self.predictions.join(format!("{}.csv", file_name(method)))
    }
}

/// A method's file name: "EMSSL + DLS" -> "emssl_dls".
pub use crate::core::atomic_file::file_name;

/// A method's answers for the test targets: one row of Table II.
pub struct Answers {
    pub method: String,
    /// Joints (radians) per test target.
    pub joints: Vec<Vec<f64>>,
    pub train_seconds: f64,
    /// Seconds to answer every test target once trained.
    pub solve_seconds: f64,
    pub epochs: Option<usize>,
    pub validation_cm: Option<f64>,
    pub diversity_rad: Option<f64>,
    pub detail: String,
}

impl Answers {
    pub fn new(
        method: &str,
        joints: Vec<Vec<f64>>,
        train_seconds: f64,
        solve_seconds: f64,
    ) -> Self {
        Answers {
            method: method.into(),
            joints,
            train_seconds,
            solve_seconds,
            epochs: None,
            validation_cm: None,
            diversity_rad: None,
            detail: String::new(),
        }
    }

    /// Epochs, validation error and how it stopped, from a run to convergence (`None`: the
    /// fixed schedule of `fixed_epochs`).
    pub fn converged(mut self, log: &Option<ConvergenceLog>, fixed_epochs: usize) -> Self {
        match log {
            Some(l) => {
                // A run continued from a checkpoint counts its seconds before the restart.
                self.train_seconds = self.train_seconds.max(l.seconds);
                self.epochs = Some(l.epochs);
                self.validation_cm = Some(l.best_validation);
                self.detail = l.summary();
            }
            None => {
                self.epochs = Some(fixed_epochs);
                self.detail = format!("{fixed_epochs} epochs (fixed)");
            }
        }
        self
    }
}

/// One epoch (or iteration) of one method's validation curve.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ValidationRow {
    pub range_deg: f64,
    pub method: String,
    pub epoch: usize,
    pub learning_rate: f64,
    pub train_loss: f64,
    pub validation_cm: f64,
    pub seconds: f64,
}

impl ValidationRow {
    /// The curve of a run to convergence.
    pub fn from_log(range_deg: f64, method: &str, log: &ConvergenceLog) -> Vec<Self> {
        log.curve
            .iter()
            .map(|p| ValidationRow {
                range_deg,
                method: method.into(),
                epoch: p.epoch,
                learning_rate: p.learning_rate,
                train_loss: p.train_loss,
                validation_cm: p.validation,
                seconds: p.seconds,
            })
            .collect()
    }
}

/// What a method hands back.
#[derive(Default)]
pub struct MethodOutput {
    pub answers: Vec<Answers>,
    pub curves: Vec<ValidationRow>,
    pub emssl_curve: Vec<EmsslIteration>,
}

/// A learned (or numerical) inverse-kinematics method of Table II.
pub trait IkMethod {
    /// Its name: the row label and the unit's file name.
    fn name(&self) -> String;
    /// Everything its result depends on besides the data: a finished unit is reused only if
    /// this is unchanged.
    fn settings(&self) -> serde_json::Value;
    /// Files it makes that later steps read (a finished unit without them runs again).
    fn required(&self, _task: &IkTask) -> Vec<PathBuf> {
        Vec::new()
    }
    /// Train, then answer `task.targets`.
    fn run(&self, task: &IkTask) -> Result<MethodOutput>;
}

/// Seconds to run `f`: one warm-up pass, then the median of three.
pub fn timed(f: &mut dyn FnMut()) -> f64 {
    crate::core::timing::median_seconds(crate::core::timing::Repeats::exactly(1, 3), f)
}

/// A value's JSON, for [`IkMethod::settings`].
pub fn settings_json<S: serde::Serialize>(s: &S) -> serde_json::Value {
    serde_json::to_value(s).expect("settings serialise")
}
