//! The data-scale ablation (self-modeling paper, Section V-C; issue 75 on the G1): a self-model
//! trained on more and more poses of one trajectory, every size tested on the same held-out
//! poses, so the rows compare.
//!
//! - By default, NeuroKin on the paper's sizes: 400, 2,000 and 12,000 samples, trained on the
//!   first 80% of each (320, 1,600, 9,600) and tested on samples 12,000-12,399 of the
//!   trajectory. The paper printed 21.88 dB for 2,000 (its Table I) and guessed "~25-26 dB"
//!   for 12,000. Rows `NeuroKin <size> samples`, folders `<size>_samples/`.
//! - `--models` (neurokin, link_splat, k3dgs) and `--sizes N,...` (training poses): each model
//!   trained on the first N poses for every N, tested on the preset's test count (400) of poses
//!   after the largest N. Rows `<model> <N> poses`, folders `<model>/<N>_poses/`.
//!
//! Writes `results.csv` and `.md`, `training_curves.png` (every run's loss), `pareto.png` and,
//! with several sizes, `scaling.png` (PSNR on the test poses against training poses, a line a
//! model).

use std::path::{Path, PathBuf};

use selfmodel::core::error::{Error, Result};
use selfmodel::report::figures::{LinePlot, line_plot, pareto_plot, training_curves};
use selfmodel::report::table::{read_curve, write_csv, write_markdown_report};
use selfmodel::self_models::harness::run_with;
use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
use selfmodel::self_models::link_splat::link_splat_run;
use selfmodel::self_models::model::SelfModel;
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::self_models::result::{ModelResult, read_results};
use selfmodel::self_models::run_config::SelfModelRun;

use crate::studies::models::paper_figures::{PaperFigures, on_papers_setup};
use crate::studies::pareto::pareto_points;
use crate::studies::run::RunOptions;

/// The self-models the ablation trains (registry names).
pub const MODELS: &[&str] = &["neurokin", "link_splat", "k3dgs"];

const TITLE: &str = "Data-scale ablation: training poses";

/// One size: its row label (after the model's name), its folder, its training poses and the
/// paper's PSNR for it.
struct Size {
    label: String,
    folder: PathBuf,
    train: usize,
    paper_psnr_db: Option<f64>,
}

/// The sizes for `preset`: the paper's for NeuroKin by default, else `sizes` (training poses)
/// for `model`. Returns them with the test poses (after the largest training set).
fn sizes(preset: &str, model: Option<&str>, given: Option<&[usize]>) -> (Vec<Size>, usize) {
    let test = if preset == "quick" { 50 } else { 400 };
    match (model, given) {
        (None, None) => {
            let paper: &[(usize, Option<f64>)] = if preset == "quick" {
                &[(50, None), (100, None), (200, None)]
            } else {
                &[(400, None), (2000, Some(21.88)), (12000, None)]
            };
            let sizes = paper
                .iter()
                .map(|&(size, p)| Size {
                    label: format!("{size} samples"),
                    folder: format!("{size}_samples").into(),
                    train: size * 4 / 5,
                    paper_psnr_db: p,
                })
                .collect();
            (sizes, test)
        }
        (model, given) => {
            let model = model.unwrap_or("neurokin");
            let given = given.unwrap_or(&[320, 1600, 9600]);
            let sizes = given
                .iter()
                .map(|&n| Size {
                    label: format!("{n} poses"),
                    folder: Path::new(model).join(format!("{n}_poses")),
                    train: n,
                    paper_psnr_db: None,
                })
                .collect();
            (sizes, test)
        }
    }
}

/// Run the ablation for `opts` into `dir`: `models` (registry names; none: NeuroKin on the
/// paper's sizes) on `given` training-pose counts.
pub fn run(
    opts: &RunOptions,
    models: Option<&[String]>,
    given: Option<&[usize]>,
    dir: &Path,
) -> Result<Vec<ModelResult>> {
    if opts.train_samples.is_some() {
        return Err(Error::Config(
            "--train-samples does not apply to ablation_data_scale: give its sizes with --sizes N,N,... (training poses)".into(),
        ));
    }
    if given.is_some_and(|g| g.is_empty() || g.contains(&0)) {
        return Err(Error::Config(
            "--sizes: give one or more training-pose counts, each at least 1".into(),
        ));
    }
    let mut rows = Vec::new();
    match models {
        None => rows.extend(model_rows("neurokin", None, given, opts, dir)?),
        Some(names) => {
            for name in names {
                rows.extend(model_rows(name, Some(name), given, opts, dir)?);
            }
        }
    }
    let csv = dir.join("results.csv");
    write_csv(&csv, &rows)?;
    write_markdown_report(
        &csv,
        TITLE,
        "Each row is a full run of the model on the first N poses of one trajectory (config in its folder); every row of a model is tested on the same held-out poses, after the largest training set. `paper_psnr_db` is the figure the paper printed, for reference. PSNR as the paper computes it; IoU at threshold 0.5.",
    )?;
    draw(dir)?;
    let points = pareto_points(&rows, |m| m.to_string());
    pareto_plot(
        &dir.join("pareto.png"),
        TITLE,
        "PSNR on the test set (dB)",
        &points,
        &[],
    )?;
    Ok(rows)
}

