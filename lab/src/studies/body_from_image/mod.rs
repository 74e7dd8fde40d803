//! `body_from_image`: the trained self-model read backwards ([`selfmodel::body`]) on the test set
//! of the papers' arm. Writes `reports/body_from_image/`:
//! - `results.csv`: joint angles from silhouettes. Methods: the mean training pose (a
//!   baseline), the amortised CNN, the CNN refined through the self-model, and a search from
//!   random starts without a guess; the refined CNN also on spoiled images (pixels flipped,
//!   an occluder, a 1-pixel shift), and refined through K-3DGS instead. Errors per joint and overall (degrees), end effector (mm),
//!   the share of poses with every joint within 2 degrees, milliseconds per pose.
//! - `drift.csv`: encoder offsets (uniform in +-`max_offset_deg` on every joint) recovered from
//!   k images, against k. The protocol: the robot visits k poses; the same poses seen once
//!   while its encoders were known good give a reference estimate, and the drift is the
//!   difference of the two estimates (the self-model's own error on those poses cancels).
//!   Every capture has its own sensor noise (`capture_flip` of the pixels flipped). The error
//!   without the reference (the estimate taken as it is) is reported beside it.
//! - `detection.csv`: the smallest offset told apart from healthy encoders. The robot's k
//!   calibration poses are estimated once while healthy; every trial is a new capture of them.
//!   The statistic is the largest |offset - reference| over the joints; the threshold is its
//!   99th percentile on healthy trials (a false alarm rate of 1%), and the table gives the
//!   share of trials detected per offset size on one joint.
//! - `calibration.csv`: link lengths from images: every link lengthened by 1, 3 or 5 cm, seen in
//!   k test poses, read through K-3DGS with its joint origins fitted ([`selfmodel::body::calibration`]).
//! - `figures`: `pose_grid.png` (observed, rendered at the estimate, error), `drift_vs_k.png`
//!   and `calibration_vs_k.png`.
//!
//! - `groups.csv`: the clean images' estimates scored per joint group (the chains between the
//!   kinematic tree's branch points: on the G1 the legs, the waist and the arms).
//!
//! The self-models are NeuroKin (checkpointed, `--resume` continues it) and K-3DGS (isotropic,
//! alpha compositing) of the same preset, trained here. The `humanoid` preset (issue 75: the
//! G1's whole body, `--urdf ... --joints all --train-samples 9600`) reads through LinkSplat
//! instead, trained 12,000 steps along a half-cosine learning rate, and reads poses only
//! (drift, detection and calibration are the arm's studies).

mod bench;
mod calibration;
mod drift;
pub mod groups;
mod pose;

use std::path::Path;

use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::{Deserialize, Serialize};

pub use bench::PoseRow;
pub use calibration::CalibrationRow;
pub use drift::{DetectionRow, DriftRow};

use bench::Bench;
use selfmodel::body::amortised::AmortisedConfig;
use selfmodel::body::calibration::VisualCalibrationConfig;
use selfmodel::body::drift::DriftConfig;
use selfmodel::body::observations::{Observed, Perturbation};
use selfmodel::body::pose::{PoseFitConfig, trained_ranges};
use selfmodel::core::atomic_file::write_json;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::provenance::git_revision;
use selfmodel::self_models::harness::Fitted;
use selfmodel::self_models::harness::fit_run;
use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
use selfmodel::self_models::link_splat::link_splat_run;
use selfmodel::self_models::model::Render;
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::sim::robots::RobotSpec;
use selfmodel::train::config::LrSchedule;
use selfmodel::train::trainer::autodiff_device;

/// The self-model the study reads through.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReadThrough {
    /// NeuroKin of the preset (checkpointed).
    #[default]
    NeuroKin,
    /// LinkSplat on the preset's data, trained `steps` steps along `schedule` (checkpointed).
    LinkSplat { steps: usize, schedule: LrSchedule },
}

impl ReadThrough {
    fn is_neurokin(&self) -> bool {
        *self == ReadThrough::NeuroKin
    }
}

/// The study's settings. Presets: `paper` (the 400 test poses) and `quick` (seconds).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BodyFromImageConfig {
    pub preset: String,
    /// Test poses read (the first ones of the test set).
    pub test_poses: usize,
    /// Test poses searched without a guess (the search is the slow method).
    pub search_poses: usize,
    pub amortised: AmortisedConfig,
    pub refine: PoseFitConfig,
    pub search: PoseFitConfig,
    pub perturbations: Vec<Perturbation>,
    pub drift: DriftConfig,
    pub drift_ks: Vec<usize>,
    pub drift_trials: usize,
    pub max_offset_deg: f64,
    /// Share of pixels flipped in every capture (sensor noise) of the drift trials.
    pub capture_flip: f64,
    pub detection_k: usize,
    pub healthy_trials: usize,
    pub detection_offsets_deg: Vec<f64>,
    pub detection_trials: usize,
    /// Visual calibration: every link lengthened by each of these (cm), read from k images.
    pub calibration_changes_cm: Vec<f64>,
    pub calibration_ks: Vec<usize>,
    pub calibration: VisualCalibrationConfig,
    pub seed: u64,
    /// The self-model read through (absent from a saved config: NeuroKin).
    #[serde(default, skip_serializing_if = "ReadThrough::is_neurokin")]
    pub reads_through: ReadThrough,
    /// Pose from image only: no K-3DGS, drift, detection or calibration (absent: the whole
    /// study).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub pose_only: bool,
}

