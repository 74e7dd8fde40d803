//! The training loop every self-model shares: seeded, Adam, global gradient-norm clipping, a
//! progress bar with loss and ETA, checkpoints (model, optimizer state and progress) every N
//! steps, `--resume` from the last checkpoint, and a clean stop when the loss stops being
//! finite (the last good checkpoint is kept).
//!
//! Batches are drawn epoch by epoch from a permutation seeded by `(seed, epoch)`, and input
//! noise by `(seed, step)`, so a resumed run sees the same batches as an uninterrupted one.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand_distr::{Distribution, Normal};

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};

/// Optimisation settings shared by every model.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrainConfig {
    /// Optimiser steps (batches).
    pub steps: usize,
    /// Images per batch (the last batch of an epoch may be smaller, as in PyTorch's
    /// `DataLoader` without `drop_last`).
    pub batch: usize,
    /// Adam learning rate (betas 0.9, 0.999 as PyTorch; eps 1e-5, burn's default, where PyTorch
    /// uses 1e-8: every committed result trained with 1e-5, and an outside check measured no
    /// effect of the difference on EMSSL).
    pub learning_rate: f64,
    /// Clip the global gradient norm to this value (PyTorch's `clip_grad_norm_`); none if
    /// absent.
    pub grad_clip_norm: Option<f32>,
    /// Standard deviation of Gaussian noise added to the input joint angles (their units,
    /// degrees for the decoders) at every step.
    pub input_noise: f64,
    pub seed: u64,
    /// Save a checkpoint every this many steps (and at the end); 0 disables checkpoints.
    pub checkpoint_every: usize,
    /// Read the losses from the device (and log their mean) every this many steps; 0: every
    /// `steps / 200` steps, at least 1 (the default; a saved config without it reads as 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub log_every: usize,
}

impl TrainConfig {
    /// Epochs the schedule covers for a training set of `n` samples.
    pub fn epochs(&self, n: usize) -> f64 {
        self.steps as f64 / n.div_ceil(self.batch).max(1) as f64
    }

    /// Steps for `epochs` passes over `n` samples, the last batch of each epoch partial.
    pub fn steps_for_epochs(epochs: usize, n: usize, batch: usize) -> usize {
        epochs * n.div_ceil(batch)
    }
}

/// The training data on the device: inputs `[n, dof]` and any targets `[n, ...]`.
#[derive(Clone, Debug)]
pub struct TrainSet {
    pub inputs: Tensor<2>,
    /// Image-like targets, each `[n, channels, H, W]` (silhouettes, depth, ...).
    pub targets: Vec<Tensor<4>>,
}

