//! One EMSSL iteration's record (a point of the learning curve, Figure 6): what the algorithm
//! ([`crate::ik::paper::emssl`]) writes and Table II's methods report ([`crate::ik::paper::method`]).

use crate::ik::data::DistanceErrors;

/// One EMSSL iteration, for the learning curve (Figure 6).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct EmsslIteration {
    pub iteration: usize,
    /// Exploration noise and learning rate used in this iteration.
    pub exploration: f64,
    pub learning_rate: f64,
    /// Test distance errors after this iteration (evaluation only; never used to stop).
    pub test: DistanceErrors,
    /// Mean distance (cm) between the desired training positions and where the model's
    /// answers for them (without noise) take the arm.
    pub train_reach_cm: f64,
    /// The same on the held-out validation goals, where the data has a validation split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation_reach_cm: Option<f64>,
    /// Mean absolute difference (normalised joints) between the model's answers for the
    /// desired positions and its answers for the positions those answers reach: zero when
    /// the model is consistent with the arm (the paper's stopping rule).
    pub disagreement: f64,
    /// Seconds of the sampling phase (batched inference, noise, forward model) and of training.
    pub sampling_seconds: f64,
    pub training_seconds: f64,
    /// Forward-model calls so far (the sampling pass and the noise-free reach check of every
    /// iteration): with a real arm as the forward model, the moves it made.
    #[serde(default)]
    pub forward_calls: usize,
    /// Optimiser steps (batches) this iteration took (the warm start's counted in the first):
    /// their sum is the run's training budget (0 in curves from before it was recorded).
    #[serde(default)]
    pub steps: usize,
}

impl EmsslIteration {
    /// The error that picks the model and stops the run: the reach error on the validation
    /// goals where there are some, on the training goals otherwise (both self-supervised:
    /// goals and the forward model, no labels).
    pub fn selection_cm(&self) -> f64 {
        self.validation_reach_cm.unwrap_or(self.train_reach_cm)
    }
}
