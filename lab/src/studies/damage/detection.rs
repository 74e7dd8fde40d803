//! Detection and localisation: k images of the arm at commanded poses scored through NeuroKin
//! trained on the healthy arm (the residual), against healthy trials of as many images; the
//! damaged link named by synthesis (which damage hypothesis' changed pixels the residual
//! covers) and by link masks.

use std::path::Path;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::index::sample;
use serde::{Deserialize, Serialize};

use super::{DamageConfig, DamageSizes};
use selfmodel::body::damage::{
    ShareBaseline, best_hypothesis, change_masks, hypotheses, link_masks, link_shares, localise,
    predicted, residual, roc_auc, roc_curve, threshold_at,
};
use selfmodel::core::error::Result;
use selfmodel::report::table::write_table;
use selfmodel::self_models::neurokin::NeuroKinConfig;
use selfmodel::self_models::{harness::Fitted, run_config::SelfModelRun};
use selfmodel::sim::arm_change::Damage;
use selfmodel::sim::camera::Camera;
use selfmodel::sim::ray_caster::{RenderOptions, silhouettes};
use selfmodel::sim::robot::Robot;

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

/// Per pose of the pool: the residual and the link shares, for one arm (healthy or damaged).
pub(super) struct PoolScores {
    residual: Vec<f64>,
    shares: Vec<Vec<f64>>,
    /// Per pose, the share of each hypothesis' changed pixels the residual covers.
    hypotheses: Vec<Vec<f64>>,
}

