//! `damage`: detect damage to the arm from k images at commanded poses, and say which link
//! it is ([`crate::body::damage`]), through NeuroKin trained on the healthy arm. Writes
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

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::index::sample;
use serde::{Deserialize, Serialize};

use crate::body::damage::{
    ShareBaseline, best_hypothesis, change_masks, hypotheses, link_masks, link_shares, localise,
    predicted, residual, roc_auc, roc_curve, threshold_at,
};
use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::core::provenance::git_revision;
use crate::report::table::write_table;
use crate::self_models::harness::fit_run;
use crate::self_models::neurokin::neurokin_run;
use crate::sim::arm_change::Damage;
use crate::sim::ray_caster::silhouettes;

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
    /// A link's standard score above which it is named damaged ([`localise`]).
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
    /// Re-simulation: identify the damage from the n images ([`crate::body::damage::identify`]),
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

/// One damage at one k.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DetectionRow {
    pub damage: String,
    pub size: f64,
    /// 1-based, as on the arm.
    pub link: usize,
    pub k: usize,
    pub auc: f64,
    /// Damaged trials above the healthy threshold at `false_alarms` (%).
    pub detected_pct: f64,
    pub false_alarms: f64,
    pub healthy_score: f64,
    pub damaged_score: f64,
    pub trials: usize,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// The link named for one damage at one k.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LocalisationRow {
    pub damage: String,
    pub size: f64,
    pub link: usize,
    pub k: usize,
    /// Trials naming the damaged link (%), by synthesis (the damage hypothesis whose changed
    /// pixels the residual covers most).
    pub correct_pct: f64,
    /// The link named most often (1-based).
    pub most_named: usize,
    /// The damage kind of the hypothesis chosen most often.
    pub most_named_kind: String,
    /// Trials naming the damaged link by the residual's share of each link's mask (%).
    pub link_masks_correct_pct: f64,
    pub trials: usize,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// One update of the self-model after one damage, from n images.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RecoveryRow {
    pub method: String,
    pub n: usize,
    /// On the test poses, the damaged arm's images: PSNR (dB) and IoU, means over images.
    pub psnr_damaged_db: f64,
    pub iou_damaged: f64,
    /// On the test poses, the healthy arm's images (forgetting).
    pub psnr_healthy_db: f64,
    pub iou_healthy: f64,
    /// Seconds the update took (training; the Fisher information for EWC).
    pub seconds: f64,
    pub damage: String,
    pub size: f64,
    pub link: usize,
    /// PSNR on the damaged test poses farther (in joint space) from the n images than the
    /// median test pose (none for an update from every training pose).
    pub psnr_damaged_far_db: Option<f64>,
    pub steps: usize,
    pub detail: String,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// Per pose of the pool: the residual and the link shares, for one arm (healthy or damaged).
struct PoolScores {
    residual: Vec<f64>,
    shares: Vec<Vec<f64>>,
    /// Per pose, the share of each hypothesis' changed pixels the residual covers.
    hypotheses: Vec<Vec<f64>>,
}

impl PoolScores {
    fn new(
        pred: &[f32],
        observed: &[f32],
        masks: &[Vec<Vec<bool>>],
        changes: &[Vec<Vec<bool>>],
        px: usize,
    ) -> Self {
        let n = masks.len();
        PoolScores {
            hypotheses: (0..n)
                .map(|i| {
                    link_shares(
                        &pred[i * px..(i + 1) * px],
                        &observed[i * px..(i + 1) * px],
                        &changes[i],
                    )
                })
                .collect(),
            residual: (0..n)
                .map(|i| residual(&pred[i * px..(i + 1) * px], &observed[i * px..(i + 1) * px]))
                .collect(),
            shares: (0..n)
                .map(|i| {
                    link_shares(
                        &pred[i * px..(i + 1) * px],
                        &observed[i * px..(i + 1) * px],
                        &masks[i],
                    )
                })
                .collect(),
        }
    }

    /// `trials` draws of k poses: each trial's mean residual, mean link shares and mean
    /// hypothesis shares.
    fn trials(&self, k: usize, trials: usize, seed: u64) -> Trials {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = self.residual.len();
        let average = |rows: &Vec<Vec<f64>>, pick: &[usize]| -> Vec<f64> {
            let width = rows.first().map_or(0, Vec::len);
            (0..width)
                .map(|l| pick.iter().map(|&i| rows[i][l]).sum::<f64>() / pick.len() as f64)
                .collect()
        };
        let mut out = Trials::default();
        for _ in 0..trials {
            let pick = sample(&mut rng, n, k.min(n)).into_vec();
            let m = pick.len() as f64;
            out.scores
                .push(pick.iter().map(|&i| self.residual[i]).sum::<f64>() / m);
            out.shares.push(average(&self.shares, &pick));
            out.hypotheses.push(average(&self.hypotheses, &pick));
        }
        out
    }
}

