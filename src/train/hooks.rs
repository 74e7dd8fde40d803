//! What a model may do during training besides descending the loss ([`TrainHooks`]): a
//! learning-rate schedule, a closure watching every step, densification (K-3DGS), early
//! stopping.

use std::path::Path;

use burn::optim::GradientsParams;

use crate::core::error::Result;

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
pub(super) struct NoHooks;
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
