//! Conditional GAN inverse kinematics, a baseline of the EMSSL paper (section IV-A): a
//! generator from (normalised position, noise) to normalised joints and a discriminator on
//! (position, joints), trained on the random data. It learns the distribution of solutions
//! for a position rather than their average, so unlike direct regression it need not average
//! redundant solutions; its samples are only as precise as the discriminator can tell.
//!
//! Training: the standard non-saturating GAN losses with logits (binary cross-entropy), Adam
//! with beta1 = 0.5 for both networks, one discriminator step then one generator step per
//! batch. Noise is drawn on the host from a seeded generator, so runs repeat exactly.
//! Evaluation: one sample per target, and best-of-k (the sample the forward model says lands
//! closest; an extra column, since it calls the forward model k times per target).
//!
//! With the fit's `converge` set, training runs epoch by epoch until the one-sample distance
//! error on the validation targets (fixed noise) stops improving, both learning rates reduced
//! on its plateaus, and keeps the best epoch's generator. With the fit's `checkpoint` set, both
//! networks, their optimisers, the plateau rule and the best generator are saved after every
//! epoch, and a killed run continues from its last epoch to the same result.

use burn::module::Module;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Point3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use crate::core::error::Result;
use crate::ik::data::{DistanceErrors, IkData, JointOutput, reach_errors};
use crate::ik::learning::{FitConfig, row_set};
use crate::ik::mlp::{InverseModelConfig, Mlp};
use crate::sim::kinematics::KinematicChain;
use crate::train::losses::bce_with_logits;
use crate::train::{
    batcher::{Batch, Batcher},
    checkpoint::{save_module, save_renamed},
    convergence::{ConvergenceLog, FitCheckpoint, Plateau, ValidationPoint},
    trainer::autodiff_device,
};

/// The two networks and their training.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GanConfig {
    /// Noise inputs of the generator (standard normal).
    pub noise: usize,
    /// Hidden widths of the generator (3 + noise -> hidden -> dof, sigmoid output).
    pub generator_hidden: Vec<usize>,
    /// Hidden widths of the discriminator (3 + dof -> hidden -> 1 logit).
    pub discriminator_hidden: Vec<usize>,
    /// Epochs, batch, learning rate (both networks) and seed.
    pub fit: FitConfig,
    /// Samples per target for the best-of-k column.
    pub best_of: usize,
}

/// Rows of standard-normal noise `[n, width]`, seeded.
fn noise(n: usize, width: usize, seed: u64, device: &Device) -> Tensor<2> {
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = Normal::new(0.0f32, 1.0).expect("unit normal");
    let v: Vec<f32> = (0..n * width).map(|_| normal.sample(&mut rng)).collect();
    Tensor::from_data(TensorData::new(v, [n, width]), device)
}

/// The trained generator and its noise width.
pub struct Generator {
    pub model: Mlp,
    pub noise: usize,
}

/// What a GAN checkpoint's `state.json` holds besides the weights.
#[derive(serde::Serialize, serde::Deserialize)]
struct GanState {
    fingerprint: serde_json::Value,
    /// Epochs done.
    epochs: usize,
    plateau: Option<Plateau>,
    log: Option<ConvergenceLog>,
    /// Training seconds so far.
    seconds: f64,
    stopped: bool,
}

/// A GAN run's checkpoint folder: `generator.bpk`, `discriminator.bpk`, their optimisers,
/// `best-<epoch>.bpk` and `state.json` (written last).
struct GanCheckpoint {
    dir: std::path::PathBuf,
    fingerprint: serde_json::Value,
}

impl GanCheckpoint {
    /// A run may be continued with a higher cap on its epochs: the cap is not in the
    /// fingerprint.
    fn new(c: &FitCheckpoint, cfg: &GanConfig, output: JointOutput) -> Self {
        let mut uncapped = cfg.clone();
        if let Some(conv) = uncapped.fit.converge.as_mut() {
            conv.max_epochs = 0;
        }
        GanCheckpoint {
            dir: c.dir.join("cgan"),
            fingerprint: serde_json::json!({ "settings": c.settings, "gan": uncapped, "output": output }),
        }
    }

    fn path(&self, file: &str) -> std::path::PathBuf {
        self.dir.join(file)
    }

