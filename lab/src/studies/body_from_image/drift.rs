//! Encoder drift read from images: constant offsets recovered from k poses against a healthy
//! reference (`drift.csv`, `drift_vs_k.png`), and the smallest offset told apart from healthy
//! encoders at a 1% false alarm rate (`detection.csv`).

use std::path::Path;

use rand::RngExt;
use rand::rngs::StdRng;
use rand::seq::index::sample;
use serde::{Deserialize, Serialize};

use super::bench::Bench;
use selfmodel::body::observations::{Observed, Perturbation};
use selfmodel::core::error::Result;
use selfmodel::report::table::{write_csv, write_markdown_report};

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
/// The test poses `poses` captured once more: their images with the study's sensor noise
/// (`capture_flip` of the pixels flipped, drawn from `seed`).
fn capture(b: &Bench, poses: &[usize], seed: u64) -> Observed {
    Observed::from_dataset(&b.fitted.data, poses)
        .perturbed(Perturbation::FlipPixels(b.cfg.capture_flip), seed)
}

/// `k` test poses drawn from `rng` (indices into the dataset).
fn test_poses(b: &Bench, rng: &mut StdRng, k: usize) -> Vec<usize> {
    let test = &b.fitted.test_range;
    sample(rng, test.len(), k)
        .into_iter()
        .map(|i| test.start + i)
        .collect()
}

/// Offsets recovered from k images for each of the config's k (`drift.csv`, its report and
/// `drift_vs_k.png` in `out`); poses and offsets drawn from `rng`, captures seeded from `seed`
/// on (the detection goes on from both).
pub fn drift_rows(
    b: &Bench,
    rng: &mut StdRng,
    seed: &mut u64,
    out: &Path,
) -> Result<Vec<DriftRow>> {
    let cfg = b.cfg;
    let data = &b.fitted.data;
    let dof = data.angles[0].len();
    let mut drift_rows = Vec::new();
    for &k in &cfg.drift_ks {
        let k = k.min(b.fitted.test_range.len());
        let (mut err, mut max, mut raw) = (0.0, 0.0f64, 0.0);
        for _ in 0..cfg.drift_trials {
            let poses = test_poses(b, rng, k);
            let truth: Vec<Vec<f64>> = poses.iter().map(|&i| data.angles[i].clone()).collect();
            let offset: Vec<f64> = (0..dof)
                .map(|_| rng.random_range(-cfg.max_offset_deg..=cfg.max_offset_deg))
                .collect();
            *seed += 2;
            let reference = b.offsets(&capture(b, &poses, *seed), &truth, &vec![0.0; dof])?;
            let now = b.offsets(&capture(b, &poses, *seed + 1), &truth, &offset)?;
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
            device: b.device_name.clone(),
            git_revision: b.revision.clone(),
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
    selfmodel::report::figures::line_plot(
        &out.join("drift_vs_k.png"),
        "Encoder offset error against the number of images",
        ("images k", "offset error (degrees, log)"),
        &curves,
        selfmodel::report::figures::LinePlot::LOG_LOG,
    )?;
    Ok(drift_rows)
}

/// Detection at a 1% false alarm rate (`detection.csv` and its report in `out`): the robot's k
/// calibration poses, their reference estimate taken once while healthy, then one new capture
/// per trial; poses drawn from `rng`, captures seeded from `seed` on.
pub fn detection_rows(
    b: &Bench,
    rng: &mut StdRng,
    seed: &mut u64,
    out: &Path,
) -> Result<Vec<DetectionRow>> {
    let cfg = b.cfg;
    let data = &b.fitted.data;
    let dof = data.angles[0].len();
    let k = cfg.detection_k.min(b.fitted.test_range.len());
    let poses = test_poses(b, rng, k);
    let calibration_truth: Vec<Vec<f64>> = poses.iter().map(|&i| data.angles[i].clone()).collect();
    *seed += 1;
    let reference = b.offsets(
        &capture(b, &poses, *seed),
        &calibration_truth,
        &vec![0.0; dof],
    )?;
    let mut trial = |offset: &[f64]| -> Result<f64> {
        *seed += 1;
        let now = b.offsets(&capture(b, &poses, *seed), &calibration_truth, offset)?;
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
            device: b.device_name.clone(),
            git_revision: b.revision.clone(),
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
    Ok(detection_rows)
}
