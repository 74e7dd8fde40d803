//! Checkpoints: model, optimiser state and progress written every N steps (each file renamed
//! into place, the progress last), and read back by `resume` when made with the same
//! configuration.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::ModuleOptimizer;

use super::config::TrainLog;
use super::hooks::TrainHooks;
use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};

/// Where checkpoints go, and whether to continue from one.
#[derive(Clone, Debug)]
pub struct CheckpointPlan {
    pub dir: PathBuf,
    pub resume: bool,
    /// Anything that must match for a resume to be valid (model and training config as JSON).
    pub fingerprint: serde_json::Value,
}

#[derive(serde::Serialize, serde::Deserialize)]
pub(super) struct CheckpointState {
    pub fingerprint: serde_json::Value,
    pub log: TrainLog,
    /// What the run's hooks keep ([`TrainHooks::save_state`]): a run to convergence's
    /// plateau rule, validation curve and best epoch.
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub hooks: serde_json::Value,
}

/// A saved model or optimiser file that cannot be read back: what failed, and that deleting
/// the checkpoint's folder `dir` (or running without `resume`) starts afresh.
pub fn unreadable_checkpoint(file: &Path, dir: &Path, e: impl std::fmt::Display) -> Error {
    Error::data(
        file,
        format!(
            "this checkpoint cannot be read ({e}); delete {} to start afresh, or run without `resume`",
            dir.display()
        ),
    )
}

/// Save a module's weights to a burnpack file, bit for bit what the module computes with: its
/// running statistics (BatchNorm's) are synchronised first, since burn writes the value before
/// the last training step's pending update, which `valid()` (and so every evaluation) applies.
pub fn save_module<M: Module>(model: &M, path: &Path) -> Result<()> {
    let _synchronised = model.valid();
    save_renamed(path, |tmp| model.clone().save_file(tmp))
}

/// `template` with the weights [`save_module`] wrote to `path`.
pub fn load_module<M: Module>(template: M, path: &Path) -> Result<M> {
    let max = crate::core::input_file::MAX_WEIGHTS_BYTES;
    crate::core::input_file::check_user_file(path, "weights file", max)?;
    template.try_load_file(path).map_err(|e| {
        Error::data(
            path,
            format!("the weights cannot be read ({e}); train the model again"),
        )
    })
}

/// Write a burnpack file to a temporary name, then rename it into place.
pub(crate) fn save_renamed(
    path: &Path,
    write: impl FnOnce(&Path) -> std::result::Result<(), burn::store::RecordError>,
) -> Result<()> {
    let tmp = path.with_extension("bpk.tmp");
    write(&tmp).map_err(|e| Error::data(path, format!("cannot write checkpoint: {e}")))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

impl CheckpointPlan {
    pub(super) fn model_path(&self) -> PathBuf {
        self.dir.join("model.bpk")
    }
    pub(super) fn optim_path(&self) -> PathBuf {
        self.dir.join("optimizer.bpk")
    }
    pub(super) fn state_path(&self) -> PathBuf {
        self.dir.join("state.json")
    }

    /// With `resume`: whether the checkpoint, if there is one, can be continued (it reads and
    /// was made with this configuration), checked without loading it, so a run of several
    /// models can refuse a foreign or damaged checkpoint before it writes anything.
    pub fn check(&self) -> Result<()> {
        if self.resume && self.state_path().exists() {
            self.read_state()?;
        }
        Ok(())
    }

    /// The checkpoint's progress, refused when it does not read or another configuration
    /// made it.
    pub(super) fn read_state(&self) -> Result<CheckpointState> {
        let path = self.state_path();
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let state: CheckpointState =
            serde_json::from_str(&text).map_err(|e| unreadable_checkpoint(&path, &self.dir, e))?;
        if state.fingerprint != self.fingerprint {
            return Err(Error::Config(format!(
                "the checkpoint in {} was made with a different configuration; drop `resume` or delete that folder",
                self.dir.display()
            )));
        }
        Ok(state)
    }

    /// Write model, optimizer and progress; each file is written to a temporary name and
    /// renamed, the progress file last, so a crash never leaves a checkpoint that claims more
    /// than it holds.
    pub(super) fn save<M: Module>(
        &self,
        model: &M,
        optim: &ModuleOptimizer,
        log: &TrainLog,
        hooks: &mut dyn TrainHooks<M>,
    ) -> Result<()> {
        std::fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        save_module(model, &self.model_path())?;
        save_renamed(&self.optim_path(), |tmp| optim.save(tmp))?;
        let hooks = hooks.save_state(&self.dir)?;
        write_json(
            &self.state_path(),
            &CheckpointState {
                fingerprint: self.fingerprint.clone(),
                log: log.clone(),
                hooks,
            },
        )
    }

    /// Load a checkpoint if `resume` is set and one exists; with `resume` set, say on stderr
    /// which of the two happened (`label`: the run's name).
    pub(super) fn load<M: Module>(
        &self,
        model: M,
        optim: ModuleOptimizer,
        label: &str,
    ) -> Result<(M, ModuleOptimizer, Option<(TrainLog, serde_json::Value)>)> {
        if !self.resume {
            return Ok((model, optim, None));
        }
        if !self.state_path().exists() {
            eprintln!(
                "{label}: resuming: no checkpoint in {}; training starts from step 0",
                self.dir.display()
            );
            return Ok((model, optim, None));
        }
        let state = self.read_state()?;
        let model = model
            .try_load_file(self.model_path())
            .map_err(|e| unreadable_checkpoint(&self.model_path(), &self.dir, e))?;
        let optim = optim
            .load(self.optim_path())
            .map_err(|e| unreadable_checkpoint(&self.optim_path(), &self.dir, e))?;
        eprintln!(
            "{label}: continuing from step {} (checkpoint in {})",
            state.log.step,
            self.dir.display()
        );
        Ok((model, optim, Some((state.log, state.hooks))))
    }
}
