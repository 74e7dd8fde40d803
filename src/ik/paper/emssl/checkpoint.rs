//! Where an EMSSL run keeps its state between iterations (model, optimiser, best model,
//! curve, the rules' state) and the settings it must match to continue.

use burn::optim::ModuleOptimizer;

use crate::core::error::Result;
use crate::ik::mlp::Mlp;
use crate::train::convergence::Plateau;

use super::{EmsslIteration, StopRule};

/// Where an EMSSL run keeps its state, and the settings it must match to continue.
pub(super) struct EmsslCheckpoint {
    pub(super) dir: std::path::PathBuf,
    pub(super) settings: serde_json::Value,
}

/// What an EMSSL checkpoint's `state.json` holds besides the weights.
#[derive(serde::Serialize, serde::Deserialize)]
pub(super) struct EmsslState {
    pub(super) settings: serde_json::Value,
    pub(super) curve: Vec<EmsslIteration>,
    pub(super) rule: StopRule,
    pub(super) plateau: Option<Plateau>,
    /// Whether the stopping rule has ended the run (its best model is final).
    pub(super) finished: bool,
}

impl EmsslCheckpoint {
    pub(super) fn path(&self, file: &str) -> std::path::PathBuf {
        self.dir.join(file)
    }

    /// The saved state, if it was made with the same settings.
    pub(super) fn load(&self) -> Option<EmsslState> {
        if !(self.path("model.bpk").exists() && self.path("optimizer.bpk").exists()) {
            return None;
        }
        let text = std::fs::read_to_string(self.path("state.json")).ok()?;
        serde_json::from_str::<EmsslState>(&text)
            .ok()
            .filter(|s| s.settings == self.settings)
    }

    pub(super) fn save(
        &self,
        model: &Mlp,
        optim: &ModuleOptimizer,
        best: Option<&Mlp>,
        state: &EmsslState,
    ) -> Result<()> {
        std::fs::create_dir_all(&self.dir).map_err(|e| crate::Error::io(&self.dir, e))?;
        crate::train::checkpoint::save_module(model, &self.path("model.bpk"))?;
        crate::train::checkpoint::save_renamed(&self.path("optimizer.bpk"), |t| optim.save(t))?;
        if let Some(b) = best {
            crate::train::checkpoint::save_module(b, &self.path("best.bpk"))?;
        }
        crate::core::atomic_file::write_json(&self.path("state.json"), state)
    }
}
