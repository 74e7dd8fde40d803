//! What a training run is told (optimisation settings) and what it reports (its log, saved
//! with each checkpoint).

use super::precision::Precision;

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
    /// The dtype the network computes in (`precision`; f32 master weights either way,
    /// [`super::precision`]). Absent from a saved config: f32.
    #[serde(default, skip_serializing_if = "Precision::is_f32")]
    pub precision: Precision,
    /// How the learning rate moves along training. Absent from a saved config: constant.
    #[serde(default, skip_serializing_if = "LrSchedule::is_constant")]
    pub schedule: LrSchedule,
}

/// How the learning rate moves along training.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum LrSchedule {
    /// The config's rate throughout.
    #[default]
    Constant,
    /// Falling along a half cosine from the config's rate (the first step) to 1% of it (after
    /// the last).
    Cosine,
}

impl LrSchedule {
    /// The rate of the step taken after `done` of `steps` steps, from `base`. A function of
    /// the step alone, so a resumed run continues the schedule where it stopped.
    pub fn rate(self, base: f64, done: usize, steps: usize) -> f64 {
        match self {
            LrSchedule::Constant => base,
            LrSchedule::Cosine => {
                let t = done as f64 / steps.max(1) as f64;
                base * (0.01 + 0.99 * 0.5 * (1.0 + (std::f64::consts::PI * t).cos()))
            }
        }
    }

    pub fn is_constant(&self) -> bool {
        *self == LrSchedule::Constant
    }
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

/// serde: leave a zero count out.
pub(super) fn is_zero(v: &usize) -> bool {
    *v == 0
}