/// Every size of the model `name`: `folder_model` names its folders (none: the paper's
/// layout).
fn model_rows(
    name: &str,
    folder_model: Option<&str>,
    given: Option<&[usize]>,
    opts: &RunOptions,
    dir: &Path,
) -> Result<Vec<ModelResult>> {
    let (sizes, test) = sizes(&opts.preset, folder_model, given);
    match name {
        "neurokin" => each_size(
            opts.apply(neurokin_run(&opts.preset)?)?,
            &sizes,
            test,
            opts,
            dir,
        ),
        "link_splat" => each_size(
            opts.apply(link_splat_run(&opts.preset)?)?,
            &sizes,
            test,
            opts,
            dir,
        ),
        "k3dgs" => each_size(
            opts.apply(k3dgs_run(&opts.preset, K3dgsVariant::Anisotropic)?)?,
            &sizes,
            test,
            opts,
            dir,
        ),
        other => Err(Error::Config(format!(
            "ablation_data_scale: no model \"{other}\" (choose from {})",
            MODELS.join(", ")
        ))),
    }
}

/// `base` trained on each size, all tested on the `test` poses after the largest.
fn each_size<M: SelfModel>(
    base: SelfModelRun<M>,
    sizes: &[Size],
    test: usize,
    opts: &RunOptions,
    dir: &Path,
) -> Result<Vec<ModelResult>> {
    let max = sizes.iter().map(|s| s.train).max().unwrap_or(0);
    let mut rows = Vec::new();
    for size in sizes {
        let mut cfg = base.clone();
        cfg.data.dataset.samples = max + test;
        cfg.data.dataset.train = max;
        cfg.data.train_samples = Some(size.train);
        cfg.data.test = Some(max..max + test);
        let scale = format!(
            "trained on the first {} poses, tested on poses {max}..{} of one {}-pose trajectory, the same for every size",
            size.train,
            max + test,
            max + test
        );
        cfg.note = if base.note.is_empty() {
            scale
        } else {
            format!("{}; {scale}", base.note)
        };
        cfg.name = format!("{} {}", base.name, size.label);
        // The paper's figures are for its arm: none for another robot (or a dataset file).
        let paper = PaperFigures {
            psnr_db: size.paper_psnr_db.filter(|_| on_papers_setup(&cfg)),
            ..PaperFigures::default()
        };
        let out = run_with(
            &cfg,
            &dir.join(&size.folder),
            opts.device,
            opts.resume,
            |rows, _| {
                rows.iter_mut().for_each(|row| paper.fill(row));
                Ok(())
            },
        )?;
        rows.push(out.result);
    }
    Ok(rows)
}

/// The runs under `dir`: each folder (one or two levels down) with a `results.csv`, its first
/// row and its folder, in the order of `dir/results.csv`'s rows.
fn runs(dir: &Path) -> Result<Vec<(ModelResult, PathBuf)>> {
    let mut found = Vec::new();
    let mut look = |d: &Path| -> Result<()> {
        let csv = d.join("results.csv");
        if d != dir && csv.is_file() {
            if let Some(row) = read_results(&csv)?.into_iter().next() {
                found.push((row, d.to_path_buf()));
            }
        }
        Ok(())
    };
    for entry in subfolders(dir)? {
        look(&entry)?;
        for inner in subfolders(&entry)? {
            look(&inner)?;
        }
    }
    let order: Vec<String> = read_results(&dir.join("results.csv"))?
        .into_iter()
        .map(|r| r.model)
        .collect();
    found.retain(|(row, _)| order.contains(&row.model));
    found.sort_by_key(|(row, _)| order.iter().position(|m| *m == row.model));
    Ok(found)
}

fn subfolders(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    out.sort();
    Ok(out)
}

/// `training_curves.png` (every run's loss, from its `curve.csv`) and, where a model has
/// several sizes, `scaling.png`, from what the runs under `dir` wrote.
pub fn draw(dir: &Path) -> Result<()> {
    let runs = runs(dir)?;
    let mut curves = Vec::new();
    for (row, folder) in &runs {
        let csv = folder.join("curve.csv");
        if csv.is_file() {
            curves.push((row.model.clone(), read_curve(&csv)?));
        }
    }
    training_curves(&dir.join("training_curves.png"), TITLE, &curves)?;
    // One line a model: its name is the row's before the size.
    let mut lines: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for (row, _) in &runs {
        let model = row
            .model
            .rsplitn(3, ' ')
            .nth(2)
            .unwrap_or(&row.model)
            .to_string();
        let point = (row.train_samples as f64, row.psnr_db_test);
        match lines.iter_mut().find(|(m, _)| *m == model) {
            Some((_, points)) => points.push(point),
            None => lines.push((model, vec![point])),
        }
    }
    if lines.iter().any(|(_, p)| p.len() > 1) {
        line_plot(
            &dir.join("scaling.png"),
            TITLE,
            ("training poses (log)", "PSNR on the test poses (dB)"),
            &lines,
            LinePlot::LOG_X,
        )?;
    }
    Ok(())
}