impl BodyFromImageConfig {
    /// The preset of the self-models it trains (`humanoid`'s: `paper`).
    fn model_preset(&self) -> &str {
        if self.preset == "humanoid" {
            "paper"
        } else {
            &self.preset
        }
    }

    pub fn preset(name: &str) -> Result<Self> {
        let paper = BodyFromImageConfig {
            preset: "paper".into(),
            test_poses: 400,
            search_poses: 50,
            amortised: AmortisedConfig::paper(),
            refine: PoseFitConfig::refine(30),
            search: PoseFitConfig::search(16, 100),
            perturbations: vec![
                Perturbation::FlipPixels(0.05),
                Perturbation::Occlude(0.10),
                Perturbation::Shift(1, 0),
            ],
            drift: DriftConfig {
                steps: 100,
                ..DriftConfig::paper()
            },
            drift_ks: vec![1, 3, 10, 30],
            drift_trials: 10,
            max_offset_deg: 5.0,
            capture_flip: 0.01,
            detection_k: 10,
            healthy_trials: 100,
            detection_offsets_deg: vec![0.1, 0.2, 0.5, 1.0, 2.0],
            detection_trials: 10,
            calibration_changes_cm: vec![1.0, 3.0, 5.0],
            calibration_ks: vec![1, 3, 10, 30],
            calibration: VisualCalibrationConfig::paper(),
            seed: 0,
            reads_through: ReadThrough::NeuroKin,
            pose_only: false,
        };
        match name {
            "paper" => Ok(paper),
            // The same, reading through the self-models of the `large` preset (12,000 images).
            "large" => Ok(BodyFromImageConfig {
                preset: "large".into(),
                ..paper
            }),
            // The G1's whole body through LinkSplat: pose from image only; the search (random
            // starts in 29 joints) on 20 poses.
            "humanoid" => Ok(BodyFromImageConfig {
                preset: "humanoid".into(),
                search_poses: 20,
                reads_through: ReadThrough::LinkSplat {
                    steps: 12_000,
                    schedule: LrSchedule::Cosine,
                },
                pose_only: true,
                ..paper
            }),
            "quick" => Ok(BodyFromImageConfig {
                preset: "quick".into(),
                test_poses: 12,
                search_poses: 4,
                amortised: AmortisedConfig::quick(),
                refine: PoseFitConfig::refine(10),
                search: PoseFitConfig::search(4, 20),
                drift: DriftConfig {
                    steps: 40,
                    ..DriftConfig::paper()
                },
                drift_ks: vec![1, 3],
                drift_trials: 2,
                detection_k: 3,
                healthy_trials: 4,
                detection_offsets_deg: vec![1.0, 5.0],
                detection_trials: 2,
                calibration_changes_cm: vec![5.0],
                calibration_ks: vec![3],
                calibration: VisualCalibrationConfig {
                    steps: 60,
                    ..VisualCalibrationConfig::paper()
                },
                ..paper
            }),
            other => Err(Error::Config(format!(
                "unknown preset \"{other}\" for body_from_image (choose paper, large, humanoid or quick)"
            ))),
        }
    }
}

