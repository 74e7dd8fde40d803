//! The training loop every self-model shares: seeded, Adam, global gradient-norm clipping, a
//! progress bar with loss and ETA, checkpoints (model, optimizer state and progress) every N
//! steps, `resume` from the last checkpoint, and a clean stop when the loss stops being
//! finite (the last good checkpoint is kept).
//!
//! Batches are drawn epoch by epoch from a permutation seeded by `(seed, epoch)`, and input
//! noise by `(seed, step)`, so a resumed run sees the same batches as an uninterrupted one.

use std::time::Instant;

use burn::module::Module;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor};

use crate::core::error::{Error, Result};

use super::batcher::{Batch, Batcher, TrainSet};
use super::checkpoint::CheckpointPlan;
use super::config::{TrainConfig, TrainLog};
use super::hooks::NoHooks;
pub use super::hooks::{TrainHooks, Watch};

/// What a training step's loss function returns: the loss as a graph for burn's autodiff to
/// differentiate, or its value with gradients computed some other way (FFKSM's hand-written
/// dense step, [`crate::self_models::ffksm::dense_step`]). A closure that returns a `Tensor<1>` needs no
/// change: it converts.
pub enum StepLoss {
    Graph(Tensor<1>),
    Computed {
        value: f64,
        gradients: GradientsParams,
    },
}

impl From<Tensor<1>> for StepLoss {
    fn from(loss: Tensor<1>) -> Self {
        StepLoss::Graph(loss)
    }
}

impl StepLoss {
    /// The gradients of `model`'s parameters. A graph's loss is first multiplied by
    /// `loss_scale` and its gradients divided by it again (f16's loss scaling,
    /// [`crate::train::precision`]; 1: neither).
    fn gradients<M: Module>(self, model: &M, loss_scale: f32) -> GradientsParams {
        match self {
            StepLoss::Graph(l) if loss_scale != 1.0 => {
                let unscale = l.clone().detach().ones_like().div_scalar(loss_scale);
                let mut grads =
                    GradientsParams::from_grads(l.mul_scalar(loss_scale).backward(), model);
                crate::train::adam::scale_gradients(model, &mut grads, unscale);
                grads
            }
            StepLoss::Graph(l) => GradientsParams::from_grads(l.backward(), model),
            StepLoss::Computed { gradients, .. } => gradients,
        }
    }
}

/// The losses of the steps since they were last read: a graph's value stays on the device
/// (without its graph) until [`PendingLosses::read`] reads them all at once, so a training
/// step waits for nothing on a GPU.
#[derive(Default)]
struct PendingLosses {
    /// `(step, value)`: on the device, or already on the host (a loss computed by hand).
    steps: Vec<(usize, PendingLoss)>,
}

enum PendingLoss {
    Device(Tensor<1>),
    Host(f64),
}

impl PendingLosses {
    fn push(&mut self, step: usize, loss: &StepLoss) {
        self.steps.push((
            step,
            match loss {
                StepLoss::Graph(l) => PendingLoss::Device(l.clone().without_autodiff()),
                StepLoss::Computed { value, .. } => PendingLoss::Host(*value),
            },
        ));
    }

    /// Every pending `(step, loss)`, in step order, with one read of the device.
    fn read(&mut self) -> Vec<(usize, f64)> {
        let steps = std::mem::take(&mut self.steps);
        let on_device: Vec<Tensor<1>> = steps
            .iter()
            .filter_map(|(_, l)| match l {
                PendingLoss::Device(t) => Some(t.clone().reshape([1])),
                PendingLoss::Host(_) => None,
            })
            .collect();
        let mut read = if on_device.is_empty() {
            Vec::new()
        } else {
            Tensor::cat(on_device, 0)
                .into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .expect("a float tensor reads as f32")
        }
        .into_iter();
        steps
            .into_iter()
            .map(|(step, l)| {
                let value = match l {
                    PendingLoss::Device(_) => read.next().expect("one value per loss") as f64,
                    PendingLoss::Host(v) => v,
                };
                (step, value)
            })
            .collect()
    }
}

