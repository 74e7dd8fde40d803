//! Recovery: the self-model updated after damage from n images of the damaged arm, one
//! function per method (unchanged, fine-tune, replay, EWC, gated experts, re-simulated, from
//! scratch). Every finished row is cached in the checkpoint folder, so that a killed run
//! resumes where it stopped and a run with more EWC weights computes only theirs.

mod methods;

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::Device;
use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::{Deserialize, Serialize};

use selfmodel::body::damage::predicted;
use selfmodel::core::atomic_file::write_json;
use selfmodel::core::error::{Error, Result};
use selfmodel::report::table::write_table;
use selfmodel::self_models::neurokin::NeuroKin;
use selfmodel::sim::arm_change::Damage;
use selfmodel::sim::ray_caster::silhouettes;
use selfmodel::train::{
    batcher::TrainSet,
    config::TrainConfig,
    trainer::{Trainer, autodiff_device},
};

use super::DamageConfig;

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

/// What the recovery runs with.
pub(super) struct Recovering<'a> {
    pub model_run: &'a selfmodel::self_models::run_config::SelfModelRun<
        selfmodel::self_models::neurokin::NeuroKinConfig,
    >,
    pub fitted: &'a selfmodel::self_models::harness::Fitted<Box<dyn selfmodel::Render>>,
    pub robot: &'a selfmodel::sim::robot::Robot,
    pub camera: &'a selfmodel::sim::camera::Camera,
    pub out: &'a Path,
    pub gate_threshold: f64,
    pub device: &'a str,
    pub revision: &'a str,
    pub resume: bool,
}

/// Finished recovery rows by damage, n and method, and what they were computed for.
#[derive(Serialize, Deserialize)]
struct RowCache {
    fingerprint: serde_json::Value,
    rows: std::collections::BTreeMap<String, RecoveryRow>,
}

/// Every recovery method for every damage and n.
pub(super) fn recover(cfg: &DamageConfig, r: &Recovering) -> Result<Vec<RecoveryRow>> {
    if cfg.recovery.damages.is_empty() {
        return Ok(Vec::new());
    }
    let mut ctx = Context::new(cfg, r)?;
    let mut rows = Vec::new();
    for damage in &cfg.recovery.damages {
        let case = ctx.case(damage)?;
        for &n in &cfg.recovery.ns {
            rows.extend(ctx.updates(&case, n)?);
        }
        if cfg.recovery.from_scratch {
            rows.push(ctx.trained_from_scratch(&case)?);
        }
    }
    Ok(rows)
}

/// `recovery.csv` (+ Markdown); the figures are drawn from it by [`super::figures`].
pub(super) fn write_recovery(
    cfg: &DamageConfig,
    out: &Path,
    recovery: &[RecoveryRow],
) -> Result<()> {
    write_table(
        &out.join("recovery.csv"),
        recovery,
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
    )
}

/// What every update shares: the healthy model, the poses, the cache of finished rows.
struct Context<'a> {
    cfg: &'a DamageConfig,
    r: &'a Recovering<'a>,
    /// The training device (autodiff).
    tdev: Device,
    checkpoint: PathBuf,
    healthy: NeuroKin,
    train_angles: Vec<Vec<f64>>,
    test_angles: Vec<Vec<f64>>,
    healthy_set: TrainSet,
    size: [usize; 2],
    cache: RowCache,
    cache_path: PathBuf,
    /// EWC's Fisher information, from the healthy model on healthy batches: once for every
    /// update (its seconds are counted in each EWC update's).
    fisher: Option<(selfmodel::train::ewc::Ewc, f64)>,
}

/// One damage: the damaged arm's test and training images, and the order its n images are
/// taken in.
struct DamageCase<'d> {
    damage: &'d Damage,
    damaged_test: Vec<f32>,
    damaged_train: Vec<f32>,
    order: Vec<usize>,
}

/// The n images of the damaged arm one update sees.
struct Sample {
    n: usize,
    angles: Vec<Vec<f64>>,
    silhouettes: Vec<f32>,
    /// Test poses farther (joint space) from the n images than the median test pose.
    far: Vec<bool>,
    set: TrainSet,
    seed: u64,
}

/// One update's result, to be scored.
struct Update<'m> {
    method: String,
    n: usize,
    /// The model scored on the damaged arm's images and the one on the healthy arm's (the
    /// same but for the gated experts).
    models: (&'m NeuroKin, &'m NeuroKin),
    seconds: f64,
    steps: usize,
    detail: String,
}