impl TrainSet {
    pub fn len(&self) -> usize {
        self.inputs.dims()[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One batch: noisy inputs and the matching targets.
pub struct Batch {
    pub inputs: Tensor<2>,
    pub targets: Vec<Tensor<4>>,
    /// The step (0-based) this batch is drawn for: for schedules (curricula) and per-step
    /// random draws that must be the same after a resume.
    pub step: usize,
    /// The samples of the training set in this batch, in its row order (on the host, so a
    /// loss that needs a sample's values on the host can keep its own copy of the training
    /// set instead of reading the batch back from the device).
    pub indices: Vec<usize>,
}

/// Progress saved with a checkpoint, and the training curve of a finished run.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct TrainLog {
    /// Steps completed.
    pub step: usize,
    /// `(step, loss)` every `log_every` steps.
    pub curve: Vec<(usize, f64)>,
    /// Seconds spent in forward, backward and optimiser steps (checkpoint I/O excluded).
    pub train_seconds: f64,
    /// Images pushed through training.
    pub images: usize,
    /// Whether this run continued from a checkpoint.
    pub resumed_from: Option<usize>,
}

impl TrainLog {
    /// Training throughput: images per second through forward, backward and the step.
    pub fn images_per_second(&self) -> f64 {
        self.images as f64 / self.train_seconds.max(1e-9)
    }
}

/// Where checkpoints go, and whether to continue from one.
#[derive(Clone, Debug)]
pub struct CheckpointPlan {
    pub dir: PathBuf,
    pub resume: bool,
    /// Anything that must match for a resume to be valid (model and training config as JSON).
    pub fingerprint: serde_json::Value,
}

#[derive(serde::Serialize, serde::Deserialize)]
struct CheckpointState {
    fingerprint: serde_json::Value,
    log: TrainLog,
    /// What the run's hooks keep ([`TrainHooks::save_state`]): a run to convergence's
    /// plateau rule, validation curve and best epoch.
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    hooks: serde_json::Value,
}

/// A saved model or optimiser file that cannot be read back: what failed, and that deleting
/// the checkpoint's folder `dir` (or running without `--resume`) starts afresh.
pub fn unreadable_checkpoint(file: &Path, dir: &Path, e: impl std::fmt::Display) -> Error {
    Error::data(
        file,
        format!(
            "this checkpoint cannot be read ({e}); delete {} to start afresh, or run without --resume",
            dir.display()
        ),
    )
}

/// Save a module's weights to a burnpack file, bit for bit what the module computes with: its
/// running statistics (BatchNorm's) are synchronised first, since burn writes the value before
/// the last training step's pending update, which `valid()` (and so every evaluation) applies.
pub fn save_module<M: Module>(model: &M, path: &Path) -> Result<()> {
    let _synchronised = model.valid();
    save_renamed(path, |tmp| model.clone().save_file(tmp))
}

/// `template` with the weights [`save_module`] wrote to `path`.
pub fn load_module<M: Module>(template: M, path: &Path) -> Result<M> {
    let max = crate::core::input_file::MAX_WEIGHTS_BYTES;
    crate::core::input_file::check_user_file(path, "weights file", max)?;
    template.try_load_file(path).map_err(|e| {
        Error::data(
            path,
            format!("the weights cannot be read ({e}); train the model again"),
        )
    })
}

/// Write a burnpack file to a temporary name, then rename it into place.
pub(crate) fn save_renamed(
    path: &Path,
    write: impl FnOnce(&Path) -> std::result::Result<(), burn::store::RecordError>,
) -> Result<()> {
    let tmp = path.with_extension("bpk.tmp");
    write(&tmp).map_err(|e| Error::data(path, format!("cannot write checkpoint: {e}")))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

impl CheckpointPlan {
    fn model_path(&self) -> PathBuf {
        self.dir.join("model.bpk")
    }
    fn optim_path(&self) -> PathBuf {
        self.dir.join("optimizer.bpk")
    }
    fn state_path(&self) -> PathBuf {
        self.dir.join("state.json")
    }

    /// With `resume`: whether the checkpoint, if there is one, can be continued (it reads and
    /// was made with this configuration), checked without loading it, so a run of several
    /// models can refuse a foreign or damaged checkpoint before it writes anything.
    pub fn check(&self) -> Result<()> {
        if self.resume && self.state_path().exists() {
            self.read_state()?;
        }
        Ok(())
    }

    /// The checkpoint's progress, refused when it does not read or another configuration
    /// made it.
    fn read_state(&self) -> Result<CheckpointState> {
        let path = self.state_path();
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let state: CheckpointState =
            serde_json::from_str(&text).map_err(|e| unreadable_checkpoint(&path, &self.dir, e))?;
        if state.fingerprint != self.fingerprint {
            return Err(Error::Config(format!(
                "the checkpoint in {} was made with a different configuration; drop --resume or delete that folder",
                self.dir.display()
            )));
        }
        Ok(state)
    }

    /// Write model, optimizer and progress; each file is written to a temporary name and
    /// renamed, the progress file last, so a crash never leaves a checkpoint that claims more
    /// than it holds.
    fn save<M: Module>(
        &self,
        model: &M,
        optim: &ModuleOptimizer,
        log: &TrainLog,
        hooks: &mut dyn TrainHooks<M>,
    ) -> Result<()> {
        std::fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        save_module(model, &self.model_path())?;
        save_renamed(&self.optim_path(), |tmp| optim.save(tmp))?;
        let hooks = hooks.save_state(&self.dir)?;
        write_json(
            &self.state_path(),
            &CheckpointState {
                fingerprint: self.fingerprint.clone(),
                log: log.clone(),
                hooks,
            },
        )
    }

    /// Load a checkpoint if `resume` is set and one exists; with `resume` set, say on stderr
    /// which of the two happened (`label`: the run's name).
    fn load<M: Module>(
        &self,
        model: M,
        optim: ModuleOptimizer,
        label: &str,
    ) -> Result<(M, ModuleOptimizer, Option<(TrainLog, serde_json::Value)>)> {
        if !self.resume {
            return Ok((model, optim, None));
        }
        if !self.state_path().exists() {
            eprintln!(
                "{label}: --resume: no checkpoint in {}; training starts from step 0",
                self.dir.display()
            );
            return Ok((model, optim, None));
        }
        let state = self.read_state()?;
        let model = model
            .try_load_file(self.model_path())
            .map_err(|e| unreadable_checkpoint(&self.model_path(), &self.dir, e))?;
        let optim = optim
            .load(self.optim_path())
            .map_err(|e| unreadable_checkpoint(&self.optim_path(), &self.dir, e))?;
        eprintln!(
            "{label}: continuing from step {} (checkpoint in {})",
            state.log.step,
            self.dir.display()
        );
        Ok((model, optim, Some((state.log, state.hooks))))
    }
}

/// Draws batches: epoch permutations seeded by `(seed, epoch)`, noise by `(seed, step)`.
///
/// What a batch needs from the host is uploaded once per epoch, not once per step: the
/// epoch's permutation as one index tensor, and the epoch's input noise (each step's rows
/// drawn from that step's own seed, as before, so the numbers are the same) as one tensor.
/// A step then only slices them on the device.
pub struct Batcher<'a> {
    data: &'a TrainSet,
    batch: usize,
    seed: u64,
    noise: f64,
    /// The epoch last asked for: its permutation, on the host and on the device, and its
    /// noise rows on the device (drawn once per epoch, not per batch).
    epoch: std::cell::RefCell<Option<EpochDraw>>,
}

struct EpochDraw {
    epoch: usize,
    perm: Vec<usize>,
    index: Tensor<1, burn::tensor::Int>,
    noise: Option<Tensor<2>>,
}

impl<'a> Batcher<'a> {
    pub fn new(data: &'a TrainSet, cfg: &TrainConfig) -> Self {
        Batcher {
            data,
            batch: cfg.batch.min(data.len()).max(1),
            seed: cfg.seed,
            noise: cfg.input_noise,
            epoch: std::cell::RefCell::new(None),
        }
    }

    fn steps_per_epoch(&self) -> usize {
        self.data.len().div_ceil(self.batch)
    }

    /// The input noise of step `step`'s `n` rows: seeded by `(seed, step)`.
    fn step_noise(&self, step: usize, n: usize, dof: usize, out: &mut Vec<f32>) {
        let mut rng = StdRng::seed_from_u64(
            self.seed.wrapping_add(1) ^ (step as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
        );
        let normal = Normal::new(0.0, self.noise).expect("noise sigma is finite");
        out.extend((0..n * dof).map(|_| normal.sample(&mut rng) as f32));
    }

    /// Draw epoch `epoch` if it is not the one held: its permutation, uploaded once, and
    /// the noise of all its steps, uploaded once.
    fn draw_epoch(&self, epoch: usize) -> std::cell::RefMut<'_, EpochDraw> {
        let mut held = self.epoch.borrow_mut();
        if held.as_ref().is_none_or(|e| e.epoch != epoch) {
            let n = self.data.len();
            let mut perm: Vec<usize> = (0..n).collect();
            let mut rng = StdRng::seed_from_u64(
                self.seed ^ (epoch as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            perm.shuffle(&mut rng);
            let device = self.data.inputs.device();
            let index = Tensor::<1, burn::tensor::Int>::from_data(
                TensorData::new(perm.iter().map(|&i| i as i64).collect::<Vec<_>>(), [n]),
                &device,
            );
            let noise = (self.noise > 0.0).then(|| {
                let dof = self.data.inputs.dims()[1];
                let spe = self.steps_per_epoch();
                let mut rows = Vec::with_capacity(n * dof);
                for k in 0..spe {
                    let rows_k = ((k + 1) * self.batch).min(n) - k * self.batch;
                    self.step_noise(epoch * spe + k, rows_k, dof, &mut rows);
                }
                Tensor::<2>::from_data(TensorData::new(rows, [n, dof]), &device)
            });
            *held = Some(EpochDraw {
                epoch,
                perm,
                index,
                noise,
            });
        }
        std::cell::RefMut::map(held, |h| h.as_mut().expect("just drawn"))
    }

    /// The rows of batch `step` (0-based) within its epoch's permutation.
    fn rows(&self, step: usize) -> (usize, std::ops::Range<usize>) {
        let spe = self.steps_per_epoch();
        let (epoch, k) = (step / spe, step % spe);
        (
            epoch,
            k * self.batch..((k + 1) * self.batch).min(self.data.len()),
        )
    }

    /// The indices of batch `step` (0-based).
    pub fn indices(&self, step: usize) -> Vec<usize> {
        let (epoch, rows) = self.rows(step);
        self.draw_epoch(epoch).perm[rows].to_vec()
    }

    /// Batch `step` on the data's device: slices of the epoch's index and noise tensors, so
    /// nothing crosses from the host within an epoch.
    pub fn batch(&self, step: usize) -> Batch {
        let (epoch, rows) = self.rows(step);
        let draw = self.draw_epoch(epoch);
        let indices = draw.perm[rows.clone()].to_vec();
        let index = draw.index.clone().slice(rows.clone());
        let mut inputs = self.data.inputs.clone().select(0, index.clone());
        if let Some(noise) = &draw.noise {
            inputs = inputs + noise.clone().slice(rows);
        }
        let targets = self
            .data
            .targets
            .iter()
            .map(|t| t.clone().select(0, index.clone()))
            .collect();
        Batch {
            inputs,
            targets,
            step,
            indices,
        }
    }
}

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
    /// The gradients of `model`'s parameters.
    fn gradients<M: Module>(self, model: &M) -> GradientsParams {
        match self {
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
        train_loop(
            model,
            optim,
            data,
            self.cfg,
            self.checkpoint,
            self.label,
            loss,
            hooks,
            self.quiet,
        )
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

/// A learning-rate schedule, as hooks: the config's rate throughout, or falling along a half
/// cosine from it to 1% of it over `steps` steps.
pub enum Schedule {
    Constant,
    Cosine { steps: usize, done: usize },
}

impl Schedule {
    pub fn cosine(steps: usize) -> Self {
        Schedule::Cosine { steps, done: 0 }
    }
}

impl<M> TrainHooks<M> for Schedule {
    fn after_step(&mut self, model: M, step: usize) -> Result<(M, bool)> {
        if let Schedule::Cosine { done, .. } = self {
            *done = step;
        }
        Ok((model, false))
    }
    fn learning_rate(&self, base: f64) -> f64 {
        match *self {
            Schedule::Constant => base,
            Schedule::Cosine { steps, done } => {
                let t = done as f64 / steps.max(1) as f64;
                base * (0.01 + 0.99 * 0.5 * (1.0 + (std::f64::consts::PI * t).cos()))
            }
        }
    }
}

/// No hooks.
struct NoHooks;
impl<M> TrainHooks<M> for NoHooks {}

/// Hooks from a closure called after every step with the model and the steps done; an error
/// from it stops training and is returned (FFKSM's restart on collapse).
pub struct Watch<W>(pub W);

impl<M, W: FnMut(&M, usize) -> Result<()>> TrainHooks<M> for Watch<W> {
    fn after_step(&mut self, model: M, step: usize) -> Result<(M, bool)> {
        (self.0)(&model, step)?;
        Ok((model, false))
    }
}

/// What a model may do during training besides descending the loss.
pub trait TrainHooks<M> {
    /// Sees each step's gradients (clipped) before the optimiser applies them.
    fn gradients(&mut self, _model: &M, _grads: &GradientsParams, _step: usize) {}
    /// Whether [`TrainHooks::gradients`] looks at the gradients: where it does not, a GPU
    /// clips them inside the optimiser's kernels instead of scaling each one first.
    fn wants_gradients(&self) -> bool {
        false
    }
    /// After each step (`step` = steps done): may replace the model (K-3DGS densifies and
    /// prunes its Gaussians) and returns whether the optimiser state must start afresh (it
    /// must when parameters changed shape). An error stops training and is returned.
    fn after_step(&mut self, model: M, _step: usize) -> Result<(M, bool)> {
        Ok((model, false))
    }
    /// Sees each step's loss, in step order. The losses are read from the device in groups
    /// (at log intervals, before checkpoints, and after any step where
    /// [`TrainHooks::wants_losses`] says so), so this comes after the step was taken.
    fn loss(&mut self, _value: f64, _step: usize) {}
    /// Whether every loss up to step `steps_done` must have reached [`TrainHooks::loss`]
    /// before [`TrainHooks::after_step`] is called for it (a read of the device).
    fn wants_losses(&self, _steps_done: usize) -> bool {
        false
    }
    /// The learning rate of the next step, given the config's (a schedule).
    fn learning_rate(&self, base: f64) -> f64 {
        base
    }
    /// Whether training should end now (early stopping).
    fn stop(&self) -> bool {
        false
    }
    /// What to keep in a checkpoint besides model, optimiser and step: files written into
    /// `dir` and the JSON returned (stored with the checkpoint's progress, written last).
    fn save_state(&mut self, _dir: &Path) -> Result<serde_json::Value> {
        Ok(serde_json::Value::Null)
    }
    /// Take back what [`TrainHooks::save_state`] kept (`model`: the resumed model, a
    /// template for any model file).
    fn load_state(&mut self, _dir: &Path, _state: serde_json::Value, _model: &M) -> Result<()> {
        Ok(())
    }
}

/// Training until a validation score stops improving: evaluated after every epoch, the
/// learning rate reduced on a plateau (PyTorch's `ReduceLROnPlateau`), stopped after
/// `patience` epochs without a new best, the best epoch's weights kept.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Convergence {
    /// Epochs at most (a cap, not a schedule).
    pub max_epochs: usize,
    /// Stop after this many epochs without a new best validation score.
    pub patience: usize,
    /// Multiply the learning rate by `lr_factor` after this many epochs without a new best
    /// (and again after as many more).
    pub lr_patience: usize,
    pub lr_factor: f64,
    /// A score counts as a new best only if it is below the best by this fraction of it.
    pub min_improvement: f64,
    /// A warm-up: for this many epochs the rate is not cut and the run not stopped (the
    /// counts start after it; best weights are kept throughout). For learners whose
    /// validation score swings early (the GAN); 0 for the others.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub min_epochs: usize,
}

fn is_zero(v: &usize) -> bool {
    *v == 0
}

impl Convergence {
    /// Up to 400 epochs; halve the learning rate after 6 epochs without a new best, stop
    /// after 20; improvements under 0.1% do not count. (With 4 and 12, the noisy validation
    /// error of batch-128 Adam halved the rate from the 9th epoch on: DSL's forward model
    /// stood at 0.71 cm after 52 epochs, where a cosine schedule reaches about 0.42.)
    pub fn standard() -> Self {
        Convergence {
            max_epochs: 400,
            patience: 20,
            lr_patience: 6,
            lr_factor: 0.5,
            min_improvement: 1e-3,
            min_epochs: 0,
        }
    }
}

/// One evaluation of a run trained to convergence.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ValidationPoint {
    /// Epochs (or, for an iterative learner, iterations) done.
    pub epoch: usize,
    pub learning_rate: f64,
    /// Mean training loss over the epoch.
    pub train_loss: f64,
    /// The validation score (lower is better).
    pub validation: f64,
    /// Training seconds so far.
    pub seconds: f64,
}

/// A plateau rule followed evaluation by evaluation: the best score, the learning-rate scale
/// and whether to stop. One rule for every learner that trains to convergence (the epoch
/// loop here and EMSSL's iterations).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Plateau {
    cfg: Convergence,
    best: f64,
    since_best: usize,
    since_reduce: usize,
    /// Scores taken in so far.
    #[serde(default)]
    seen: usize,
    /// The factor on the base learning rate.
    pub scale: f64,
}

impl Plateau {
    pub fn new(cfg: &Convergence) -> Self {
        Plateau {
            cfg: cfg.clone(),
            best: f64::INFINITY,
            since_best: 0,
            since_reduce: 0,
            seen: 0,
            scale: 1.0,
        }
    }

    /// Take in one score: `(whether it is a new best, whether to stop now)`.
    pub fn observe(&mut self, score: f64) -> (bool, bool) {
        let improved = score.is_finite()
            && (self.best.is_infinite() || score < self.best * (1.0 - self.cfg.min_improvement));
        if improved {
            self.best = score;
            self.since_best = 0;
        } else {
            self.since_best += 1;
        }
        self.since_reduce += 1;
        self.seen += 1;
        if self.seen <= self.cfg.min_epochs {
            // The warm-up: nothing counts yet.
            self.since_best = 0;
            self.since_reduce = 0;
            return (improved, false);
        }
        if !improved
            && self.since_best >= self.cfg.lr_patience
            && self.since_reduce >= self.cfg.lr_patience
        {
            self.scale *= self.cfg.lr_factor;
            self.since_reduce = 0;
        }
        (improved, self.since_best >= self.cfg.patience)
    }

    pub fn best(&self) -> f64 {
        self.best
    }
}

/// What a run to convergence returns besides its best model.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ConvergenceLog {
    pub curve: Vec<ValidationPoint>,
    /// The epoch whose weights were kept.
    pub best_epoch: usize,
    pub best_validation: f64,
    /// Epochs run, and whether the run stopped on the plateau (or hit `max_epochs`).
    pub epochs: usize,
    pub stopped_on_plateau: bool,
    pub seconds: f64,
}

impl Default for ConvergenceLog {
    fn default() -> Self {
        ConvergenceLog {
            curve: Vec::new(),
            best_epoch: 0,
            best_validation: f64::INFINITY,
            epochs: 0,
            stopped_on_plateau: false,
            seconds: 0.0,
        }
    }
}

impl ConvergenceLog {
    /// "stopped on a plateau after 57 epochs, best at 45" (or "hit the cap of ...").
    pub fn summary(&self) -> String {
        if self.stopped_on_plateau {
            format!(
                "stopped on a plateau after {} epochs, best at {}",
                self.epochs, self.best_epoch
            )
        } else {
            format!(
                "hit the cap of {} epochs, best at {}",
                self.epochs, self.best_epoch
            )
        }
    }
}

/// The hooks of a run to convergence.
struct Converging<M, V> {
    label: String,
    validate: V,
    rule: Plateau,
    steps_per_epoch: usize,
    best: Option<M>,
    log: ConvergenceLog,
    losses: (f64, usize),
    stop: bool,
    base_rate: f64,
    started: Instant,
    /// Seconds trained before a resume.
    earlier_seconds: f64,
    best_file: BestFile,
}

/// The best epoch's weights beside a checkpoint: `best-<epoch>.bpk`, written once per new
/// best. The file the checkpoint on disk names stays until a newer state names another, so a
/// crash between the two writes never leaves a state without its best weights.
#[derive(Default)]
pub struct BestFile {
    /// The epoch of the file the latest state names.
    saved: Option<usize>,
    /// Files no state names once the next state is written.
    stale: Vec<usize>,
}

impl BestFile {
    fn path(dir: &Path, epoch: usize) -> PathBuf {
        dir.join(format!("best-{epoch}.bpk"))
    }

    /// Before writing a state that names `epoch`: remove the files no state names any more,
    /// and write `best` if its epoch is new.
    pub fn save<M: Module>(&mut self, dir: &Path, epoch: usize, best: Option<&M>) -> Result<()> {
        for old in self.stale.drain(..) {
            let _ = std::fs::remove_file(Self::path(dir, old));
        }
        if let Some(best) = best
            && self.saved != Some(epoch)
        {
            save_module(best, &Self::path(dir, epoch))?;
            self.stale.extend(self.saved.replace(epoch));
        }
        Ok(())
    }

    /// After reading a state that names `epoch` (0: no best yet): the best weights, loaded
    /// into `template`; files of a run killed before it removed them are deleted.
    pub fn load<M: Module>(&mut self, dir: &Path, epoch: usize, template: M) -> Result<Option<M>> {
        let best = if epoch > 0 {
            let path = Self::path(dir, epoch);
            let m = template
                .try_load_file(&path)
                .map_err(|e| unreadable_checkpoint(&path, dir, e))?;
            self.saved = Some(epoch);
            Some(m)
        } else {
            None
        };
        let keep = self.saved.map(|e| format!("best-{e}.bpk"));
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with("best-") && name.ends_with(".bpk") && Some(&name) != keep.as_ref() {
                let _ = std::fs::remove_file(entry.path());
            }
        }
        Ok(best)
    }
}

/// What a run to convergence keeps in its checkpoint besides the weights.
#[derive(serde::Serialize, serde::Deserialize)]
struct ConvergingState {
    rule: Plateau,
    log: ConvergenceLog,
    stop: bool,
    seconds: f64,
    /// The epoch's training losses so far (a checkpoint taken mid-epoch, on Ctrl-C).
    #[serde(default)]
    losses: (f64, usize),
}

impl<M, V> Converging<M, V> {
    fn seconds(&self) -> f64 {
        self.earlier_seconds + self.started.elapsed().as_secs_f64()
    }
}

impl<M: Module, V: FnMut(&M) -> f64> TrainHooks<M> for Converging<M, V> {
    fn loss(&mut self, value: f64, _step: usize) {
        self.losses.0 += value;
        self.losses.1 += 1;
    }
    fn wants_losses(&self, steps_done: usize) -> bool {
        steps_done % self.steps_per_epoch == 0
    }
    fn learning_rate(&self, base: f64) -> f64 {
        base * self.rule.scale
    }
    fn stop(&self) -> bool {
        self.stop
    }
    fn save_state(&mut self, dir: &Path) -> Result<serde_json::Value> {
        self.best_file
            .save(dir, self.log.best_epoch, self.best.as_ref())?;
        serde_json::to_value(ConvergingState {
            rule: self.rule.clone(),
            log: self.log.clone(),
            stop: self.stop,
            seconds: self.seconds(),
            losses: self.losses,
        })
        .map_err(|e| Error::Config(format!("{}: checkpoint state: {e}", self.label)))
    }
    fn load_state(&mut self, dir: &Path, state: serde_json::Value, model: &M) -> Result<()> {
        let state: ConvergingState = serde_json::from_value(state)
            .map_err(|e| unreadable_checkpoint(&dir.join("state.json"), dir, e))?;
        self.best = self
            .best_file
            .load(dir, state.log.best_epoch, model.clone())?;
        self.rule = state.rule;
        self.log = state.log;
        self.stop = state.stop;
        self.earlier_seconds = state.seconds;
        self.losses = state.losses;
        self.started = Instant::now();
        Ok(())
    }
    fn after_step(&mut self, model: M, step: usize) -> Result<(M, bool)> {
        if step % self.steps_per_epoch != 0 {
            return Ok((model, false));
        }
        let epoch = step / self.steps_per_epoch;
        let learning_rate = self.base_rate * self.rule.scale;
        let score = (self.validate)(&model);
        let (improved, stop) = self.rule.observe(score);
        if improved {
            self.best = Some(model.clone());
            self.log.best_epoch = epoch;
            self.log.best_validation = score;
        }
        self.log.curve.push(ValidationPoint {
            epoch,
            learning_rate,
            train_loss: self.losses.0 / self.losses.1.max(1) as f64,
            validation: score,
            seconds: self.seconds(),
        });
        self.losses = (0.0, 0);
        self.log.epochs = epoch;
        self.stop = stop;
        self.log.stopped_on_plateau = stop;
        // Without a terminal (a run in the background) the bar is hidden: a line per epoch.
        if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            eprintln!(
                "{}: epoch {epoch}, validation {score:.4}{}, best {:.4} at {}, lr {learning_rate:.2e}, {:.0} s",
                self.label,
                if improved { " (best)" } else { "" },
                self.log.best_validation,
                self.log.best_epoch,
                self.seconds()
            );
        }
        Ok((model, false))
    }
}

