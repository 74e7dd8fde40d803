//! What a model may do during training besides descending the loss ([`TrainHooks`]): a
//! closure watching every step, densification (K-3DGS), early stopping and its learning-rate
//! cuts. (The schedule a run is given is its config's: [`super::config::LrSchedule`].)

use std::path::Path;

use burn::optim::GradientsParams;

use crate::core::error::Result;

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
    /// The learning rate of the next step, given the config's schedule's (a plateau rule's
    /// cuts).
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
