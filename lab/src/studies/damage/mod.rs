//! `damage`: detect damage to the arm from k images at commanded poses, and say which link
//! it is ([`selfmodel::body::damage`]), through NeuroKin trained on the healthy arm. Writes
//! `reports/damage/`:
//! - `detection.csv`: per damage (kind, size, link) and k, the ROC AUC of the k-image
//!   residual against healthy trials, and the share detected at a 1% false-alarm threshold;
//! - `localisation.csv`: per damage and k, the share of trials naming the damaged link;
//! - `roc.png` (ROC curves per kind at one k) and `auc_vs_k.png`.
//!
//! The k poses of a trial are drawn from a pool of the dataset's test poses; the healthy
//! arm's images there are the dataset's own, the damaged arm's are rendered with the same
//! camera. Healthy and damaged trials draw their poses independently (seeded).

use std::path::Path;

use serde::{Deserialize, Serialize};

mod detection;
mod figures;
mod recovery;

pub use detection::{DetectionRow, LocalisationRow};
pub use recovery::RecoveryRow;

use detection::{detect, write_detection};
use recovery::{Recovering, recover, write_recovery};
use selfmodel::core::atomic_file::write_json;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::preset::Preset;
use selfmodel::core::provenance::git_revision;
use selfmodel::self_models::harness::fit_run;
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::sim::arm_change::Damage;

/// A kind of damage and its sizes (degrees for `bend`, centimetres for `lengthen` and
/// `shorten`, the share missing for `truncate`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DamageSizes {
    pub kind: String,
    pub sizes: Vec<f64>,
}

impl DamageSizes {
    /// The unit of the sizes.
    fn unit(&self) -> &'static str {
        match self.kind.as_str() {
            "bend" => "deg",
            "lengthen" | "shorten" => "cm",
            _ => "missing",
        }
    }

    fn damage(&self, link: usize, size: f64) -> Result<Damage> {
        Ok(match self.kind.as_str() {
            "bend" => Damage::Bend { link, deg: size },
            "lengthen" => Damage::Length { link, cm: size },
            "shorten" => Damage::Length { link, cm: -size },
            "truncate" => Damage::Truncate {
                link,
                fraction: size,
            },
            other => {
                return Err(Error::Config(format!(
                    "damage kind \"{other}\" (known: bend, lengthen, shorten, truncate)"
                )));
            }
        })
    }
}

/// The study's settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DamageConfig {
    pub preset: String,
    /// The NeuroKin preset trained on the healthy arm ...
    pub model_preset: String,
    /// ... on a dataset of this many samples (its last `test_samples` the test set; `None`:
    /// the preset's), for this many steps (`None`: the preset's).
    #[serde(default)]
    pub samples: Option<usize>,
    #[serde(default)]
    pub test_samples: Option<usize>,
    #[serde(default)]
    pub steps: Option<usize>,
    pub damages: Vec<DamageSizes>,
    /// Links damaged (joint-vector order, 0-based); empty: every link the joints move.
    pub links: Vec<usize>,
    /// Images per trial.
    pub ks: Vec<usize>,
    /// Trials per damage and k (and healthy trials per k).
    pub trials: usize,
    /// Test poses the trials draw from.
    pub pool: usize,
    /// A link's standard score above which it is named damaged ([`selfmodel::body::damage::localise`]).
    pub z_threshold: f64,
    pub false_alarms: f64,
    pub seed: u64,
    pub recovery: RecoveryConfig,
}

/// Updating the self-model after damage, from n images of the damaged arm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecoveryConfig {
    pub damages: Vec<Damage>,
    /// Images of the damaged arm (at training poses) each update sees.
    pub ns: Vec<usize>,
    /// Each update's optimiser steps, batch and learning rate (Adam, from the healthy weights;
    /// the healthy model's clipping and input noise).
    pub steps: usize,
    pub batch: usize,
    pub learning_rate: f64,
    /// EWC's weights (one update per value: the trade-off between the damaged arm and the
    /// healthy one) and the healthy batches its Fisher information is estimated on.
    pub ewc_lambdas: Vec<f64>,
    pub fisher_batches: usize,
    /// Replay: healthy training images mixed in, as many as damaged ones in every epoch.
    pub replay: bool,
    /// Images the gate of the gated experts scores (the detection score, its threshold at
    /// the study's false-alarm rate on healthy trials of as many images).
    pub gate_k: usize,
    /// Also train from scratch on the damaged arm's whole training set (the healthy model's
    /// schedule): the reference a recovery is measured against.
    pub from_scratch: bool,
    /// Re-simulation: identify the damage from the n images ([`selfmodel::body::damage::identify`]),
    /// render the training poses with the robot's description so damaged, and fine-tune on
    /// them (and the n images) for this many steps; also as the damage expert of the gated
    /// experts. `None`: not run.
    #[serde(default)]
    pub resimulate_steps: Option<usize>,
}

