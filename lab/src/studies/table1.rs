//! Table I of the self-modeling paper: every self-model in the zoo trained on the same
//! dataset, one row each, and the speed-quality Pareto plot.
//!
//! The zoo is the registry: every experiment marked `in_table1` runs into `dir/<name>/` and
//! its `results.csv` rows are gathered, so a new self-model (FFKSM, K-3DGS) appears here by
//! registering itself, with no edit to this file. Under `reproduce` and with `table1 --reuse`,
//! rows the experiments have written into their own folders under `reports/` (same preset,
//! dataset and steps) are gathered instead of trained again, from the experiment's
//! `results.csv` or, while it is still running, from those of the models it has finished.

use std::path::Path;

use crate::studies::pareto::{pareto_floors, pareto_points};
use crate::studies::run::{Experiment, RunOptions, write_rows};
use selfmodel::core::error::Result;
use selfmodel::report::figures::pareto_plot;
use selfmodel::self_models::result::{ModelResult, read_results};
use selfmodel::self_models::run_config::preset_train_samples;
use selfmodel::sim::robots::BuiltinRobot;

/// Self-models a Table I takes only when `--models` names them (beside those marked
/// `in_table1`).
pub const ON_REQUEST: &[&str] = &["neurokin_tree", "link_splat"];

/// Whether Table I can hold `e` (when `--models` names it).
fn can_hold(e: &Experiment) -> bool {
    e.in_table1 || ON_REQUEST.contains(&e.name)
}

/// Refuse `--models` names that are not self-models of Table I, naming those that are.
pub fn check_models(models: &[String], experiments: &[Experiment]) -> Result<()> {
    let known: Vec<&str> = experiments
        .iter()
        .filter(|e| can_hold(e))
        .map(|e| e.name)
        .collect();
    if models.is_empty() {
        return Err(selfmodel::Error::Config(format!(
            "--models needs at least one name ({})",
            known.join(", ")
        )));
    }
    match models.iter().find(|m| !known.contains(&m.as_str())) {
        Some(m) => Err(selfmodel::Error::Config(format!(
            "--models: \"{m}\" is not a self-model of Table I (choose from {})",
            known.join(", ")
        ))),
        None => Ok(()),
    }
}

/// Run the zoo (the `experiments` marked `in_table1`, or those `opts.models` names, in the
/// registry's order) on `opts` into `dir` and write the table and the Pareto plot.
pub fn run(opts: &RunOptions, dir: &Path, experiments: &[Experiment]) -> Result<Vec<ModelResult>> {
    let mut rows = Vec::new();
    let chosen = |e: &&Experiment| match &opts.models {
        Some(m) => can_hold(e) && m.iter().any(|m| m == e.name),
        None => e.in_table1,
    };
    for e in experiments.iter().filter(chosen) {
        let sub = dir.join(e.name);
        // Resumed: an experiment that finished in this folder (its table written) is read,
        // not trained again; one still running continues from its checkpoints.
        if opts.resume
            && let Some(found) = finished_rows(opts, &sub.join("results.csv"))?
        {
            eprintln!(
                "table1: {} ({} preset): {} rows of the finished run in {}",
                e.name,
                opts.preset,
                found.len(),
                sub.display()
            );
            rows.extend(found);
            continue;
        }
        if let Some(found) = reusable_rows(opts, e.default_dir)? {
            eprintln!(
                "table1: {} ({} preset): {} rows reused from {}",
                e.name,
                opts.preset,
                found.len(),
                e.default_dir
            );
            rows.extend(found);
            continue;
        }
        eprintln!("table1: {} ({} preset)", e.name, opts.preset);
        (e.run)(opts, &sub)?;
        rows.extend(read_results(&sub.join("results.csv"))?);
    }
    write_rows(
        dir,
        &rows,
        &format!(
            "Table I: self-models of {}, quality against speed",
            match opts.robot_spec(BuiltinRobot::Arm4) {
                r if r.is_papers_arm() && opts.dataset.is_none() => "the 4-DOF arm".to_string(),
                _ if opts.dataset.is_some() => "the robot of the given dataset".to_string(),
                r => r.label(),
            }
        ),
        &format!(
            "All models trained and tested on the same dataset ({} preset). PSNR as the paper computes it (per image, then averaged) on the first 100 test images and on the whole test set; IoU of silhouettes thresholded at 0.5. Inference speed: median of synchronised timed calls after warm-up, at batch 1 (latency) and batch 256. `train_img_per_s` is training throughput, which is what the paper's \"FPS\" column measured; the paper's figures (`paper_*`) were taken on an NVIDIA T4 and are shown for reference only. Each model's folder holds its config, training curve and qualitative figure.",
            opts.preset
        ),
    )?;
    let points = pareto_points(&rows, |m| m.to_string());
    pareto_plot(
        &dir.join("pareto.png"),
        "Self-models: quality against inference speed",
        "PSNR on the test set (dB)",
        &points,
        &pareto_floors(&rows),
    )?;
    Ok(rows)
}

