//! Named presets of a config: every model and experiment has at least `paper` (the papers'
//! facts) and `quick` (tiny, seconds, for tests and CI).

use crate::core::error::{Error, Result};

/// A config with named presets.
pub trait Preset: Sized {
    /// The papers' settings.
    fn paper() -> Self;
    /// Tiny settings for tests.
    fn quick() -> Self;
    /// Look a preset up by name.
    fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(Self::paper()),
            "quick" => Ok(Self::quick()),
            other => Err(Error::Config(format!(
                "unknown preset \"{other}\" (choose paper or quick)"
            ))),
        }
    }
}
