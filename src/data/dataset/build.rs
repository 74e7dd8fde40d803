//! Render and save a dataset with its stats and config beside it, as the `dataset` binary
//! does.

use std::path::Path;

use serde::Serialize;

use super::{Dataset, DatasetConfig, DatasetStats};
use crate::core::atomic_file::write_json;
use crate::core::error::Result;
use crate::core::provenance::git_revision;
use crate::sim::robot::Robot;

/// What [`build_and_save`] did.
#[derive(Clone, Debug, Serialize)]
pub struct BuildReport {
    pub stats: DatasetStats,
    pub robot: String,
    pub shapes: usize,
    pub render_seconds: f64,
    pub write_seconds: f64,
    pub images_per_second: f64,
    pub threads: usize,
    pub git_revision: String,
}

/// Sample (or take `angles`), render, and write `out` (.npz) with `.stats.json` and
/// `.config.json` beside it (`report::dataset_preview` draws its `.preview.png`).
/// `progress`: show a progress bar.
pub fn build_and_save(
    robot: &Robot,
    robot_label: &str,
    cfg: &DatasetConfig,
    angles: Option<Vec<Vec<f64>>>,
    out: &Path,
    progress: bool,
) -> Result<(Dataset, BuildReport)> {
    let bar = progress
        .then(|| crate::core::progress::progress_bar(cfg.samples as u64, "render", "images"));
    let start = std::time::Instant::now();
    let data = match angles {
        Some(rows) => Dataset::render(robot, cfg, rows, bar.as_ref())?,
        None => Dataset::generate(robot, cfg, bar.as_ref())?,
    };
    let render_seconds = start.elapsed().as_secs_f64();
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    data.check_in_view()?;
    let write_start = std::time::Instant::now();
    data.save(out)?;
    let write_seconds = write_start.elapsed().as_secs_f64();

    let names: Vec<String> = robot
        .chain
        .movable_joints()
        .map(|j| j.name.clone())
        .collect();
    let stats = data.stats(&names);
    let report = BuildReport {
        stats,
        robot: robot_label.to_string(),
        shapes: robot.shape_count(),
        render_seconds,
        write_seconds,
        images_per_second: data.len() as f64 / render_seconds,
        threads: rayon::current_num_threads(),
        git_revision: git_revision(),
    };
    write_json(&out.with_extension("stats.json"), &report)?;
    write_json(&out.with_extension("config.json"), cfg)?;
    Ok((data, report))
}