/// The rows under `opts.reuse_root/default_dir/results.csv`, if that file exists and every row
/// matches this run (see `finished_rows`). Without that file (an experiment of
/// several models still running, FFKSM's paper preset), the matching rows of its models'
/// own `default_dir/*/results.csv`, if any: Table I then holds the models that are done.
fn reusable_rows(opts: &RunOptions, default_dir: &str) -> Result<Option<Vec<ModelResult>>> {
    let Some(root) = &opts.reuse_root else {
        return Ok(None);
    };
    let dir = root.join(default_dir);
    if let Some(rows) = finished_rows(opts, &dir.join("results.csv"))? {
        return Ok(Some(rows));
    }
    if dir.join("results.csv").is_file() {
        return Ok(None);
    }
    let mut subdirs: Vec<std::path::PathBuf> = match std::fs::read_dir(&dir) {
        Ok(entries) => entries.filter_map(|e| e.ok().map(|e| e.path())).collect(),
        Err(_) => return Ok(None),
    };
    subdirs.sort();
    let mut rows = Vec::new();
    for sub in subdirs {
        if let Some(found) = finished_rows(opts, &sub.join("results.csv"))? {
            rows.extend(found);
        }
    }
    Ok((!rows.is_empty()).then_some(rows))
}

/// The rows of the table at `path`, if it exists, has rows, and every row has this run's
/// preset, dataset, precision, learning-rate schedule, step count and training-sample count (`--steps N`, `--train-samples N`:
/// N; none: the preset's, so a shortened run, or one on more poses, is never taken for the
/// preset's).
fn finished_rows(opts: &RunOptions, path: &Path) -> Result<Option<Vec<ModelResult>>> {
    if !path.is_file() {
        return Ok(None);
    }
    let train_samples = match opts.train_samples {
        Some(n) => n,
        None => preset_train_samples(&opts.preset)?,
    };
    let dataset = if opts.paper_compatible {
        "paper_compatible"
    } else {
        "clean"
    };
    let matches = |r: &ModelResult| {
        r.preset == opts.preset
            && r.dataset == dataset
            && r.precision == opts.precision
            && r.schedule == opts.schedule
            && match opts.steps {
                Some(s) => r.train_steps == s,
                None => r.steps_override.is_none(),
            }
            && r.train_samples == train_samples
            && opts.batch.is_none_or(|b| r.batch == b)
    };
    let rows = read_results(path)?;
    Ok((!rows.is_empty() && rows.iter().all(matches)).then_some(rows))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row trained on more poses (`--train-samples`) is gathered only by a run that asks
    /// for as many, and a run that asks for none takes only the preset's.
    #[test]
    fn finished_rows_match_the_training_poses() {
        let root = crate::workspace().join("reports/robots/panda");
        let preset_rows = root.join("table1/neurokin/results.csv");
        let more_rows = root.join("table1_9600/neurokin/results.csv");
        let mut opts = RunOptions::preset("paper");
        assert!(finished_rows(&opts, &preset_rows).unwrap().is_some());
        assert!(finished_rows(&opts, &more_rows).unwrap().is_none());
        opts.train_samples = Some(9600);
        assert!(finished_rows(&opts, &more_rows).unwrap().is_some());
        assert!(finished_rows(&opts, &preset_rows).unwrap().is_none());
    }
}
