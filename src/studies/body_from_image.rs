//! `body_from_image`: the trained self-model read backwards ([`crate::body`]) on the test set
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
//!   k test poses, read through K-3DGS with its joint origins fitted ([`crate::body::calibration`]).
//! - `figures`: `pose_grid.png` (observed, rendered at the estimate, error), `drift_vs_k.png`
//!   and `calibration_vs_k.png`.
//!
//! The self-models are NeuroKin (checkpointed, `--resume` continues it) and K-3DGS (isotropic,
//! alpha compositing) of the same preset, trained here.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use rand::rngs::StdRng;
use rand::seq::index::sample;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::body::amortised::{AmortisedConfig, train_estimator};
use crate::body::calibration::{VisualCalibrationConfig, fit_joint_origins};
use crate::body::drift::{DriftConfig, estimate_offsets};
use crate::body::observations::{Observed, Perturbation, host};
use crate::body::pose::{PoseFitConfig, pose_from_image, pose_losses, trained_ranges};
use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::provenance::git_revision;
use crate::core::timing::{Repeats, median_seconds};
use crate::report::figures::{GridRow, image_grid, log_log_lines};
use crate::report::table::{write_csv, write_markdown_report};
use crate::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
use crate::self_models::neurokin::neurokin_run;
use crate::self_models::{harness::fit_run, model::Render};
use crate::sim::robot::Robot;
use crate::train::trainer::autodiff_device;

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

/// Offset recovery against k: a row of `drift.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriftRow {
    pub k: usize,
    pub trials: usize,
    /// Mean over trials and joints of |recovered - true| with the healthy reference.
    pub offset_error_deg: f64,
    /// The largest over trials and joints.
    pub max_offset_error_deg: f64,
    /// The same without the reference (the estimate as it is).
    pub offset_error_no_reference_deg: f64,
    pub preset: String,
    pub device: String,
    pub git_revision: String,
}

/// Detection of a small offset: a row of `detection.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectionRow {
    pub offset_deg: f64,
    pub k: usize,
    pub trials: usize,
    /// The healthy trials' 99th percentile of max |offset| (the alarm threshold).
    pub threshold_deg: f64,
    pub detected_share: f64,
    pub preset: String,
    pub device: String,
    pub git_revision: String,
}

/// Link lengths read from images: a row of `calibration.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CalibrationRow {
    /// Every link lengthened by this much (cm).
    pub change_cm: f64,
    pub k: usize,
    /// The change recovered on each link with a length, "l1 / l2 / ..." (mm): the fit to the
    /// changed arm's images less the fit to the healthy arm's images of the same poses.
    pub recovered_mm: String,
    /// Mean and largest |recovered - true| over those links (mm).
    pub mean_error_mm: f64,
    pub max_error_mm: f64,
    /// The mean error of the fit to the changed arm taken as it is (no healthy reference).
    pub mean_error_no_reference_mm: f64,
    pub preset: String,
    pub device: String,
    pub git_revision: String,
}

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
        median: crate::core::timing::median(&all),
        per_joint,
        end_effector_mm: ee,
        within_2: within as f64 / truth.len() as f64,
    }
}

/// Everything one run shares.
struct Bench<'a> {
    cfg: &'a BodyFromImageConfig,
    robot: &'a Robot,
    renderer: &'a dyn Render,
    differentiable: &'a dyn Render,
    device: &'a Device,
    autodiff: &'a Device,
    image: [usize; 2],
    ranges: Vec<[f64; 2]>,
    device_name: String,
    revision: String,
}