/// A training set of `angles` (degrees) and their silhouettes, on `device`.
fn set_of(
    angles: &[Vec<f64>],
    silhouettes: Vec<f32>,
    size: [usize; 2],
    device: &Device,
) -> TrainSet {
    use burn::tensor::{Tensor, TensorData};
    let (n, dof) = (angles.len(), angles.first().map_or(0, Vec::len));
    let q: Vec<f32> = angles.iter().flatten().map(|&v| v as f32).collect();
    TrainSet {
        inputs: Tensor::from_data(TensorData::new(q, [n, dof]), device),
        targets: vec![Tensor::from_data(
            TensorData::new(silhouettes, [n, 1, size[0], size[1]]),
            device,
        )],
    }
}

/// The healthy model from its checkpoint.
fn load_healthy(r: &Recovering, tdev: &Device, checkpoint: &Path) -> Result<NeuroKin> {
    r.model_run
        .model
        .init(tdev, r.model_run.train.seed)?
        .try_load_file(checkpoint)
        .map_err(|e| {
            Error::data(
                checkpoint,
                format!("the healthy NeuroKin cannot be read ({e}); run again without --resume"),
            )
        })
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

impl<'a> Context<'a> {
    fn new(cfg: &'a DamageConfig, r: &'a Recovering<'a>) -> Result<Self> {
        let rc = &cfg.recovery;
        let nk = &r.model_run.model;
        let data = &r.fitted.data;
        let size = [data.height, data.width];
        let tdev = autodiff_device(&r.fitted.device, cfg.seed);
        let checkpoint = r.out.join("checkpoint").join("model.bpk");
        let of = |range: std::ops::Range<usize>| -> Vec<Vec<f64>> {
            range.map(|i| data.angles[i].clone()).collect()
        };
        let train_angles = of(r.fitted.train_range.clone());
        let test_angles = of(r.fitted.test_range.clone());
        let healthy_train: Vec<f32> = r
            .fitted
            .train_range
            .clone()
            .flat_map(|i| data.image(i).iter().map(|&v| v as f32 / 255.0))
            .collect();
        let healthy_set = nk.training_set(&set_of(&train_angles, healthy_train, size, &tdev));
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
            let text =
                std::fs::read_to_string(&cache_path).map_err(|e| Error::io(&cache_path, e))?;
            if let Ok(old) = serde_json::from_str::<RowCache>(&text)
                && old.fingerprint == fingerprint
            {
                cache = old;
            }
        }
        let healthy = load_healthy(r, &tdev, &checkpoint)?;
        Ok(Context {
            cfg,
            r,
            tdev,
            checkpoint,
            healthy,
            train_angles,
            test_angles,
            healthy_set,
            size,
            cache,
            cache_path,
            fisher: None,
        })
    }

    /// A fresh copy of the healthy model for every update: clones of a burn module share its
    /// BatchNorm running statistics, which training one would move in all.
    fn load(&self) -> Result<NeuroKin> {
        load_healthy(self.r, &self.tdev, &self.checkpoint)
    }

    fn train_cfg(&self, steps: usize, seed: u64) -> TrainConfig {
        let rc = &self.cfg.recovery;
        TrainConfig {
            steps,
            batch: rc.batch,
            learning_rate: rc.learning_rate,
            seed,
            checkpoint_every: 0,
            log_every: 0,
            ..self.r.model_run.train.clone()
        }
    }

    /// Train a fresh copy of the healthy model on `set` for `steps` (the update's loss).
    fn fine_tuned(
        &self,
        set: &TrainSet,
        steps: usize,
        seed: u64,
        label: &str,
    ) -> Result<(NeuroKin, f64)> {
        let t = std::time::Instant::now();
        let loss = self.r.model_run.model.training_loss();
        let (tuned, _) =
            Trainer::new(&self.train_cfg(steps, seed), label).fit(self.load()?, set, &loss)?;
        Ok((tuned, t.elapsed().as_secs_f64()))
    }

    fn px(&self) -> usize {
        self.size[0] * self.size[1]
    }

    /// Per image of `truth`: PSNR (dB) and IoU of `model`'s silhouettes at the test poses.
    fn scores(&self, model: &NeuroKin, truth: &[f32]) -> Result<(Vec<f64>, Vec<f64>)> {
        let angles = &self.test_angles;
        let pred = predicted(&model.valid(), &self.r.fitted.device, angles, 64)?;
        let px = truth.len() / angles.len().max(1);
        fn image(v: &[f32], px: usize, i: usize) -> &[f32] {
            &v[i * px..(i + 1) * px]
        }
        let psnr = (0..angles.len())
            .map(|i| selfmodel::eval::evaluation::psnr_db(image(&pred, px, i), image(truth, px, i)))
            .collect();
        let iou = (0..angles.len())
            .map(|i| selfmodel::eval::evaluation::iou(image(&pred, px, i), image(truth, px, i)))
            .collect();
        Ok((psnr, iou))
    }

    /// The row of one update: its models scored on both arms' test images.
    fn row(&self, case: &DamageCase, far: &[bool], u: Update) -> Result<RecoveryRow> {
        let (pd, idam) = self.scores(u.models.0, &case.damaged_test)?;
        let (ph, ih) = self.scores(u.models.1, &self.r.fitted.truth)?;
        let far_psnr: Vec<f64> = pd
            .iter()
            .zip(far)
            .filter(|(_, f)| **f)
            .map(|(p, _)| *p)
            .collect();
        let damage = case.damage;
        Ok(RecoveryRow {
            method: u.method,
            n: u.n,
            psnr_damaged_db: mean(&pd),
            iou_damaged: mean(&idam),
            psnr_healthy_db: mean(&ph),
            iou_healthy: mean(&ih),
            seconds: u.seconds,
            damage: damage.kind().into(),
            size: damage.size(),
            link: damage.link() + 1,
            psnr_damaged_far_db: (!far_psnr.is_empty()).then(|| mean(&far_psnr)),
            steps: u.steps,
            detail: u.detail,
            git_revision: self.r.revision.into(),
            device: self.r.device.into(),
            preset: self.cfg.preset.clone(),
        })
    }

    /// `key`'s finished row, or `compute`'s, kept in the cache.
    fn cached_or(
        &mut self,
        key: String,
        compute: impl FnOnce(&mut Self) -> Result<RecoveryRow>,
    ) -> Result<RecoveryRow> {
        if let Some(done) = self.cache.rows.get(&key) {
            return Ok(done.clone());
        }
        let row = compute(self)?;
        self.keep(key, row)
    }

    fn keep(&mut self, key: String, row: RecoveryRow) -> Result<RecoveryRow> {
        self.cache.rows.insert(key, row.clone());
        write_json(&self.cache_path, &self.cache)?;
        Ok(row)
    }

    /// The damaged arm's images, and the seeded order its n images are drawn in.
    fn case<'d>(&self, damage: &'d Damage) -> Result<DamageCase<'d>> {
        let damaged_robot = damage.apply(self.r.robot)?;
        let render = |angles: &[Vec<f64>]| {
            silhouettes(
                &damaged_robot,
                self.r.camera,
                &self.r.model_run.data.dataset.render,
                angles,
            )
        };
        let mut order: Vec<usize> = (0..self.train_angles.len()).collect();
        rand::seq::SliceRandom::shuffle(
            order.as_mut_slice(),
            &mut StdRng::seed_from_u64(self.cfg.seed ^ 0x5EED),
        );
        Ok(DamageCase {
            damage,
            damaged_test: render(&self.test_angles),
            damaged_train: render(&self.train_angles),
            order,
        })
    }

    /// The first n images of `case`'s order, and the test poses far from them.
    fn sample(&self, case: &DamageCase, n: usize) -> Sample {
        let px = self.px();
        let picked = &case.order[..n];
        let angles: Vec<Vec<f64>> = picked
            .iter()
            .map(|&i| self.train_angles[i].clone())
            .collect();
        let silhouettes: Vec<f32> = picked
            .iter()
            .flat_map(|&i| case.damaged_train[i * px..(i + 1) * px].iter().copied())
            .collect();
        let distance = |a: &[f64], t: &[f64]| {
            a.iter()
                .zip(t)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let nearest: Vec<f64> = self
            .test_angles
            .iter()
            .map(|t| {
                angles
                    .iter()
                    .map(|a| distance(a, t))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let mut sorted = nearest.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        let far = nearest.iter().map(|&d| d > median).collect();
        let set = self.r.model_run.model.training_set(&set_of(
            &angles,
            silhouettes.clone(),
            self.size,
            &self.tdev,
        ));
        Sample {
            n,
            angles,
            silhouettes,
            far,
            set,
            seed: self.cfg.seed ^ (n as u64) << 8,
        }
    }

    fn ewc_method(&self, lambda: f64) -> String {
        if self.cfg.recovery.ewc_lambdas.len() == 1 {
            "EWC".to_string()
        } else {
            format!("EWC (lambda {lambda:e})")
        }
    }

    /// Every update of `case` from n images, in the table's order.
    fn updates(&mut self, case: &DamageCase, n: usize) -> Result<Vec<RecoveryRow>> {
        let cfg: &'a DamageConfig = self.cfg;
        let rc = &cfg.recovery;
        let n = n.min(case.order.len());
        let key = |method: &str| format!("{} n={n} {method}", case.damage.label());
        let mut methods = vec!["unchanged".to_string(), "fine-tune".into()];
        if rc.replay {
            methods.push("replay".into());
        }
        methods.extend(rc.ewc_lambdas.iter().map(|&l| self.ewc_method(l)));
        methods.push("gated experts".into());
        let resimulated = rc.resimulate_steps.map(|steps| {
            [
                format!("re-simulated/{steps}"),
                format!("gated experts (re-simulated)/{steps}"),
            ]
        });
        methods.extend(resimulated.iter().flatten().cloned());
        if methods
            .iter()
            .all(|m| self.cache.rows.contains_key(&key(m)))
        {
            return Ok(methods
                .iter()
                .map(|m| self.cache.rows[&key(m)].clone())
                .collect());
        }
        let s = self.sample(case, n);
        let mut group = Vec::new();
        group.push(self.cached_or(key("unchanged"), |c| {
            let h = &c.healthy;
            c.row(
                case,
                &s.far,
                Update {
                    method: "unchanged".into(),
                    n,
                    models: (h, h),
                    seconds: 0.0,
                    steps: 0,
                    detail: String::new(),
                },
            )
        })?);
        // The fine-tuned model (also the gated experts' damage expert), where a row needs it.
        let tuned = if self.cache.rows.contains_key(&key("fine-tune"))
            && self.cache.rows.contains_key(&key("gated experts"))
        {
            None
        } else {
            let label = format!("fine-tune ({}, n = {n})", case.damage.label());
            Some(self.fine_tuned(&s.set, rc.steps, s.seed, &label)?)
        };
        group.push(self.cached_or(key("fine-tune"), |c| {
            let (tuned, seconds) = tuned.as_ref().expect("trained above");
            c.row(
                case,
                &s.far,
                Update {
                    method: "fine-tune".into(),
                    n,
                    models: (tuned, tuned),
                    seconds: *seconds,
                    steps: rc.steps,
                    detail: String::new(),
                },
            )
        })?);
        if rc.replay {
            group.push(self.cached_or(key("replay"), |c| c.replay(case, &s))?);
        }
        for &lambda in &rc.ewc_lambdas {
            let method = self.ewc_method(lambda);
            group.push(self.cached_or(key(&method), |c| c.ewc(case, &s, lambda, method))?);
        }
        // Gated experts: the healthy model and the fine-tuned one, the gate scoring what the
        // arm looks like now through the healthy model.
        let gate = (
            self.gated(&case.damaged_test, s.seed ^ 1)?,
            self.gated(&self.r.fitted.truth, s.seed ^ 2)?,
        );
        group.push(self.cached_or(key("gated experts"), |c| {
            let (tuned, seconds) = tuned.as_ref().expect("trained above");
            c.gated_experts(
                case,
                &s,
                gate,
                (tuned, *seconds, rc.steps),
                ("gated experts", "fine-tuned"),
                String::new(),
            )
        })?);
        if let (Some(steps), Some([rkey, gkey])) = (rc.resimulate_steps, &resimulated) {
            if let (Some(a), Some(b)) = (
                self.cache.rows.get(&key(rkey)),
                self.cache.rows.get(&key(gkey)),
            ) {
                group.extend([a.clone(), b.clone()]);
            } else {
                let [resim, gated] = self.resimulated(case, &s, steps, gate)?;
                group.push(self.keep(key(rkey), resim)?);
                group.push(self.keep(key(gkey), gated)?);
            }
        }
        Ok(group)
    }
}
