//! What every part of the study shares ([`Bench`]: the trained self-model, its data, the
//! devices) and how an estimate is scored against the true angles.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::BodyFromImageConfig;
use selfmodel::body::drift::estimate_offsets;
use selfmodel::body::observations::{ImageFit, Observed};
use selfmodel::body::pose::{PoseFitConfig, pose_from_image, pose_losses};
use selfmodel::core::error::Result;
use selfmodel::self_models::harness::Fitted;
use selfmodel::self_models::model::Render;
use selfmodel::sim::robot::Robot;

/// Errors of estimated poses against the truth.
struct Scores {
    mean: f64,
    median: f64,
    per_joint: Vec<f64>,
    end_effector_mm: f64,
    within_2: f64,
}

fn score(robot: &Robot, found: &[Vec<f64>], truth: &[Vec<f64>]) -> Scores {
    let dof = truth[0].len();
    let mut all: Vec<f64> = Vec::new();
    let mut per_joint = vec![0.0; dof];
    let mut within = 0;
    let mut ee = 0.0;
    for (f, t) in found.iter().zip(truth) {
        let e: Vec<f64> = f.iter().zip(t).map(|(a, b)| (a - b).abs()).collect();
        for (j, v) in e.iter().enumerate() {
            per_joint[j] += v / truth.len() as f64;
        }
        within += usize::from(e.iter().all(|&v| v <= 2.0));
        all.extend(e);
        let (pf, pt) = (
            robot.chain.end_effector(&robot.chain.to_si(f)),
            robot.chain.end_effector(&robot.chain.to_si(t)),
        );
        ee += 1000.0 * (pf - pt).norm() / truth.len() as f64;
    }
    Scores {
        mean: all.iter().sum::<f64>() / all.len() as f64,
        median: selfmodel::core::timing::median(&all),
        per_joint,
        end_effector_mm: ee,
        within_2: within as f64 / truth.len() as f64,
    }
}

/// One method on one kind of image: a row of `pose.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseRow {
    pub method: String,
    pub images: String,
    pub poses: usize,
    pub mean_joint_error_deg: f64,
    pub median_joint_error_deg: f64,
    /// Mean error of each joint, "j1 / j2 / ...".
    pub per_joint_deg: String,
    pub end_effector_mm: f64,
    /// Poses with every joint within 2 degrees.
    pub within_2deg_share: f64,
    /// Milliseconds per pose, one image at a time (NaN: not timed).
    pub ms_per_pose_b1: f64,
    /// Milliseconds per pose over the whole batch.
    pub ms_per_pose_batched: f64,
    /// Poses whose estimate the self-model scores better (a lower loss against the observed
    /// image) than the true angles: there the model's optimum is not the truth, and no
    /// optimiser could do better through it.
    pub loss_below_truth_share: f64,
    pub preset: String,
    pub device: String,
    pub git_revision: String,
}
/// Everything one run shares: the trained self-model (and its data), the robot, the devices.
pub struct Bench<'a> {
    pub cfg: &'a BodyFromImageConfig,
    pub robot: &'a Robot,
    pub fitted: &'a Fitted<Box<dyn Render>>,
    pub renderer: &'a dyn Render,
    pub differentiable: &'a dyn Render,
    pub device: &'a Device,
    pub autodiff: &'a Device,
    pub image: [usize; 2],
    pub ranges: Vec<[f64; 2]>,
    pub device_name: String,
    pub revision: String,
}

/// Milliseconds per pose: one image at a time and over the whole batch (NaN: not timed).
#[derive(Clone, Copy)]
pub struct Ms {
    pub b1: f64,
    pub batched: f64,
}

impl Ms {
    pub const UNTIMED: Ms = Ms {
        b1: f64::NAN,
        batched: f64::NAN,
    };
}

/// Images an estimate was made from, and what they are ("clean", or a perturbation's label).
pub struct Seen<'a> {
    pub label: &'a str,
    pub observed: &'a Observed,
}

impl Bench<'_> {
    /// A row of `results.csv`: `found` against `truth` for the images `seen`, judged
    /// through `through` (on its device).
    pub fn row(
        &self,
        method: &str,
        found: &[Vec<f64>],
        truth: &[Vec<f64>],
        ms: Ms,
        seen: Seen,
        through: (&dyn Render, &Device),
    ) -> Result<PoseRow> {
        let s = score(self.robot, found, truth);
        let images = seen.label;
        let seen = seen.observed.select(0..found.len());
        let at = |q: &[Vec<f64>]| pose_losses(through.0, through.1, &seen, q, self.cfg.refine.loss);
        let (l_found, l_truth) = (at(found)?, at(truth)?);
        let below = l_found.iter().zip(&l_truth).filter(|(f, t)| f < t).count();
        Ok(PoseRow {
            method: method.into(),
            images: images.into(),
            poses: truth.len(),
            mean_joint_error_deg: s.mean,
            median_joint_error_deg: s.median,
            per_joint_deg: s
                .per_joint
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
                .join(" / "),
            end_effector_mm: s.end_effector_mm,
            within_2deg_share: s.within_2,
            ms_per_pose_b1: ms.b1,
            ms_per_pose_batched: ms.batched,
            loss_below_truth_share: below as f64 / found.len() as f64,
            preset: self.cfg.preset.clone(),
            device: self.device_name.clone(),
            git_revision: self.revision.clone(),
        })
    }

    /// Refine `guesses` through `through` (a differentiable self-model on `self.autodiff`).
    pub fn refine(
        &self,
        through: &dyn Render,
        observed: &Observed,
        guesses: &[Vec<f64>],
        cfg: &PoseFitConfig,
    ) -> Result<Vec<Vec<f64>>> {
        Ok(pose_from_image(
            ImageFit {
                renderer: through,
                device: self.autodiff,
                image: self.image,
                observed,
            },
            &self.ranges,
            Some(guesses),
            cfg,
            |_| {},
        )?
        .angles)
    }

    /// The offsets estimated from one capture of poses `truth` whose encoders report
    /// `truth + offset`.
    pub fn offsets(
        &self,
        observed: &Observed,
        truth: &[Vec<f64>],
        offset: &[f64],
    ) -> Result<Vec<f64>> {
        let reported: Vec<Vec<f64>> = truth
            .iter()
            .map(|q| q.iter().zip(offset).map(|(v, o)| v + o).collect())
            .collect();
        estimate_offsets(
            ImageFit {
                renderer: self.differentiable,
                device: self.autodiff,
                image: self.image,
                observed,
            },
            &reported,
            &self.cfg.drift,
        )
    }
}
