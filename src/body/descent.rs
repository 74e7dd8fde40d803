//! How every unknown of [`crate::body`] is found: full-batch Adam on a module that holds only
//! the unknowns, through a frozen self-model, its learning rate along a half cosine, with the
//! one training loop kept quiet (the callers show their own progress).

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};

use crate::body::observations::{Observed, check_angles};
use crate::core::error::{Error, Result};
use crate::train::{
    batcher::{Batch, TrainSet},
    config::TrainConfig,
    hooks::Schedule,
    trainer::Trainer,
};

/// Reject a schedule that cannot descend (`what`: the fit, for the message).
pub fn check_schedule(steps: usize, learning_rate: f64, what: &str) -> Result<()> {
    if steps == 0 || !(learning_rate.is_finite() && learning_rate > 0.0) {
        return Err(Error::Config(format!(
            "{what} needs at least one step and a positive learning rate"
        )));
    }
    Ok(())
}

/// Images seen at known joint angles, checked (the model's `image` size, no empty image, one
/// finite joint vector per image), as a set: inputs the angles `[k, dof]`, target the images.
pub fn views(
    observed: &Observed,
    angles: &[Vec<f64>],
    image: [usize; 2],
    what: &str,
    device: &Device,
) -> Result<TrainSet> {
    observed.check_for(image)?;
    let dof = angles.first().map_or(0, Vec::len);
    if angles.len() != observed.n || dof == 0 {
        return Err(Error::Config(format!(
            "{} {what} joint vectors for {} images",
            angles.len(),
            observed.n
        )));
    }
    check_angles(angles, dof, what)?;
    let q: Vec<f32> = angles.iter().flatten().map(|&v| v as f32).collect();
    Ok(TrainSet {
        inputs: Tensor::from_data(TensorData::new(q, [observed.n, dof]), device),
        targets: vec![observed.tensor(device)],
    })
}

/// `steps` full-batch Adam steps on `module` from `learning_rate` along a half cosine;
/// `loss(module, batch)` renders through the frozen model.
pub fn descend<M: Module>(
    module: M,
    set: &TrainSet,
    steps: usize,
    learning_rate: f64,
    label: &str,
    loss: impl Fn(&M, &Batch) -> Tensor<1>,
) -> Result<M> {
    let train = TrainConfig {
        steps,
        batch: set.len(),
        learning_rate,
        grad_clip_norm: None,
        input_noise: 0.0,
        seed: 0,
        checkpoint_every: 0,
        log_every: 0,
    };
    let mut schedule = Schedule::cosine(steps);
    let (fitted, _) = Trainer::new(&train, label)
        .quiet()
        .hooks(&mut schedule)
        .fit(module, set, loss)?;
    Ok(fitted)
}
