//! FFKSM, the occupancy-field self-model (self-modeling paper section IV-B; Hu, Lin, Lipson
//! 2024): training with the centre-crop curriculum, evaluation with both ray marchers, novel
//! views and depth. The logic behind the `ffksm` binary and FFKSM's rows of `table1`.
//!
//! Training (the reimplementation's code): one image per step, all its rays (10,000 for
//! 100x100) marched densely with stratified samples, plain MSE between the rendered pixels and
//! the silhouette (a robot-pixel weight is an option: the paper's text says 5, its code used
//! none), Adam 5e-4 for 8,000 steps, and for the first 500 steps only the central 50x50
//! pixels (the curriculum). The original authors' variant crops for 200 steps and restarts
//! with a fresh model when training collapses to an all-black image (their code restarted
//! when the validation loss stopped changing, which is what an all-black model does).
//!
//! A run writes into its folder: `config.json`, `results.csv`/`results.md` (one row per
//! renderer: dense marching and the accelerated marcher, the same trained model),
//! `renderers.csv` (evaluations per image, images/s, PSNR, and the accelerated image's PSNR
//! against the dense one), `novel_views.csv` (cameras turned about the vertical through the
//! point they look at, against the simulator's images from there), `curve.csv` and `training_curve.png`, `qualitative.png`,
//! `novel_views.png`, and `checkpoint/`.

pub mod accelerated_marcher;
pub mod dense_step;
pub mod encoding;
pub mod field;
pub mod grid;
pub mod marcher;
pub mod virtual_frame;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};

use crate::core::atomic_file::write_json;
use crate::core::device::DeviceChoice;
use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::data::dataset::Dataset;
use crate::eval::evaluation::DepthPixels;
use crate::eval::evaluation::{Predictions, Quality, iou, psnr_db, score};
use crate::eval::inference_speed::SpeedConfig;
use crate::report::figures::{GridRow, image_grid};
use crate::report::table::write_table;
use crate::self_models::ffksm::accelerated_marcher::{
    AcceleratedConfig, render_accelerated, render_silhouette_skipping,
};
use crate::self_models::ffksm::dense_step::dense_step;
use crate::self_models::ffksm::field::{OccupancyField, OccupancyFieldConfig};
use crate::self_models::ffksm::marcher::{MarchConfig, render_dense, render_silhouette};
use crate::self_models::ffksm::virtual_frame::{JointsFrame, VirtualFrame};
use crate::self_models::result::PaperReference;
use crate::self_models::{
    camera_input::views_of_rows,
    data_spec::DataSpec,
    harness::{grid_picks, host_targets, nth_image},
    model::{Fit, Render, ReportContext, SelfModel, Trained},
    run_config::SelfModelRun,
};
use crate::sim::camera::Camera;
use crate::sim::robot::Robot;
use crate::train::{
    config::{TrainConfig, TrainLog},
    hooks::Watch,
    trainer::{StepLoss, Trainer},
};

/// Train on the central `crop x crop` pixels for the first `steps` steps.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Curriculum {
    pub steps: usize,
    pub crop: usize,
}

/// Restart with a fresh model when the rendered centre of the first training image is all
/// black (every pixel below 1e-3), checked every `every` steps up to step `until`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CollapseRestart {
    pub every: usize,
    pub until: usize,
    pub max_restarts: usize,
}

/// How training renders its rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainMarcher {
    /// Every sample of every ray (the paper's: 640,000 evaluations per 100x100 image).
    #[default]
    Dense,
    /// Only samples in occupied cells of the per-pose grid (`accelerated.grid`), rebuilt
    /// from the current model at every step (beyond the paper).
    Skipping,
}

/// How a dense training step's gradients are computed. Both give the same gradients
/// (`tests/ffksm.rs` compares them); they differ in speed.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DenseGradients {
    /// The hand-written step of [`crate::self_models::ffksm::dense_step`] on the CPU backends (2-3x
    /// burn's graph on 2 cores, `bench_ffksm_step`); burn's autodiff on a GPU.
    #[default]
    HandWrittenOnCpu,
    /// burn's autodiff through the dense marcher everywhere (the reference).
    Autodiff,
}

/// FFKSM's model and how it trains (the run around it: [`SelfModelRun`], from [`ffksm_run`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Ffksm {
    pub field: OccupancyFieldConfig,
    pub march: MarchConfig,
    pub accelerated: AcceleratedConfig,
    pub curriculum: Curriculum,
    #[serde(default)]
    pub train_marcher: TrainMarcher,
    /// How dense steps are differentiated (not part of a checkpoint's fingerprint: both paths
    /// compute the same gradients, so a run may resume on the other).
    #[serde(default)]
    pub dense_gradients: DenseGradients,
    /// MSE weight of robot pixels (1: the code's plain MSE; the text's 5).
    pub robot_weight: f64,
    pub restart: Option<CollapseRestart>,
    /// Novel views: the training camera orbited about the world z axis by these angles (deg).
    pub novel_views_deg: Vec<f64>,
    /// Rays per network call when marching densely.
    pub chunk_rays: usize,
    /// After the curriculum, train each step on this many pixels drawn at random (seeded by
    /// the step) instead of the whole image (NeRF-style ray batches; none: every pixel, the
    /// papers').
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rays_per_step: Option<usize>,
    /// Output image size `[height, width]`.
    pub image: [usize; 2],
    /// Also render with dense marching (the paper's renderer, the accelerated marcher's
    /// reference, ~1 s an image) and write the renderer comparison and novel views; off in the
    /// `short` preset, which shows the accelerated marcher's row only.
    #[serde(default = "yes")]
    pub reference_renderers: bool,
    /// World metres per field unit: the field learns the scene shrunk by this about the
    /// origin (1 for the papers' arm; set by `fit` for a robot framed automatically, so the
    /// field's inputs span what they span for the papers' arm). Derived from the data, so
    /// neither saved nor fingerprinted.
    #[serde(skip, default = "unit_scale")]
    pub scene_scale: f64,
}

fn unit_scale() -> f64 {
    1.0
}

fn yes() -> bool {
    true
}

/// The three FFKSM models of Table I.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FfksmVariant {
    /// The reimplementation (the paper preset = its code).
    Reimplementation,
    /// The original authors' model: L = 10, the shorter predictive module, their virtual
    /// frame, a 200-step curriculum and restarts on collapse.
    Original,
    /// The reimplementation trained with empty-space skipping (beyond the paper): the same
    /// model, data and schedule, each step marching only the samples in occupied cells of a
    /// grid probed from the current model.
    Skipping,
}

impl FfksmVariant {
    /// Every variant with its folder name.
    pub const ALL: [(&str, FfksmVariant); 3] = [
        ("ffksm", FfksmVariant::Reimplementation),
        ("ffksm_original", FfksmVariant::Original),
        ("ffksm_skipping", FfksmVariant::Skipping),
    ];