/// The one training loop, configured by a builder: `Trainer::new(&cfg, label)`, then any of
/// `.checkpoint(plan)` (save every `cfg.checkpoint_every` steps and at the end; resume when
/// the plan says so), `.optimizer(optim)` (continue from an optimiser state: a learner that
/// trains one model on a sequence of datasets, EMSSL's iterations, keeps Adam's moments
/// across them, as one optimiser created before the loop does in PyTorch), `.hooks(h)` (see
/// [`TrainHooks`]; [`Watch`] for a closure), and `.run(model, data, loss)`.
///
/// `model` and `data` live on an autodiff device; `loss(model, batch)` is the step's loss. A
/// non-finite loss stops the run with [`Error::Training`], keeping the last good checkpoint.
pub struct Trainer<'a, M> {
    cfg: &'a TrainConfig,
    label: &'a str,
    checkpoint: Option<&'a CheckpointPlan>,
    optim: Option<ModuleOptimizer>,
    hooks: Option<&'a mut dyn TrainHooks<M>>,
    quiet: bool,
}

impl<'a, M: Module> Trainer<'a, M> {
    pub fn new(cfg: &'a TrainConfig, label: &'a str) -> Self {
        Trainer {
            cfg,
            label,
            checkpoint: None,
            optim: None,
            hooks: None,
            quiet: false,
        }
    }

    /// No progress bar and no progress lines: for many short fits inside one task that shows
    /// its own progress (reading poses from images, [`crate::body`]).
    pub fn quiet(mut self) -> Self {
        self.quiet = true;
        self
    }

    pub fn checkpoint(mut self, plan: Option<&'a CheckpointPlan>) -> Self {
        self.checkpoint = plan;
        self
    }

    pub fn optimizer(mut self, optim: ModuleOptimizer) -> Self {
        self.optim = Some(optim);
        self
    }

    pub fn hooks(mut self, hooks: &'a mut dyn TrainHooks<M>) -> Self {
        self.hooks = Some(hooks);
        self
    }

    /// Train; returns the model, the optimiser state and the log.
    pub fn run<L, S>(
        self,
        model: M,
        data: &TrainSet,
        loss: L,
    ) -> Result<(M, ModuleOptimizer, TrainLog)>
    where
        L: Fn(&M, &Batch) -> S,
        S: Into<StepLoss>,
    {
        let optim = self.optim.unwrap_or_else(|| crate::train::adam::adam());
        let mut none = NoHooks;
        let hooks: &mut dyn TrainHooks<M> = match self.hooks {
            Some(h) => h,
            None => &mut none,
        };
        let settings = Settings {
            cfg: self.cfg,
            checkpoint: self.checkpoint,
            label: self.label,
            quiet: self.quiet,
        };
        train_loop(model, optim, data, &settings, loss, hooks)
    }

    /// [`Trainer::run`] without the optimiser state.
    pub fn fit<L, S>(self, model: M, data: &TrainSet, loss: L) -> Result<(M, TrainLog)>
    where
        L: Fn(&M, &Batch) -> S,
        S: Into<StepLoss>,
    {
        let (model, _, log) = self.run(model, data, loss)?;
        Ok((model, log))
    }
}

/// What a [`Trainer`] was configured with, for its loop.
struct Settings<'a> {
    cfg: &'a TrainConfig,
    checkpoint: Option<&'a CheckpointPlan>,
    label: &'a str,
    quiet: bool,
}