impl Bench<'_> {
    /// A row of `results.csv`: `found` against `truth` for the images `observed`, judged
    /// through `through` (on `device`).
    #[allow(clippy::too_many_arguments)]
    fn row(
        &self,
        method: &str,
        images: &str,
        found: &[Vec<f64>],
        truth: &[Vec<f64>],
        b1: f64,
        batched: f64,
        observed: &Observed,
        through: (&dyn Render, &Device),
    ) -> Result<PoseRow> {
        let s = score(self.robot, found, truth);
        let seen = observed.select(0..found.len());
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
            ms_per_pose_b1: b1,
            ms_per_pose_batched: batched,
            loss_below_truth_share: below as f64 / found.len() as f64,
            preset: self.cfg.preset.clone(),
            device: self.device_name.clone(),
            git_revision: self.revision.clone(),
        })
    }

    /// Refine `guesses` through `through` (a differentiable self-model on `self.autodiff`).
    fn refine(
        &self,
        through: &dyn Render,
        observed: &Observed,
        guesses: &[Vec<f64>],
        cfg: &PoseFitConfig,
    ) -> Result<Vec<Vec<f64>>> {
        Ok(pose_from_image(
            through,
            self.autodiff,
            self.image,
            observed,
            &self.ranges,
            Some(guesses),
            cfg,
            |_| {},
        )?
        .angles)
    }

    /// The offsets estimated from one capture of poses `truth` whose encoders report
    /// `truth + offset`.
    fn offsets(&self, observed: &Observed, truth: &[Vec<f64>], offset: &[f64]) -> Result<Vec<f64>> {
        let reported: Vec<Vec<f64>> = truth
            .iter()
            .map(|q| q.iter().zip(offset).map(|(v, o)| v + o).collect())
            .collect();
        estimate_offsets(
            self.differentiable,
            self.autodiff,
            self.image,
            observed,
            &reported,
            &self.cfg.drift,
        )
    }
}