    /// The variants a run trains: on the papers' arm all three, but under `short` (the few
    /// minutes of the main command) only the one that learns in that time, the original
    /// model. On any other robot only the original model, at every preset: the
    /// reimplementation and its skipping variant reproduce the paper's FFKSM figure on the
    /// papers' arm (17.35 dB), the original model is the best FFKSM (21.8 dB against 17.9 on
    /// that arm), and each of the others would add about two hours of training on 2 cores.
    pub fn of_run(preset: &str, papers_arm: bool) -> &'static [(&'static str, FfksmVariant)] {
        if preset == "short" || !papers_arm {
            &Self::ALL[1..2]
        } else {
            &Self::ALL
        }
    }
}

impl PaperReference {
    /// FFKSM in the paper: 17.35 dB at 5.22 FPS (191.6 ms) on a T4, ~50 minutes of training.
    pub fn ffksm() -> Self {
        PaperReference {
            psnr_db: Some(17.35),
            fps: Some(5.22),
            latency_ms: Some(191.6),
            train_time_s: Some(3000.0),
        }
    }

    /// The original authors' model: their logs correspond to about 23.4 dB (12,000 samples,
    /// far longer training); no speed was published with it.
    pub fn ffksm_original() -> Self {
        PaperReference {
            psnr_db: Some(23.4),
            ..Default::default()
        }
    }
}

/// Training steps of the `short` preset (the main command's few minutes).
const SHORT_STEPS: usize = 300;
/// Pixels per training step of the `short` preset (of 10,000).
const SHORT_RAYS: usize = 1500;
/// Test images the `short` preset scores (the accelerated marcher: ~0.1 s an image).
const SHORT_TEST_IMAGES: usize = 20;

/// An FFKSM run on `preset`: `paper`, `short` (the paper's model and data, trained on
/// [`SHORT_RAYS`] random pixels a step for [`SHORT_STEPS`] steps and scored on [`SHORT_TEST_IMAGES`] test images, for
/// the main command), `quick` (tiny, seconds; 24 test images).
pub fn ffksm_run(preset: &str, variant: FfksmVariant) -> Result<SelfModelRun<Ffksm>> {
    let quick = preset == "quick";
    let mut model = Ffksm {
        field: if quick {
            OccupancyFieldConfig::quick()
        } else {
            OccupancyFieldConfig::paper()
        },
        march: if quick {
            MarchConfig {
                samples: 32,
                ..MarchConfig::paper()
            }
        } else {
            MarchConfig::paper()
        },
        accelerated: AcceleratedConfig::paper(),
        curriculum: Curriculum {
            steps: if quick { 50 } else { 500 },
            crop: if quick { 16 } else { 50 },
        },
        train_marcher: TrainMarcher::Dense,
        dense_gradients: DenseGradients::default(),
        robot_weight: 1.0,
        restart: None,
        novel_views_deg: vec![30.0, 60.0],
        chunk_rays: 2048,
        rays_per_step: None,
        image: SelfModelRun::<Ffksm>::image(preset)?,
        reference_renderers: preset != "short",
        scene_scale: 1.0,
    };
    if quick {
        model.accelerated.grid.block = 2;
    }
    let mut run = SelfModelRun::new(preset, "FFKSM", model, 16, PaperReference::ffksm())?;
    run.train = TrainConfig {
        steps: if quick { 400 } else { 8000 },
        batch: 1,
        learning_rate: if quick { 5e-3 } else { 5e-4 },
        grad_clip_norm: None,
        input_noise: 0.0,
        seed: 0,
        checkpoint_every: if quick { 100 } else { 250 },
        log_every: 0,
    };
    // Rendering is per image: timed at batch 1 (median of 3 after one warm-up image).
    run.speed = SpeedConfig {
        warmup: 1,
        min_repeats: 3,
        min_seconds: 0.0,
        batches: vec![1],
    };
    let mut test_images = quick.then_some(24);
    if preset == "short" {
        run.train.steps = SHORT_STEPS;
        run.model.curriculum.steps = SHORT_STEPS / 4;
        run.model.rays_per_step = Some(SHORT_RAYS);
        test_images = Some(SHORT_TEST_IMAGES);
        run.note = format!(
            "short preset: {SHORT_STEPS} steps instead of 8,000, each on {SHORT_RAYS} random pixels after the crop curriculum, scored on the first {SHORT_TEST_IMAGES} test images, rendered by the accelerated marcher only (CPU time budget)"
        );
    }
    // Dense marching of the paper preset costs ~1 s per image on a 2-core CPU.
    if let Some(k) = test_images {
        let start = run.data.dataset.train;
        run.data.test = Some(start..start + k.min(run.data.dataset.samples - start));
    }
    match variant {
        FfksmVariant::Reimplementation => {}
        FfksmVariant::Original => {
            run.name = "FFKSM (original model)".into();
            let m = &mut run.model;
            m.field = if quick {
                OccupancyFieldConfig {
                    bands: 5,
                    ..OccupancyFieldConfig::quick()
                }
            } else {
                OccupancyFieldConfig::original()
            };
            m.field.relu_before_output = false;
            m.field.virtual_frame =
                crate::self_models::ffksm::virtual_frame::VirtualFrame::Original;
            m.curriculum.steps = m.curriculum.steps * 2 / 5;
            m.restart = Some(CollapseRestart {
                every: if quick { 25 } else { 100 },
                until: m.curriculum.steps * 5,
                max_restarts: 5,
            });
            run.reference = PaperReference::ffksm_original();
        }
        FfksmVariant::Skipping => {
            run.name = "FFKSM (trained with skipping)".into();
            run.model.train_marcher = TrainMarcher::Skipping;
        }
    }
    Ok(run)
}

/// Row-major indices of the central `crop x crop` pixels of a `height x width` image.
pub fn centre_crop(height: usize, width: usize, crop: usize) -> Vec<usize> {
    let (ch, cw) = (crop.min(height), crop.min(width));
    let (r0, c0) = ((height - ch) / 2, (width - cw) / 2);
    (r0..r0 + ch)
        .flat_map(|r| (c0..c0 + cw).map(move |c| r * width + c))
        .collect()
}

/// User units (degrees; metres for a prismatic joint) to the field's SI units.
fn radians(angles_deg: &[f32], chain: &crate::sim::kinematics::KinematicChain) -> Vec<f64> {
    let user: Vec<f64> = angles_deg.iter().map(|&v| v as f64).collect();
    chain.to_si(&user)
}

