//! The one harness every self-model runs in: it renders the dataset, trains the model through
//! [`SelfModel::fit`], predicts the test poses in batches, scores them, times inference, and
//! writes the row of Table I ([`ModelResult`]) with its report. A self-model brings only what
//! is its own: its config (with presets), its network and loss, and how it renders.
//!
//! A run writes into its folder: `config.json` (everything that defines it), `results.csv`
//! and `results.md` (one [`ModelResult`] row per renderer), `curve.csv` and `training_curve.png`
//! (the figure where training took more than one step),
//! `qualitative.png` (ground truth, prediction and error for six test poses, plus depth where
//! the model predicts it), and `checkpoint/` (model, optimizer state, progress; `resume`
//! continues).

use std::ops::Range;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};

use crate::core::atomic_file::write_json;
use crate::core::device::DeviceChoice;
use crate::core::error::{Error, Result};
use crate::data::dataset::Dataset;
use crate::eval::evaluation::{Predictions, Quality, score};
use crate::eval::inference_speed::{Timing, measure};
#[cfg(feature = "figures")]
use crate::report::figures::{GridRow, image_grid};
use crate::report::table::{write_csv, write_markdown_report};
use crate::self_models::camera_input::camera_input;
use crate::self_models::model::{Fit, Render, RenderedSet, ReportContext, SelfModel, Trained};
use crate::self_models::result::ModelResult;
use crate::self_models::run_config::SelfModelRun;
use crate::train::{
    batcher::TrainSet, checkpoint::CheckpointPlan, config::TrainLog, trainer::autodiff_device,
};

/// After a run refused its input or failed before training wrote anything: remove the
/// `config.json` it wrote (and the folder, if it made it), so a refused run leaves nothing
/// behind. A run that wrote a checkpoint keeps it (and its config) for `resume`.
fn leave_as_found(dir: &Path, (new_dir, new_config): (bool, bool)) {
    if dir.join("checkpoint").exists() || !new_config {
        return;
    }
    let _ = std::fs::remove_file(dir.join("config.json"));
    if new_dir {
        let _ = std::fs::remove_dir(dir);
    }
}

/// What a run produced.
pub struct RunOutcome {
    /// The first renderer's row and quality.
    pub result: ModelResult,
    pub quality: Quality,
    /// One row per renderer.
    pub rows: Vec<ModelResult>,
    pub log: TrainLog,
}

/// The test set as host arrays: silhouettes in [0, 1] and depth, `[n, H * W]`.
pub(crate) fn host_targets(data: &Dataset, range: &Range<usize>) -> (Vec<f32>, Vec<f32>) {
    let mut sil = Vec::new();
    let mut depth = Vec::new();
    for i in range.clone() {
        sil.extend(data.image(i).iter().map(|&v| v as f32 / 255.0));
        depth.extend_from_slice(data.depth_map(i));
    }
    (sil, depth)
}

/// Upload samples `range` with their host targets (from [`host_targets`]): angles
/// `[n, dof]` (degrees), followed by each sample's [`camera_input`] where `with_camera`
/// (`[n, dof + 9]`); silhouettes and depth `[n, 1, H, W]`.
pub(crate) fn device_set(
    data: &Dataset,
    range: &Range<usize>,
    (sil, depth): (Vec<f32>, Vec<f32>),
    device: &Device,
    with_camera: bool,
) -> TrainSet {
    let n = range.len();
    let width = data.dof() + if with_camera { 9 } else { 0 };
    let (h, w) = (data.height, data.width);
    let inputs: Vec<f32> = range
        .clone()
        .flat_map(|i| {
            let mut row: Vec<f32> = data.angles[i].iter().map(|&a| a as f32).collect();
            if with_camera {
                row.extend(camera_input(&data.camera_of(i)));
            }
            row
        })
        .collect();
    TrainSet {
        inputs: Tensor::from_data(TensorData::new(inputs, [n, width]), device),
        targets: vec![
            Tensor::from_data(TensorData::new(sil, [n, 1, h, w]), device),
            Tensor::from_data(TensorData::new(depth, [n, 1, h, w]), device),
        ],
    }
}

