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
    ShareBaseline, link_masks, link_shares, localise, predicted, residual, roc_auc, roc_curve,
    threshold_at,
};
use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::core::provenance::git_revision;
use crate::report::table::write_table;
use crate::self_models::harness::fit_run;
use crate::self_models::neurokin::neurokin_run;
use crate::sim::arm_change::Damage;
use crate::sim::ray_caster::RayCaster;

/// A kind of damage and its sizes (degrees for `bend`, centimetres for `lengthen` and
/// `shorten`, the share missing for `truncate`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DamageSizes {
    pub kind: String,
    pub sizes: Vec<f64>,
}

impl DamageSizes {
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
    /// The NeuroKin preset trained on the healthy arm.
    pub model_preset: String,
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
}

impl Preset for DamageConfig {
    /// NeuroKin's paper preset; bends of 3, 5 and 10 degrees, links 1, 2, 3 and 5 cm longer,
    /// 1, 2 and 3 cm shorter, a quarter and a half missing; every link; k in {1, 3, 10, 30};
    /// 200 trials from the 400 test poses.
    fn paper() -> Self {
        DamageConfig {
            preset: "paper".into(),
            model_preset: "paper".into(),
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
        }
    }

    /// NeuroKin's quick preset (32x32), a 10-degree bend and a 3 cm lengthening of link 2,
    /// k in {1, 10}: seconds.
    fn quick() -> Self {
        DamageConfig {
            preset: "quick".into(),
            model_preset: "quick".into(),
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
    /// Trials naming the damaged link (%).
    pub correct_pct: f64,
    /// The link named most often (1-based).
    pub most_named: usize,
    pub trials: usize,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// Per pose of the pool: the residual and the link shares, for one arm (healthy or damaged).
struct PoolScores {
    residual: Vec<f64>,
    shares: Vec<Vec<f64>>,
}

impl PoolScores {
    fn new(pred: &[f32], observed: &[f32], masks: &[Vec<Vec<bool>>], px: usize) -> Self {
        let n = masks.len();
        PoolScores {
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

    /// `trials` draws of k poses: each trial's mean residual and mean link shares.
    fn trials(&self, k: usize, trials: usize, seed: u64) -> (Vec<f64>, Vec<Vec<f64>>) {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = self.residual.len();
        let links = self.shares.first().map_or(0, Vec::len);
        let (mut scores, mut shares) = (Vec::new(), Vec::new());
        for _ in 0..trials {
            let pick = sample(&mut rng, n, k.min(n)).into_vec();
            let m = pick.len() as f64;
            scores.push(pick.iter().map(|&i| self.residual[i]).sum::<f64>() / m);
            shares.push(
                (0..links)
                    .map(|l| pick.iter().map(|&i| self.shares[i][l]).sum::<f64>() / m)
                    .collect(),
            );
        }
        (scores, shares)
    }
}

/// Run the study into `out`.
pub fn run(
    cfg: &DamageConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
) -> Result<String> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    write_json(&out.join("config.json"), cfg)?;
    let model_run = opts.apply(neurokin_run(&cfg.model_preset)?)?;
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
    let healthy = PoolScores::new(&pred, &healthy_obs, &masks, px);
    let links: Vec<usize> = if cfg.links.is_empty() {
        (0..robot.dof()).collect()
    } else {
        cfg.links.clone()
    };
    let si: Vec<Vec<f64>> = angles.iter().map(|q| robot.chain.to_si(q)).collect();
    let render_options = model_run.data.dataset.render.clone();
    let (device, preset, revision) = (opts.device.to_string(), cfg.preset.clone(), git_revision());
    // Healthy trials per k: the detection threshold and the localisation baseline.
    let healthy_trials: Vec<(Vec<f64>, Vec<Vec<f64>>)> = cfg
        .ks
        .iter()
        .map(|&k| healthy.trials(k, cfg.trials, cfg.seed ^ 0x4EA1 ^ k as u64))
        .collect();
    let baselines: Vec<ShareBaseline> = healthy_trials
        .iter()
        .map(|(_, s)| ShareBaseline::new(s))
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
                let frames = RayCaster::new(&damaged_robot, camera.clone(), render_options.clone())
                    .render_batch(&si, None);
                let observed: Vec<f32> = frames
                    .iter()
                    .flat_map(|f| f.silhouette.iter().map(|&v| v as f32 / 255.0))
                    .collect();
                let scores = PoolScores::new(&pred, &observed, &masks, px);
                for (ki, &k) in cfg.ks.iter().enumerate() {
                    let (h_scores, _) = &healthy_trials[ki];
                    let (d_scores, d_shares) = scores.trials(
                        k,
                        cfg.trials,
                        cfg.seed ^ 0xDA3A6E ^ ((link * 131 + ki) as u64),
                    );
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
                    let named: Vec<usize> = d_shares
                        .iter()
                        .map(|s| localise(s, &baselines[ki], cfg.z_threshold))
                        .collect();
                    let mut counts = vec![0usize; robot.dof()];
                    for &n in &named {
                        counts[n] += 1;
                    }
                    let most = counts
                        .iter()
                        .enumerate()
                        .max_by_key(|(_, c)| **c)
                        .map_or(0, |(i, _)| i);
                    localisation.push(LocalisationRow {
                        damage: sizes.kind.clone(),
                        size,
                        link: link + 1,
                        k,
                        correct_pct: 100.0 * counts[link] as f64 / named.len().max(1) as f64,
                        most_named: most + 1,
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
                format!("{} {size}", sizes.kind),
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
            "The residual (pixels where NeuroKin and the image disagree) against each link's mask at the commanded pose (rendered alone, grown by {} px); each link's share of it, averaged over the k images and standardised against healthy trials; named: the link nearest the base scoring above {}, else the highest.",
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
    let summary = detection
        .iter()
        .filter(|r| r.k == roc_k)
        .map(|r| format!("{} {} link {}: AUC {:.3}", r.damage, r.size, r.link, r.auc))
        .collect::<Vec<_>>()
        .join("; ");
    Ok(summary)
}
