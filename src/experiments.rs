//! The one registry of experiments: it drives the smoke tests (`tests/experiments.rs`, every
//! entry on its `quick` preset), the reproduce-everything command (`reproduce`) and the
//! reports. Each binary in `experiments/` parses its arguments and calls the same function.

use std::path::Path;

use crate::dataset::{DatasetConfig, build_and_save};
use crate::error::Result;
use crate::mesh_fidelity::{self, FidelityConfig};
use crate::preset::Preset;

/// One experiment.
pub struct Experiment {
    /// The binary's name (`cargo run --release --bin NAME`).
    pub name: &'static str,
    /// One line: what it reproduces.
    pub about: &'static str,
    /// Where `reproduce` writes it, relative to the repository root.
    pub default_dir: &'static str,
    /// Run a preset (`paper`, `quick`) with defaults into a folder; returns a one-line summary.
    pub run: fn(preset: &str, dir: &Path) -> Result<String>,
}

fn run_dataset(preset: &str, dir: &Path) -> Result<String> {
    let cfg = DatasetConfig::preset(preset)?;
    let robot = crate::arm4::arm4();
    let (data, report) =
        build_and_save(&robot, "arm4", &cfg, None, &dir.join("dataset.npz"), false)?;
    Ok(format!(
        "{} samples rendered in {:.3} s, mean occupancy {:.2}%",
        data.len(),
        report.render_seconds,
        100.0 * report.stats.occupancy.mean
    ))
}

fn run_mesh_fidelity(preset: &str, dir: &Path) -> Result<String> {
    let rows = mesh_fidelity::run(&FidelityConfig::preset(preset)?, dir)?;
    Ok(format!(
        "arm4 vs mesh robot: mean IoU {:.4} over {} poses",
        rows[0].mean_iou, rows[0].poses
    ))
}

/// Every experiment, in the order `reproduce` runs them.
pub const EXPERIMENTS: &[Experiment] = &[
    Experiment {
        name: "dataset",
        about: "the papers' 2,000-sample Lorenz dataset of the 4-DOF arm (silhouettes, depth, angles)",
        default_dir: "data",
        run: run_dataset,
    },
    Experiment {
        name: "mesh_fidelity",
        about: "silhouette IoU of the built-in arm4 against the mesh robot (and PyBullet)",
        default_dir: "reports/mesh_fidelity",
        run: run_mesh_fidelity,
    },
];