fn to_host(t: Tensor<4>) -> Vec<f32> {
    t.into_data().try_into_vec::<f32>().expect("float tensor")
}

/// Evaluate `predict` over the test set in batches.
fn predict_all(model: &dyn Render, test: &TrainSet, batch: usize, pixels: usize) -> Predictions {
    let n = test.len();
    let mut sil = Vec::with_capacity(n * pixels);
    let mut depth: Option<Vec<f32>> = None;
    let mut start = 0;
    while start < n {
        let end = (start + batch).min(n);
        let q = test.inputs.clone().slice([start..end]);
        let (s, d) = model.render(q);
        sil.extend(to_host(s));
        if let Some(d) = d {
            depth.get_or_insert_with(Vec::new).extend(to_host(d));
        }
        start = end;
    }
    Predictions {
        silhouettes: sil,
        depth,
        pixels,
        depth_pixels: model.depth_pixels(),
    }
}

/// A self-model trained by [`fit_run`] (rendered by `R`), with the data it is scored on.
pub struct Fitted<R> {
    pub trained: Trained<R>,
    /// Per joint input, whether it is rotational (empty where the robot is not the
    /// dataset's).
    pub rotational: Vec<bool>,
    /// Where it renders.
    pub device: Device,
    pub data: crate::data::dataset::Dataset,
    pub train_range: std::ops::Range<usize>,
    pub test_range: std::ops::Range<usize>,
    /// The test poses and targets on `device`.
    pub test_set: TrainSet,
    /// The test silhouettes and depth on the host.
    pub truth: Vec<f32>,
    pub truth_depth: Vec<f32>,
}

impl<R: Render + 'static> Fitted<R> {
    /// The same, its renderers of any kind: for a study that holds models of several kinds
    /// alike.
    pub fn erased(self) -> Fitted<Box<dyn Render>> {
        let Fitted {
            trained,
            rotational,
            device,
            data,
            train_range,
            test_range,
            test_set,
            truth,
            truth_depth,
        } = self;
        let Trained {
            renderers,
            parameters,
            log,
            note,
        } = trained;
        Fitted {
            trained: Trained {
                renderers: renderers
                    .into_iter()
                    .map(|(label, r)| (label, Box::new(r) as Box<dyn Render>))
                    .collect(),
                parameters,
                log,
                note,
            },
            rotational,
            device,
            data,
            train_range,
            test_range,
            test_set,
            truth,
            truth_depth,
        }
    }
}

