//! What every layer stands on: typed errors, atomic files and claims, the one place that
//! names a burn backend (`device`), named presets and provenance (the revision every result
//! records). Imports nothing else of the crate.

pub mod atomic_file;
pub mod denormals;
pub mod device;
pub mod error;
pub mod input_file;
pub mod interrupt;
pub mod json_diff;
pub mod memory;
pub mod preset;
pub mod progress;
pub mod provenance;
pub mod spread;
pub mod timing;
pub mod unit_cache;
