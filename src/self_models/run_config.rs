//! Everything that defines one self-model run ([`SelfModelRun`]): the model's config, its
//! training, its data, its evaluation and speed settings, and the presets every self-model
//! shares (`paper`, `short`, `quick`, `large`).

use crate::core::error::{Error, Result};
use crate::eval::inference_speed::SpeedConfig;
use crate::self_models::data_spec::DataSpec;
use crate::train::config::TrainConfig;

/// Everything that defines one self-model run: the model's config and what every run shares.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SelfModelRun<M> {
    /// Row label (`NeuroKin`, `NeuroKin (sigma 0)`, ...).
    pub name: String,
    pub preset: String,
    pub model: M,
    pub train: TrainConfig,
    pub data: DataSpec,
    /// PSNR is also reported on the first this-many test images (the paper's 100).
    pub paper_subset: usize,
    pub eval_batch: usize,
    pub speed: SpeedConfig,
    /// Said in the results row (a shortened run, ...).
    pub note: String,
    /// `--steps N` when it changed the preset's step count.
    pub steps_override: Option<usize>,
}

/// The presets of the self-model runs: `paper`, `quick`, `short` (the paper's data and
/// models with training cut so the whole of `table1` runs in under 5 minutes on a 2-core CPU,
/// `reports/table1_short/console*.txt` say how long it took; each row says so in its note),
/// and `large` (the paper's models on 12,000 training images of the same trajectory, trained
/// three times as long: the self-model `damage` and `body_from_image --preset large` act on).
pub const SELF_MODEL_PRESETS: &[&str] = &["paper", "short", "quick", "large"];

/// The notebooks' training protocol: Adam 1e-3, batch 32, 3,000 steps, clip 1.0, N(0, 0.01)
/// noise on the angles in degrees (`quick`: 200 steps of batch 16; `large`: 9,000 steps, 24
/// epochs of its 12,000 images).
pub fn notebook_train(preset: &str) -> TrainConfig {
    match preset {
        "large" => TrainConfig {
            steps: 9000,
            ..notebook_train("paper")
        },
        "quick" => TrainConfig {
            precision: Default::default(),
            schedule: Default::default(),
            steps: 200,
            batch: 16,
            learning_rate: 1e-3,
            grad_clip_norm: Some(1.0),
            input_noise: 0.01,
            seed: 0,
            checkpoint_every: 50,
            log_every: 0,
        },
        _ => TrainConfig {
            precision: Default::default(),
            schedule: Default::default(),
            steps: 3000,
            batch: 32,
            learning_rate: 1e-3,
            grad_clip_norm: Some(1.0),
            input_noise: 0.01,
            seed: 0,
            checkpoint_every: 250,
            log_every: 0,
        },
    }
}

/// How many poses a preset trains on (the paper's: 1,600).
pub fn preset_train_samples(preset: &str) -> Result<usize> {
    Ok(preset_parts(preset)?.0.dataset.train)
}

fn preset_parts(preset: &str) -> Result<(DataSpec, SpeedConfig)> {
    match preset {
        "paper" => Ok((DataSpec::paper(), SpeedConfig::paper())),
        "short" => Ok((DataSpec::paper(), SpeedConfig::short())),
        "large" => Ok((DataSpec::large(), SpeedConfig::paper())),
        "quick" => Ok((DataSpec::quick(), SpeedConfig::quick())),
        other => Err(Error::Config(format!(
            "unknown preset \"{other}\" (choose paper, short, quick or large)"
        ))),
    }
}

/// The model preset a run preset uses (`short` and `large` train the paper's models).
pub fn model_preset(preset: &str) -> &str {
    if preset == "short" || preset == "large" {
        "paper"
    } else {
        preset
    }
}

impl<M> SelfModelRun<M> {
    /// A run of `model` on a preset's data and speed settings, with the notebooks' training
    /// protocol and PSNR also on the paper's first 100 test images.
    pub fn new(preset: &str, name: &str, model: M, eval_batch: usize) -> Result<Self> {
        let (data, speed) = preset_parts(preset)?;
        Ok(SelfModelRun {
            name: name.into(),
            preset: preset.into(),
            model,
            train: notebook_train(preset),
            data,
            paper_subset: 100,
            eval_batch,
            speed,
            note: String::new(),
            steps_override: None,
        })
    }

    /// The image size of a preset's camera, `[height, width]`.
    pub fn image(preset: &str) -> Result<[usize; 2]> {
        let camera = &preset_parts(preset)?.0.dataset.camera;
        Ok([camera.height, camera.width])
    }

    /// Shorten a paper-preset run for the `short` preset, and say so in its note.
    pub fn shorten(mut self, steps: usize, batch: usize) -> Self {
        if self.preset == "short" {
            self.note = format!(
                "short preset: {steps} steps of batch {batch} instead of {} of {} (CPU time budget)",
                self.train.steps, self.train.batch
            );
            self.train.steps = steps;
            self.train.batch = batch;
        }
        self
    }

    /// Score a `short` run on the first `n` test images only (the paper's PSNR subset is the
    /// first 100), and say so in its note.
    pub fn short_test_set(mut self, n: usize) -> Self {
        if self.preset == "short" {
            let start = self.data.dataset.train;
            let end = (start + n).min(self.data.dataset.samples);
            self.data.test = Some(start..end);
            let said = format!("scored on the first {} test images", end - start);
            self.note = if self.note.is_empty() {
                format!("short preset: {said}")
            } else {
                format!("{}, {said}", self.note)
            };
        }
        self
    }

    /// Switch to the paper-compatible dataset (silhouettes with the ground-plane artefact).
    pub fn paper_compatible(mut self, on: bool) -> Self {
        self.data.dataset.render.ground_artifact = on;
        self
    }
}