/// The weighted MSE of `pred` `[rays]` against `truth` (host, `[rays]` in [0, 1]):
/// `mean(w (pred − truth)²)` with `w = robot_weight` on robot pixels, 1 elsewhere (the
/// paper's equation 10).
pub fn weighted_mse(pred: Tensor<1>, truth: &[f32], robot_weight: f64) -> Tensor<1> {
    let device = pred.device();
    let n = truth.len();
    let weights: Vec<f32> = truth
        .iter()
        .map(|&t| if t >= 0.5 { robot_weight as f32 } else { 1.0 })
        .collect();
    let t = Tensor::<1>::from_data(TensorData::new(truth.to_vec(), [n]), &device);
    let w = Tensor::<1>::from_data(TensorData::new(weights, [n]), &device);
    ((pred - t).square() * w).mean()
}

/// Dense marching against the accelerated marcher, the same model and test images.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RendererRow {
    pub model: String,
    pub renderer: String,
    pub test_images: usize,
    /// Mean network evaluations per image (the accelerated marcher's include its grid).
    pub evaluations_per_image: f64,
    pub grid_evaluations_per_image: f64,
    /// Mean fraction of grid cells occupied (1 for dense marching, which has no grid).
    pub grid_occupancy: f64,
    /// Dense evaluations per image divided by this renderer's.
    pub fewer_evaluations: f64,
    pub img_per_s: f64,
    pub psnr_db_test: f64,
    pub iou_test: f64,
    /// PSNR of this renderer's images against dense marching's (infinite for dense itself).
    pub psnr_db_vs_dense: f64,
    pub depth_mae_mm: Option<f64>,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// Quality from a camera the model was never trained on.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct NovelViewRow {
    pub model: String,
    /// Camera orbited about the world z axis by this angle (0: the training camera).
    pub yaw_deg: f64,
    pub test_images: usize,
    pub psnr_db: f64,
    pub iou: f64,
    pub depth_mae_mm: Option<f64>,
    /// A view-blind model's score: the training camera's true silhouette offered as the
    /// prediction for this camera (what a 2-D decoder such as NeuroKin can at best output).
    pub view_blind_psnr_db: f64,
    pub view_blind_iou: f64,
    pub renderer: String,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// Images rendered by one renderer, with per-image evaluations and seconds.
struct Rendered {
    predictions: Predictions,
    evaluations: Vec<usize>,
    grid_evaluations: Vec<usize>,
    grid_occupancy: Vec<f64>,
    seconds: Vec<f64>,
}

impl Rendered {
    fn empty() -> Self {
        Rendered {
            predictions: Predictions {
                silhouettes: Vec::new(),
                depth: Some(Vec::new()),
                pixels: 0,
                depth_pixels: DepthPixels::Drawn,
            },
            evaluations: Vec::new(),
            grid_evaluations: Vec::new(),
            grid_occupancy: Vec::new(),
            seconds: Vec::new(),
        }
    }

    /// Append `other`'s images.
    fn extend(&mut self, other: Rendered) {
        self.predictions.pixels = other.predictions.pixels;
        self.predictions
            .silhouettes
            .extend(other.predictions.silhouettes);
        if let (Some(d), Some(o)) = (self.predictions.depth.as_mut(), other.predictions.depth) {
            d.extend(o);
        }
        self.evaluations.extend(other.evaluations);
        self.grid_evaluations.extend(other.grid_evaluations);
        self.grid_occupancy.extend(other.grid_occupancy);
        self.seconds.extend(other.seconds);
    }

    /// The first `n` images (the test set: the harness renders it before it times).
    fn first(&self, n: usize) -> Rendered {
        let px = self.predictions.pixels;
        let n = n.min(self.evaluations.len());
        Rendered {
            predictions: Predictions {
                silhouettes: self.predictions.silhouettes[..n * px].to_vec(),
                depth: self
                    .predictions
                    .depth
                    .as_ref()
                    .map(|d| d[..n * px].to_vec()),
                pixels: px,
                depth_pixels: self.predictions.depth_pixels,
            },
            evaluations: self.evaluations[..n].to_vec(),
            grid_evaluations: self.grid_evaluations[..n].to_vec(),
            grid_occupancy: self.grid_occupancy[..n].to_vec(),
            seconds: self.seconds[..n].to_vec(),
        }
    }

    fn mean_evaluations(&self) -> f64 {
        self.evaluations.iter().sum::<usize>() as f64 / self.evaluations.len().max(1) as f64
    }

    /// Images per second from the median time per image, the first (warm-up) left out.
    fn images_per_second(&self) -> f64 {
        let t: Vec<f64> = self.seconds.iter().skip(1).copied().collect();
        let t = if t.is_empty() { &self.seconds } else { &t };
        1.0 / crate::core::timing::median(t).max(1e-12)
    }
}

/// Render every pose of `angles_deg` (`[n][dof]`, degrees) from `camera`, densely (`None`) or
/// with the accelerated marcher.
fn render_all(
    field: &OccupancyField,
    robot: &Robot,
    camera: &Camera,
    angles_deg: &[Vec<f64>],
    cfg: &Ffksm,
    accelerated: Option<&AcceleratedConfig>,
    device: &Device,
    label: &str,
) -> Rendered {
    let camera = &cfg.field_camera(camera);
    let pixels = camera.width * camera.height;
    let all: Vec<usize> = (0..pixels).collect();
    let mut out = Rendered {
        predictions: Predictions {
            silhouettes: Vec::new(),
            depth: Some(Vec::new()),
            pixels,
            depth_pixels: crate::eval::evaluation::DepthPixels::Drawn,
        },
        evaluations: Vec::new(),
        grid_evaluations: Vec::new(),
        grid_occupancy: Vec::new(),
        seconds: Vec::new(),
    };
    let bar = crate::core::progress::progress_bar(angles_deg.len() as u64, label, "images");
    for a in angles_deg {
        let a32: Vec<f32> = a.iter().map(|&v| v as f32).collect();
        let radians = radians(&a32, &robot.chain);
        let view = (camera, radians.as_slice());
        let t0 = Instant::now();
        let (sil, depth, evals, grid, occupancy) = if let Some(acc) = accelerated {
            let img = render_accelerated(field, view, &cfg.march, acc, device);
            (
                img.silhouette,
                img.depth,
                img.evaluations,
                img.grid_evaluations,
                img.grid_occupancy,
            )
        } else {
            let (s, d, e) =
                render_dense(field, view, &all, &cfg.march, None, cfg.chunk_rays, device);
            let host = |t: Tensor<1>| t.into_data().try_into_vec::<f32>().expect("float");
            (host(s), host(d), e, 0, 1.0)
        };
        out.seconds.push(t0.elapsed().as_secs_f64());
        out.predictions.silhouettes.extend(sil);
        if let Some(d) = out.predictions.depth.as_mut() {
            if cfg.scene_scale == 1.0 {
                d.extend(depth);
            } else {
                d.extend(depth.iter().map(|&v| v * cfg.scene_scale as f32));
            }
        }
        out.evaluations.push(evals);
        out.grid_evaluations.push(grid);
        out.grid_occupancy.push(occupancy);
        bar.inc(1);
    }
    bar.finish_and_clear();
    out
}