/// Run the study into `out`.
pub fn run(
    cfg: &BodyFromImageConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
) -> Result<String> {
    let (device_choice, resume) = (opts.device, opts.resume);
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // The robot and camera the options name (the papers' arm by default).
    let model_run = opts.apply(neurokin_run(&cfg.preset)?)?;
    let fitted = fit_run(&model_run, &out.join("checkpoint"), device_choice, resume)?;
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
    )?;
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

    // Pose from image.
    let dof = truth[0].len();
    let mean: Vec<f64> = (0..dof)
        .map(|j| seen.iter().map(|q| q[j]).sum::<f64>() / seen.len() as f64)
        .collect();
    let nk: (&dyn Render, &Device) = (renderer, &device);
    let mut rows = vec![bench.row(
        "mean training pose",
        "clean",
        &vec![mean; n],
        &truth,
        f64::NAN,
        f64::NAN,
        &observed,
        nk,
    )?];
    let estimator = train_estimator(
        &cfg.amortised,
        renderer,
        &device,
        bench.image,
        &bench.ranges,
        seen,
    )?;
    let t = std::time::Instant::now();
    let guesses = estimator.estimate(&observed, &device, 64)?;
    let cnn_batched = 1000.0 * t.elapsed().as_secs_f64() / n as f64;
    let one = observed.select(0..1);
    let cnn_b1 = 1000.0
        * median_seconds(Repeats::exactly(2, 10), || {
            let _ = estimator.estimate(&one, &device, 1);
        });
    rows.push(bench.row(
        "amortised CNN",
        "clean",
        &guesses,
        &truth,
        cnn_b1,
        cnn_batched,
        &observed,
        nk,
    )?);
    let refined_label = format!("CNN + {} refinement steps", cfg.refine.steps);
    let t = std::time::Instant::now();
    let refined = bench.refine(bench.differentiable, &observed, &guesses, &cfg.refine)?;
    let refine_batched = 1000.0 * t.elapsed().as_secs_f64() / n as f64 + cnn_batched;
    let refine_b1 = 1000.0
        * median_seconds(Repeats::exactly(1, 3), || {
            let g = estimator
                .estimate(&one, &device, 1)
                .expect("estimated above");
            let _ = bench.refine(bench.differentiable, &one, &g, &cfg.refine);
        });
    rows.push(bench.row(
        &refined_label,
        "clean",
        &refined,
        &truth,
        refine_b1,
        refine_batched,
        &observed,
        nk,
    )?);
    // The diagnostic: the same refinement started at the true angles. Where it walks away
    // from them, the self-model's optimum is not the truth (its own error, or what a
    // silhouette cannot show).
    let from_truth = bench.refine(bench.differentiable, &observed, &truth, &cfg.refine)?;
    rows.push(bench.row(
        &format!(
            "true angles + {} refinement steps (diagnostic)",
            cfg.refine.steps
        ),
        "clean",
        &from_truth,
        &truth,
        f64::NAN,
        f64::NAN,
        &observed,
        nk,
    )?);
    // The same refinement through K-3DGS (trained on the same data), from the same CNN.
    let t = std::time::Instant::now();
    let through_gaussians = bench.refine(k3dgs.as_ref(), &observed, &guesses, &cfg.refine)?;
    let gaussians_batched = 1000.0 * t.elapsed().as_secs_f64() / n as f64 + cnn_batched;
    rows.push(bench.row(
        &format!("{refined_label}, through K-3DGS"),
        "clean",
        &through_gaussians,
        &truth,
        f64::NAN,
        gaussians_batched,
        &observed,
        (k3dgs.as_ref(), &autodiff),
    )?);
    let m = cfg.search_poses.min(n);
    let t = std::time::Instant::now();
    let searched = pose_from_image(
        bench.differentiable,
        &autodiff,
        bench.image,
        &observed.select(0..m),
        &bench.ranges,
        None,
        &cfg.search,
        |_| {},
    )?;
    let search_batched = 1000.0 * t.elapsed().as_secs_f64() / m as f64;
    rows.push(bench.row(
        &format!(
            "search ({} starts, {} steps)",
            cfg.search.starts, cfg.search.steps
        ),
        "clean",
        &searched.angles,
        &truth[..m],
        f64::NAN,
        search_batched,
        &observed,
        nk,
    )?);
    for (i, p) in cfg.perturbations.iter().enumerate() {
        let spoiled = observed.perturbed(*p, cfg.seed + 1 + i as u64);
        let g = estimator.estimate(&spoiled, &device, 64)?;
        let r = bench.refine(bench.differentiable, &spoiled, &g, &cfg.refine)?;
        for (method, found) in [("amortised CNN", &g), (refined_label.as_str(), &r)] {
            let (b1, batched) = (f64::NAN, f64::NAN);
            rows.push(bench.row(method, &p.label(), found, &truth, b1, batched, &spoiled, nk)?);
        }
    }
    let pose_csv = out.join("results.csv");
    write_csv(&pose_csv, &rows)?;
    write_markdown_report(
        &pose_csv,
        "Joint angles from a silhouette",
        "The test poses' silhouettes read back through the trained NeuroKin (one row: through K-3DGS, \
         isotropic with alpha compositing, from the same CNN answers). Errors are absolute joint \
         errors in degrees (mean and median over every joint of every pose), the end effector's \
         distance in mm, and the share of poses with every joint within 2 degrees. The CNN is trained \
         on the self-model's own renderings; the refinement descends the silhouette's cross-entropy \
         through the model from the CNN's answer; the search starts from poses drawn within the \
         training poses' range, keeping the start with the lowest loss. The diagnostic row starts the \
         refinement at the true angles. `loss_below_truth_share`: the poses whose estimate the model \
         scores better than the truth (the model's optimum is elsewhere). Milliseconds on this \
         machine's CPU, one image at a time (b1) and per pose over a batch.",
    )?;
    pose_grid(
        &bench,
        &observed,
        &refined,
        &truth,
        &out.join("pose_grid.png"),
    )?;

    // Drift.
    let mut rng = StdRng::seed_from_u64(cfg.seed ^ 0xD41F7);
    let capture = |poses: &[usize], seed: u64| {
        Observed::from_dataset(data, poses)
            .perturbed(Perturbation::FlipPixels(cfg.capture_flip), seed)
    };
    let mut drift_rows = Vec::new();
    let mut seed = 1000u64;
    for &k in &cfg.drift_ks {
        let k = k.min(fitted.test_range.len());
        let (mut err, mut max, mut raw) = (0.0, 0.0f64, 0.0);
        for _ in 0..cfg.drift_trials {
            let poses: Vec<usize> = sample(&mut rng, fitted.test_range.len(), k)
                .into_iter()
                .map(|i| fitted.test_range.start + i)
                .collect();
            let truth: Vec<Vec<f64>> = poses.iter().map(|&i| data.angles[i].clone()).collect();
            let offset: Vec<f64> = (0..dof)
                .map(|_| rng.random_range(-cfg.max_offset_deg..=cfg.max_offset_deg))
                .collect();
            seed += 2;
            let reference = bench.offsets(&capture(&poses, seed), &truth, &vec![0.0; dof])?;
            let now = bench.offsets(&capture(&poses, seed + 1), &truth, &offset)?;
            let rel: Vec<f64> = now.iter().zip(&reference).map(|(a, b)| a - b).collect();
            for j in 0..dof {
                let e = (rel[j] - offset[j]).abs();
                err += e / (dof * cfg.drift_trials) as f64;
                max = max.max(e);
                raw += (now[j] - offset[j]).abs() / (dof * cfg.drift_trials) as f64;
            }
        }
        drift_rows.push(DriftRow {
            k,
            trials: cfg.drift_trials,
            offset_error_deg: err,
            max_offset_error_deg: max,
            offset_error_no_reference_deg: raw,
            preset: cfg.preset.clone(),
            device: bench.device_name.clone(),
            git_revision: bench.revision.clone(),
        });
    }
    let drift_csv = out.join("drift.csv");
    write_csv(&drift_csv, &drift_rows)?;
    write_markdown_report(
        &drift_csv,
        "Encoder drift from k images",
        "Constant offsets, uniform in +-5 degrees on every joint, recovered from k test poses: the \
         difference between the estimate now and the estimate on the same poses seen while the \
         encoders were healthy (each capture with its own 1% of pixels flipped), and the estimate \
         taken as it is (no reference). Errors in degrees, mean over trials and joints.",
    )?;
    let curves: Vec<(String, Vec<(f64, f64)>)> = vec![
        (
            "against a healthy reference".into(),
            drift_rows
                .iter()
                .map(|r| (r.k as f64, r.offset_error_deg))
                .collect(),
        ),
        (
            "estimate as it is".into(),
            drift_rows
                .iter()
                .map(|r| (r.k as f64, r.offset_error_no_reference_deg))
                .collect(),
        ),
    ];
    log_log_lines(
        &out.join("drift_vs_k.png"),
        "Encoder offset error against the number of images",
        "images k",
        "offset error (degrees, log)",
        &curves,
    )?;

    // Detection at a 1% false alarm rate: the robot's k calibration poses, their reference
    // estimate taken once while healthy, then one new capture per trial.
    let k = cfg.detection_k.min(fitted.test_range.len());
    let poses: Vec<usize> = sample(&mut rng, fitted.test_range.len(), k)
        .into_iter()
        .map(|i| fitted.test_range.start + i)
        .collect();
    let calibration_truth: Vec<Vec<f64>> = poses.iter().map(|&i| data.angles[i].clone()).collect();
    seed += 1;
    let reference = bench.offsets(&capture(&poses, seed), &calibration_truth, &vec![0.0; dof])?;
    let mut trial = |offset: &[f64]| -> Result<f64> {
        seed += 1;
        let now = bench.offsets(&capture(&poses, seed), &calibration_truth, offset)?;
        Ok(now
            .iter()
            .zip(&reference)
            .fold(0.0f64, |a, (v, r)| a.max((v - r).abs())))
    };
    let mut healthy = Vec::new();
    for _ in 0..cfg.healthy_trials {
        healthy.push(trial(&vec![0.0; dof])?);
    }
    healthy.sort_by(f64::total_cmp);
    let threshold =
        healthy[((0.99 * healthy.len() as f64).ceil() as usize).clamp(1, healthy.len()) - 1];
    let mut detection_rows = Vec::new();
    for &a in &cfg.detection_offsets_deg {
        let mut hits = 0;
        for t in 0..cfg.detection_trials {
            let mut offset = vec![0.0; dof];
            offset[t % dof] = if t % 2 == 0 { a } else { -a };
            hits += usize::from(trial(&offset)? > threshold);
        }
        detection_rows.push(DetectionRow {
            offset_deg: a,
            k,
            trials: cfg.detection_trials,
            threshold_deg: threshold,
            detected_share: hits as f64 / cfg.detection_trials as f64,
            preset: cfg.preset.clone(),
            device: bench.device_name.clone(),
            git_revision: bench.revision.clone(),
        });
    }
    let detection_csv = out.join("detection.csv");
    write_csv(&detection_csv, &detection_rows)?;
    write_markdown_report(
        &detection_csv,
        "Detecting a small encoder offset",
        "An offset on one joint (each joint in turn, both signs) against healthy encoders. The robot's \
         k calibration poses were captured once while healthy (the reference estimate); every trial is \
         a new capture (its own 1% of pixels flipped). The statistic is the largest |estimate - \
         reference| over the joints; the threshold is its 99th percentile over healthy trials (false \
         alarms 1%).",
    )?;
    let calibration_rows = visual_calibration(cfg, out, k3dgs.as_ref(), &bench, &fitted)?;
    write_json(&out.join("config.json"), cfg)?;
    let r = &rows[2];
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
    Ok(format!(
        "pose from image ({}): median joint error {:.2} deg, {:.0}% of poses within 2 deg, {:.1} ms/pose batched; drift from {} images: {:.2} deg; smallest offset detected in 90% of trials: {smallest}{calibrated}",
        r.method,
        r.median_joint_error_deg,
        100.0 * r.within_2deg_share,
        r.ms_per_pose_batched,
        drift_rows.last().map_or(0, |d| d.k),
        drift_rows.last().map_or(f64::NAN, |d| d.offset_error_deg),
    ))
}