/// Load `cfg`'s data and train its model on `device_choice`, checkpointing into
/// `checkpoint_dir` (`resume`: continue from there). The first half of [`run`]; the
/// GPU-against-CPU test calls it directly.
pub fn fit_run<M: SelfModel>(
    cfg: &SelfModelRun<M>,
    checkpoint_dir: &Path,
    device_choice: DeviceChoice,
    resume: bool,
) -> Result<Fitted<M::Renderer>> {
    let device = crate::core::device::select(device_choice)?;
    cfg.train.precision.check(&device)?;
    let (robot, data, train_range, test_range) = cfg.data.load_with_robot()?;
    if let Some(dof) = cfg.model.dof()
        && dof != data.dof()
    {
        return Err(Error::Config(format!(
            "{}: the model takes {dof} joint values but the robot has {} (a config for another robot)",
            cfg.name,
            data.dof()
        )));
    }
    let image = cfg.model.image();
    if image != [data.height, data.width] {
        return Err(Error::Config(format!(
            "{}: the model outputs {}x{} images but the dataset has {}x{}{}",
            cfg.name,
            image[0],
            image[1],
            data.height,
            data.width,
            if cfg.data.file.is_some() {
                " (resize the dataset's images to the preset's size: 100x100 for paper and short, 32x32 for quick)"
            } else {
                ""
            }
        )));
    }
    if cfg.model.needs_robot() && robot.dof() != data.dof() {
        return Err(Error::Config(format!(
            "{}: the model hangs on the robot's kinematic chain, but the robot ({}) has {} joints and the dataset {}: give the robot that made the dataset (`urdf`, `tip`)",
            cfg.name,
            cfg.data.robot.label(),
            robot.dof(),
            data.dof()
        )));
    }
    let camera = cfg.data.camera(&data);
    let tdev = autodiff_device(&device, cfg.train.seed);
    // A 3-D model reads the camera where the dataset has several (or one placed by `views`).
    let cameras_in_inputs = cfg.model.camera_input()
        || (cfg.model.renders_any_view() && cfg.data.dataset.views.is_some());
    let train_set = device_set(
        &data,
        &train_range,
        host_targets(&data, &train_range),
        &tdev,
        cameras_in_inputs,
    );
    let (truth, truth_depth) = host_targets(&data, &test_range);
    let test_set = device_set(
        &data,
        &test_range,
        (truth.clone(), truth_depth.clone()),
        &device,
        cameras_in_inputs,
    );
    if resume {
        carry_in(checkpoint_dir)?;
    }
    let plan = CheckpointPlan {
        dir: checkpoint_dir.to_path_buf(),
        resume,
        fingerprint: cfg.model.fingerprint(&cfg.train, &cfg.data),
    };
    let trained = cfg.model.fit(&Fit {
        train_set: &train_set,
        train: &cfg.train,
        plan: &plan,
        label: &cfg.name,
        train_device: &tdev,
        device: &device,
        robot: &robot,
        camera: &camera,
        device_choice,
        cameras_in_inputs,
    })?;
    let rotational = if robot.dof() == data.dof() {
        robot
            .chain
            .movable_joints()
            .map(|j| j.kind.is_rotational())
            .collect()
    } else {
        Vec::new()
    };
    Ok(Fitted {
        trained,
        rotational,
        device,
        data,
        train_range,
        test_range,
        test_set,
        truth,
        truth_depth,
    })
}

/// The committed copy of a checkpoint, beside its git-ignored folder `checkpoint`: a run too
/// long for one sitting whose checkpoint is small (FFKSM's and K-3DGS's, about a megabyte)
/// is carried to the next in git by copying `checkpoint/` to `checkpoint_carried/`.
pub fn carried(checkpoint_dir: &Path) -> PathBuf {
    let name = checkpoint_dir
        .file_name()
        .map_or("checkpoint".into(), |n| n.to_string_lossy().into_owned());
    checkpoint_dir.with_file_name(format!("{name}_carried"))
}

/// Resuming where `checkpoint_dir` is absent (a fresh clone) but its carried copy is
/// committed beside it: copy it in, so training continues from there.
fn carry_in(checkpoint_dir: &Path) -> Result<()> {
    let from = carried(checkpoint_dir);
    if checkpoint_dir.exists() || !from.is_dir() {
        return Ok(());
    }
    copy_checkpoint(&from, checkpoint_dir)?;
    eprintln!("resuming from the carried checkpoint {}", from.display());
    Ok(())
}

/// Copy the checkpoint's files in `from` into the folder `to` (made if absent).
pub fn copy_checkpoint(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to).map_err(|e| Error::io(to, e))?;
    for f in std::fs::read_dir(from).map_err(|e| Error::io(from, e))? {
        let f = f.map_err(|e| Error::io(from, e))?.path();
        if let Some(name) = f.file_name() {
            std::fs::copy(&f, to.join(name)).map_err(|e| Error::io(&f, e))?;
        }
    }
    Ok(())
}

/// With `resume`: refuse a checkpoint in `dir` that another configuration made, or that does
/// not read, before anything is written (a run of several models checks them all first).
pub fn check_resumable<M: SelfModel>(
    cfg: &SelfModelRun<M>,
    dir: &Path,
    resume: bool,
) -> Result<()> {
    if resume {
        carry_in(&dir.join("checkpoint"))?;
    }
    CheckpointPlan {
        dir: dir.join("checkpoint"),
        resume,
        fingerprint: cfg.model.fingerprint(&cfg.train, &cfg.data),
    }
    .check()
}