impl PoolScores {
    pub(super) fn new(
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
    pub(super) fn trials(&self, k: usize, trials: usize, seed: u64) -> Trials {
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
pub(super) struct Trials {
    pub scores: Vec<f64>,
    pub shares: Vec<Vec<f64>>,
    pub hypotheses: Vec<Vec<f64>>,
}
/// What detection found: the tables' rows, the ROC curves at `roc_k`, and the gate's
/// threshold for the recovery (healthy trials of `gate_k` images at the false-alarm rate).
pub(super) struct Detected {
    pub detection: Vec<DetectionRow>,
    pub localisation: Vec<LocalisationRow>,
    pub roc: Vec<(String, Vec<(f64, f64)>)>,
    pub roc_k: usize,
    pub gate_threshold: f64,
    /// Test poses the trials drew from.
    pub pool: usize,
    /// Damage hypotheses localisation by synthesis chose from.
    pub hypotheses: usize,
}

/// `detection.csv`, `localisation.csv` (+ Markdown) and `roc.png`.
pub(super) fn write_detection(cfg: &DamageConfig, out: &Path, found: &Detected) -> Result<()> {
    let note = format!(
        "NeuroKin ({} preset) trained on the healthy arm; k images at test poses drawn from a pool of {} ({} trials per damage and k, as many healthy). Score: the mean over the k images of 1 - IoU between NeuroKin's silhouette and the observed one. AUC: the chance a damaged trial outscores a healthy one; detected: damaged trials above the healthy trials' {}% false-alarm threshold. Sizes: degrees (bend), cm (lengthen, shorten), share missing (truncate). Links counted from the base, 1 first.",
        cfg.model_preset,
        found.pool,
        cfg.trials,
        100.0 * cfg.false_alarms
    );
    write_table(
        &out.join("detection.csv"),
        &found.detection,
        "Damage detection from k images",
        &note,
    )?;
    write_table(
        &out.join("localisation.csv"),
        &found.localisation,
        "Which link is damaged, from k images",
        &format!(
            "The residual: the pixels where NeuroKin and the image disagree. `correct_pct`, by synthesis: the robot's description damaged in {} ways (each link bent 4 degrees either way, 2 cm longer or shorter, 40% missing) gives the pixels each damage changes at the commanded poses; the share of them the residual covers, averaged over the k images and standardised against healthy trials, picks a hypothesis, whose link is named (`most_named_kind`: the kind picked most). `link_masks_correct_pct`: each link's mask (rendered alone, grown by {} px) instead, named: the link nearest the base scoring above {} standard deviations, else the highest.",
            found.hypotheses,
            selfmodel::body::damage::MASK_DILATION_PX,
            cfg.z_threshold
        ),
    )?;
    selfmodel::report::figures::line_plot(
        &out.join("roc.png"),
        &format!(
            "ROC of the residual score, k = {} images, every link",
            found.roc_k
        ),
        ("false alarm rate", "detection rate"),
        &found.roc,
        selfmodel::report::figures::LinePlot::LINEAR,
    )?;
    Ok(())
}

/// The healthy model's view of the pool of test poses, and what each trial is scored against.
struct Pool<'a> {
    cfg: &'a DamageConfig,
    robot: &'a Robot,
    render: RenderOptions,
    angles: Vec<Vec<f64>>,
    pred: Vec<f32>,
    masks: Vec<Vec<Vec<bool>>>,
    named: Vec<Damage>,
    changes: Vec<Vec<Vec<bool>>>,
    px: usize,
    /// Healthy trials per k: the detection threshold and the localisation baselines.
    healthy_trials: Vec<Trials>,
    baselines: Vec<ShareBaseline>,
    hypothesis_baselines: Vec<ShareBaseline>,
    stamp: (String, String),
}

/// Every damage of `cfg` to every link at every k, scored on the pool of test poses through
/// the fitted healthy model. `stamp`: the rows' device and revision.
pub(super) fn detect(
    cfg: &DamageConfig,
    model_run: &SelfModelRun<NeuroKinConfig>,
    fitted: &Fitted<Box<dyn selfmodel::Render>>,
    robot: &Robot,
    camera: &Camera,
    stamp: (String, String),
) -> Result<Detected> {
    let data = &fitted.data;
    let px = data.width * data.height;
    let pool: Vec<usize> = fitted
        .test_range
        .clone()
        .take(cfg.pool.min(fitted.test_range.len()))
        .collect();
    let angles: Vec<Vec<f64>> = pool.iter().map(|&i| data.angles[i].clone()).collect();
    let renderer = fitted.trained.renderers[0].1.as_ref();
    let pred = predicted(renderer, &fitted.device, &angles, 64)?;
    let healthy_obs: Vec<f32> = pool
        .iter()
        .flat_map(|&i| data.images[i * px..(i + 1) * px].iter())
        .map(|&v| v as f32 / 255.0)
        .collect();
    let masks = link_masks(robot, camera, &angles);
    let named = hypotheses(robot.dof());
    let changes = change_masks(robot, camera, &angles, &named);
    let healthy = PoolScores::new(&pred, &healthy_obs, &masks, &changes, px);
    let healthy_trials: Vec<Trials> = cfg
        .ks
        .iter()
        .map(|&k| healthy.trials(k, cfg.trials, cfg.seed ^ 0x4EA1 ^ k as u64))
        .collect();
    let baselines = healthy_trials
        .iter()
        .map(|t| ShareBaseline::new(&t.shares))
        .collect();
    let hypothesis_baselines = healthy_trials
        .iter()
        .map(|t| ShareBaseline::new(&t.hypotheses))
        .collect();
    let p = Pool {
        cfg,
        robot,
        render: model_run.data.dataset.render.clone(),
        angles,
        pred,
        masks,
        named,
        changes,
        px,
        healthy_trials,
        baselines,
        hypothesis_baselines,
        stamp,
    };
    let links: Vec<usize> = if cfg.links.is_empty() {
        (0..robot.dof()).collect()
    } else {
        cfg.links.clone()
    };
    let roc_k = cfg
        .ks
        .iter()
        .copied()
        .find(|&k| k >= 10)
        .unwrap_or(cfg.ks[cfg.ks.len() - 1]);
    let mut found = Detected {
        detection: Vec::new(),
        localisation: Vec::new(),
        roc: Vec::new(),
        roc_k,
        gate_threshold: {
            let t = healthy.trials(cfg.recovery.gate_k, cfg.trials, cfg.seed ^ 0x6A7E);
            threshold_at(&t.scores, cfg.false_alarms)
        },
        pool: pool.len(),
        hypotheses: p.named.len(),
    };
    for sizes in &cfg.damages {
        for &size in &sizes.sizes {
            // One ROC curve per kind and size at `roc_k`, every link's trials together.
            let (mut roc_healthy, mut roc_damaged) = (Vec::new(), Vec::new());
            for &link in &links {
                let damage = sizes.damage(link, size)?;
                let damaged_robot = damage.apply(robot)?;
                let observed = silhouettes(&damaged_robot, camera, &p.render, &p.angles);
                let scores = PoolScores::new(&p.pred, &observed, &p.masks, &p.changes, p.px);
                for (ki, &k) in cfg.ks.iter().enumerate() {
                    let seed = cfg.seed ^ 0xDA3A6E ^ ((link * 131 + ki) as u64);
                    let d = scores.trials(k, cfg.trials, seed);
                    let at = Trial {
                        sizes,
                        size,
                        link,
                        k,
                        ki,
                    };
                    found.detection.push(p.detection_row(&at, &d));
                    found.localisation.push(p.localisation_row(&at, &d));
                    if k == roc_k {
                        roc_healthy.extend_from_slice(&p.healthy_trials[ki].scores);
                        roc_damaged.extend(d.scores);
                    }
                }
            }
            found.roc.push((
                format!("{} {size} {}", sizes.kind, sizes.unit()),
                roc_curve(&roc_healthy, &roc_damaged),
            ));
        }
    }
    Ok(found)
}

/// One damage (kind and size, link) at one k (the `ki`-th).
struct Trial<'s> {
    sizes: &'s DamageSizes,
    size: f64,
    link: usize,
    k: usize,
    ki: usize,
}

impl Pool<'_> {
    /// The damaged trials `d` against the healthy ones: AUC and the share detected.
    fn detection_row(&self, at: &Trial, d: &Trials) -> DetectionRow {
        let cfg = self.cfg;
        let h_scores = &self.healthy_trials[at.ki].scores;
        let threshold = threshold_at(h_scores, cfg.false_alarms);
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        DetectionRow {
            damage: at.sizes.kind.clone(),
            size: at.size,
            link: at.link + 1,
            k: at.k,
            auc: roc_auc(h_scores, &d.scores),
            detected_pct: 100.0 * d.scores.iter().filter(|&&s| s > threshold).count() as f64
                / d.scores.len().max(1) as f64,
            false_alarms: cfg.false_alarms,
            healthy_score: mean(h_scores),
            damaged_score: mean(&d.scores),
            trials: cfg.trials,
            git_revision: self.stamp.1.clone(),
            device: self.stamp.0.clone(),
            preset: cfg.preset.clone(),
        }
    }