/// Mean PSNR of `a` against `b`, image by image (`pixels` each).
fn mean_psnr(a: &[f32], b: &[f32], pixels: usize) -> f64 {
    let n = a.len() / pixels.max(1);
    (0..n)
        .map(|i| {
            psnr_db(
                &a[i * pixels..(i + 1) * pixels],
                &b[i * pixels..(i + 1) * pixels],
            )
        })
        .sum::<f64>()
        / n.max(1) as f64
}

fn mean_iou(a: &[f32], b: &[f32], pixels: usize) -> f64 {
    let n = a.len() / pixels.max(1);
    (0..n)
        .map(|i| {
            iou(
                &a[i * pixels..(i + 1) * pixels],
                &b[i * pixels..(i + 1) * pixels],
            )
        })
        .sum::<f64>()
        / n.max(1) as f64
}

/// What a checkpoint must match to be resumed: everything that shapes training except the
/// step count (step `k` draws the same image and samples whatever the total, so a longer run
/// continues a shorter one: `--steps 2000` then `--resume` to the preset's 8,000).
fn fingerprint(cfg: &Ffksm, train: &TrainConfig, data: &DataSpec) -> serde_json::Value {
    let mut train = serde_json::to_value(train).expect("serialisable");
    if let Some(t) = train.as_object_mut() {
        t.remove("steps");
    }
    let mut print = serde_json::json!({"field": cfg.field, "march": cfg.march, "train": train, "curriculum": cfg.curriculum, "robot_weight": cfg.robot_weight, "data": data.fingerprint()});
    // A scene other than the papers' gets the robot's own virtual frame (`fitted_to_scene`):
    // checkpoints trained before with the paper's frame must not resume into it.
    let papers_scene = data.robot == crate::sim::robots::RobotSpec::default()
        && data.configured_camera() == Some(&Camera::paper());
    if !papers_scene {
        print["virtual_frame"] = serde_json::json!("the robot's first two joints");
    }
    // Only when it is not the default, so checkpoints from before the option still resume.
    if cfg.train_marcher != TrainMarcher::Dense {
        print["train_marcher"] = serde_json::json!(cfg.train_marcher);
    }
    print
}

/// A count a run keeps beside its checkpoint (JSON): `None` when the file is not there; an
/// error naming it when it is there but damaged (a resumed run would report wrong counts).
fn read_kept<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>> {
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map(Some).map_err(|e| {
        Error::data(
            path,
            format!(
                "damaged ({e}); delete the checkpoint folder it sits in and train again without --resume"
            ),
        )
    })
}

/// What every training step of the field reads (the training set on the host, read once: a
/// step finds its image's angles, camera and pixels there by the batch's indices rather than
/// reading its batch back from the device) and the counts it keeps, so a resumed run reports
/// all its steps.
struct FieldSteps<'a> {
    cfg: &'a Ffksm,
    fit: &'a Fit<'a>,
    hand_written: bool,
    /// The curriculum's centre crop, and every pixel.
    crop: Vec<usize>,
    all: Vec<usize>,
    host_inputs: Vec<f32>,
    host_targets: Vec<f32>,
    columns: usize,
    pixels_per_image: usize,
    /// Network evaluations and steps of training so far.
    evaluations: std::cell::Cell<usize>,
    steps: std::cell::Cell<usize>,
}

impl<'a> FieldSteps<'a> {
    fn new(cfg: &'a Ffksm, fit: &'a Fit<'a>, hand_written: bool, earlier: [usize; 2]) -> Self {
        let camera = cfg.field_camera(fit.camera);
        let (h, w) = (camera.height, camera.width);
        // FFKSM trains without input noise, so these are the batch's inputs.
        debug_assert_eq!(fit.train.input_noise, 0.0);
        let host = |t: Tensor<2>| {
            t.into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .expect("float")
        };
        let train_set = fit.train_set;
        let host_targets = host(train_set.targets[0].clone().flatten::<2>(1, 3));
        FieldSteps {
            cfg,
            fit,
            hand_written,
            crop: centre_crop(h, w, cfg.curriculum.crop),
            all: (0..h * w).collect(),
            host_inputs: host(train_set.inputs.clone()),
            columns: train_set.inputs.dims()[1],
            pixels_per_image: host_targets.len() / train_set.len().max(1),
            host_targets,
            evaluations: std::cell::Cell::new(earlier[0]),
            steps: std::cell::Cell::new(earlier[1]),
        }
    }

    /// The pixels step `step` trains on: the centre crop during the curriculum, then
    /// `rays_per_step` drawn at random (seeded by the step) or every pixel.
    fn pixels(&self, step: usize) -> std::borrow::Cow<'_, [usize]> {
        let train = self.fit.train;
        if step < self.cfg.curriculum.steps {
            std::borrow::Cow::Borrowed(&self.crop)
        } else if let Some(n) = self.cfg.rays_per_step.filter(|&n| n < self.all.len()) {
            use rand::SeedableRng;
            use rand::seq::IndexedRandom;
            let mut rng = rand::rngs::StdRng::seed_from_u64(
                train.seed ^ (step as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
            );
            std::borrow::Cow::Owned(self.all.sample(&mut rng, n).copied().collect())
        } else {
            std::borrow::Cow::Borrowed(&self.all)
        }
    }

