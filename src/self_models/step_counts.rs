//! What a self-model's training step asks of a GPU: kernel launches, host reads and uploads,
//! step by step ([`crate::eval::device_counts`]). `tests/gpu/counts.rs` bounds them on lavapipe;
//! the lab's `gpu_check` reports them on a real GPU. Behind the `cube` feature.

use crate::core::device::DeviceChoice;
use crate::core::error::{Error, Result};

/// What each step of a NeuroKin training run (the `preset`'s model, 4 joints, random
/// silhouettes, the paper's clipping and input noise; an epoch every 4 steps) asks of the GPU:
/// one [`crate::eval::device_counts::DeviceCounts`] per step, from the end of the step before to the end of its own (its
/// loss read included when the step is a log step), and the run's log.
pub fn neurokin_step_counts(
    device: DeviceChoice,
    preset: &str,
    batch: usize,
    steps: usize,
    log_every: usize,
) -> Result<(
    Vec<crate::eval::device_counts::DeviceCounts>,
    crate::train::config::TrainLog,
)> {
    use crate::eval::device_counts;
    use crate::self_models::neurokin::NeuroKin;
    use crate::train::{
        batcher::TrainSet,
        config::TrainConfig,
        hooks::Watch,
        trainer::{Trainer, autodiff_device},
    };
    use burn::tensor::{Distribution, Tensor};
    if !device_counts::install() {
        return Err(Error::Device(
            "another tracing subscriber is installed".into(),
        ));
    }
    let device = crate::core::device::select(device)?;
    let tdev = autodiff_device(&device, 0);
    // The run's model (its image the preset's camera's): the model `device_equivalence`
    // trains, so that on lavapipe the two share their compiled and tuned kernels.
    let mut cfg = crate::self_models::neurokin::neurokin_run(preset)?.model;
    cfg.dof = 4;
    let n = 4 * batch;
    let set = crate::core::device::with_seed(&tdev, 1, || TrainSet {
        inputs: Tensor::<2>::random([n, cfg.dof], Distribution::Normal(0.0, 30.0), &tdev),
        targets: vec![Tensor::<4>::random(
            [n, 1, cfg.image[0], cfg.image[1]],
            Distribution::Bernoulli(0.1),
            &tdev,
        )],
    });
    let set = cfg.training_set(&set);
    let train = TrainConfig {
        precision: Default::default(),
        schedule: Default::default(),
        steps,
        batch,
        learning_rate: 1e-3,
        grad_clip_norm: Some(1.0),
        input_noise: 0.01,
        seed: 0,
        checkpoint_every: 0,
        log_every,
    };
    let mut last = device_counts::snapshot();
    let mut per_step = Vec::with_capacity(steps);
    let mut watch = Watch(|_: &NeuroKin, _: usize| {
        let now = device_counts::snapshot();
        per_step.push(now.since(&last));
        last = now;
        Ok(())
    });
    let model = cfg.init(&tdev, 0)?;
    let (_, log) = Trainer::new(&train, "counts")
        .quiet()
        .hooks(&mut watch)
        .fit(model, &set, cfg.training_loss())?;
    Ok((per_step, log))
}
