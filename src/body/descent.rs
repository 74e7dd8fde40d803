//! How every unknown of [`crate::body`] is found: full-batch Adam on a module that holds only
//! the unknowns, through a frozen self-model, its learning rate along a half cosine, with the
//! one training loop kept quiet (the callers show their own progress).

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};

use crate::body::observations::{Observed, check_angles};
use crate::core::error::{Error, Result};
use crate::train::{
    batcher::{Batch, TrainSet},
    config::{LrSchedule, TrainConfig},
    trainer::Trainer,
};

/// A descent's schedule: `steps` full-batch Adam steps from `learning_rate` along a half
/// cosine, named `label` (for messages and progress).
#[derive(Clone, Copy, Debug)]
pub struct Descent<'a> {
    pub steps: usize,
    pub learning_rate: f64,
    pub label: &'a str,
}

impl<'a> Descent<'a> {
    /// The schedule, refused in one line where it cannot descend (no step, a learning rate
    /// that is not positive and finite).
    pub fn checked(steps: usize, learning_rate: f64, label: &'a str) -> Result<Self> {
        if steps == 0 || !(learning_rate.is_finite() && learning_rate > 0.0) {
            return Err(Error::Config(format!(
                "{label} needs at least one step and a positive learning rate"
            )));
        }
        Ok(Descent {
            steps,
            learning_rate,
            label,
        })
    }

    /// Descend on `module` over `set`; `loss(module, batch)` renders through the frozen model.
    pub fn run<M: Module>(
        self,
        module: M,
        set: &TrainSet,
        loss: impl Fn(&M, &Batch) -> Tensor<1>,
    ) -> Result<M> {
        let train = TrainConfig {
            precision: Default::default(),
            schedule: LrSchedule::Cosine,
            steps: self.steps,
            batch: set.len(),
            learning_rate: self.learning_rate,
            grad_clip_norm: None,
            input_noise: 0.0,
            seed: 0,
            checkpoint_every: 0,
            log_every: 0,
        };
        let (fitted, _) = Trainer::new(&train, self.label)
            .quiet()
            .fit(module, set, loss)?;
        Ok(fitted)
    }
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