    /// One step's loss: one image (its joint angles, then on multi-view data its camera), its
    /// pixels marched densely (our hand-written backward pass where asked) or with skipping.
    fn loss(&self, m: &OccupancyField, b: &crate::train::batcher::Batch) -> StepLoss {
        let (cfg, fit) = (self.cfg, self.fit);
        let dof = fit.robot.dof();
        let i = b.indices[0];
        let a = &self.host_inputs[i * self.columns..(i + 1) * self.columns];
        let ppi = self.pixels_per_image;
        let truth = &self.host_targets[i * ppi..(i + 1) * ppi];
        let pixels = self.pixels(b.step);
        let pixels: &[usize] = &pixels;
        let t: Vec<f32> = pixels.iter().map(|&p| truth[p]).collect();
        let jitter = fit.train.seed ^ (b.step as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let own = views_of_rows(a, a.len(), dof, fit.camera)
            .expect("the harness built the camera inputs from valid cameras")
            .remove(0)
            .1;
        let own = cfg.field_camera(&own);
        let radians = radians(&a[..dof], &fit.robot.chain);
        let view = (&own, radians.as_slice());
        self.steps.set(self.steps.get() + 1);
        match cfg.train_marcher {
            TrainMarcher::Dense => {
                self.evaluations
                    .set(self.evaluations.get() + pixels.len() * cfg.march.samples);
                if self.hand_written {
                    let step = dense_step(
                        m,
                        view,
                        pixels,
                        &t,
                        cfg.robot_weight,
                        &cfg.march,
                        Some(jitter),
                        fit.device,
                    );
                    return StepLoss::Computed {
                        value: step.loss,
                        gradients: step.gradients,
                    };
                }
                let pred = render_silhouette(
                    m,
                    view,
                    pixels,
                    &cfg.march,
                    Some(jitter),
                    &b.inputs.device(),
                );
                StepLoss::Graph(weighted_mse(pred, &t, cfg.robot_weight))
            }
            TrainMarcher::Skipping => {
                let (pred, evaluations) = render_silhouette_skipping(
                    m,
                    &m.valid(),
                    view,
                    pixels,
                    &cfg.march,
                    &cfg.accelerated.grid,
                    Some(jitter),
                    &b.inputs.device(),
                );
                self.evaluations.set(self.evaluations.get() + evaluations);
                StepLoss::Graph(weighted_mse(pred, &t, cfg.robot_weight))
            }
        }
    }

    /// Network evaluations a step over a finished run of `log.step` steps.
    fn per_step(&self, log: &TrainLog) -> f64 {
        let cfg = self.cfg;
        match cfg.train_marcher {
            // Known exactly, however many processes the run took.
            TrainMarcher::Dense => {
                let cropped = log.step.min(cfg.curriculum.steps) * self.crop.len();
                let full = log.step.saturating_sub(cfg.curriculum.steps) * self.all.len();
                ((cropped + full) * cfg.march.samples) as f64 / log.step.max(1) as f64
            }
            TrainMarcher::Skipping => {
                self.evaluations.get() as f64 / self.steps.get().max(1) as f64
            }
        }
    }
}

/// The first training image, where collapse is probed: its angles (from the first camera),
/// and whether its centre crop shows the robot (an all-black probe is a collapse only then;
/// a robot framed automatically may lie outside the crop in that pose).
struct CollapseProbe {
    angles: Vec<f32>,
    sees_robot: bool,
}

impl CollapseProbe {
    fn new(fit: &Fit, crop: &[usize]) -> Self {
        // The first training sample's row of a tensor, on the host.
        fn first<const D: usize>(t: &Tensor<D>) -> Vec<f32> {
            t.clone()
                .slice([0..1])
                .into_data()
                .convert::<f32>()
                .try_to_vec::<f32>()
                .expect("float")
        }
        let dof = fit.robot.dof();
        let image = first(&fit.train_set.targets[0]);
        CollapseProbe {
            angles: first(&fit.train_set.inputs)[..dof].to_vec(),
            sees_robot: crop.iter().any(|&p| image[p] >= 0.5),
        }
    }

    /// `Err(Collapsed)` where the field `m` draws the probe all black at `step`, inside the
    /// restart rule's window (the last try, after `max_restarts`, trains to the end whatever it
    /// draws: a robot the field cannot pick up then gets its row and its low score).
    fn check(
        &self,
        cfg: &Ffksm,
        fit: &Fit,
        m: &OccupancyField,
        step: usize,
        restarts: usize,
        crop: &[usize],
    ) -> Result<()> {
        let Some(r) = cfg
            .restart
            .as_ref()
            .filter(|r| self.sees_robot && restarts < r.max_restarts)
        else {
            return Ok(());
        };
        if step > r.until || step % r.every.max(1) != 0 {
            return Ok(());
        }
        let camera = cfg.field_camera(fit.camera);
        let probe = render_silhouette(
            &m.valid(),
            (&camera, &radians(&self.angles, &fit.robot.chain)),
            crop,
            &cfg.march,
            None,
            fit.device,
        );
        if probe.max().into_scalar::<f32>() < 1e-3 {
            Err(Error::Collapsed { step })
        } else {
            Ok(())
        }
    }
}

/// Train the field, restarting with a fresh model on collapse when the config asks for it:
/// the field, its log, the restarts and the network evaluations per step.
fn train_field(
    cfg: &Ffksm,
    name: &str,
    fit: &Fit,
    hand_written: bool,
) -> Result<(OccupancyField, TrainLog, usize, f64)> {
    let (plan, train) = (fit.plan, fit.train);
    let resume = plan.resume;
    // Restarts after collapse so far, so a resumed run reports them (and initialises the same
    // model).
    let restarts_path = plan.dir.join("restarts.json");
    let mut restarts: usize = if resume {
        read_kept(&restarts_path)?.unwrap_or(0)
    } else {
        0
    };
    // Network evaluations and steps of training, so a resumed run reports them for all its
    // steps (`[evaluations, steps]`).
    let counts_path = plan.dir.join("evaluations.json");
    let earlier: [usize; 2] = if resume {
        read_kept(&counts_path)?.unwrap_or([0, 0])
    } else {
        [0, 0]
    };
    let steps = FieldSteps::new(cfg, fit, hand_written, earlier);
    let probe = CollapseProbe::new(fit, &steps.crop);
    loop {
        let seed = train.seed + 1000 * restarts as u64;
        let field = cfg.field.init(fit.train_device, seed)?;
        let loss = |m: &OccupancyField, b: &crate::train::batcher::Batch| steps.loss(m, b);
        let watch = |m: &OccupancyField, step: usize| -> Result<()> {
            // The counts go beside each checkpoint (saved right after this), so a run stopped
            // and resumed still reports all its steps.
            let every = train.checkpoint_every;
            if every > 0 && (step % every == 0 || step == train.steps) {
                std::fs::create_dir_all(&plan.dir).map_err(|e| Error::io(&plan.dir, e))?;
                write_json(&counts_path, &[steps.evaluations.get(), steps.steps.get()])?;
            }
            probe.check(cfg, fit, m, step, restarts, &steps.crop)
        };
        let label = if restarts == 0 {
            name.to_string()
        } else {
            format!("{name} (restart {restarts})")
        };
        let mut watch = Watch(watch);
        match Trainer::new(train, &label)
            .checkpoint(Some(plan))
            .hooks(&mut watch)
            .fit(field, fit.train_set, loss)
        {
            Ok((field, log)) => {
                if plan.dir.is_dir() {
                    write_json(&counts_path, &[steps.evaluations.get(), steps.steps.get()])?;
                }
                let per_step = steps.per_step(&log);
                return Ok((field.valid(), log, restarts, per_step));
            }
            Err(Error::Collapsed { step }) => {
                let max = cfg.restart.as_ref().map_or(0, |r| r.max_restarts);
                eprintln!("{label}: all-black image at step {step}; restarting with a fresh model");
                if restarts >= max {
                    return Err(Error::Training(format!(
                        "{}: collapsed to an all-black image {} times; raise the robot-pixel weight or the curriculum",
                        name,
                        restarts + 1
                    )));
                }
                restarts += 1;
                // The checkpoint holds the collapsed model: start the next try from scratch.
                let _ = std::fs::remove_dir_all(&plan.dir);
                if train.checkpoint_every > 0 {
                    std::fs::create_dir_all(&plan.dir).map_err(|e| Error::io(&plan.dir, e))?;
                    write_json(&restarts_path, &restarts)?;
                }
                steps.evaluations.set(0);
                steps.steps.set(0);
            }
            Err(e) => return Err(e),
        }
    }
}

impl SelfModel for Ffksm {
    const KIND: &'static str = "ffksm";