/// Where a run to convergence keeps a checkpoint (after every epoch: weights, optimiser,
/// plateau rule, curve and best weights), and the settings it must have been made with to be
/// continued; one made with other settings is deleted and the run starts afresh.
#[derive(Clone, Debug, PartialEq)]
pub struct FitCheckpoint {
    pub dir: PathBuf,
    pub settings: serde_json::Value,
}

/// Train `model` on `data` with `loss` until `validate` (lower is better, called with the
/// model after every epoch) stops improving: `cfg.steps` is ignored for `conv.max_epochs`
/// epochs, the learning rate follows [`Plateau`]. Returns the best epoch's model and the
/// validation curve. With `checkpoint`, a killed run continues from its last epoch to the
/// same result.
#[allow(clippy::too_many_arguments)]
pub fn train_to_convergence<M, L, S, V>(
    model: M,
    optim: ModuleOptimizer,
    data: &TrainSet,
    cfg: &TrainConfig,
    conv: &Convergence,
    label: &str,
    loss: L,
    validate: V,
    checkpoint: Option<&FitCheckpoint>,
) -> Result<(M, ConvergenceLog)>
where
    M: Module,
    L: Fn(&M, &Batch) -> S,
    S: Into<StepLoss>,
    V: FnMut(&M) -> f64,
{
    let steps_per_epoch = data.len().div_ceil(cfg.batch.min(data.len()).max(1));
    let cfg = TrainConfig {
        steps: conv.max_epochs.max(1) * steps_per_epoch,
        checkpoint_every: if checkpoint.is_some() {
            steps_per_epoch
        } else {
            cfg.checkpoint_every
        },
        ..cfg.clone()
    };
    let plan = checkpoint.map(|c| {
        let fingerprint = serde_json::json!({
            "settings": c.settings,
            "label": label,
            "train": &cfg,
            "converge": conv,
            "samples": data.len(),
        });
        let state = c.dir.join("state.json");
        let matches = std::fs::read_to_string(&state)
            .ok()
            .and_then(|t| serde_json::from_str::<CheckpointState>(&t).ok())
            .is_some_and(|s| s.fingerprint == fingerprint);
        if !matches && c.dir.exists() {
            // Made with other settings (or half written): not this run's.
            let _ = std::fs::remove_dir_all(&c.dir);
        }
        CheckpointPlan {
            dir: c.dir.clone(),
            resume: matches,
            fingerprint,
        }
    });
    let mut hooks = Converging {
        label: label.to_string(),
        validate,
        rule: Plateau::new(conv),
        steps_per_epoch,
        best: None,
        log: ConvergenceLog::default(),
        losses: (0.0, 0),
        stop: false,
        base_rate: cfg.learning_rate,
        started: Instant::now(),
        earlier_seconds: 0.0,
        best_file: BestFile::default(),
    };
    let (model, _, _) = Trainer::new(&cfg, label)
        .optimizer(optim)
        .checkpoint(plan.as_ref())
        .hooks(&mut hooks)
        .run(model, data, loss)?;
    let mut log = hooks.log.clone();
    log.seconds = hooks.seconds();
    Ok((hooks.best.unwrap_or(model), log))
}