/// Observed silhouettes, the self-model's rendering at the estimate and their difference,
/// for up to 8 test poses, each captioned with its mean joint error.
fn pose_grid(
    b: &Bench,
    observed: &Observed,
    found: &[Vec<f64>],
    truth: &[Vec<f64>],
    path: &Path,
) -> Result<()> {
    // Eight poses spread over the test trajectory (neighbours on it look alike).
    let n = observed.n.min(8);
    let picks: Vec<usize> = (0..n).map(|i| i * observed.n / n).collect();
    let observed = Observed::new(
        picks
            .iter()
            .flat_map(|&i| observed.image(i).iter().copied())
            .collect(),
        n,
        observed.size,
    )?;
    let found: Vec<Vec<f64>> = picks.iter().map(|&i| found[i].clone()).collect();
    let truth: Vec<Vec<f64>> = picks.iter().map(|&i| truth[i].clone()).collect();
    let dof = found[0].len();
    let q: Vec<f32> = found.iter().flatten().map(|&v| v as f32).collect();
    let rendered = host(
        b.renderer
            .render(Tensor::from_data(TensorData::new(q, [n, dof]), b.device))
            .0,
    )?;
    let px = b.image[0] * b.image[1];
    let obs: Vec<&[f32]> = (0..n).map(|i| observed.image(i)).collect();
    let ren: Vec<&[f32]> = (0..n).map(|i| &rendered[i * px..(i + 1) * px]).collect();
    let err: Vec<Vec<f32>> = obs
        .iter()
        .zip(&ren)
        .map(|(o, r)| o.iter().zip(r.iter()).map(|(a, b)| (a - b).abs()).collect())
        .collect();
    let captions: Vec<String> = (0..n)
        .map(|i| {
            let e = found[i]
                .iter()
                .zip(&truth[i])
                .map(|(a, b)| (a - b).abs())
                .sum::<f64>()
                / dof as f64;
            format!("{e:.2} deg")
        })
        .collect();
    image_grid(
        path,
        &[GridRow::Grey(obs), GridRow::Grey(ren), GridRow::Error(err)],
        &["observed", "rendered at estimate", "|difference|"],
        &captions,
        b.image[1],
        b.image[0],
        2,
    )
}