/// Train, evaluate, time and report one self-model into `dir` ([`run_with`], nothing added).
pub fn run<M: SelfModel>(
    cfg: &SelfModelRun<M>,
    dir: &Path,
    device_choice: DeviceChoice,
    resume: bool,
) -> Result<RunOutcome> {
    run_with(cfg, dir, device_choice, resume, |_, _| Ok(()))
}

/// Train, evaluate, time and report one self-model into `dir`; `study` sees the run once it
/// is evaluated and before its rows are written: it may add to the rows (reference columns,
/// a note, a flag) and write reports of its own from the trained renderers
/// ([`ReportContext::renderers`]).
pub fn run_with<M: SelfModel>(
    cfg: &SelfModelRun<M>,
    dir: &Path,
    device_choice: DeviceChoice,
    resume: bool,
    study: impl FnOnce(&mut [ModelResult], &ReportContext<M::Renderer>) -> Result<()>,
) -> Result<RunOutcome> {
    // Settings that can never render are refused before anything is written.
    if cfg.data.file.is_none() {
        cfg.data.dataset.validate()?;
    }
    let config = dir.join("config.json");
    let fresh = (!dir.exists(), !config.exists());
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&config, cfg)?;
    // Read the revision now: a run that spans commits is the code it started with.
    let git_revision = crate::core::provenance::git_revision();
    let fitted = fit_run(cfg, &dir.join("checkpoint"), device_choice, resume);
    if fitted.is_err() {
        leave_as_found(dir, fresh);
    }
    let fitted = fitted?;
    let run = Evaluation {
        device_choice,
        git_revision: &git_revision,
    };
    let mut rows = Vec::new();
    let mut qualities = Vec::new();
    let mut rendered: Vec<RenderedSet> = Vec::new();
    for (label, renderer) in &fitted.trained.renderers {
        let (row, quality, set) = run.evaluate(cfg, &fitted, label, renderer);
        rows.push(row);
        qualities.push(quality);
        rendered.push(set);
    }
    let data = &fitted.data;
    let truth: (&[f32], &[f32]) = (&fitted.truth, &fitted.truth_depth);
    let ctx = ReportContext {
        dir,
        name: &cfg.name,
        spec: &cfg.data,
        data,
        test: &fitted.test_range,
        truth,
        rendered: &rendered,
        paper_subset: cfg.paper_subset,
        device: &fitted.device,
        git_revision: &git_revision,
        device_name: device_choice.to_string(),
        preset: &cfg.preset,
        renderers: &fitted.trained.renderers,
    };
    study(&mut rows, &ctx)?;
    let log = &fitted.trained.log;
    write_report(dir, cfg, &rows, log)?;
    save_model(cfg, dir, &fitted, &rendered[0], &rows[0], &git_revision)?;
    #[cfg(feature = "figures")]
    qualitative_figure(
        &dir.join("qualitative.png"),
        truth.0,
        truth.1,
        &rendered[0].predictions,
        [data.height, data.width],
    )?;
    let (result, quality) = (rows[0].clone(), qualities.swap_remove(0));
    Ok(RunOutcome {
        result,
        quality,
        rows,
        log: fitted.trained.log,
    })
}

/// Where and from which revision a run's rows are measured.
struct Evaluation<'a> {
    device_choice: DeviceChoice,
    git_revision: &'a str,
}