impl Settings<'_> {
    /// Steps between two points of the curve (and two reads of the losses).
    fn log_every(&self) -> usize {
        match self.cfg.log_every {
            0 => (self.cfg.steps / 200).max(1),
            n => n,
        }
    }

    /// The progress bar (hidden for a quiet run), at the step a resumed run starts from.
    fn progress_bar(&self, step: usize) -> indicatif::ProgressBar {
        let bar = if self.quiet {
            indicatif::ProgressBar::hidden()
        } else {
            crate::core::progress::progress_bar(self.cfg.steps as u64, self.label, "steps")
        };
        bar.set_position(step as u64);
        bar.reset_eta();
        bar
    }

    /// Without a terminal (a run in the background, CI) the bar is hidden: a line every 5%.
    fn progress_line(&self, log: &TrainLog, bar: &indicatif::ProgressBar) {
        let steps = self.cfg.steps;
        if !self.quiet
            && bar.is_hidden()
            && (log.step % (steps / 20).max(1) == 0 || log.step == steps)
        {
            let last = log.curve.last().map_or(f64::NAN, |c| c.1);
            eprintln!(
                "{}: step {}/{steps}, loss {last:.4}, {:.2} s/step, ETA {}",
                self.label,
                log.step,
                log.train_seconds / log.step as f64,
                indicatif::HumanDuration(bar.eta())
            );
        }
    }

    /// The run's end at a loss that is not finite, saying what was kept.
    fn diverged(&self, value: f64, step: usize) -> Error {
        let kept = match self.checkpoint {
            Some(plan) if plan.state_path().exists() => {
                format!("the last good checkpoint is in {}", plan.dir.display())
            }
            _ => "no checkpoint was saved".to_string(),
        };
        Error::Training(format!(
            "{}: the loss became {value} at step {step}; {kept}; lower the learning rate or check the data",
            self.label
        ))
    }

    /// The run's end at Ctrl-C after `step`, saying how to go on.
    fn interrupted(&self, step: usize) -> Error {
        let label = self.label;
        Error::Interrupted(match self.checkpoint {
            Some(plan) => format!(
                "{label} stopped after step {step}; its checkpoint is in {}: run the same command with `resume` to continue",
                plan.dir.display()
            ),
            None => format!(
                "{label} stopped after step {step}; this run keeps no checkpoint, so it starts afresh when run again"
            ),
        })
    }
}

/// The losses read since the last read, into the hooks and the curve (a point every
/// `log_every` steps, the mean of the window); a loss that is not finite ends the run.
struct Curve {
    log_every: usize,
    window: (f64, usize),
}

impl Curve {
    fn record<M>(
        &mut self,
        values: Vec<(usize, f64)>,
        settings: &Settings,
        log: &mut TrainLog,
        hooks: &mut dyn TrainHooks<M>,
        bar: &indicatif::ProgressBar,
    ) -> Result<()> {
        for (at, value) in values {
            if !value.is_finite() {
                bar.abandon();
                return Err(settings.diverged(value, at + 1));
            }
            hooks.loss(value, at);
            self.window.0 += value;
            self.window.1 += 1;
            if (at + 1) % self.log_every == 0 || at + 1 == settings.cfg.steps {
                let mean = self.window.0 / self.window.1 as f64;
                log.curve.push((at + 1, mean));
                bar.set_message(format!("loss {mean:.4}"));
                self.window = (0.0, 0);
            }
        }
        Ok(())
    }
}