/// The loop behind [`Trainer`].
#[allow(clippy::too_many_arguments)]
fn train_loop<M, L, S>(
    mut model: M,
    mut optim: ModuleOptimizer,
    data: &TrainSet,
    cfg: &TrainConfig,
    checkpoint: Option<&CheckpointPlan>,
    label: &str,
    loss: L,
    hooks: &mut dyn TrainHooks<M>,
    quiet: bool,
) -> Result<(M, ModuleOptimizer, TrainLog)>
where
    M: Module,
    L: Fn(&M, &Batch) -> S,
    S: Into<StepLoss>,
{
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
    let log_every = match cfg.log_every {
        0 => (cfg.steps / 200).max(1),
        n => n,
    };
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        crate::core::progress::progress_bar(cfg.steps as u64, label, "steps")
    };
    bar.set_position(log.step as u64);
    bar.reset_eta();
    let mut losses = PendingLosses::default();
    let mut window = (0.0f64, 0usize);
    while log.step < cfg.steps && !hooks.stop() {
        let step = log.step;
        let t0 = Instant::now();
        let batch = batcher.batch(step);
        let n = batch.inputs.dims()[0];
        let step_loss: StepLoss = loss(&model, &batch).into();
        losses.push(step, &step_loss);
        let mut grads = step_loss.gradients(&model);
        let mut clip = cfg.grad_clip_norm;
        if hooks.wants_gradients() {
            if let Some(max) = clip.take() {
                crate::train::adam::clip_global_norm(&model, &mut grads, max);
            }
            hooks.gradients(&model, &grads, step);
        }
        let lr = hooks.learning_rate(cfg.learning_rate);
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
            for (at, value) in values {
                if !value.is_finite() {
                    bar.abandon();
                    let kept = match checkpoint {
                        Some(plan) if plan.state_path().exists() => {
                            format!("the last good checkpoint is in {}", plan.dir.display())
                        }
                        _ => "no checkpoint was saved".to_string(),
                    };
                    return Err(Error::Training(format!(
                        "{label}: the loss became {value} at step {}; {kept}; lower the learning rate or check the data",
                        at + 1
                    )));
                }
                hooks.loss(value, at);
                window.0 += value;
                window.1 += 1;
                if (at + 1) % log_every == 0 || at + 1 == cfg.steps {
                    let mean = window.0 / window.1 as f64;
                    log.curve.push((at + 1, mean));
                    bar.set_message(format!("loss {mean:.4}"));
                    window = (0.0, 0);
                }
            }
        }
        bar.inc(1);
        // Without a terminal (a run in the background, CI) the bar is hidden: a line every 5%.
        if !quiet
            && bar.is_hidden()
            && (log.step % (cfg.steps / 20).max(1) == 0 || log.step == cfg.steps)
        {
            let last = log.curve.last().map_or(f64::NAN, |c| c.1);
            eprintln!(
                "{label}: step {}/{}, loss {last:.4}, {:.2} s/step, ETA {}",
                log.step,
                cfg.steps,
                log.train_seconds / log.step as f64,
                indicatif::HumanDuration(bar.eta())
            );
        }
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
            return Err(Error::Interrupted(match checkpoint {
                Some(plan) => format!(
                    "{label} stopped after step {}; its checkpoint is in {}: run the same command with --resume to continue",
                    log.step,
                    plan.dir.display()
                ),
                None => format!(
                    "{label} stopped after step {}; this run keeps no checkpoint, so it starts afresh when run again",
                    log.step
                ),
            }));
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