/// K-3DGS (`renderer`, differentiable, trained on the same data as `fitted`), its joint
/// origins fitted to k test poses of the arm with every link lengthened (the Table IV change).
fn visual_calibration(
    cfg: &BodyFromImageConfig,
    out: &Path,
    renderer: &dyn Render,
    bench: &Bench,
    fitted: &crate::self_models::harness::Fitted,
) -> Result<Vec<CalibrationRow>> {
    let nominal = renderer
        .joint_origins()
        .ok_or_else(|| Error::Config("K-3DGS has no chain".into()))?;
    let has_length: Vec<bool> = nominal
        .iter()
        .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() > 1e-3)
        .collect();
    let robot = bench.robot;
    let data = &fitted.data;
    let mut rows = Vec::new();
    let mut rng = StdRng::seed_from_u64(cfg.seed ^ 0xCA11B);
    for &cm in &cfg.calibration_changes_cm {
        let mut changed = robot.clone();
        changed.chain = crate::sim::arm_change::ArmChange::Lengthen { cm }.apply(&robot.chain)?;
        for &k in &cfg.calibration_ks {
            let k = k.min(fitted.test_range.len());
            let poses: Vec<usize> = sample(&mut rng, fitted.test_range.len(), k)
                .into_iter()
                .map(|i| fitted.test_range.start + i)
                .collect();
            let angles: Vec<Vec<f64>> = poses.iter().map(|&i| data.angles[i].clone()).collect();
            let mut data_cfg = neurokin_run(&cfg.preset)?.data.dataset;
            data_cfg.samples = k;
            data_cfg.train = k;
            // The same poses seen by the healthy arm and by the changed one: the change is the
            // difference of the two fits (K-3DGS's own error on those poses cancels).
            let fit_to = |arm: &Robot| -> Result<Vec<f64>> {
                let images =
                    crate::data::dataset::Dataset::render(arm, &data_cfg, angles.clone(), None)?;
                let observed = Observed::from_dataset(&images, &(0..k).collect::<Vec<_>>());
                let fit = fit_joint_origins(
                    renderer,
                    bench.autodiff,
                    [data.height, data.width],
                    &observed,
                    &angles,
                    &cfg.calibration,
                )?;
                Ok(fit
                    .change_mm
                    .iter()
                    .zip(&has_length)
                    .filter(|(_, l)| **l)
                    .map(|(c, _)| *c)
                    .collect())
            };
            let (healthy, now) = (fit_to(robot)?, fit_to(&changed)?);
            let recovered: Vec<f64> = now.iter().zip(&healthy).map(|(a, b)| a - b).collect();
            let errors: Vec<f64> = recovered.iter().map(|c| (c - 10.0 * cm).abs()).collect();
            let raw_error =
                now.iter().map(|c| (c - 10.0 * cm).abs()).sum::<f64>() / now.len().max(1) as f64;
            rows.push(CalibrationRow {
                change_cm: cm,
                k,
                recovered_mm: recovered
                    .iter()
                    .map(|v| format!("{v:.1}"))
                    .collect::<Vec<_>>()
                    .join(" / "),
                mean_error_mm: errors.iter().sum::<f64>() / errors.len().max(1) as f64,
                max_error_mm: errors.iter().fold(0.0, |a: f64, &b| a.max(b)),
                mean_error_no_reference_mm: raw_error,
                preset: cfg.preset.clone(),
                device: bench.device_name.clone(),
                git_revision: bench.revision.clone(),
            });
        }
    }
    let csv = out.join("calibration.csv");
    write_csv(&csv, &rows)?;
    write_markdown_report(
        &csv,
        "Link lengths from images",
        "Every link of the arm lengthened (the EMSSL paper's Table IV change), seen in k test poses; \
         K-3DGS's joint origins fitted to the images with its Gaussians frozen, and fitted again to \
         the healthy arm's images of the same poses: the change recovered along each link with a \
         length is the difference of the two fits (mm), its error against the true change beside \
         the error of the changed arm's fit taken as it is.",
    )?;
    let curves: Vec<(String, Vec<(f64, f64)>)> = cfg
        .calibration_changes_cm
        .iter()
        .map(|&cm| {
            (
                format!("links +{cm} cm"),
                rows.iter()
                    .filter(|r| r.change_cm == cm)
                    .map(|r| (r.k as f64, r.mean_error_mm))
                    .collect(),
            )
        })
        .collect();
    log_log_lines(
        &out.join("calibration_vs_k.png"),
        "Link-length error against the number of images",
        "images k",
        "mean link error (mm, log)",
        &curves,
    )?;
    Ok(rows)
}