/// Run the study into `out`: the self-models trained (or resumed), then pose from image, drift,
/// detection and calibration, each writing its table; the summary line.
pub fn run(
    cfg: &BodyFromImageConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
) -> Result<String> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // The robot and camera the options name (the papers' arm by default).
    let (fitted, robot_spec, model) = read_through(cfg, opts, out)?;
    let device = fitted.device.clone();
    let autodiff = autodiff_device(&device, cfg.seed);
    let renderer = fitted.trained.renderers[0].1.as_ref();
    let differentiable = renderer
        .differentiable(&autodiff)
        .ok_or_else(|| Error::Config("the self-model cannot be differentiated".into()))?;
    let k3dgs = if cfg.pose_only {
        None
    } else {
        Some(k3dgs(cfg, opts, out, &autodiff)?)
    };
    let robot = robot_spec.load()?;
    let data = &fitted.data;
    let seen = &data.angles[fitted.train_range.clone()];
    let bench = Bench {
        cfg,
        robot: &robot,
        fitted: &fitted,
        renderer,
        differentiable: differentiable.as_ref(),
        device: &device,
        autodiff: &autodiff,
        image: [data.height, data.width],
        ranges: trained_ranges(seen),
        device_name: opts.device.to_string(),
        revision: git_revision(),
    };
    let n = cfg.test_poses.min(fitted.test_range.len());
    let test: Vec<usize> = fitted.test_range.clone().take(n).collect();
    let truth: Vec<Vec<f64>> = test.iter().map(|&i| data.angles[i].clone()).collect();
    let observed = Observed::from_dataset(data, &test);
    let through = pose::Through {
        model: &model,
        k3dgs: k3dgs.as_deref(),
    };
    let rows = pose::pose_rows(&bench, through, seen, &observed, &truth, out)?;
    let Some(k3dgs) = k3dgs else {
        write_json(&out.join("config.json"), cfg)?;
        return Ok(summary(&rows[2], &[], &[], &[]));
    };
    // Drift, then detection, drawing from one generator and one run of capture seeds.
    let mut rng = StdRng::seed_from_u64(cfg.seed ^ 0xD41F7);
    let mut seed = 1000u64;
    let drift_rows = drift::drift_rows(&bench, &mut rng, &mut seed, out)?;
    let detection_rows = drift::detection_rows(&bench, &mut rng, &mut seed, out)?;
    let calibration_rows = calibration::visual_calibration(k3dgs.as_ref(), &bench, out)?;
    write_json(&out.join("config.json"), cfg)?;
    Ok(summary(
        &rows[2],
        &drift_rows,
        &detection_rows,
        &calibration_rows,
    ))
}

/// The self-model the study reads through, trained (or resumed, `--resume`) on the data the
/// options name, checkpointed in `out/checkpoint`; with the robot it sees and its name.
fn read_through(
    cfg: &BodyFromImageConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
) -> Result<(Fitted<Box<dyn Render>>, RobotSpec, String)> {
    let (device, resume, checkpoint) = (opts.device, opts.resume, out.join("checkpoint"));
    let preset = cfg.model_preset();
    Ok(match &cfg.reads_through {
        ReadThrough::NeuroKin => {
            let run = opts.apply(neurokin_run(preset)?)?;
            let fitted = fit_run(&run, &checkpoint, device, resume)?.erased();
            (fitted, run.data.robot.clone(), run.name)
        }
        ReadThrough::LinkSplat { steps, schedule } => {
            let mut run = opts.apply(link_splat_run(preset)?)?;
            run.train.steps = *steps;
            run.train.schedule = *schedule;
            let fitted = fit_run(&run, &checkpoint, device, resume)?.erased();
            (fitted, run.data.robot.clone(), run.name)
        }
    })
}

/// K-3DGS (isotropic, alpha compositing) on the same data, differentiable on `autodiff`: its
/// Gaussians hang on the chain, so it also reads link lengths. It keeps no checkpoint
/// (densification changes its shapes); it trains in about a minute on the paper preset.
fn k3dgs(
    cfg: &BodyFromImageConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
    autodiff: &burn::tensor::Device,
) -> Result<Box<dyn Render>> {
    let run = opts.apply(k3dgs_run(cfg.model_preset(), K3dgsVariant::IsotropicAlpha)?)?;
    let fitted = fit_run(&run, &out.join("k3dgs_checkpoint"), opts.device, false)?.erased();
    let _ = std::fs::remove_dir_all(out.join("k3dgs_checkpoint"));
    fitted.trained.renderers[0]
        .1
        .differentiable(autodiff)
        .ok_or_else(|| Error::Config("K-3DGS cannot be differentiated".into()))
}

/// The line the binary prints: the refined CNN and, where the study ran them, the drift at
/// the largest k, the smallest offset detected in 90% of trials and the calibration at the
/// largest k.
fn summary(
    r: &PoseRow,
    drift_rows: &[DriftRow],
    detection_rows: &[DetectionRow],
    calibration_rows: &[CalibrationRow],
) -> String {
    let mut line = format!(
        "pose from image ({}): median joint error {:.2} deg, {:.0}% of poses within 2 deg, {:.1} ms/pose batched",
        r.method,
        r.median_joint_error_deg,
        100.0 * r.within_2deg_share,
        r.ms_per_pose_batched,
    );
    if let Some(d) = drift_rows.last() {
        let smallest = detection_rows
            .iter()
            .find(|r| r.detected_share >= 0.9)
            .map_or("none".to_string(), |r| format!("{} deg", r.offset_deg));
        line += &format!(
            "; drift from {} images: {:.2} deg; smallest offset detected in 90% of trials: {smallest}",
            d.k, d.offset_error_deg
        );
    }
    if let Some(c) = calibration_rows.last() {
        line += &format!(
            "; links +{} cm from {} images: {:.1} mm mean error",
            c.change_cm, c.k, c.mean_error_mm
        );
    }
    line
}