impl Evaluation<'_> {
    /// One trained renderer (`label`: its variant, empty for the model itself) on the test
    /// set: its row of the results, its scores and its predictions with their timings.
    fn evaluate<M: SelfModel>(
        &self,
        cfg: &SelfModelRun<M>,
        fitted: &Fitted<M::Renderer>,
        label: &str,
        renderer: &dyn Render,
    ) -> (ModelResult, Quality, RenderedSet) {
        let (data, trained) = (&fitted.data, &fitted.trained);
        let pixels = data.height * data.width;
        let predictions = predict_all(renderer, &fitted.test_set, cfg.eval_batch, pixels);
        let timings = measure(
            |q| renderer.render(q).0,
            data.dof(),
            &fitted.device,
            &cfg.speed,
        );
        let quality = score(
            &predictions,
            &fitted.truth,
            Some(&fitted.truth_depth),
            cfg.paper_subset,
        );
        let untimed = |batch| Timing {
            batch,
            median_s: f64::NAN,
            repeats: 0,
        };
        let t1 = timings
            .iter()
            .find(|t| t.batch == 1)
            .cloned()
            .unwrap_or(untimed(1));
        // The largest batch timed (none beyond batch 1: not measured).
        let tb = timings
            .iter()
            .filter(|t| t.batch > 1)
            .max_by_key(|t| t.batch)
            .cloned()
            .unwrap_or(untimed(0));
        let predicts_depth = predictions.depth.is_some();
        let log = &trained.log;
        let row = ModelResult {
            model: if label.is_empty() {
                cfg.name.clone()
            } else {
                format!("{} ({label})", cfg.name)
            },
            dataset: cfg.data.label().into(),
            preset: cfg.preset.clone(),
            device: self.device_choice.to_string(),
            precision: cfg.train.precision,
            schedule: cfg.train.schedule,
            git_revision: self.git_revision.into(),
            parameters: trained.parameters,
            train_samples: fitted.train_range.len(),
            train_steps: log.step,
            batch: cfg.train.batch,
            train_time_s: log.train_seconds,
            train_img_per_s: log.images_per_second(),
            psnr_db_first100: quality.psnr_db_paper_subset,
            psnr_db_test: quality.psnr_db_test,
            iou_test: quality.iou_test,
            depth_mae_mm: quality.depth_mae_mm.filter(|_| predicts_depth),
            depth_constant_mae_mm: quality.depth_constant_mae_mm.filter(|_| predicts_depth),
            infer_b1_img_per_s: t1.images_per_second(),
            latency_b1_ms: 1000.0 * t1.median_s,
            infer_b256_img_per_s: tb.images_per_second(),
            paper_psnr_db: None,
            paper_fps: None,
            paper_latency_ms: None,
            paper_train_time_s: None,
            note: [
                trained.note.as_str(),
                cfg.note.as_str(),
                &cfg.train.precision.note(),
            ]
            .iter()
            .filter(|n| !n.is_empty())
            .copied()
            .collect::<Vec<_>>()
            .join("; "),
            steps_override: cfg.steps_override,
            lower_bound: false,
        };
        let set = RenderedSet {
            label: label.to_string(),
            predictions,
            timings,
        };
        (row, quality, set)
    }
}

/// The trained model saved into `dir/model` (its configuration, weights and a probe of test
/// poses with what this run predicted for them), for `SelfModel.load` to answer as it did.
fn save_model<M: SelfModel>(
    cfg: &SelfModelRun<M>,
    dir: &Path,
    fitted: &Fitted<M::Renderer>,
    first: &RenderedSet,
    row: &ModelResult,
    git_revision: &str,
) -> Result<()> {
    crate::self_models::saved::save(
        &dir.join("model"),
        &crate::self_models::saved::ToSave {
            kind: M::KIND,
            model: serde_json::to_value(&cfg.model).expect("a model configuration serialises"),
            name: &cfg.name,
            save_weights: &|path| fitted.trained.renderers[0].1.save(path),
            camera: cfg.data.camera(&fitted.data),
            rotational: fitted.rotational.clone(),
            data: &fitted.data,
            data_fingerprint: cfg.data.fingerprint(),
            test_inputs: &fitted.test_set.inputs,
            predictions: &first.predictions,
            psnr_db_test: row.psnr_db_test,
            iou_test: row.iou_test,
            preset: &cfg.preset,
            git_revision,
        },
    )?;
    Ok(())
}