    /// The link each damaged trial of `d` names, by synthesis and by link masks.
    fn localisation_row(&self, at: &Trial, d: &Trials) -> LocalisationRow {
        let cfg = self.cfg;
        let by_masks = d
            .shares
            .iter()
            .filter(|s| localise(s, &self.baselines[at.ki], cfg.z_threshold) == at.link)
            .count();
        let chosen: Vec<usize> = d
            .hypotheses
            .iter()
            .map(|s| best_hypothesis(s, &self.hypothesis_baselines[at.ki]))
            .collect();
        let mut counts = vec![0usize; self.robot.dof()];
        let mut kinds = vec![0usize; self.named.len()];
        for &h in &chosen {
            counts[self.named[h].link()] += 1;
            kinds[h] += 1;
        }
        let argmax = |v: &[usize]| {
            v.iter()
                .enumerate()
                .max_by_key(|(_, c)| **c)
                .map_or(0, |(i, _)| i)
        };
        let trials_n = chosen.len().max(1) as f64;
        LocalisationRow {
            damage: at.sizes.kind.clone(),
            size: at.size,
            link: at.link + 1,
            k: at.k,
            correct_pct: 100.0 * counts[at.link] as f64 / trials_n,
            most_named: argmax(&counts) + 1,
            most_named_kind: self.named[argmax(&kinds)].kind().into(),
            link_masks_correct_pct: 100.0 * by_masks as f64 / trials_n,
            trials: cfg.trials,
            git_revision: self.stamp.1.clone(),
            device: self.stamp.0.clone(),
            preset: cfg.preset.clone(),
        }
    }
}