    fn image(&self) -> [usize; 2] {
        self.image
    }

    fn fingerprint(&self, train: &TrainConfig, data: &DataSpec) -> serde_json::Value {
        fingerprint(self, train, data)
    }

    fn dof(&self) -> Option<usize> {
        Some(self.field.dof)
    }

    fn needs_robot(&self) -> bool {
        true
    }

    fn renders_any_view(&self) -> bool {
        true
    }

    fn set_dof(&mut self, dof: usize) {
        self.field.dof = dof;
    }

    /// Its field, as fitted to the scene, marched by the renderer it was saved with, on the
    /// robot and from the camera it was trained with.
    fn load(
        &self,
        weights: &std::path::Path,
        ctx: &crate::self_models::model::LoadContext,
    ) -> Result<Option<Box<dyn Render + Send + Sync>>> {
        let state: FfksmState = serde_json::from_value(ctx.state.clone())
            .map_err(|e| Error::data(weights, format!("its saved state: {e}")))?;
        let robot = ctx
            .robot
            .ok_or_else(|| Error::Config("FFKSM loads with its robot".into()))?;
        let field = crate::train::checkpoint::load_module(
            state.fitted.field.init(ctx.device, 0)?,
            weights,
        )?;
        let shared = Arc::new(FfksmShared {
            field,
            model: state.fitted,
            camera: ctx.camera.clone(),
            robot: robot.clone(),
            device: ctx.device.clone(),
            stats: Default::default(),
        });
        Ok(Some(Box::new(FfksmRenderer {
            shared,
            accelerated: state.accelerated,
            label: state.label,
        })))
    }

    /// Train the field; it renders two ways: dense marching (the paper's) and the
    /// accelerated marcher.
    fn fit(&self, fit: &Fit) -> Result<Trained> {
        let (this, marched) = self.fitted_to_scene(fit);
        let this = &this;
        let hand_written = this.dense_gradients == DenseGradients::HandWrittenOnCpu
            && matches!(fit.device_choice, DeviceChoice::Cpu | DeviceChoice::Ndarray);
        let (field, log, restarts, train_evals) = train_field(this, fit.label, fit, hand_written)?;
        let mut note = marched.into_iter().collect::<Vec<_>>();
        note.push(format!(
            "trained with {} marching, {train_evals:.0} evaluations per step",
            match self.train_marcher {
                TrainMarcher::Dense if hand_written => "dense (hand-written gradients)",
                TrainMarcher::Dense => "dense",
                TrainMarcher::Skipping => "skipping",
            }
        ));
        if restarts > 0 {
            note.push(format!("{restarts} restarts after collapse"));
        }
        if this
            .restart
            .as_ref()
            .is_some_and(|r| r.max_restarts > 0 && restarts >= r.max_restarts)
        {
            note.push("the last try trained without the collapse check".into());
        }
        let shared = Arc::new(FfksmShared {
            field,
            model: this.clone(),
            camera: fit.camera.clone(),
            robot: fit.robot.clone(),
            device: fit.device.clone(),
            stats: Default::default(),
        });
        let renderer = |accelerated: Option<AcceleratedConfig>, label: &str| -> Box<dyn Render> {
            Box::new(FfksmRenderer {
                shared: shared.clone(),
                accelerated,
                label: label.to_string(),
            })
        };
        Ok(Trained {
            parameters: shared.field.num_params(),
            renderers: [
                this.reference_renderers
                    .then(|| ("dense marching".into(), renderer(None, "dense marching"))),
                Some((
                    "accelerated".into(),
                    renderer(Some(this.accelerated.clone()), "accelerated"),
                )),
            ]
            .into_iter()
            .flatten()
            .collect(),
            log,
            note: note.join("; "),
        })
    }

    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        ffksm_run(preset, FfksmVariant::Reimplementation)
    }
}

impl Ffksm {
    /// This config for the scene `fit` renders: as it is for the papers' camera; for any other
    /// camera (a robot framed automatically), rays are marched over the depths the robot
    /// occupies over its training poses, 5% wider each way, instead of the papers' [0.6, 1.4]
    /// m (and the row's note says so).
    fn fitted_to_scene(&self, fit: &Fit) -> (Ffksm, Option<String>) {
        let paper = Camera::paper();
        let c = fit.camera;
        if (c.eye, c.target, c.up, c.fov_deg) == (paper.eye, paper.target, paper.up, paper.fov_deg)
        {
            return (self.clone(), None);
        }
        let [n, dof] = fit.train_set.inputs.dims();
        let user: Vec<f32> = fit
            .train_set
            .inputs
            .clone()
            .into_data()
            .convert::<f32>()
            .try_to_vec::<f32>()
            .expect("float inputs");
        let si: Vec<Vec<f64>> = user
            .chunks(dof.max(1))
            .take(n)
            .map(|q| {
                fit.robot
                    .chain
                    .to_si(&q.iter().map(|&v| v as f64).collect::<Vec<_>>())
            })
            .collect();
        let frame = c.frame();
        // The robot's points over its training poses: their depths and their reach.
        let points = crate::data::dataset::swept_points(fit.robot, &si);
        let depths: Vec<f64> = points
            .iter()
            .filter_map(|p| frame.project(p).map(|(_, _, z)| z))
            .collect();
        let (lo, hi) = depths
            .iter()
            .fold((f64::INFINITY, 0f64), |(l, h), &z| (l.min(z), h.max(z)));
        if !(lo.is_finite() && hi > lo) {
            return (self.clone(), None);
        }
        let pad = 0.05 * (hi - lo);
        let mut this = self.clone();
        // The papers' arm reaches about 0.45 m from the origin: shrink the scene to that.
        let reach = points.iter().map(|p| p.coords.norm()).fold(0f64, f64::max);
        this.scene_scale = (reach / PAPERS_ARM_REACH_M).max(1e-6);
        this.march.near = (lo - pad).max(1e-3) / this.scene_scale;
        this.march.far = (hi + pad) / this.scene_scale;
        let mut said = format!(
            "rays marched over depths {:.3} to {:.3} m (where the robot is), the scene shrunk {:.2}x about the base for the field",
            (lo - pad).max(1e-3),
            hi + pad,
            this.scene_scale
        );
        // The robot's own first two joints, with their axes and pivots, set the virtual frame.
        match JointsFrame::of_chain(&fit.robot.chain, this.scene_scale) {
            Some(frame) => {
                this.field.virtual_frame = VirtualFrame::Joints(frame);
                said += "; the virtual frame is the robot's first two joints'";
            }
            None => {
                said +=
                    "; the paper's virtual frame (the first two joints do not alone place a link)"
            }
        }
        (this, Some(said))
    }