impl Preset for DamageConfig {
    /// NeuroKin's paper network trained on 12,000 images of the Lorenz trajectory (the
    /// paper's 1,600 score 25.2 dB, 9,600 28.9 dB in `ablation_data_scale`) for 9,000 steps,
    /// tested on the next 500; bends of 3, 5 and 10 degrees, links 1, 2, 3 and 5 cm longer,
    /// 1, 2 and 3 cm shorter, a quarter and a half missing; every link; k in {1, 3, 10, 30};
    /// 200 trials from 400 test poses.
    fn paper() -> Self {
        DamageConfig {
            preset: "paper".into(),
            model_preset: "paper".into(),
            samples: Some(12_500),
            test_samples: Some(500),
            steps: Some(9_000),
            damages: vec![
                DamageSizes {
                    kind: "bend".into(),
                    sizes: vec![3.0, 5.0, 10.0],
                },
                DamageSizes {
                    kind: "lengthen".into(),
                    sizes: vec![1.0, 2.0, 3.0, 5.0],
                },
                DamageSizes {
                    kind: "shorten".into(),
                    sizes: vec![1.0, 2.0, 3.0],
                },
                DamageSizes {
                    kind: "truncate".into(),
                    sizes: vec![0.25, 0.5],
                },
            ],
            links: Vec::new(),
            ks: vec![1, 3, 10, 30],
            trials: 200,
            pool: 400,
            z_threshold: 4.0,
            false_alarms: 0.01,
            seed: 0,
            recovery: RecoveryConfig {
                damages: vec![
                    Damage::Bend { link: 1, deg: 5.0 },
                    Damage::Length { link: 2, cm: 2.0 },
                ],
                ns: vec![10, 50, 200],
                steps: 600,
                batch: 32,
                learning_rate: 5e-4,
                ewc_lambdas: vec![1e6, 1e7, 1e8, 1e9, 1e10],
                fisher_batches: 50,
                replay: true,
                gate_k: 10,
                from_scratch: true,
                resimulate_steps: Some(1500),
            },
        }
    }

    /// NeuroKin's quick preset (32x32), a 10-degree bend and a 3 cm lengthening of link 2,
    /// k in {1, 10}: seconds.
    fn quick() -> Self {
        DamageConfig {
            preset: "quick".into(),
            model_preset: "quick".into(),
            samples: None,
            test_samples: None,
            steps: None,
            damages: vec![
                DamageSizes {
                    kind: "bend".into(),
                    sizes: vec![10.0],
                },
                DamageSizes {
                    kind: "lengthen".into(),
                    sizes: vec![3.0],
                },
            ],
            links: vec![1],
            ks: vec![1, 10],
            trials: 40,
            pool: 100,
            recovery: RecoveryConfig {
                damages: vec![Damage::Bend { link: 1, deg: 10.0 }],
                ns: vec![10, 50],
                steps: 60,
                fisher_batches: 5,
                ewc_lambdas: vec![1e6, 1e8],
                resimulate_steps: Some(100),
                ..Self::paper().recovery
            },
            ..Self::paper()
        }
    }
}

/// The NeuroKin run the study trains on the healthy arm (the paper preset's is NeuroKin's
/// `large` preset: 12,000 training images, 9,000 steps).
pub fn model_run(
    cfg: &DamageConfig,
    opts: &crate::studies::run::RunOptions,
) -> Result<
    selfmodel::self_models::run_config::SelfModelRun<
        selfmodel::self_models::neurokin::NeuroKinConfig,
    >,
> {
    let mut model_run = opts.apply(neurokin_run(&cfg.model_preset)?)?;
    if let Some(n) = cfg.samples {
        let test = cfg.test_samples.unwrap_or(n / 5).min(n - 1);
        model_run.data.dataset.samples = n;
        model_run.data.dataset.train = n - test;
    }
    if let Some(steps) = cfg.steps {
        model_run.train.steps = steps;
    }
    Ok(model_run)
}

/// Run the study into `out`.
pub fn run(
    cfg: &DamageConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
) -> Result<String> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    write_json(&out.join("config.json"), cfg)?;
    let model_run = model_run(cfg, opts)?;
    let fitted = fit_run(
        &model_run,
        &out.join("checkpoint"),
        opts.device,
        opts.resume,
    )?
    .erased();
    let robot = model_run.data.robot.load()?;
    let camera = model_run.data.camera(&fitted.data);
    let (device, revision) = (opts.device.to_string(), git_revision());
    let found = detect(
        cfg,
        &model_run,
        &fitted,
        &robot,
        &camera,
        (device.clone(), revision.clone()),
    )?;
    write_detection(cfg, out, &found)?;
    let recovery = recover(
        cfg,
        &Recovering {
            model_run: &model_run,
            fitted: &fitted,
            robot: &robot,
            camera: &camera,
            out,
            gate_threshold: found.gate_threshold,
            device: &device,
            revision: &revision,
            resume: opts.resume,
        },
    )?;
    if !recovery.is_empty() {
        write_recovery(cfg, out, &recovery)?;
        figures::draw_recovery(out, &recovery)?;
    }
    let summary = found
        .detection
        .iter()
        .filter(|r| r.k == found.roc_k)
        .map(|r| format!("{} {} link {}: AUC {:.3}", r.damage, r.size, r.link, r.auc))
        .collect::<Vec<_>>()
        .join("; ");
    Ok(summary)
}