fn write_report<M>(
    dir: &Path,
    cfg: &SelfModelRun<M>,
    rows: &[ModelResult],
    log: &TrainLog,
) -> Result<()> {
    let row = &rows[0];
    let csv_path = dir.join("results.csv");
    write_csv(&csv_path, rows)?;
    write_markdown_report(
        &csv_path,
        &format!(
            "{} ({} preset, {} dataset)",
            cfg.name,
            cfg.preset,
            cfg.data.label()
        ),
        &format!(
            "{} steps of batch {} ({:.1} epochs); PSNR per image as the paper computes it, on the first {} test images and on all {}; IoU at threshold 0.5. `paper_*` columns are the paper's published figures, for reference (its FPS was training throughput). Config: `config.json`.{}",
            row.train_steps,
            row.batch,
            cfg.train.epochs(row.train_samples),
            cfg.paper_subset,
            cfg.data
                .test
                .as_ref()
                .map(|r| r.len())
                .unwrap_or(cfg.data.dataset.samples - cfg.data.dataset.train),
            if row.note.is_empty() {
                String::new()
            } else {
                format!(" Note: {}", row.note)
            }
        ),
    )?;
    crate::report::table::write_training_curve(dir, &cfg.name, log)
}

/// Six test poses spread over the test set: ground truth, prediction, error (and true depth,
/// and predicted depth where the predicted silhouette is the robot).
#[cfg(feature = "figures")]
pub(crate) fn qualitative_figure(
    path: &Path,
    truth: &[f32],
    truth_depth: &[f32],
    pred: &Predictions,
    size: [usize; 2],
) -> Result<()> {
    let px = size[0] * size[1];
    let picks = grid_picks(truth.len() / px);
    let gt: Vec<&[f32]> = picks.iter().map(|&i| nth_image(truth, i, px)).collect();
    let pr: Vec<&[f32]> = picks
        .iter()
        .map(|&i| nth_image(&pred.silhouettes, i, px))
        .collect();
    let err: Vec<Vec<f32>> = gt
        .iter()
        .zip(&pr)
        .map(|(g, p)| g.iter().zip(p.iter()).map(|(a, b)| (a - b).abs()).collect())
        .collect();
    // The depth head is trained on robot pixels only: show it where the predicted silhouette
    // says robot, background elsewhere.
    let masked_depth: Vec<Vec<f32>> = match &pred.depth {
        Some(d) => picks
            .iter()
            .map(|&i| {
                let sil = nth_image(&pred.silhouettes, i, px);
                nth_image(d, i, px)
                    .iter()
                    .zip(sil)
                    .map(|(&d, &s)| if s >= 0.5 { d } else { 0.0 })
                    .collect()
            })
            .collect(),
        None => Vec::new(),
    };
    // Under each column: that sample's PSNR and IoU.
    let captions: Vec<String> = gt
        .iter()
        .zip(&pr)
        .map(|(g, p)| {
            format!(
                "{:.1} dB, IoU {:.2}",
                crate::eval::evaluation::psnr_db(p, g),
                crate::eval::evaluation::iou(p, g)
            )
        })
        .collect();
    let mut titles = vec!["truth", "prediction", "|error|"];
    let mut rows = vec![GridRow::Grey(gt), GridRow::Grey(pr), GridRow::Error(err)];
    if pred.depth.is_some() {
        let robot: Vec<f32> = truth_depth.iter().copied().filter(|&v| v > 0.0).collect();
        let lo = robot.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = robot.iter().copied().fold(0.0, f32::max);
        let range = if lo.is_finite() { [lo, hi] } else { [0.5, 1.5] };
        rows.push(GridRow::Depth(
            picks
                .iter()
                .map(|&i| nth_image(truth_depth, i, px))
                .collect(),
            range,
        ));
        rows.push(GridRow::Depth(
            masked_depth.iter().map(|v| v.as_slice()).collect(),
            range,
        ));
        titles.extend(["true depth", "predicted depth"]);
    }
    image_grid(path, &rows, &titles, &captions, size[1], size[0], 2)
}

/// Image `i` of a stack of `px`-pixel images.
#[cfg(feature = "figures")]
pub fn nth_image(v: &[f32], i: usize, px: usize) -> &[f32] {
    &v[i * px..(i + 1) * px]
}

/// The (at most) six samples of `n` a qualitative grid shows, spread evenly.
#[cfg(feature = "figures")]
pub fn grid_picks(n: usize) -> Vec<usize> {
    (0..6.min(n)).map(|k| k * n / 6.min(n).max(1)).collect()
}