/// The loop behind [`Trainer`]: resume, then step by step (batch, loss, gradients, Adam), the
/// losses read at log intervals, checkpoints saved, until the steps are done, a hook stops it
/// or Ctrl-C.
fn train_loop<M, L, S>(
    mut model: M,
    mut optim: ModuleOptimizer,
    data: &TrainSet,
    settings: &Settings,
    loss: L,
    hooks: &mut dyn TrainHooks<M>,
) -> Result<(M, ModuleOptimizer, TrainLog)>
where
    M: Module,
    L: Fn(&M, &Batch) -> S,
    S: Into<StepLoss>,
{
    let (cfg, checkpoint, label) = (settings.cfg, settings.checkpoint, settings.label);
    if data.is_empty() || cfg.steps == 0 || cfg.batch == 0 {
        return Err(Error::Config(format!(
            "{label}: nothing to train (samples {}, steps {}, batch {})",
            data.len(),
            cfg.steps,
            cfg.batch
        )));
    }
    let mut log = TrainLog::default();
    if let Some(plan) = checkpoint {
        let (m, o, resumed) = plan.load(model, optim, label)?;
        model = m;
        optim = o;
        if let Some((l, state)) = resumed {
            log = l;
            log.resumed_from = Some(log.step);
            hooks.load_state(&plan.dir, state, &model)?;
        }
    }
    let batcher = Batcher::new(data, cfg);
    let log_every = settings.log_every();
    let bar = settings.progress_bar(log.step);
    let mut losses = PendingLosses::default();
    let mut curve = Curve {
        log_every,
        window: (0.0, 0),
    };
    while log.step < cfg.steps && !hooks.stop() {
        let step = log.step;
        let t0 = Instant::now();
        let batch = batcher.batch(step);
        let n = batch.inputs.dims()[0];
        // Lower precision: the step runs on a cast copy of the f32 parameters.
        let step_loss: StepLoss = match cfg.precision.autocast(&model) {
            Some(low) => loss(&low, &batch.with_inputs_in(cfg.precision.dtype())),
            None => loss(&model, &batch),
        }
        .into();
        losses.push(step, &step_loss);
        let mut grads = step_loss.gradients(&model, cfg.precision.loss_scale());
        let mut clip = cfg.grad_clip_norm;
        if hooks.wants_gradients() {
            if let Some(max) = clip.take() {
                crate::train::adam::clip_global_norm(&model, &mut grads, max);
            }
            hooks.gradients(&model, &grads, step);
        }
        let lr = hooks.learning_rate(cfg.schedule.rate(cfg.learning_rate, step, cfg.steps));
        model = crate::train::adam::step(&mut optim, lr, model, grads, clip);
        log.train_seconds += t0.elapsed().as_secs_f64();
        log.images += n;
        log.step += 1;
        let interrupted = crate::core::interrupt::requested();
        let save = checkpoint.is_some()
            && (interrupted
                || cfg.checkpoint_every > 0
                    && (log.step % cfg.checkpoint_every == 0 || log.step == cfg.steps));
        // The losses are read where a person looks at them (log intervals), where a hook
        // needs them, and before a checkpoint is written: one read for all the steps since
        // the last, which also waits for the device (its time counts as training time).
        if log.step % log_every == 0
            || log.step == cfg.steps
            || save
            || interrupted
            || hooks.wants_losses(log.step)
        {
            let t1 = Instant::now();
            let values = losses.read();
            log.train_seconds += t1.elapsed().as_secs_f64();
            curve.record(values, settings, &mut log, hooks, &bar)?;
        }
        bar.inc(1);
        settings.progress_line(&log, &bar);
        match hooks.after_step(model, log.step) {
            Ok((m, reset)) => {
                model = m;
                if reset {
                    optim = crate::train::adam::adam();
                }
            }
            Err(e) => {
                bar.abandon();
                return Err(e);
            }
        }
        if let Some(plan) = checkpoint
            && save
        {
            plan.save(&model, &optim, &log, hooks)?;
        }
        if interrupted {
            bar.abandon();
            return Err(settings.interrupted(log.step));
        }
    }
    if log.step < cfg.steps {
        bar.finish_with_message("stopped early");
    } else {
        bar.finish();
    }
    Ok((model, optim, log))
}

/// The training device: an autodiff device over `device`, seeded.
pub fn autodiff_device(device: &Device, seed: u64) -> Device {
    let tdev = device.clone().autodiff();
    crate::core::device::with_seed(&tdev, seed, || ());
    tdev
}

/// Trainable parameters, as PyTorch counts them: burn's `num_params` minus the running
/// statistics (mean and variance) of the given BatchNorm layers.
pub fn trainable_params<M: Module>(model: &M, batch_norms: &[&burn::nn::BatchNorm]) -> usize {
    let running: usize = batch_norms.iter().map(|b| 2 * b.gamma.dims()[0]).sum();
    model.num_params() - running
}
