//! Link lengths read from images: every link lengthened, seen in k test poses, K-3DGS's joint
//! origins fitted to them and to the healthy arm's images of the same poses
//! (`calibration.csv`, `calibration_vs_k.png`).

use std::path::Path;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::index::sample;
use serde::{Deserialize, Serialize};

use super::bench::Bench;
use selfmodel::body::calibration::fit_joint_origins;
use selfmodel::body::observations::{ImageFit, Observed};
use selfmodel::core::error::{Error, Result};
use selfmodel::report::table::{write_csv, write_markdown_report};
use selfmodel::self_models::model::Render;
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::sim::robot::Robot;

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
/// K-3DGS (`renderer`, differentiable, trained on the same data as `fitted`), its joint
/// origins fitted to k test poses of the arm with every link lengthened (the Table IV change).
pub fn visual_calibration(
    renderer: &dyn Render,
    bench: &Bench,
    out: &Path,
) -> Result<Vec<CalibrationRow>> {
    let (cfg, fitted) = (bench.cfg, bench.fitted);
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
        changed.chain =
            selfmodel::sim::arm_change::ArmChange::Lengthen { cm }.apply(&robot.chain)?;
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
                let images = selfmodel::data::dataset::Dataset::render(
                    arm,
                    &data_cfg,
                    angles.clone(),
                    None,
                )?;
                let observed = Observed::from_dataset(&images, &(0..k).collect::<Vec<_>>());
                let fit = fit_joint_origins(
                    ImageFit {
                        renderer,
                        device: bench.autodiff,
                        image: [data.height, data.width],
                        observed: &observed,
                    },
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
    selfmodel::report::figures::line_plot(
        &out.join("calibration_vs_k.png"),
        "Link-length error against the number of images",
        ("images k", "mean link error (mm, log)"),
        &curves,
        selfmodel::report::figures::LinePlot::LOG_LOG,
    )?;
    Ok(rows)
}
