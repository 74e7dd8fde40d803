//! The recovery methods after fine-tuning, one function each: the gate, replay, EWC, gated
//! experts, re-simulation from a fitted arm, training from scratch.

use burn::module::Module;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::index::sample;

use crate::studies::damage::{DamageConfig, RecoveryRow};
use selfmodel::body::damage::{predicted, residual};
use selfmodel::core::error::{Error, Result};
use selfmodel::self_models::neurokin::NeuroKin;
use selfmodel::sim::ray_caster::silhouettes;
use selfmodel::train::trainer::Trainer;

use super::{Context, DamageCase, Sample, Update, mean, set_of};

impl<'a> Context<'a> {
    /// The gate's view of the arm: the mean residual of the healthy model on `gate_k` test
    /// images of `truth`.
    fn gate_score(&self, truth: &[f32], seed: u64) -> Result<f64> {
        let (px, test) = (self.px(), &self.test_angles);
        let mut rng = StdRng::seed_from_u64(seed);
        let pick = sample(
            &mut rng,
            test.len(),
            self.cfg.recovery.gate_k.min(test.len()),
        )
        .into_vec();
        let angles: Vec<Vec<f64>> = pick.iter().map(|&i| test[i].clone()).collect();
        let obs: Vec<f32> = pick
            .iter()
            .flat_map(|&i| truth[i * px..(i + 1) * px].iter().copied())
            .collect();
        let pred = predicted(&self.healthy.valid(), &self.r.fitted.device, &angles, 64)?;
        Ok(mean(
            &(0..pick.len())
                .map(|i| residual(&pred[i * px..(i + 1) * px], &obs[i * px..(i + 1) * px]))
                .collect::<Vec<_>>(),
        ))
    }

    /// Whether the gate takes `truth` for the damaged arm.
    pub(super) fn gated(&self, truth: &[f32], seed: u64) -> Result<bool> {
        Ok(self.gate_score(truth, seed)? > self.r.gate_threshold)
    }

    /// Replay: every epoch, the n damaged images repeated to as many as the healthy ones.
    pub(super) fn replay(&self, case: &DamageCase, s: &Sample) -> Result<RecoveryRow> {
        let (n, data) = (s.n, &self.r.fitted.data);
        let m = self.train_angles.len().min(n.max(400));
        let reps = m.div_ceil(n.max(1));
        let mut q: Vec<Vec<f64>> = Vec::new();
        let mut px_all: Vec<f32> = Vec::new();
        for _ in 0..reps {
            q.extend(s.angles.iter().cloned());
            px_all.extend_from_slice(&s.silhouettes);
        }
        for &i in case.order.iter().rev().take(m) {
            q.push(self.train_angles[i].clone());
            px_all.extend(
                data.image(self.r.fitted.train_range.start + i)
                    .iter()
                    .map(|&v| v as f32 / 255.0),
            );
        }
        let mixed = self
            .r
            .model_run
            .model
            .training_set(&set_of(&q, px_all, self.size, &self.tdev));
        let label = format!("replay ({}, n = {n})", case.damage.label());
        let steps = self.cfg.recovery.steps;
        let (model, seconds) = self.fine_tuned(&mixed, steps, s.seed, &label)?;
        self.row(
            case,
            &s.far,
            Update {
                method: "replay".into(),
                n,
                models: (&model, &model),
                seconds,
                steps,
                detail: format!("{m} healthy images mixed in"),
            },
        )
    }

    /// Fine-tuning with Elastic Weight Consolidation at weight `lambda`.
    pub(super) fn ewc(
        &mut self,
        case: &DamageCase,
        s: &Sample,
        lambda: f64,
        method: String,
    ) -> Result<RecoveryRow> {
        let cfg: &'a DamageConfig = self.cfg;
        let rc = &cfg.recovery;
        let loss = self.r.model_run.model.training_loss();
        if self.fisher.is_none() {
            let t = std::time::Instant::now();
            // A fresh copy: a training-mode pass moves BatchNorm's running statistics.
            let ewc = selfmodel::train::ewc::Ewc::new(
                &self.load()?,
                &self.healthy_set,
                &self.train_cfg(rc.fisher_batches, self.cfg.seed),
                rc.fisher_batches,
                &loss,
                1.0,
            )?;
            self.fisher = Some((ewc, t.elapsed().as_secs_f64()));
        }
        let (ewc, fisher_s) = self.fisher.as_mut().expect("computed above");
        ewc.lambda = lambda;
        let fisher_s = *fisher_s;
        let label = format!("{method} ({}, n = {})", case.damage.label(), s.n);
        let t = std::time::Instant::now();
        let ewc = &self.fisher.as_ref().expect("computed above").0;
        let (model, _) = Trainer::new(&self.train_cfg(rc.steps, s.seed), &label).fit(
            self.load()?,
            &s.set,
            |m, b| loss(m, b) + ewc.penalty(m),
        )?;
        self.row(
            case,
            &s.far,
            Update {
                method,
                n: s.n,
                models: (&model, &model),
                seconds: t.elapsed().as_secs_f64() + fisher_s,
                steps: rc.steps,
                detail: format!(
                    "lambda {lambda:e}; Fisher from {} healthy batches",
                    rc.fisher_batches
                ),
            },
        )
    }