    /// The saved state if it was made with the same settings; otherwise the folder is
    /// cleared.
    fn load(&self) -> Option<GanState> {
        let state = std::fs::read_to_string(self.path("state.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<GanState>(&t).ok())
            .filter(|s| s.fingerprint == self.fingerprint);
        if state.is_none() && self.dir.exists() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
        state
    }
}

/// The two networks and their optimisers (Adam with beta 1 of 0.5, as GANs are trained).
struct Gan {
    generator: Mlp,
    discriminator: Mlp,
    g_optim: ModuleOptimizer,
    d_optim: ModuleOptimizer,
    /// Columns of a joint row the generator writes.
    width: usize,
}

/// A checkpoint's files of a [`Gan`]: the networks, then their optimisers.
const GAN_FILES: [&str; 4] = [
    "generator.bpk",
    "discriminator.bpk",
    "generator_optimizer.bpk",
    "discriminator_optimizer.bpk",
];

impl Gan {
    /// Fresh networks on `tdev` (seeded by the fit's seed): the generator from a position and
    /// `cfg.noise` noise values to `dof` joints under `output`, the discriminator from a
    /// position and a joint row to one logit.
    fn new(cfg: &GanConfig, dof: usize, output: JointOutput, tdev: &Device) -> Result<Gan> {
        let width = output.width(dof);
        Ok(Gan {
            generator: InverseModelConfig::with_output(
                3 + cfg.noise,
                cfg.generator_hidden.clone(),
                dof,
                output,
            )
            .init(tdev, cfg.fit.seed)?,
            discriminator: InverseModelConfig {
                inputs: 3 + width,
                hidden: cfg.discriminator_hidden.clone(),
                outputs: 1,
                sigmoid_output: false,
                unit_pairs: false,
            }
            .init(tdev, cfg.fit.seed ^ 0xD15C)?,
            g_optim: crate::train::adam::adam_with_beta_1(0.5),
            d_optim: crate::train::adam::adam_with_beta_1(0.5),
            width,
        })
    }

    /// One step on `batch` at `rate`: the discriminator on real pairs against generated ones
    /// (the generator detached), then the generator to make it call its pairs real (the
    /// non-saturating loss), noise seeded by the step. The generator's loss, if `read`.
    fn step(
        self,
        batch: Batch,
        step: usize,
        rate: f64,
        cfg: &GanConfig,
        read: bool,
    ) -> (Gan, Option<f64>) {
        let Gan {
            generator,
            discriminator,
            mut g_optim,
            mut d_optim,
            width,
        } = self;
        let p = batch.inputs;
        let [n, _] = p.dims();
        let tdev = p.device();
        let real = batch.targets[0].clone().reshape([n, width]);
        let ones = Tensor::<2>::ones([n, 1], &tdev);
        let zeros = Tensor::<2>::zeros([n, 1], &tdev);
        let z = noise(n, cfg.noise, cfg.fit.seed ^ (2 * step as u64 + 1), &tdev);
        let fake = generator
            .forward(Tensor::cat(vec![p.clone(), z], 1))
            .detach();
        let d_loss = bce_with_logits(
            discriminator.forward(Tensor::cat(vec![p.clone(), real], 1)),
            ones.clone(),
        ) + bce_with_logits(
            discriminator.forward(Tensor::cat(vec![p.clone(), fake], 1)),
            zeros,
        );
        let grads = GradientsParams::from_grads(d_loss.backward(), &discriminator);
        let discriminator = d_optim.step(rate, discriminator, grads);
        let z = noise(n, cfg.noise, cfg.fit.seed ^ (2 * step as u64 + 2), &tdev);
        let fake = generator.forward(Tensor::cat(vec![p.clone(), z], 1));
        let g_loss = bce_with_logits(discriminator.forward(Tensor::cat(vec![p, fake], 1)), ones);
        let value = read.then(|| g_loss.clone().into_scalar::<f32>() as f64);
        let grads = GradientsParams::from_grads(g_loss.backward(), &generator);
        let generator = g_optim.step(rate, generator, grads);
        let gan = Gan {
            generator,
            discriminator,
            g_optim,
            d_optim,
            width,
        };
        (gan, value)
    }

    /// The networks and optimisers saved in `c`'s folder.
    fn restore(self, c: &GanCheckpoint) -> Result<Gan> {
        let bad = |file: &str, e: &dyn std::fmt::Display| {
            crate::train::checkpoint::unreadable_checkpoint(&c.path(file), &c.dir, e)
        };
        let load = |m: Mlp, file: &str| m.try_load_file(c.path(file)).map_err(|e| bad(file, &e));
        let optim =
            |o: ModuleOptimizer, file: &str| o.load(c.path(file)).map_err(|e| bad(file, &e));
        Ok(Gan {
            generator: load(self.generator, GAN_FILES[0])?,
            discriminator: load(self.discriminator, GAN_FILES[1])?,
            g_optim: optim(self.g_optim, GAN_FILES[2])?,
            d_optim: optim(self.d_optim, GAN_FILES[3])?,
            width: self.width,
        })
    }

    /// The networks and optimisers into `c`'s folder.
    fn save(&self, c: &GanCheckpoint) -> Result<()> {
        save_module(&self.generator, &c.path(GAN_FILES[0]))?;
        save_module(&self.discriminator, &c.path(GAN_FILES[1]))?;
        save_renamed(&c.path(GAN_FILES[2]), |t| self.g_optim.save(t))?;
        save_renamed(&c.path(GAN_FILES[3]), |t| self.d_optim.save(t))
    }
}

/// The run's end at Ctrl-C after `epoch` (its checkpoint written), saying how to go on.
fn interrupted(checkpoint: Option<&GanCheckpoint>, epoch: usize) -> crate::Error {
    crate::Error::Interrupted(match checkpoint {
        Some(c) => format!(
            "CGAN stopped after epoch {epoch}; its checkpoint is in {}: run the same command with `resume` to continue",
            c.dir.display()
        ),
        None => format!(
            "CGAN stopped after epoch {epoch}; this run keeps no checkpoint, so it starts afresh when run again"
        ),
    })
}

/// The networks, optimisers and best generator a checkpoint `c` holds (`state` read from it).
fn resume(
    gan: Gan,
    c: &GanCheckpoint,
    best_file: &mut crate::train::convergence::BestFile,
    state: &GanState,
) -> Result<(Gan, Option<Mlp>)> {
    let gan = gan.restore(c)?;
    let best_epoch = state.log.as_ref().map_or(0, |l| l.best_epoch);
    let best = best_file.load(&c.dir, best_epoch, gan.generator.valid())?;
    eprintln!(
        "CGAN: continuing from epoch {} (checkpoint in {})",
        state.epochs,
        c.dir.display()
    );
    Ok((gan, best))
}

/// The generator as it is (off the autodiff graph) and its mean reach error (cm) on the
/// validation targets, one sample each.
fn validation_cm(
    generator: &Mlp,
    chain: &KinematicChain,
    data: &IkData,
    cfg: &GanConfig,
    device: &Device,
) -> (Generator, f64) {
    let candidate = Generator {
        model: generator.valid(),
        noise: cfg.noise,
    };
    let targets = &data.positions[data.validation()];
    let joints = candidate.sample(data, targets, cfg.fit.inference_batch, 0x7A1, device);
    let score = DistanceErrors::from_metres(&reach_errors(chain, targets, &joints)).mean_cm;
    (candidate, score)
}

/// Train the conditional GAN on the random training pairs of `data`, its generator writing
/// joints under `output`: `cfg.fit.epochs` epochs, or with `cfg.fit.converge` until the
/// validation error (through `chain`) stops improving (its log returned).
pub fn train_gan(
    chain: &KinematicChain,
    data: &IkData,
    cfg: &GanConfig,
    output: JointOutput,
    device: &Device,
) -> Result<(Generator, Option<ConvergenceLog>)> {
    let tdev = autodiff_device(device, cfg.fit.seed);
    let dof = data.joints[0].len();
    let width = output.width(dof);
    let train = data.train();
    let set = row_set(
        data.position_rows(&data.positions[train.clone()]),
        3,
        data.joint_rows_as(&data.joints[train], output),
        width,
        &tdev,
    );
    let mut gan = Gan::new(cfg, dof, output, &tdev)?;
    let train_cfg = cfg.fit.train_config(set.len());
    let steps_per_epoch = set.len().div_ceil(train_cfg.batch.min(set.len()).max(1));
    let epochs = cfg
        .fit
        .converge
        .as_ref()
        .map_or(cfg.fit.epochs, |c| c.max_epochs);
    let mut plateau = cfg.fit.converge.as_ref().map(Plateau::new);
    let mut log = cfg.fit.converge.as_ref().map(|_| ConvergenceLog::default());
    let mut best: Option<Mlp> = None;
    let mut started = std::time::Instant::now();
    let mut earlier_seconds = 0.0;
    let mut first_epoch = 0;
    let mut stopped = false;
    let mut best_file = crate::train::convergence::BestFile::default();
    let checkpoint = cfg
        .fit
        .checkpoint
        .as_ref()
        .map(|c| GanCheckpoint::new(c, cfg, output));
    if let Some(c) = &checkpoint
        && let Some(state) = c.load()
    {
        (gan, best) = resume(gan, c, &mut best_file, &state)?;
        first_epoch = state.epochs;
        plateau = state.plateau;
        log = state.log;
        earlier_seconds = state.seconds;
        stopped = state.stopped;
        started = std::time::Instant::now();
    }
    let seconds = |started: &std::time::Instant| earlier_seconds + started.elapsed().as_secs_f64();
    let batcher = Batcher::new(&set, &train_cfg);
    let bar =
        crate::core::progress::progress_bar((epochs * steps_per_epoch) as u64, "CGAN", "steps");
    bar.set_position((first_epoch * steps_per_epoch) as u64);
    bar.reset_eta();
    for epoch in first_epoch..epochs {
        if stopped {
            break;
        }
        let rate = cfg.fit.learning_rate * plateau.as_ref().map_or(1.0, |p| p.scale);
        let mut g_losses = (0.0f64, 0usize);
        for step in epoch * steps_per_epoch..(epoch + 1) * steps_per_epoch {
            let (next, loss) = gan.step(batcher.batch(step), step, rate, cfg, plateau.is_some());
            gan = next;
            if let Some(v) = loss {
                g_losses.0 += v;
                g_losses.1 += 1;
            }
            bar.inc(1);
        }
        let (Some(rule), Some(log)) = (plateau.as_mut(), log.as_mut()) else {
            continue;
        };
        let (candidate, score) = validation_cm(&gan.generator, chain, data, cfg, device);
        let (improved, stop) = rule.observe(score);
        if improved {
            best = Some(candidate.model);
            log.best_epoch = epoch + 1;
            log.best_validation = score;
        }
        log.curve.push(ValidationPoint {
            epoch: epoch + 1,
            learning_rate: rate,
            train_loss: g_losses.0 / g_losses.1.max(1) as f64,
            validation: score,
            seconds: seconds(&started),
        });
        log.epochs = epoch + 1;
        log.stopped_on_plateau = stop;
        stopped = stop;
        if let Some(c) = &checkpoint {
            std::fs::create_dir_all(&c.dir).map_err(|e| crate::Error::io(&c.dir, e))?;
            best_file.save(&c.dir, log.best_epoch, best.as_ref())?;
            gan.save(c)?;
            crate::core::atomic_file::write_json(
                &c.path("state.json"),
                &GanState {
                    fingerprint: c.fingerprint.clone(),
                    epochs: epoch + 1,
                    plateau: Some(rule.clone()),
                    log: Some(log.clone()),
                    seconds: seconds(&started),
                    stopped: stop,
                },
            )?;
        }
        bar.set_message(format!("validation {score:.2} cm"));
        if bar.is_hidden() {
            eprintln!(
                "CGAN: epoch {}, validation {score:.4}, best {:.4} at {}, lr {rate:.2e}",
                epoch + 1,
                log.best_validation,
                log.best_epoch
            );
        }
        if stop {
            break;
        }
        // Ctrl-C: the epoch's checkpoint is written; stop here (the one training loop
        // checks the same flag after every step).
        if crate::core::interrupt::requested() {
            bar.abandon();
            return Err(interrupted(checkpoint.as_ref(), epoch + 1));
        }
    }
    bar.finish();
    if let Some(log) = log.as_mut() {
        log.seconds = seconds(&started);
    }
    Ok((
        Generator {
            model: best.unwrap_or_else(|| gan.generator.valid()),
            noise: cfg.noise,
        },
        log,
    ))
}

impl Generator {
    /// One sample of joints (radians) per position, noise seeded by `seed`.
    pub fn sample(
        &self,
        data: &IkData,
        positions: &[Point3<f64>],
        batch: usize,
        seed: u64,
        device: &Device,
    ) -> Vec<Vec<f64>> {
        let mut out = Vec::with_capacity(positions.len());
        for (c, part) in positions.chunks(batch.max(1)).enumerate() {
            let n = part.len();
            let p = Tensor::from_data(TensorData::new(data.position_rows(part), [n, 3]), device);
            let z = noise(n, self.noise, seed ^ ((c as u64) << 20), device);
            let q = self.model.forward(Tensor::cat(vec![p, z], 1));
            let [_, width] = q.dims();
            let output = self.model.joint_output();
            let v = q.into_data().try_into_vec::<f32>().expect("float");
            out.extend(v.chunks(width).map(|r| data.decode_joints(r, output)));
        }
        out
    }

    /// For each position, the one of `draws.k` samples (seeds `draws.seed`, `+ 1`, ...) whose
    /// forward kinematics lands closest.
    pub fn best_of(
        &self,
        chain: &KinematicChain,
        data: &IkData,
        positions: &[Point3<f64>],
        draws: crate::ik::flow::Draws,
        device: &Device,
    ) -> Vec<Vec<f64>> {
        let samples: Vec<Vec<Vec<f64>>> = (0..draws.k.max(1))
            .map(|s| {
                let seed = draws.seed.wrapping_add(s as u64);
                self.sample(data, positions, draws.batch, seed, device)
            })
            .collect();
        crate::ik::flow::best_of(chain, positions, &samples)
    }
}

/// The conditional GAN as a Table II method: one sample, and the best of `gan.best_of`.
pub struct CganMethod {
    pub name: String,
    pub gan: GanConfig,
    pub output: JointOutput,
}

impl crate::ik::paper::method::IkMethod for CganMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn settings(&self) -> serde_json::Value {
        crate::ik::paper::method::settings_json(&(&self.gan, self.output))
    }

    fn run(
        &self,
        task: &crate::ik::paper::method::IkTask,
    ) -> Result<crate::ik::paper::method::MethodOutput> {
        use crate::ik::paper::method::{Answers, MethodOutput, ValidationRow, timed};
        let gan = &self.gan;
        let t = std::time::Instant::now();
        let gan = &GanConfig {
            fit: task.checkpointed(&self.name, self.settings(), &gan.fit),
            ..gan.clone()
        };
        let (generator, log) = train_gan(task.chain, task.data, gan, self.output, task.device)?;
        // Counting the seconds before a restart from the checkpoint.
        let train_s = t
            .elapsed()
            .as_secs_f64()
            .max(log.as_ref().map_or(0.0, |l| l.seconds));
        let seed = gan.fit.seed ^ 0x5EED;
        let mut joints = Vec::new();
        let solve_s = timed(&mut || {
            joints = generator.sample(task.data, task.targets, task.batch, seed, task.device)
        });
        let one =
            Answers::new(&self.name, joints, train_s, solve_s).converged(&log, gan.fit.epochs);
        let k = gan.best_of;
        let mut samples = Vec::new();
        let solve_k = timed(&mut || {
            samples = (0..k as u64)
                .map(|s| {
                    generator.sample(
                        task.data,
                        task.targets,
                        task.batch,
                        seed.wrapping_add(s),
                        task.device,
                    )
                })
                .collect::<Vec<_>>()
        });
        let t = std::time::Instant::now();
        let joints = crate::ik::flow::best_of(task.chain, task.targets, &samples);
        let pick_s = t.elapsed().as_secs_f64();
        let sfx = self.name.strip_prefix("CGAN").unwrap_or("");
        let mut best = Answers::new(
            &format!("CGAN best of {k}{sfx}"),
            joints,
            train_s,
            solve_k + pick_s,
        );
        best.diversity_rad = Some(crate::ik::flow::diversity(&samples));
        best.detail = format!("the sample of {k} the forward model puts closest");
        Ok(MethodOutput {
            answers: vec![one, best],
            curves: log
                .iter()
                .flat_map(|l| ValidationRow::from_log(task.range_deg, &self.name, l))
                .collect(),
            emssl_curve: Vec::new(),
        })
    }
}