/// Trials of k images: the detection scores, the link shares and the hypothesis shares.
#[derive(Default)]
struct Trials {
    scores: Vec<f64>,
    shares: Vec<Vec<f64>>,
    hypotheses: Vec<Vec<f64>>,
}

/// The NeuroKin run the study trains on the healthy arm (the paper preset's is NeuroKin's
/// `large` preset: 12,000 training images, 9,000 steps).
pub fn model_run(
    cfg: &DamageConfig,
    opts: &crate::studies::run::RunOptions,
) -> Result<crate::self_models::harness::SelfModelRun<crate::self_models::neurokin::NeuroKinConfig>>
{
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
    )?;
    let renderer = fitted.trained.renderers[0].1.as_ref();
    let data = &fitted.data;
    let robot = model_run.data.robot.load()?;
    let camera = model_run.data.camera(data);
    let px = data.width * data.height;
    let pool: Vec<usize> = fitted
        .test_range
        .clone()
        .take(cfg.pool.min(fitted.test_range.len()))
        .collect();
    let angles: Vec<Vec<f64>> = pool.iter().map(|&i| data.angles[i].clone()).collect();
    let pred = predicted(renderer, &fitted.device, &angles, 64)?;
    let healthy_obs: Vec<f32> = pool
        .iter()
        .flat_map(|&i| data.images[i * px..(i + 1) * px].iter())
        .map(|&v| v as f32 / 255.0)
        .collect();
    let masks = link_masks(&robot, &camera, &angles);
    let named = hypotheses(robot.dof());
    let changes = change_masks(&robot, &camera, &angles, &named);
    let healthy = PoolScores::new(&pred, &healthy_obs, &masks, &changes, px);
    let links: Vec<usize> = if cfg.links.is_empty() {
        (0..robot.dof()).collect()
    } else {
        cfg.links.clone()
    };
    let render_options = model_run.data.dataset.render.clone();
    let (device, preset, revision) = (opts.device.to_string(), cfg.preset.clone(), git_revision());
    // Healthy trials per k: the detection threshold and the localisation baseline.
    let healthy_trials: Vec<Trials> = cfg
        .ks
        .iter()
        .map(|&k| healthy.trials(k, cfg.trials, cfg.seed ^ 0x4EA1 ^ k as u64))
        .collect();
    let baselines: Vec<ShareBaseline> = healthy_trials
        .iter()
        .map(|t| ShareBaseline::new(&t.shares))
        .collect();
    let hypothesis_baselines: Vec<ShareBaseline> = healthy_trials
        .iter()
        .map(|t| ShareBaseline::new(&t.hypotheses))
        .collect();
    let mut detection = Vec::new();
    let mut localisation = Vec::new();
    let mut roc: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let roc_k = cfg
        .ks
        .iter()
        .copied()
        .find(|&k| k >= 10)
        .unwrap_or(cfg.ks[cfg.ks.len() - 1]);
    for sizes in &cfg.damages {
        for &size in &sizes.sizes {
            // One ROC curve per kind and size at `roc_k`, every link's trials together.
            let (mut roc_healthy, mut roc_damaged) = (Vec::new(), Vec::new());
            for &link in &links {
                let damage = sizes.damage(link, size)?;
                let damaged_robot = damage.apply(&robot)?;
                let observed = silhouettes(&damaged_robot, &camera, &render_options, &angles);
                let scores = PoolScores::new(&pred, &observed, &masks, &changes, px);
                for (ki, &k) in cfg.ks.iter().enumerate() {
                    let h_scores = &healthy_trials[ki].scores;
                    let d = scores.trials(
                        k,
                        cfg.trials,
                        cfg.seed ^ 0xDA3A6E ^ ((link * 131 + ki) as u64),
                    );
                    let d_scores = d.scores.clone();
                    let threshold = threshold_at(h_scores, cfg.false_alarms);
                    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
                    detection.push(DetectionRow {
                        damage: sizes.kind.clone(),
                        size,
                        link: link + 1,
                        k,
                        auc: roc_auc(h_scores, &d_scores),
                        detected_pct: 100.0
                            * d_scores.iter().filter(|&&s| s > threshold).count() as f64
                            / d_scores.len().max(1) as f64,
                        false_alarms: cfg.false_alarms,
                        healthy_score: mean(h_scores),
                        damaged_score: mean(&d_scores),
                        trials: cfg.trials,
                        git_revision: revision.clone(),
                        device: device.clone(),
                        preset: preset.clone(),
                    });
                    let by_masks = d
                        .shares
                        .iter()
                        .filter(|s| localise(s, &baselines[ki], cfg.z_threshold) == link)
                        .count();
                    let chosen: Vec<usize> = d
                        .hypotheses
                        .iter()
                        .map(|s| best_hypothesis(s, &hypothesis_baselines[ki]))
                        .collect();
                    let mut counts = vec![0usize; robot.dof()];
                    let mut kinds = vec![0usize; named.len()];
                    for &h in &chosen {
                        counts[named[h].link()] += 1;
                        kinds[h] += 1;
                    }
                    let argmax = |v: &[usize]| {
                        v.iter()
                            .enumerate()
                            .max_by_key(|(_, c)| **c)
                            .map_or(0, |(i, _)| i)
                    };
                    let trials_n = chosen.len().max(1) as f64;
                    localisation.push(LocalisationRow {
                        damage: sizes.kind.clone(),
                        size,
                        link: link + 1,
                        k,
                        correct_pct: 100.0 * counts[link] as f64 / trials_n,
                        most_named: argmax(&counts) + 1,
                        most_named_kind: named[argmax(&kinds)].kind().into(),
                        link_masks_correct_pct: 100.0 * by_masks as f64 / trials_n,
                        trials: cfg.trials,
                        git_revision: revision.clone(),
                        device: device.clone(),
                        preset: preset.clone(),
                    });
                    if k == roc_k {
                        roc_healthy.extend_from_slice(h_scores);
                        roc_damaged.extend(d_scores);
                    }
                }
            }
            roc.push((
                format!("{} {size} {}", sizes.kind, sizes.unit()),
                roc_curve(&roc_healthy, &roc_damaged),
            ));
        }
    }
    let note = format!(
        "NeuroKin ({} preset) trained on the healthy arm; k images at test poses drawn from a pool of {} ({} trials per damage and k, as many healthy). Score: the mean over the k images of 1 - IoU between NeuroKin's silhouette and the observed one. AUC: the chance a damaged trial outscores a healthy one; detected: damaged trials above the healthy trials' {}% false-alarm threshold. Sizes: degrees (bend), cm (lengthen, shorten), share missing (truncate). Links counted from the base, 1 first.",
        cfg.model_preset,
        pool.len(),
        cfg.trials,
        100.0 * cfg.false_alarms
    );
    write_table(
        &out.join("detection.csv"),
        &detection,
        "Damage detection from k images",
        &note,
    )?;
    write_table(
        &out.join("localisation.csv"),
        &localisation,
        "Which link is damaged, from k images",
        &format!(
            "The residual: the pixels where NeuroKin and the image disagree. `correct_pct`, by synthesis: the robot's description damaged in {} ways (each link bent 4 degrees either way, 2 cm longer or shorter, 40% missing) gives the pixels each damage changes at the commanded poses; the share of them the residual covers, averaged over the k images and standardised against healthy trials, picks a hypothesis, whose link is named (`most_named_kind`: the kind picked most). `link_masks_correct_pct`: each link's mask (rendered alone, grown by {} px) instead, named: the link nearest the base scoring above {} standard deviations, else the highest.",
            named.len(),
            crate::body::damage::MASK_DILATION_PX,
            cfg.z_threshold
        ),
    )?;
    crate::report::figures::lines(
        &out.join("roc.png"),
        &format!("ROC of the residual score, k = {roc_k} images, every link"),
        "false alarm rate",
        "detection rate",
        &roc,
    )?;
    let gate_threshold = {
        let t = healthy.trials(cfg.recovery.gate_k, cfg.trials, cfg.seed ^ 0x6A7E);
        threshold_at(&t.scores, cfg.false_alarms)
    };
    let recovery = recover(
        cfg,
        &Recovering {
            model_run: &model_run,
            fitted: &fitted,
            robot: &robot,
            camera: &camera,
            out,
            gate_threshold,
            device: &device,
            revision: &revision,
            resume: opts.resume,
        },
    )?;
    if !recovery.is_empty() {
        write_table(
            &out.join("recovery.csv"),
            &recovery,
            "Recovery: the self-model updated from n images of the damaged arm",
            &format!(
                "NeuroKin ({} preset) trained on the healthy arm, then updated from n images of the damaged arm at training poses: `unchanged` (no update), `fine-tune` ({} Adam steps, batch {}, rate {}), `replay` (the same, every epoch as many healthy training images as damaged ones), `EWC` (fine-tuning with Elastic Weight Consolidation, lambda {:?}, the per-image empirical Fisher from {} healthy batches), `gated experts` (the healthy model and the fine-tuned one; the detection score of {} images of the arm picks one), `re-simulated` (the damage identified from the n images by matching rendered silhouettes over a family of damages to every link, the training poses rendered with the robot's description so damaged and the healthy model fine-tuned on them and the n images), `gated experts (re-simulated)` (the gate choosing between the healthy and the re-simulated model), `from scratch` (a new NeuroKin on the damaged arm's whole training set, the healthy model's schedule: the reference). PSNR and IoU on the test poses, of the damaged arm and of the healthy arm (forgetting); far: the damaged test poses farther from the n images than the median.",
                cfg.model_preset,
                cfg.recovery.steps,
                cfg.recovery.batch,
                cfg.recovery.learning_rate,
                cfg.recovery.ewc_lambdas,
                cfg.recovery.fisher_batches,
                cfg.recovery.gate_k
            ),
        )?;
        draw_recovery(out, &recovery)?;
    }
    let summary = detection
        .iter()
        .filter(|r| r.k == roc_k)
        .map(|r| format!("{} {} link {}: AUC {:.3}", r.damage, r.size, r.link, r.auc))
        .collect::<Vec<_>>()
        .join("; ");
    Ok(summary)
}