    /// `camera` in the field's units (shrunk by [`Ffksm::scene_scale`] about the origin): the
    /// same image, every depth divided by the scale.
    fn field_camera(&self, camera: &Camera) -> Camera {
        let shrink = |v: [f64; 3]| v.map(|x| x / self.scene_scale);
        Camera {
            eye: shrink(camera.eye),
            target: shrink(camera.target),
            ..camera.clone()
        }
    }
}

/// How far the papers' arm reaches from its base (m): a framed robot's scene is shrunk to it.
const PAPERS_ARM_REACH_M: f64 = 0.45;

/// A trained field and what its renderers share: every image they render is kept.
struct FfksmShared {
    field: OccupancyField,
    model: Ffksm,
    camera: Camera,
    robot: Robot,
    device: Device,
    /// Per renderer label: the images rendered so far (the test set first).
    stats: Mutex<BTreeMap<String, Rendered>>,
}

/// One of a trained field's renderers (dense marching, or the accelerated marcher).
struct FfksmRenderer {
    shared: Arc<FfksmShared>,
    accelerated: Option<AcceleratedConfig>,
    label: String,
}

impl FfksmRenderer {
    fn render_from(&self, camera: &Camera, angles_deg: &[Vec<f64>], label: &str) -> Rendered {
        let s = &self.shared;
        render_all(
            &s.field,
            &s.robot,
            camera,
            angles_deg,
            &s.model,
            self.accelerated.as_ref(),
            &s.device,
            label,
        )
    }
}

/// `[n, dof]` degrees as host rows.
fn angle_rows(angles: Tensor<2>) -> Vec<Vec<f64>> {
    let [_, dof] = angles.dims();
    let v = angles
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .expect("float");
    v.chunks(dof.max(1))
        .map(|r| r.iter().map(|&a| a as f64).collect())
        .collect()
}

/// What a saved FFKSM keeps beside its field's weights: its configuration as fitted to the
/// scene, and which marcher renders.
#[derive(serde::Serialize, serde::Deserialize)]
struct FfksmState {
    fitted: Ffksm,
    accelerated: Option<AcceleratedConfig>,
    label: String,
}

impl Render for FfksmRenderer {
    fn save(&self, path: &std::path::Path) -> Result<Option<serde_json::Value>> {
        crate::train::checkpoint::save_module(&self.shared.field, path)?;
        let state = FfksmState {
            fitted: self.shared.model.clone(),
            accelerated: self.accelerated.clone(),
            label: self.label.clone(),
        };
        Ok(Some(
            serde_json::to_value(state).expect("FFKSM's state serialises"),
        ))
    }

