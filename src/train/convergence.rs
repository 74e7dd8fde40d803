//! Training until a validation score stops improving: the plateau rule, the validation
//! curve, the best epoch's weights kept, resumable after every epoch.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::module::Module;
use burn::optim::ModuleOptimizer;

use super::batcher::{Batch, TrainSet};
use super::checkpoint::{CheckpointPlan, CheckpointState};
use super::checkpoint::{save_module, unreadable_checkpoint};
use super::config::{TrainConfig, is_zero};
use super::hooks::TrainHooks;
use super::trainer::{StepLoss, Trainer};
use crate::core::error::{Error, Result};

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
// The loop's inputs, each named at its two callers: what trains (model, optimiser, data), how
// (settings, stopping rule, label), the two closures that differ per model (loss, validation)
// and where it keeps its state; grouping any of them would be a struct used once.
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