/// What the recovery runs with.
struct Recovering<'a> {
    model_run:
        &'a crate::self_models::harness::SelfModelRun<crate::self_models::neurokin::NeuroKinConfig>,
    fitted: &'a crate::self_models::harness::Fitted,
    robot: &'a crate::sim::robot::Robot,
    camera: &'a crate::sim::camera::Camera,
    out: &'a Path,
    gate_threshold: f64,
    device: &'a str,
    revision: &'a str,
    resume: bool,
}

/// A training set of `angles` (degrees) and their silhouettes, on `device`.
fn set_of(
    angles: &[Vec<f64>],
    silhouettes: Vec<f32>,
    size: [usize; 2],
    device: &burn::tensor::Device,
) -> crate::train::trainer::TrainSet {
    use burn::tensor::{Tensor, TensorData};
    let (n, dof) = (angles.len(), angles.first().map_or(0, Vec::len));
    let q: Vec<f32> = angles.iter().flatten().map(|&v| v as f32).collect();
    crate::train::trainer::TrainSet {
        inputs: Tensor::from_data(TensorData::new(q, [n, dof]), device),
        targets: vec![Tensor::from_data(
            TensorData::new(silhouettes, [n, 1, size[0], size[1]]),
            device,
        )],
    }
}

/// Per image of `truth`: PSNR (dB) and IoU of `model`'s silhouettes at `angles`.
fn scores(
    model: &crate::self_models::neurokin::NeuroKin,
    r: &Recovering,
    angles: &[Vec<f64>],
    truth: &[f32],
) -> Result<(Vec<f64>, Vec<f64>)> {
    use burn::module::Module;
    let valid = model.valid();
    let pred = predicted(&valid, &r.fitted.device, angles, 64)?;
    let px = truth.len() / angles.len().max(1);
    let psnr = (0..angles.len())
        .map(|i| {
            crate::eval::evaluation::psnr_db(
                &pred[i * px..(i + 1) * px],
                &truth[i * px..(i + 1) * px],
            )
        })
        .collect();
    let iou = (0..angles.len())
        .map(|i| {
            crate::eval::evaluation::iou(&pred[i * px..(i + 1) * px], &truth[i * px..(i + 1) * px])
        })
        .collect();
    Ok((psnr, iou))
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Every recovery method for every damage and n.
fn recover(cfg: &DamageConfig, r: &Recovering) -> Result<Vec<RecoveryRow>> {
    use crate::train::trainer::{TrainConfig, Trainer, autodiff_device};
    use burn::module::Module;
    let rc = &cfg.recovery;
    if rc.damages.is_empty() {
        return Ok(Vec::new());
    }
    let nk = &r.model_run.model;
    let data = &r.fitted.data;
    let size = [data.height, data.width];
    let tdev = autodiff_device(&r.fitted.device, cfg.seed);
    let checkpoint = r.out.join("checkpoint").join("model.bpk");
    // A fresh copy for every update: clones of a burn module share its BatchNorm running
    // statistics, which training one would move in all.
    let load = || -> Result<crate::self_models::neurokin::NeuroKin> {
        nk.init(&tdev, r.model_run.train.seed)?
            .try_load_file(&checkpoint)
            .map_err(|e| {
                Error::data(
                    &checkpoint,
                    format!(
                        "the healthy NeuroKin cannot be read ({e}); run again without --resume"
                    ),
                )
            })
    };
    let healthy = load()?;
    let loss = nk.training_loss();
    let train_angles: Vec<Vec<f64>> = r
        .fitted
        .train_range
        .clone()
        .map(|i| data.angles[i].clone())
        .collect();
    let test_angles: Vec<Vec<f64>> = r
        .fitted
        .test_range
        .clone()
        .map(|i| data.angles[i].clone())
        .collect();
    let healthy_train: Vec<f32> = r
        .fitted
        .train_range
        .clone()
        .flat_map(|i| data.image(i).iter().map(|&v| v as f32 / 255.0))
        .collect();
    let healthy_set = nk.training_set(&set_of(&train_angles, healthy_train, size, &tdev));
    let train_cfg = |steps: usize, seed: u64| TrainConfig {
        steps,
        batch: rc.batch,
        learning_rate: rc.learning_rate,
        seed,
        checkpoint_every: 0,
        log_every: 0,
        ..r.model_run.train.clone()
    };
    // The healthy arm's test images, and the gate's view of the healthy arm.
    let healthy_truth = &r.fitted.truth;
    let px = size[0] * size[1];
    let gate_score =
        |model: &crate::self_models::neurokin::NeuroKin, truth: &[f32], seed: u64| -> Result<f64> {
            use burn::module::Module;
            let mut rng = StdRng::seed_from_u64(seed);
            let pick = sample(
                &mut rng,
                test_angles.len(),
                rc.gate_k.min(test_angles.len()),
            )
            .into_vec();
            let angles: Vec<Vec<f64>> = pick.iter().map(|&i| test_angles[i].clone()).collect();
            let obs: Vec<f32> = pick
                .iter()
                .flat_map(|&i| truth[i * px..(i + 1) * px].iter().copied())
                .collect();
            let pred = predicted(&model.valid(), &r.fitted.device, &angles, 64)?;
            Ok(mean(
                &(0..pick.len())
                    .map(|i| residual(&pred[i * px..(i + 1) * px], &obs[i * px..(i + 1) * px]))
                    .collect::<Vec<_>>(),
            ))
        };
    // Finished rows (one method on one damage at one n), kept in the checkpoint folder so
    // that a killed run resumes where it stopped, and a run with more EWC weights computes
    // only theirs.
    let cache_path = r.out.join("checkpoint").join("recovery_rows.json");
    let mut recovery = serde_json::to_value(rc).map_err(|e| Error::Training(e.to_string()))?;
    if let Some(fields) = recovery.as_object_mut() {
        // Rows that depend on these name them in their keys.
        fields.remove("ewc_lambdas");
        fields.remove("resimulate_steps");
    }
    let fingerprint =
        serde_json::json!({"recovery": recovery, "run": r.model_run, "seed": cfg.seed});
    let mut cache = RowCache {
        fingerprint: fingerprint.clone(),
        rows: Default::default(),
    };
    if r.resume && cache_path.exists() {
        let text = std::fs::read_to_string(&cache_path).map_err(|e| Error::io(&cache_path, e))?;
        if let Ok(old) = serde_json::from_str::<RowCache>(&text)
            && old.fingerprint == fingerprint
        {
            cache = old;
        }
    }
    let keep = |cache: &mut RowCache, key: String, row: RecoveryRow| -> Result<RecoveryRow> {
        cache.rows.insert(key, row.clone());
        write_json(&cache_path, cache)?;
        Ok(row)
    };
    // EWC's Fisher information, from the healthy model on healthy batches: once for every
    // update (its seconds are counted in each EWC update's).
    let mut fisher: Option<(crate::train::ewc::Ewc, f64)> = None;
    let mut rows = Vec::new();
    for damage in &rc.damages {
        let damaged_robot = damage.apply(r.robot)?;
        let render = |angles: &[Vec<f64>]| {
            silhouettes(
                &damaged_robot,
                r.camera,
                &r.model_run.data.dataset.render,
                angles,
            )
        };
        let (damaged_test, damaged_train) = (render(&test_angles), render(&train_angles));
        let mut order: Vec<usize> = (0..train_angles.len()).collect();
        rand::seq::SliceRandom::shuffle(
            order.as_mut_slice(),
            &mut StdRng::seed_from_u64(cfg.seed ^ 0x5EED),
        );
        // `models`: the model scored on the damaged arm's images and the one on the healthy
        // arm's (the same but for the gated experts).
        let row = |method: &str,
                   n: usize,
                   models: (
            &crate::self_models::neurokin::NeuroKin,
            &crate::self_models::neurokin::NeuroKin,
        ),
                   seconds: f64,
                   steps: usize,
                   far: &[bool],
                   detail: String|
         -> Result<RecoveryRow> {
            let (pd, idam) = scores(models.0, r, &test_angles, &damaged_test)?;
            let (ph, ih) = scores(models.1, r, &test_angles, healthy_truth)?;
            let far_psnr: Vec<f64> = pd
                .iter()
                .zip(far)
                .filter(|(_, f)| **f)
                .map(|(p, _)| *p)
                .collect();
            Ok(RecoveryRow {
                method: method.into(),
                n,
                psnr_damaged_db: mean(&pd),
                iou_damaged: mean(&idam),
                psnr_healthy_db: mean(&ph),
                iou_healthy: mean(&ih),
                seconds,
                damage: damage.kind().into(),
                size: damage.size(),
                link: damage.link() + 1,
                psnr_damaged_far_db: (!far_psnr.is_empty()).then(|| mean(&far_psnr)),
                steps,
                detail,
                git_revision: r.revision.into(),
                device: r.device.into(),
                preset: cfg.preset.clone(),
            })
        };
        for &n in &rc.ns {
            let n = n.min(order.len());
            let key = |method: &str| format!("{} n={n} {method}", damage.label());
            let ewc_method = |lambda: f64| {
                if rc.ewc_lambdas.len() == 1 {
                    "EWC".to_string()
                } else {
                    format!("EWC (lambda {lambda:e})")
                }
            };
            let mut methods = vec!["unchanged".to_string(), "fine-tune".into()];
            if rc.replay {
                methods.push("replay".into());
            }
            methods.extend(rc.ewc_lambdas.iter().map(|&l| ewc_method(l)));
            methods.push("gated experts".into());
            let resimulated = rc.resimulate_steps.map(|steps| {
                [
                    format!("re-simulated/{steps}"),
                    format!("gated experts (re-simulated)/{steps}"),
                ]
            });
            methods.extend(resimulated.iter().flatten().cloned());
            if methods.iter().all(|m| cache.rows.contains_key(&key(m))) {
                rows.extend(methods.iter().map(|m| cache.rows[&key(m)].clone()));
                continue;
            }
            let mut group = Vec::new();
            let picked: Vec<usize> = order[..n].to_vec();
            let angles: Vec<Vec<f64>> = picked.iter().map(|&i| train_angles[i].clone()).collect();
            let sil: Vec<f32> = picked
                .iter()
                .flat_map(|&i| damaged_train[i * px..(i + 1) * px].iter().copied())
                .collect();
            // Test poses far from the n images (joint space, degrees).
            let nearest: Vec<f64> = test_angles
                .iter()
                .map(|t| {
                    angles
                        .iter()
                        .map(|a| {
                            a.iter()
                                .zip(t)
                                .map(|(x, y)| (x - y).powi(2))
                                .sum::<f64>()
                                .sqrt()
                        })
                        .fold(f64::INFINITY, f64::min)
                })
                .collect();
            let mut sorted = nearest.clone();
            sorted.sort_by(f64::total_cmp);
            let median = sorted[sorted.len() / 2];
            let far: Vec<bool> = nearest.iter().map(|&d| d > median).collect();
            let set = nk.training_set(&set_of(&angles, sil.clone(), size, &tdev));
            let seed = cfg.seed ^ (n as u64) << 8;
            group.push(match cache.rows.get(&key("unchanged")) {
                Some(done) => done.clone(),
                None => keep(
                    &mut cache,
                    key("unchanged"),
                    row(
                        "unchanged",
                        n,
                        (&healthy, &healthy),
                        0.0,
                        0,
                        &far,
                        String::new(),
                    )?,
                )?,
            });
            // The fine-tuned model (also the gated experts' damage expert), where a row needs it.
            let fine_tuned = || -> Result<(crate::self_models::neurokin::NeuroKin, f64)> {
                let label = format!("fine-tune ({}, n = {n})", damage.label());
                let t = std::time::Instant::now();
                let (tuned, _) =
                    Trainer::new(&train_cfg(rc.steps, seed), &label).fit(load()?, &set, &loss)?;
                Ok((tuned, t.elapsed().as_secs_f64()))
            };
            let tuned = if cache.rows.contains_key(&key("fine-tune"))
                && cache.rows.contains_key(&key("gated experts"))
            {
                None
            } else {
                Some(fine_tuned()?)
            };
            group.push(match (cache.rows.get(&key("fine-tune")), &tuned) {
                (Some(done), _) => done.clone(),
                (None, Some((tuned, tuned_s))) => keep(
                    &mut cache,
                    key("fine-tune"),
                    row(
                        "fine-tune",
                        n,
                        (tuned, tuned),
                        *tuned_s,
                        rc.steps,
                        &far,
                        String::new(),
                    )?,
                )?,
                (None, None) => unreachable!("trained above"),
            });
            if let Some(done) = cache.rows.get(&key("replay")).filter(|_| rc.replay) {
                group.push(done.clone());
            } else if rc.replay {
                // Every epoch: the n damaged images repeated to as many as the healthy ones.
                let m = train_angles.len().min(n.max(400));
                let reps = m.div_ceil(n.max(1));
                let mut q: Vec<Vec<f64>> = Vec::new();
                let mut px_all: Vec<f32> = Vec::new();
                for _ in 0..reps {
                    q.extend(angles.iter().cloned());
                    px_all.extend_from_slice(&sil);
                }
                for &i in order.iter().rev().take(m) {
                    q.push(train_angles[i].clone());
                    px_all.extend(
                        data.image(r.fitted.train_range.start + i)
                            .iter()
                            .map(|&v| v as f32 / 255.0),
                    );
                }
                let mixed = nk.training_set(&set_of(&q, px_all, size, &tdev));
                let label = format!("replay ({}, n = {n})", damage.label());
                let t = std::time::Instant::now();
                let (m_model, _) =
                    Trainer::new(&train_cfg(rc.steps, seed), &label).fit(load()?, &mixed, &loss)?;
                group.push(keep(
                    &mut cache,
                    key("replay"),
                    row(
                        "replay",
                        n,
                        (&m_model, &m_model),
                        t.elapsed().as_secs_f64(),
                        rc.steps,
                        &far,
                        format!("{m} healthy images mixed in"),
                    )?,
                )?);
            }
            for &lambda in &rc.ewc_lambdas {
                let method = ewc_method(lambda);
                if let Some(done) = cache.rows.get(&key(&method)) {
                    group.push(done.clone());
                    continue;
                }
                if fisher.is_none() {
                    let t = std::time::Instant::now();
                    // A fresh copy: a training-mode pass moves BatchNorm's running statistics.
                    let ewc = crate::train::ewc::Ewc::new(
                        &load()?,
                        &healthy_set,
                        &train_cfg(rc.fisher_batches, cfg.seed),
                        rc.fisher_batches,
                        &loss,
                        1.0,
                    )?;
                    fisher = Some((ewc, t.elapsed().as_secs_f64()));
                }
                let (ewc, fisher_s) = fisher.as_mut().expect("computed above");
                ewc.lambda = lambda;
                let label = format!("{method} ({}, n = {n})", damage.label());
                let t = std::time::Instant::now();
                let ewc = &*ewc;
                let (e_model, _) = Trainer::new(&train_cfg(rc.steps, seed), &label).fit(
                    load()?,
                    &set,
                    |m, b| loss(m, b) + ewc.penalty(m),
                )?;
                let done = row(
                    &method,
                    n,
                    (&e_model, &e_model),
                    t.elapsed().as_secs_f64() + *fisher_s,
                    rc.steps,
                    &far,
                    format!(
                        "lambda {lambda:e}; Fisher from {} healthy batches",
                        rc.fisher_batches
                    ),
                )?;
                group.push(keep(&mut cache, key(&method), done)?);
            }
            // Gated experts: the healthy model and the fine-tuned one, the gate scoring what the
            // arm looks like now through the healthy model.
            let gated = |truth: &[f32], seed: u64| -> Result<bool> {
                Ok(gate_score(&healthy, truth, seed)? > r.gate_threshold)
            };
            let (on_damaged, on_healthy) = (
                gated(&damaged_test, seed ^ 1)?,
                gated(healthy_truth, seed ^ 2)?,
            );
            let expert = |damaged: bool| {
                if damaged {
                    "damage (fine-tuned expert)"
                } else {
                    "healthy (healthy expert)"
                }
            };
            group.push(match (cache.rows.get(&key("gated experts")), &tuned) {
                (Some(done), _) => done.clone(),
                (None, Some((tuned, tuned_s))) => {
                    let pick = |damaged: bool| if damaged { tuned } else { &healthy };
                    let done = row(
                        "gated experts",
                        n,
                        (pick(on_damaged), pick(on_healthy)),
                        *tuned_s,
                        rc.steps,
                        &far,
                        format!(
                            "gate on the damaged arm: {}; on the healthy arm: {}",
                            expert(on_damaged),
                            expert(on_healthy)
                        ),
                    )?;
                    keep(&mut cache, key("gated experts"), done)?
                }
                (None, None) => unreachable!("trained above"),
            });
            if let (Some(steps), Some([rkey, gkey])) = (rc.resimulate_steps, &resimulated) {
                if let (Some(a), Some(b)) = (cache.rows.get(&key(rkey)), cache.rows.get(&key(gkey)))
                {
                    group.extend([a.clone(), b.clone()]);
                } else {
                    let t = std::time::Instant::now();
                    let options = &r.model_run.data.dataset.render;
                    let (found, fit) =
                        crate::body::damage::identify(r.robot, r.camera, options, &angles, &sil)
                            .ok_or_else(|| {
                                Error::Config(
                                    "re-simulation: no candidate damage applies to the robot"
                                        .into(),
                                )
                            })?;
                    let resim_robot = found.apply(r.robot)?;
                    let mut q = train_angles.clone();
                    let mut pixels = silhouettes(&resim_robot, r.camera, options, &train_angles);
                    q.extend(angles.iter().cloned());
                    pixels.extend_from_slice(&sil);
                    let resim_set = nk.training_set(&set_of(&q, pixels, size, &tdev));
                    let label = format!("re-simulated ({}, n = {n})", damage.label());
                    let (resim, _) = Trainer::new(&train_cfg(steps, seed), &label).fit(
                        load()?,
                        &resim_set,
                        &loss,
                    )?;
                    let seconds = t.elapsed().as_secs_f64();
                    let detail = format!(
                        "identified: {} (mean IoU {fit:.3} on the n images); fine-tuned on its {} rendered training poses and the n images",
                        found.label(),
                        train_angles.len()
                    );
                    let done = row(
                        "re-simulated",
                        n,
                        (&resim, &resim),
                        seconds,
                        steps,
                        &far,
                        detail.clone(),
                    )?;
                    group.push(keep(&mut cache, key(rkey), done)?);
                    let pick = |damaged: bool| if damaged { &resim } else { &healthy };
                    let resim_expert = |damaged: bool| {
                        if damaged {
                            "damage (re-simulated expert)"
                        } else {
                            "healthy (healthy expert)"
                        }
                    };
                    let done = row(
                        "gated experts (re-simulated)",
                        n,
                        (pick(on_damaged), pick(on_healthy)),
                        seconds,
                        steps,
                        &far,
                        format!(
                            "gate on the damaged arm: {}; on the healthy arm: {}; {detail}",
                            resim_expert(on_damaged),
                            resim_expert(on_healthy)
                        ),
                    )?;
                    group.push(keep(&mut cache, key(gkey), done)?);
                }
            }
            rows.extend(group);
        }
        let key = format!("{} from scratch", damage.label());
        if let Some(done) = cache.rows.get(&key).filter(|_| rc.from_scratch) {
            rows.push(done.clone());
        } else if rc.from_scratch {
            let all = nk.training_set(&set_of(&train_angles, damaged_train.clone(), size, &tdev));
            let label = format!("from scratch ({})", damage.label());
            let plan = crate::train::trainer::CheckpointPlan {
                dir: r.out.join("checkpoint").join(format!(
                    "scratch_{}",
                    crate::core::atomic_file::file_name(&damage.label())
                )),
                resume: true,
                fingerprint: serde_json::json!({"damage": damage, "model": nk, "train": r.model_run.train}),
            };
            let t = std::time::Instant::now();
            let (scratch, log) = Trainer::new(&r.model_run.train, &label)
                .checkpoint(Some(&plan))
                .fit(nk.init(&tdev, r.model_run.train.seed)?, &all, &loss)?;
            let all_far = vec![false; test_angles.len()];
            let done = row(
                "from scratch",
                train_angles.len(),
                (&scratch, &scratch),
                t.elapsed().as_secs_f64().max(log.train_seconds),
                r.model_run.train.steps,
                &all_far,
                "every training pose of the damaged arm".into(),
            )?;
            rows.push(keep(&mut cache, key, done)?);
        }
    }
    Ok(rows)
}

/// Finished recovery rows by damage, n and method, and what they were computed for.
#[derive(Serialize, Deserialize)]
struct RowCache {
    fingerprint: serde_json::Value,
    rows: std::collections::BTreeMap<String, RecoveryRow>,
}

/// `recovery_damaged.png` and `recovery_healthy.png`: PSNR against n per method, the first
/// damage; `recovery_tradeoff_<damage>.png` per damage: at the n nearest 50, each method's PSNR
/// on the healthy arm against the damaged one's (EWC's weights joined, as a path).
fn draw_recovery(out: &Path, rows: &[RecoveryRow]) -> Result<()> {
    let first = &rows[0];
    let same =
        |r: &&RecoveryRow| r.damage == first.damage && r.size == first.size && r.link == first.link;
    let mut methods: Vec<&str> = Vec::new();
    for r in rows.iter().filter(same) {
        if r.method != "from scratch" && !methods.contains(&r.method.as_str()) {
            methods.push(&r.method);
        }
    }
    for (file, what, f) in [
        (
            "recovery_damaged.png",
            "the damaged arm",
            (|r: &RecoveryRow| r.psnr_damaged_db) as fn(&RecoveryRow) -> f64,
        ),
        (
            "recovery_healthy.png",
            "the healthy arm (forgetting)",
            |r: &RecoveryRow| r.psnr_healthy_db,
        ),
    ] {
        let runs: Vec<(String, Vec<(f64, f64)>)> = methods
            .iter()
            .map(|m| {
                (
                    m.to_string(),
                    rows.iter()
                        .filter(same)
                        .filter(|r| r.method == *m)
                        .map(|r| (r.n as f64, f(r)))
                        .collect(),
                )
            })
            .collect();
        crate::report::figures::lines_log_x(
            &out.join(file),
            &format!(
                "PSNR on {what} after recovery from n images ({} {}, link {})",
                first.damage, first.size, first.link
            ),
            "images of the damaged arm (n)",
            "PSNR (dB)",
            &runs,
        )?;
    }
    let mut damages: Vec<(&str, f64, usize)> = Vec::new();
    for r in rows {
        let d = (r.damage.as_str(), r.size, r.link);
        if !damages.contains(&d) {
            damages.push(d);
        }
    }
    for (damage, size, link) in damages {
        let of: Vec<&RecoveryRow> = rows
            .iter()
            .filter(|r| (r.damage.as_str(), r.size, r.link) == (damage, size, link))
            .collect();
        let Some(n) = of
            .iter()
            .filter(|r| r.method != "from scratch")
            .map(|r| r.n)
            .min_by_key(|n| n.abs_diff(50))
        else {
            continue;
        };
        let point = |r: &RecoveryRow| (r.psnr_healthy_db, r.psnr_damaged_db);
        let mut runs: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
        let ewc: Vec<(f64, f64)> = of
            .iter()
            .filter(|r| r.n == n && r.method.starts_with("EWC"))
            .map(|r| point(r))
            .collect();
        for r in &of {
            if r.method.starts_with("EWC") || (r.n != n && r.method != "from scratch") {
                continue;
            }
            runs.push((r.method.clone(), vec![point(r)]));
        }
        if !ewc.is_empty() {
            runs.push(("EWC, weight rising".into(), ewc));
        }
        crate::report::figures::lines_marked(
            &out.join(format!(
                "recovery_tradeoff_{}.png",
                crate::core::atomic_file::file_name(&format!("{damage} {size} link {link}"))
            )),
            &format!(
                "Damaged arm against healthy arm, {damage} {size} link {link}, n = {n} images"
            ),
            "PSNR on the healthy arm (dB)",
            "PSNR on the damaged arm (dB)",
            &runs,
            true,
        )?;
    }
    Ok(())
}