    /// Inputs of `dof + 9` columns (trained on several views): each row from its camera.
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        let dof = self.shared.robot.dof();
        let camera = &self.shared.camera;
        let rows = angle_rows(angles);
        let flat: Vec<f32> = rows.iter().flatten().map(|&v| v as f32).collect();
        let width = rows.first().map_or(dof, Vec::len);
        let views =
            views_of_rows(&flat, width, dof, camera).expect("camera inputs of valid cameras");
        let (mut sil, mut depth) = (Vec::new(), Some(Vec::new()));
        for (run, view) in views {
            let angles: Vec<Vec<f64>> = rows[run].iter().map(|r| r[..dof].to_vec()).collect();
            let r = self.render_from(&view, &angles, &self.label);
            sil.extend_from_slice(&r.predictions.silhouettes);
            depth = depth
                .zip(r.predictions.depth.as_ref())
                .map(|(mut d, more)| {
                    d.extend_from_slice(more);
                    d
                });
            self.shared
                .stats
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .entry(self.label.clone())
                .or_insert_with(Rendered::empty)
                .extend(r);
        }
        let shape = [rows.len(), 1, camera.height, camera.width];
        let tensor =
            |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, shape), &self.shared.device);
        (tensor(sil), depth.map(tensor))
    }

    fn depth_pixels(&self) -> DepthPixels {
        DepthPixels::Drawn
    }

    fn render_view(&self, camera: &Camera, angles: Tensor<2>) -> Option<Tensor<4>> {
        let rows = angle_rows(angles);
        let shape = [rows.len(), 1, camera.height, camera.width];
        let r = self.render_from(camera, &rows, &self.label);
        Some(Tensor::<4>::from_data(
            TensorData::new(r.predictions.silhouettes, shape),
            &self.shared.device,
        ))
    }

    fn note(&self, test_images: usize) -> String {
        let evals = self
            .shared
            .stats
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&self.label)
            .map_or(0.0, |r| r.first(test_images).mean_evaluations());
        format!("{evals:.0} network evaluations per image; tested on {test_images} images")
    }

    /// The accelerated marcher (the last renderer) writes the field's own reports:
    /// `renderers.csv` (both marchers, and the accelerated one without early termination)
    /// and the novel views (`novel_views.csv`, `novel_views.png`).
    fn extra_reports(&self, ctx: &ReportContext) -> Result<()> {
        if self.accelerated.is_none() || !self.shared.model.reference_renderers {
            return Ok(());
        }
        let s = &self.shared;
        let (truth, truth_depth) = ctx.truth;
        let pixels = s.camera.width * s.camera.height;
        let n = ctx.test.len();
        let test_angles: Vec<Vec<f64>> = ctx
            .test
            .clone()
            .map(|i| ctx.data.angles[i].clone())
            .collect();
        let score_of =
            |p: &Predictions, t: &[f32], d: &[f32]| score(p, t, Some(d), ctx.paper_subset);
        let first = |label: &str| -> Result<Rendered> {
            s.stats
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get(label)
                .map(|r| r.first(n))
                .ok_or_else(|| Error::Training(format!("{label}: nothing rendered")))
        };
        let dense = first("dense marching")?;
        let fast = first("accelerated")?;
        // What early termination adds to the grid: the same marcher without it.
        let no_termination = FfksmRenderer {
            shared: s.clone(),
            accelerated: Some(AcceleratedConfig {
                termination: None,
                ..s.model.accelerated.clone()
            }),
            label: "skipping only".into(),
        };
        let skipping_only = no_termination.render_from(&s.camera, &test_angles, "skipping only");
        let dense_evals = dense.mean_evaluations();
        let renderer_row = |name: &str, r: &Rendered| {
            let q = score_of(&r.predictions, truth, truth_depth);
            RendererRow {
                model: ctx.name.into(),
                renderer: name.into(),
                test_images: q.test_images,
                evaluations_per_image: r.mean_evaluations(),
                grid_evaluations_per_image: r.grid_evaluations.iter().sum::<usize>() as f64
                    / r.grid_evaluations.len().max(1) as f64,
                grid_occupancy: r.grid_occupancy.iter().sum::<f64>()
                    / r.grid_occupancy.len().max(1) as f64,
                fewer_evaluations: dense_evals / r.mean_evaluations().max(1.0),
                img_per_s: r.images_per_second(),
                psnr_db_test: q.psnr_db_test,
                iou_test: q.iou_test,
                psnr_db_vs_dense: mean_psnr(
                    &r.predictions.silhouettes,
                    &dense.predictions.silhouettes,
                    pixels,
                ),
                depth_mae_mm: q.depth_mae_mm,
                git_revision: ctx.git_revision.into(),
                device: ctx.device_name.clone(),
                preset: ctx.preset.into(),
            }
        };
        let renderers = vec![
            renderer_row("dense marching", &dense),
            renderer_row("accelerated", &fast),
            renderer_row("accelerated without early termination", &skipping_only),
        ];
        // Novel views: the simulator's images from orbited cameras, the accelerated marcher.
        let fast_q = score_of(&fast.predictions, truth, truth_depth);
        let view_row = |yaw: f64, q: &Quality, blind: (f64, f64)| NovelViewRow {
            model: ctx.name.into(),
            yaw_deg: yaw,
            test_images: q.test_images,
            psnr_db: q.psnr_db_test,
            iou: q.iou_test,
            depth_mae_mm: q.depth_mae_mm,
            view_blind_psnr_db: blind.0,
            view_blind_iou: blind.1,
            renderer: "accelerated".into(),
            git_revision: ctx.git_revision.into(),
            device: ctx.device_name.clone(),
            preset: ctx.preset.into(),
        };
        let mut novel = vec![view_row(0.0, &fast_q, (f64::INFINITY, 1.0))];
        let mut novel_images = Vec::new();
        // The cameras turn about the vertical through the point they look at: the configured
        // target, or for a framed or recorded camera (whose record keeps no target) the point
        // on its axis nearest the centre of the robot's poses.
        let pivot = if let Some(configured) = ctx.spec.configured_camera() {
            configured.target
        } else {
            let si: Vec<Vec<f64>> = ctx
                .data
                .angles
                .iter()
                .map(|q| s.robot.chain.to_si(q))
                .collect();
            let points = crate::data::dataset::swept_points(&s.robot, &si);
            s.camera
                .axis_point_nearest(crate::sim::shape::Aabb::from_points(&points).center())
        };
        for &yaw in &s.model.novel_views_deg {
            // The simulator's view of the same poses from the orbited camera.
            let mut spec = ctx.spec.dataset.clone();
            spec.camera = s.camera.orbited_about(pivot, yaw);
            spec.framing = None;
            spec.samples = ctx.data.len();
            spec.train = ctx.data.n_train;
            let view_data = Dataset::render(&s.robot, &spec, ctx.data.angles.clone(), None)?;
            let (vt, vd) = host_targets(&view_data, ctx.test);
            let r = self.render_from(&spec.camera, &test_angles, &format!("novel view {yaw} deg"));
            let q = score_of(&r.predictions, &vt, &vd);
            novel.push(view_row(
                yaw,
                &q,
                (mean_psnr(truth, &vt, pixels), mean_iou(truth, &vt, pixels)),
            ));
            novel_images.push((vt, r.predictions.silhouettes));
        }
        write_reports(ctx.dir, ctx.name, &renderers, &novel)?;
        novel_view_figure(
            &ctx.dir.join("novel_views.png"),
            &novel_images,
            &s.model.novel_views_deg,
            [s.camera.height, s.camera.width],
        )
    }
}

fn write_reports(
    dir: &Path,
    name: &str,
    renderers: &[RendererRow],
    novel: &[NovelViewRow],
) -> Result<()> {
    write_table(
        &dir.join("renderers.csv"),
        renderers,
        &format!("{name}: dense marching against the accelerated marcher"),
        "Same model, same test images. `fewer_evaluations` is dense marching's network evaluations per image over this renderer's (the grid's probes included); `psnr_db_vs_dense` compares the two renderers' images directly. Images/s: median time per image after one warm-up image, batch 1, this machine.",
    )?;
    write_table(
        &dir.join("novel_views.csv"),
        novel,
        &format!("{name}: views it was never trained on"),
        "The training camera turned about the vertical through the point it looks at (the papers' camera: the world z axis); the truth is the simulator's image from that camera. `view_blind_*`: the training camera's true silhouette offered as the prediction, what a 2-D decoder (NeuroKin) can at best output for another camera.",
    )
}

/// For each novel view (camera yaw `yaws_deg`), a row of truths then a row of predictions (six
/// poses).
fn novel_view_figure(
    path: &Path,
    views: &[(Vec<f32>, Vec<f32>)],
    yaws_deg: &[f64],
    size: [usize; 2],
) -> Result<()> {
    let px = size[0] * size[1];
    let Some(first) = views.first() else {
        return Ok(());
    };
    // The same six test poses from every view.
    let picks = grid_picks(first.0.len() / px);
    let mut rows = Vec::new();
    for (truth, pred) in views {
        rows.push(GridRow::Grey(
            picks.iter().map(|&i| nth_image(truth, i, px)).collect(),
        ));
        rows.push(GridRow::Grey(
            picks.iter().map(|&i| nth_image(pred, i, px)).collect(),
        ));
    }
    let titles: Vec<String> = yaws_deg
        .iter()
        .flat_map(|y| {
            [
                format!("{y:.0} deg: truth"),
                format!("{y:.0} deg: prediction"),
            ]
        })
        .collect();
    let titles: Vec<&str> = titles.iter().map(String::as_str).collect();
    // Under each column: that pose's PSNR and IoU from each view, a line per view.
    let captions: Vec<String> = picks
        .iter()
        .map(|&i| {
            views
                .iter()
                .zip(yaws_deg)
                .map(|((truth, pred), yaw)| {
                    let (t, p) = (nth_image(truth, i, px), nth_image(pred, i, px));
                    format!(
                        "{yaw:.0} deg: {:.1} dB IoU {:.2}",
                        crate::eval::evaluation::psnr_db(p, t),
                        crate::eval::evaluation::iou(p, t)
                    )
                })
                .collect::<Vec<_>>()
                .join(", ")
        })
        .collect();
    image_grid(path, &rows, &titles, &captions, size[1], size[0], 2)
}
