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
//! The self-models are NeuroKin (checkpointed, `--resume` continues it) and K-3DGS (isotropic,
//! alpha compositing) of the same preset, trained here.

mod bench;
mod calibration;
mod drift;
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
use selfmodel::self_models::harness::fit_run;
use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::train::trainer::autodiff_device;

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
}

impl BodyFromImageConfig {
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
        };
        match name {
            "paper" => Ok(paper),
            // The same, reading through the self-models of the `large` preset (12,000 images).
            "large" => Ok(BodyFromImageConfig {
                preset: "large".into(),
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
                "unknown preset \"{other}\" for body_from_image (choose paper, large or quick)"
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
    let (device_choice, resume) = (opts.device, opts.resume);
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // The robot and camera the options name (the papers' arm by default).
    let model_run = opts.apply(neurokin_run(&cfg.preset)?)?;
    let fitted = fit_run(&model_run, &out.join("checkpoint"), device_choice, resume)?.erased();
    let device = fitted.device.clone();
    let autodiff = autodiff_device(&device, cfg.seed);
    let renderer = fitted.trained.renderers[0].1.as_ref();
    let differentiable = renderer
        .differentiable(&autodiff)
        .ok_or_else(|| Error::Config("the self-model cannot be differentiated".into()))?;
    // K-3DGS (isotropic, alpha compositing) on the same data: its Gaussians hang on the
    // chain, so it also reads link lengths. It keeps no checkpoint (densification changes its
    // shapes); it trains in about a minute on the paper preset.
    let k3dgs_run = opts.apply(k3dgs_run(&cfg.preset, K3dgsVariant::IsotropicAlpha)?)?;
    let k3dgs_fitted = fit_run(
        &k3dgs_run,
        &out.join("k3dgs_checkpoint"),
        device_choice,
        false,
    )?
    .erased();
    let _ = std::fs::remove_dir_all(out.join("k3dgs_checkpoint"));
    let k3dgs = k3dgs_fitted.trained.renderers[0]
        .1
        .differentiable(&autodiff)
        .ok_or_else(|| Error::Config("K-3DGS cannot be differentiated".into()))?;
    let robot = model_run.data.robot.load()?;
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
        device_name: device_choice.to_string(),
        revision: git_revision(),
    };
    let n = cfg.test_poses.min(fitted.test_range.len());
    let test: Vec<usize> = fitted.test_range.clone().take(n).collect();
    let truth: Vec<Vec<f64>> = test.iter().map(|&i| data.angles[i].clone()).collect();
    let observed = Observed::from_dataset(data, &test);
    let rows = pose::pose_rows(&bench, k3dgs.as_ref(), seen, &observed, &truth, out)?;
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

/// The line the binary prints: the refined CNN, the drift at the largest k, the smallest
/// offset detected in 90% of trials and the calibration at the largest k.
fn summary(
    r: &PoseRow,
    drift_rows: &[DriftRow],
    detection_rows: &[DetectionRow],
    calibration_rows: &[CalibrationRow],
) -> String {
    let smallest = detection_rows
        .iter()
        .find(|r| r.detected_share >= 0.9)
        .map_or("none".to_string(), |r| format!("{} deg", r.offset_deg));
    let calibrated = calibration_rows.last().map_or(String::new(), |c| {
        format!(
            "; links +{} cm from {} images: {:.1} mm mean error",
            c.change_cm, c.k, c.mean_error_mm
        )
    });
    format!(
        "pose from image ({}): median joint error {:.2} deg, {:.0}% of poses within 2 deg, {:.1} ms/pose batched; drift from {} images: {:.2} deg; smallest offset detected in 90% of trials: {smallest}{calibrated}",
        r.method,
        r.median_joint_error_deg,
        100.0 * r.within_2deg_share,
        r.ms_per_pose_batched,
        drift_rows.last().map_or(0, |d| d.k),
        drift_rows.last().map_or(f64::NAN, |d| d.offset_error_deg),
    )
}