    /// The gated experts: the healthy model and `expert` (a model, its seconds and steps),
    /// the gate's choice on the damaged and on the healthy arm given (`gate`).
    pub(super) fn gated_experts(
        &self,
        case: &DamageCase,
        s: &Sample,
        gate: (bool, bool),
        expert: (&NeuroKin, f64, usize),
        (method, expert_name): (&str, &str),
        detail: String,
    ) -> Result<RecoveryRow> {
        let (model, seconds, steps) = expert;
        let pick = |damaged: bool| if damaged { model } else { &self.healthy };
        let name = |damaged: bool| {
            if damaged {
                format!("damage ({expert_name} expert)")
            } else {
                "healthy (healthy expert)".to_string()
            }
        };
        let mut text = format!(
            "gate on the damaged arm: {}; on the healthy arm: {}",
            name(gate.0),
            name(gate.1)
        );
        if !detail.is_empty() {
            text += &format!("; {detail}");
        }
        self.row(
            case,
            &s.far,
            Update {
                method: method.into(),
                n: s.n,
                models: (pick(gate.0), pick(gate.1)),
                seconds,
                steps,
                detail: text,
            },
        )
    }

    /// Re-simulation: the damage identified from the n images, the training poses rendered
    /// with the description so damaged and a fresh copy fine-tuned on them and the n images;
    /// its row and the gated experts' with it as the damage expert.
    pub(super) fn resimulated(
        &self,
        case: &DamageCase,
        s: &Sample,
        steps: usize,
        gate: (bool, bool),
    ) -> Result<[RecoveryRow; 2]> {
        let r = self.r;
        let t = std::time::Instant::now();
        let options = &r.model_run.data.dataset.render;
        let (found, fit) = selfmodel::body::damage::identify(
            r.robot,
            r.camera,
            options,
            &s.angles,
            &s.silhouettes,
        )
        .ok_or_else(|| {
            Error::Config("re-simulation: no candidate damage applies to the robot".into())
        })?;
        let resim_robot = found.apply(r.robot)?;
        let mut q = self.train_angles.clone();
        let mut pixels = silhouettes(&resim_robot, r.camera, options, &self.train_angles);
        q.extend(s.angles.iter().cloned());
        pixels.extend_from_slice(&s.silhouettes);
        let resim_set = r
            .model_run
            .model
            .training_set(&set_of(&q, pixels, self.size, &self.tdev));
        let label = format!("re-simulated ({}, n = {})", case.damage.label(), s.n);
        let (resim, _) = self.fine_tuned(&resim_set, steps, s.seed, &label)?;
        // The identification and rendering count too.
        let seconds = t.elapsed().as_secs_f64();
        let detail = format!(
            "identified: {} (mean IoU {fit:.3} on the n images); fine-tuned on its {} rendered training poses and the n images",
            found.label(),
            self.train_angles.len()
        );
        let row = self.row(
            case,
            &s.far,
            Update {
                method: "re-simulated".into(),
                n: s.n,
                models: (&resim, &resim),
                seconds,
                steps,
                detail: detail.clone(),
            },
        )?;
        let gated = self.gated_experts(
            case,
            s,
            gate,
            (&resim, seconds, steps),
            ("gated experts (re-simulated)", "re-simulated"),
            detail,
        )?;
        Ok([row, gated])
    }

    /// A new NeuroKin on the damaged arm's whole training set, the healthy model's schedule:
    /// the reference a recovery is measured against.
    pub(super) fn trained_from_scratch(&mut self, case: &DamageCase) -> Result<RecoveryRow> {
        let key = format!("{} from scratch", case.damage.label());
        self.cached_or(key, |c| {
            let (r, nk) = (c.r, &c.r.model_run.model);
            let all = nk.training_set(&set_of(
                &c.train_angles,
                case.damaged_train.clone(),
                c.size,
                &c.tdev,
            ));
            let label = format!("from scratch ({})", case.damage.label());
            let plan = selfmodel::train::checkpoint::CheckpointPlan {
                dir: r.out.join("checkpoint").join(format!(
                    "scratch_{}",
                    selfmodel::core::atomic_file::file_name(&case.damage.label())
                )),
                resume: true,
                fingerprint: serde_json::json!({"damage": case.damage, "model": nk, "train": r.model_run.train}),
            };
            let t = std::time::Instant::now();
            let loss = nk.training_loss();
            let (scratch, log) = Trainer::new(&r.model_run.train, &label)
                .checkpoint(Some(&plan))
                .fit(nk.init(&c.tdev, r.model_run.train.seed)?, &all, &loss)?;
            let all_far = vec![false; c.test_angles.len()];
            c.row(case, &all_far, Update {
                method: "from scratch".into(),
                n: c.train_angles.len(),
                models: (&scratch, &scratch),
                seconds: t.elapsed().as_secs_f64().max(log.train_seconds),
                steps: r.model_run.train.steps,
                detail: "every training pose of the damaged arm".into(),
            })
        })
    }
}
