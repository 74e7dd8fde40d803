//! The one harness every self-model runs in: it renders the dataset, trains the model through
//! [`SelfModel::fit`], predicts the test poses in batches, scores them, times inference, and
//! writes the row of Table I ([`ModelResult`]) with its report. A self-model brings only what
//! is its own: its config (with presets), its network and loss, and how it renders.
//!
//! A run writes into its folder: `config.json` (everything that defines it), `results.csv`
//! and `results.md` (one [`ModelResult`] row per renderer), `curve.csv` and `training_curve.png`
//! (the figure where training took more than one step),
//! `qualitative.png` (ground truth, prediction and error for six test poses, plus depth where
//! the model predicts it), and `checkpoint/` (model, optimizer state, progress; `--resume`
//! continues).

use std::ops::Range;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};

use crate::core::atomic_file::write_json;
use crate::core::device::DeviceChoice;
use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::data::dataset::{Dataset, DatasetConfig};
use crate::eval::evaluation::{DepthPixels, Predictions, Quality, score};
use crate::eval::inference_speed::{SpeedConfig, Timing, measure};
use crate::report::figures::{GridRow, image_grid};
use crate::report::table::{write_csv, write_markdown_report};
use crate::self_models::result::{ModelResult, PaperReference};
use crate::sim::camera::Camera;
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;
use crate::train::{
    batcher::TrainSet,
    checkpoint::CheckpointPlan,
    config::{TrainConfig, TrainLog},
    trainer::autodiff_device,
};

/// A visual self-model: joint angles in, the robot's silhouette (and depth) out. Implement
/// it on the model's config; [`run`] does the rest.
pub trait SelfModel: Clone + std::fmt::Debug + PartialEq + serde::Serialize {
    /// Its kind in a saved model's `model.json` ([`crate::self_models::saved`]), which
    /// picks its loader ([`crate::self_models::loading`]).
    const KIND: &'static str;
    /// The image it renders, `[height, width]` (the dataset's camera must match).
    fn image(&self) -> [usize; 2];
    /// Train on `fit.train_set` and hand back what renders.
    fn fit(&self, fit: &Fit) -> Result<Trained>;
    /// What a checkpoint must match to be resumed.
    fn fingerprint(&self, train: &TrainConfig, data: &DataSpec) -> serde_json::Value {
        serde_json::json!({"model": self, "train": train, "data": data.fingerprint()})
    }
    /// Whether it is a lower bound every model must beat (a constant), not a model.
    fn lower_bound(&self) -> bool {
        false
    }
    /// The number of joint values its network takes, where its config fixes one.
    fn dof(&self) -> Option<usize> {
        None
    }
    /// Take `dof` joint values (the robot's): a network's input width follows the robot.
    fn set_dof(&mut self, _dof: usize) {}
    /// The robot's joints as a tree (each input's parent input,
    /// [`crate::sim::kinematics::KinematicChain::input_parents`]), for a model that follows
    /// it (NeuroKin's tree encoder); called after [`SelfModel::set_dof`] where the robot's
    /// description is known.
    fn set_joint_tree(&mut self, _parents: &[Option<usize>]) {}
    /// Whether it needs the robot's kinematic chain and geometry (K-3DGS, FFKSM), not only
    /// joint values and images.
    fn needs_robot(&self) -> bool {
        false
    }
    /// Whether it takes the camera as input: each sample's inputs are then its joint angles
    /// followed by its camera's [`camera_input`] (`[n, dof + 9]`).
    fn camera_input(&self) -> bool {
        false
    }
    /// Whether it is a 3-D model that renders any camera (FFKSM, K-3DGS): trained on a
    /// multi-view dataset, it reads each sample's camera from its inputs (as a
    /// camera-conditioned model does, [`SelfModel::camera_input`]) and renders from it.
    fn renders_any_view(&self) -> bool {
        false
    }
    /// The renderer whose weights its renderer saved to `weights` ([`Render::save`], with the
    /// state it returned), built on `ctx.device`; `None`: this kind saves no weights that load.
    fn load(
        &self,
        _weights: &Path,
        _ctx: &LoadContext,
    ) -> Result<Option<Box<dyn Render + Send + Sync>>> {
        Ok(None)
    }
    /// Its run on a preset of [`SELF_MODEL_PRESETS`] (what the registry runs).
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>>
    where
        Self: Sized;
}

/// What a saved self-model is rebuilt with ([`SelfModel::load`]).
pub struct LoadContext<'a> {
    pub device: &'a Device,
    /// What its renderer's [`Render::save`] returned.
    pub state: &'a serde_json::Value,
    /// The robot it was trained on, loaded again for a model that hangs on its chain
    /// ([`SelfModel::needs_robot`]).
    pub robot: Option<&'a Robot>,
    /// The camera of its first image.
    pub camera: &'a Camera,
}

/// [`SelfModel::load`] for a network: `template` (its configuration's untrained network on the
/// device) given the weights its [`Render::save`] wrote to `weights`.
pub fn load_network<R>(template: R, weights: &Path) -> Result<Option<Box<dyn Render + Send + Sync>>>
where
    R: Render + burn::module::Module + Send + Sync + 'static,
{
    let network = crate::train::checkpoint::load_module(template, weights)?;
    Ok(Some(Box::new(network)))
}

/// What a self-model trains with.
pub struct Fit<'a> {
    /// On the training (autodiff) device: inputs `[n, dof]` joint angles in degrees, targets
    /// silhouettes and depth (metres), each `[n, 1, H, W]`.
    pub train_set: &'a TrainSet,
    pub train: &'a TrainConfig,
    /// Checkpoints (`--resume`), for the shared training loop.
    pub plan: &'a CheckpointPlan,
    /// The run's name, for progress bars.
    pub label: &'a str,
    /// Where the model trains (autodiff, seeded) and where the trained model renders.
    pub train_device: &'a Device,
    pub device: &'a Device,
    /// The robot and the camera the dataset was rendered with (for models with geometry).
    pub robot: &'a Robot,
    pub camera: &'a Camera,
    /// The device as chosen (`--device`): CPU-only fast paths check it.
    pub device_choice: DeviceChoice,
    /// Whether each sample's inputs end with its camera's [`camera_input`] (a
    /// camera-conditioned model, or a 3-D model on a multi-view dataset): split them with
    /// [`views_of_rows`].
    pub cameras_in_inputs: bool,
}

/// A trained self-model.
pub struct Trained {
    /// What renders, each with its label (empty for a model's one renderer; otherwise its
    /// row is "name (label)"). The first draws the qualitative figure.
    pub renderers: Vec<(String, Box<dyn Render>)>,
    /// Trainable parameters (PyTorch's count).
    pub parameters: usize,
    pub log: TrainLog,
    /// Said in the results row before the run's own note (empty: nothing).
    pub note: String,
}

impl Trained {
    /// A model with one renderer and nothing of its own to say in its row.
    pub fn one(renderer: impl Render + 'static, parameters: usize, log: TrainLog) -> Self {
        Trained {
            renderers: vec![(String::new(), Box::new(renderer))],
            parameters,
            log,
            note: String::new(),
        }
    }
}

/// Rendering with a trained self-model.
pub trait Render {
    /// `[n, dof]` joint angles (degrees) -> silhouette probabilities in [0, 1]
    /// `[n, 1, H, W]`, and depth in metres where the model predicts it.
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>);
    /// The pixels its depth error counts (where the true silhouette is the robot, unless
    /// the model draws depth only where it draws the robot).
    fn depth_pixels(&self) -> DepthPixels {
        DepthPixels::TrueRobot
    }
    /// Said first in its row's note, once the `test_images` are rendered (empty: nothing).
    fn note(&self, _test_images: usize) -> String {
        String::new()
    }
    /// Silhouettes `[n, 1, H, W]` of `angles` seen from `camera` (same image size) instead
    /// of the camera it was trained with: a 3-D model renders any view. `None`: a model of
    /// the views it was trained on (a camera-conditioned one takes the camera as input).
    fn render_view(&self, _camera: &Camera, _angles: Tensor<2>) -> Option<Tensor<4>> {
        None
    }
    /// Write its weights to `path` for [`SelfModel::load`], and return what else it needs
    /// to be rebuilt (kept in `model.json`); `None`: it saves none.
    fn save(&self, _path: &Path) -> Result<Option<serde_json::Value>> {
        Ok(None)
    }
    /// Reports of its own beside the harness's (FFKSM's renderers, K-3DGS's speeds).
    fn extra_reports(&self, _ctx: &ReportContext) -> Result<()> {
        Ok(())
    }
    /// The same renderer on `autodiff` (an autodiff device), its weights frozen, so that what
    /// it renders is differentiable in the joint angles given to it: for reading the body
    /// from an image ([`crate::body`]). `None` where the model cannot be differentiated.
    fn differentiable(&self, _autodiff: &Device) -> Option<Box<dyn Render>> {
        None
    }
    /// For a model that hangs on the kinematic chain (K-3DGS): its joint origins'
    /// translations `[J, 3]` (metres, the order of
    /// [`crate::sim::tensor_kinematics::TensorChain::origin_rows`]). `None`: no chain.
    fn joint_origins(&self) -> Option<Vec<[f32; 3]>> {
        None
    }
    /// Silhouettes `[n, 1, H, W]` of `angles` with the chain's joint origin translations
    /// `origin_t` `[J, 3]` instead of its own, differentiable in them (visual calibration of
    /// link lengths, [`crate::body::calibration`]). `None`: no chain.
    fn render_with_origins(&self, _angles: Tensor<2>, _origin_t: Tensor<2>) -> Option<Tensor<4>> {
        None
    }
}

/// One renderer's test predictions and inference timings.
pub struct RenderedSet {
    pub label: String,
    pub predictions: Predictions,
    pub timings: Vec<Timing>,
}

/// What a model's own reports may use.
pub struct ReportContext<'a> {
    pub dir: &'a Path,
    pub name: &'a str,
    pub spec: &'a DataSpec,
    pub data: &'a Dataset,
    pub test: &'a Range<usize>,
    /// The test silhouettes and depth, `[n, H * W]`.
    pub truth: (&'a [f32], &'a [f32]),
    /// Every renderer's predictions and timings, in order.
    pub rendered: &'a [RenderedSet],
    pub paper_subset: usize,
    pub device: &'a Device,
    /// Revision, device and preset, as every result row records them.
    pub git_revision: &'a str,
    pub device_name: String,
    pub preset: &'a str,
}

/// The data a run trains and tests on.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DataSpec {
    /// The robot seen (the papers' arm4 unless `--robot`/`--urdf` says otherwise).
    #[serde(default)]
    pub robot: RobotSpec,
    /// Rendered in-process (0.4 s for the paper's 2,000 samples).
    pub dataset: DatasetConfig,
    /// Train on only the first this-many samples of the training split.
    pub train_samples: Option<usize>,
    /// Test on these samples instead of the test split (indices into the dataset).
    pub test: Option<Range<usize>>,
    /// Train and test on this dataset file instead of rendering `dataset` (`--dataset`: what
    /// the `dataset` binary writes, or silhouettes captured elsewhere in its format; the
    /// camera comes from its `poses` and `focal`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<std::path::PathBuf>,
}

impl DataSpec {
    /// What of the data a checkpoint's fingerprint records: all of it, except the robot when
    /// it is the papers' arm4 (checkpoints from before the robot was recorded then still
    /// resume; any other robot is part of the fingerprint).
    pub fn fingerprint(&self) -> serde_json::Value {
        let mut print = serde_json::to_value(self).expect("a DataSpec serialises");
        if self.robot == RobotSpec::default()
            && let Some(fields) = print.as_object_mut()
        {
            fields.remove("robot");
        }
        print
    }

    /// The paper's 2,000-sample dataset (clean: no ground-plane artefact).
    pub fn paper() -> Self {
        DataSpec {
            robot: RobotSpec::default(),
            dataset: DatasetConfig::paper(),
            train_samples: None,
            test: None,
            file: None,
        }
    }

    /// The paper's dataset made large: 12,500 samples of the same Lorenz trajectory, the
    /// last 500 the test set (NeuroKin went from 25.2 dB on the paper's 1,600 training images
    /// to 28.9 dB on 9,600 in `ablation_data_scale`: data is what the simulator makes free).
    pub fn large() -> Self {
        let mut data = Self::paper();
        data.dataset.samples = 12_500;
        data.dataset.train = 12_000;
        data
    }

    /// The paper's 2,000 Lorenz samples (1,600 train) at 32x32 pixels, same camera and field
    /// of view (fewer samples would cover too little of the trajectory: 200 consecutive
    /// samples barely move the arm).
    pub fn quick() -> Self {
        let mut dataset = DatasetConfig::paper();
        dataset.preset = "quick".into();
        dataset.camera = Camera {
            width: 32,
            height: 32,
            ..Camera::paper()
        };
        DataSpec {
            robot: RobotSpec::default(),
            dataset,
            train_samples: None,
            test: None,
            file: None,
        }
    }

    /// `clean`, `paper_compatible` or `file` (a dataset read from `--dataset`).
    pub fn label(&self) -> &'static str {
        if self.file.is_some() {
            "file"
        } else if self.dataset.render.ground_artifact {
            "paper_compatible"
        } else {
            "clean"
        }
    }

    /// Render the dataset and pick the train and test samples.
    pub fn load(&self) -> Result<(Dataset, Range<usize>, Range<usize>)> {
        self.load_with_robot()
            .map(|(_, data, train, test)| (data, train, test))
    }

    /// The camera `data` was rendered (or captured) with: the config's camera, unless it was
    /// framed automatically or read from a file (then the dataset's record of it).
    pub fn camera(&self, data: &Dataset) -> Camera {
        self.configured_camera()
            .cloned()
            .unwrap_or_else(|| data.camera())
    }

    /// The config's camera when the data is rendered from it as it stands: `None` when it is
    /// framed automatically or the data is read from a file (then only the dataset's record
    /// says where the camera was).
    pub fn configured_camera(&self) -> Option<&Camera> {
        (self.file.is_none() && self.dataset.framing.is_none()).then_some(&self.dataset.camera)
    }

    /// [`DataSpec::load`] with the robot it rendered (loaded once: a URDF reads its meshes).
    pub fn load_with_robot(&self) -> Result<(Robot, Dataset, Range<usize>, Range<usize>)> {
        let robot = self.robot.load()?;
        let data = match &self.file {
            Some(path) => {
                let data = Dataset::load(path)?;
                // A dataset that names its joints is read only with the robot that made it.
                let names = robot.chain.joint_names();
                if !data.joint_names.is_empty()
                    && !self.robot.is_papers_arm()
                    && data.joint_names != names
                {
                    return Err(Error::data(
                        path,
                        format!(
                            "its joints are [{}] but the robot description ({}) has [{}]: give the robot that made the dataset (--urdf, --tip, --joints, --tips)",
                            data.joint_names.join(", "),
                            self.robot.label(),
                            names.join(", ")
                        ),
                    ));
                }
                let empty = data.empty_images();
                if 2 * empty > data.len() {
                    return Err(Error::data(
                        path,
                        format!(
                            "{empty} of its {} silhouettes are empty: \"images\" must show the robot (uint8, 255 where it is)",
                            data.len()
                        ),
                    ));
                }
                data
            }
            None => {
                let data = Dataset::generate(&robot, &self.dataset, None)?;
                data.check_in_view()?;
                data
            }
        };
        let (train, test) = data.split();
        if train.is_empty() {
            return Err(Error::Config(format!(
                "the dataset{} has no training samples (n_train 0): a self-model needs some",
                self.file
                    .as_ref()
                    .map_or(String::new(), |f| format!(" {}", f.display()))
            )));
        }
        let train = match self.train_samples {
            Some(k) if k > train.len() => {
                return Err(Error::Config(format!(
                    "train_samples {k} is more than the {} training samples",
                    train.len()
                )));
            }
            Some(k) => train.start..train.start + k,
            None => train,
        };
        let test = self.test.clone().unwrap_or(test);
        if test.end > data.len() || test.is_empty() {
            return Err(Error::Config(format!(
                "test range {test:?} is outside the {} samples",
                data.len()
            )));
        }
        Ok((robot, data, train, test))
    }
}

/// After a run refused its input or failed before training wrote anything: remove the
/// `config.json` it wrote (and the folder, if it made it), so a refused run leaves nothing
/// behind. A run that wrote a checkpoint keeps it (and its config) for `--resume`.
fn leave_as_found(dir: &Path, (new_dir, new_config): (bool, bool)) {
    if dir.join("checkpoint").exists() || !new_config {
        return;
    }
    let _ = std::fs::remove_file(dir.join("config.json"));
    if new_dir {
        let _ = std::fs::remove_dir(dir);
    }
}

/// Everything that defines one self-model run: the model's config and what every run shares.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SelfModelRun<M> {
    /// Row label (`NeuroKin`, `NeuroKin (sigma 0)`, ...).
    pub name: String,
    pub preset: String,
    pub model: M,
    pub train: TrainConfig,
    pub data: DataSpec,
    /// PSNR is also reported on the first this-many test images (the paper's 100).
    pub paper_subset: usize,
    pub eval_batch: usize,
    pub speed: SpeedConfig,
    pub reference: PaperReference,
    /// Said in the results row (a shortened run, ...).
    pub note: String,
    /// `--steps N` when it changed the preset's step count.
    pub steps_override: Option<usize>,
}

/// The presets of the self-model runs: `paper`, `quick`, `short` (the paper's data and
/// models with training cut so the whole of `table1` runs in under 5 minutes on a 2-core CPU,
/// `reports/table1_short/console*.txt` say how long it took; each row says so in its note),
/// and `large` (the paper's models on 12,000 training images of the same trajectory, trained
/// three times as long: the self-model `damage` and `body_from_image --preset large` act on).
pub const SELF_MODEL_PRESETS: &[&str] = &["paper", "short", "quick", "large"];

/// The notebooks' training protocol: Adam 1e-3, batch 32, 3,000 steps, clip 1.0, N(0, 0.01)
/// noise on the angles in degrees (`quick`: 200 steps of batch 16; `large`: 9,000 steps, 24
/// epochs of its 12,000 images).
pub fn notebook_train(preset: &str) -> TrainConfig {
    match preset {
        "large" => TrainConfig {
            steps: 9000,
            ..notebook_train("paper")
        },
        "quick" => TrainConfig {
            steps: 200,
            batch: 16,
            learning_rate: 1e-3,
            grad_clip_norm: Some(1.0),
            input_noise: 0.01,
            seed: 0,
            checkpoint_every: 50,
            log_every: 0,
        },
        _ => TrainConfig {
            steps: 3000,
            batch: 32,
            learning_rate: 1e-3,
            grad_clip_norm: Some(1.0),
            input_noise: 0.01,
            seed: 0,
            checkpoint_every: 250,
            log_every: 0,
        },
    }
}

/// How many poses a preset trains on (the paper's: 1,600).
pub fn preset_train_samples(preset: &str) -> Result<usize> {
    Ok(preset_parts(preset)?.0.dataset.train)
}

fn preset_parts(preset: &str) -> Result<(DataSpec, SpeedConfig)> {
    match preset {
        "paper" => Ok((DataSpec::paper(), SpeedConfig::paper())),
        "short" => Ok((DataSpec::paper(), SpeedConfig::short())),
        "large" => Ok((DataSpec::large(), SpeedConfig::paper())),
        "quick" => Ok((DataSpec::quick(), SpeedConfig::quick())),
        other => Err(Error::Config(format!(
            "unknown preset \"{other}\" (choose paper, short, quick or large)"
        ))),
    }
}

/// The model preset a run preset uses (`short` and `large` train the paper's models).
pub fn model_preset(preset: &str) -> &str {
    if preset == "short" || preset == "large" {
        "paper"
    } else {
        preset
    }
}

impl<M: SelfModel> SelfModelRun<M> {
    /// A run of `model` on a preset's data and speed settings, with the notebooks' training
    /// protocol and PSNR also on the paper's first 100 test images.
    pub fn new(
        preset: &str,
        name: &str,
        model: M,
        eval_batch: usize,
        reference: PaperReference,
    ) -> Result<Self> {
        let (data, speed) = preset_parts(preset)?;
        Ok(SelfModelRun {
            name: name.into(),
            preset: preset.into(),
            model,
            train: notebook_train(preset),
            data,
            paper_subset: 100,
            eval_batch,
            speed,
            reference,
            note: String::new(),
            steps_override: None,
        })
    }

    /// The image size of a preset's camera, `[height, width]`.
    pub fn image(preset: &str) -> Result<[usize; 2]> {
        let camera = &preset_parts(preset)?.0.dataset.camera;
        Ok([camera.height, camera.width])
    }

    /// Shorten a paper-preset run for the `short` preset, and say so in its note.
    pub fn shorten(mut self, steps: usize, batch: usize) -> Self {
        if self.preset == "short" {
            self.note = format!(
                "short preset: {steps} steps of batch {batch} instead of {} of {} (CPU time budget)",
                self.train.steps, self.train.batch
            );
            self.train.steps = steps;
            self.train.batch = batch;
        }
        self
    }

    /// Score a `short` run on the first `n` test images only (the paper's PSNR subset is the
    /// first 100), and say so in its note.
    pub fn short_test_set(mut self, n: usize) -> Self {
        if self.preset == "short" {
            let start = self.data.dataset.train;
            let end = (start + n).min(self.data.dataset.samples);
            self.data.test = Some(start..end);
            let said = format!("scored on the first {} test images", end - start);
            self.note = if self.note.is_empty() {
                format!("short preset: {said}")
            } else {
                format!("{}, {said}", self.note)
            };
        }
        self
    }

    /// Switch to the paper-compatible dataset (silhouettes with the ground-plane artefact).
    pub fn paper_compatible(mut self, on: bool) -> Self {
        self.data.dataset.render.ground_artifact = on;
        self
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

/// What a camera-conditioned model reads of a camera: its pose as 9 numbers, the eye
/// position and the first two columns of its rotation (right and up: the continuous 6-D
/// representation of a rotation, Zhou et al., CVPR 2019; Euler angles and quaternions jump),
/// times [`CAMERA_INPUT_SCALE`] so that they span what the joint angles in degrees span.
pub fn camera_input(camera: &Camera) -> [f32; 9] {
    camera.to_vector().map(|v| (v * CAMERA_INPUT_SCALE) as f32)
}

/// The camera a [`camera_input`] describes (its rotation made orthonormal again), with the
/// field of view and image size of `like`.
pub fn camera_from_input(v: &[f32], like: &Camera) -> Result<Camera> {
    let v: [f64; 9] = std::array::from_fn(|i| f64::from(v[i]) / CAMERA_INPUT_SCALE);
    Camera::from_vector(&v, like)
}

/// Host input rows `[n, width]` split into runs of consecutive rows seen from one camera:
/// `width = dof + 9` rows end with their camera's [`camera_input`]; `width = dof` rows are
/// all seen from `own` (one run). How a 3-D model renders a multi-view batch.
pub fn views_of_rows(
    inputs: &[f32],
    width: usize,
    dof: usize,
    own: &Camera,
) -> Result<Vec<(Range<usize>, Camera)>> {
    let n = inputs.len() / width.max(1);
    if width == dof {
        return Ok(vec![(0..n, own.clone())]);
    }
    if width != dof + 9 {
        return Err(Error::Config(format!(
            "inputs of {width} values per sample: expected the robot's {dof} joint values, optionally followed by 9 of a camera"
        )));
    }
    let camera_of = |i: usize| &inputs[i * width + dof..(i + 1) * width];
    let mut runs: Vec<(Range<usize>, Camera)> = Vec::new();
    let mut start = 0;
    for i in 1..=n {
        if i == n || camera_of(i) != camera_of(start) {
            runs.push((start..i, camera_from_input(camera_of(start), own)?));
            start = i;
        }
    }
    Ok(runs)
}

/// [`views_of_rows`] on a device batch: each run's joint angles `[rows, dof]` with its camera
/// (`inputs` of `dof` columns: one run, seen from `own`, read without leaving the device).
pub fn split_views(
    inputs: &Tensor<2>,
    dof: usize,
    own: &Camera,
) -> Result<Vec<(Tensor<2>, Camera)>> {
    let [_, width] = inputs.dims();
    if width == dof {
        return Ok(vec![(inputs.clone(), own.clone())]);
    }
    let host = inputs
        .clone()
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| Error::Config(format!("camera inputs: {e:?}")))?;
    Ok(views_of_rows(&host, width, dof, own)?
        .into_iter()
        .map(|(rows, camera)| (inputs.clone().slice([rows, 0..dof]), camera))
        .collect())
}

/// Camera inputs are the pose vector times this (eye in centimetres, rotation entries in
/// [-100, 100]): the joint angles' scale in degrees.
pub const CAMERA_INPUT_SCALE: f64 = 100.0;

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

/// A self-model trained by [`fit_run`], with the data it is scored on.
pub struct Fitted {
    pub trained: Trained,
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

/// Load `cfg`'s data and train its model on `device_choice`, checkpointing into
/// `checkpoint_dir` (`resume`: continue from there). The first half of [`run`]; the
/// GPU-against-CPU test calls it directly.
pub fn fit_run<M: SelfModel>(
    cfg: &SelfModelRun<M>,
    checkpoint_dir: &Path,
    device_choice: DeviceChoice,
    resume: bool,
) -> Result<Fitted> {
    let device = crate::core::device::select(device_choice)?;
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
            "{}: the model hangs on the robot's kinematic chain, but the robot ({}) has {} joints and the dataset {}: give the robot that made the dataset (--urdf, --tip)",
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
    Ok(Fitted {
        trained,
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

/// Train, evaluate, time and report one self-model into `dir`.
pub fn run<M: SelfModel>(
    cfg: &SelfModelRun<M>,
    dir: &Path,
    device_choice: DeviceChoice,
    resume: bool,
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
    let Fitted {
        trained,
        device,
        data,
        train_range,
        test_range,
        test_set,
        truth,
        truth_depth,
    } = fitted?;
    let log = &trained.log;
    let pixels = data.height * data.width;
    let git_revision = git_revision.as_str();
    let mut rows = Vec::new();
    let mut qualities = Vec::new();
    let mut rendered: Vec<RenderedSet> = Vec::new();
    for (label, renderer) in &trained.renderers {
        let renderer = renderer.as_ref();
        let predictions = predict_all(renderer, &test_set, cfg.eval_batch, pixels);
        let timings = measure(|q| renderer.render(q).0, data.dof(), &device, &cfg.speed);
        let quality = score(&predictions, &truth, Some(&truth_depth), cfg.paper_subset);
        let timing = |b: usize| timings.iter().find(|t| t.batch == b).cloned();
        let t1 = timing(1).unwrap_or(Timing {
            batch: 1,
            median_s: f64::NAN,
            repeats: 0,
        });
        // The largest batch timed (none beyond batch 1: not measured).
        let tb = timings
            .iter()
            .filter(|t| t.batch > 1)
            .max_by_key(|t| t.batch)
            .cloned()
            .unwrap_or(Timing {
                batch: 0,
                median_s: f64::NAN,
                repeats: 0,
            });
        let predicts_depth = predictions.depth.is_some();
        let renderer_note = renderer.note(test_range.len());
        rows.push(
            ModelResult {
                model: if label.is_empty() {
                    cfg.name.clone()
                } else {
                    format!("{} ({label})", cfg.name)
                },
                dataset: cfg.data.label().into(),
                preset: cfg.preset.clone(),
                device: device_choice.to_string(),
                git_revision: git_revision.into(),
                parameters: trained.parameters,
                train_samples: train_range.len(),
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
                    renderer_note.as_str(),
                    trained.note.as_str(),
                    cfg.note.as_str(),
                ]
                .iter()
                .filter(|n| !n.is_empty())
                .copied()
                .collect::<Vec<_>>()
                .join("; "),
                steps_override: cfg.steps_override,
                lower_bound: cfg.model.lower_bound(),
            }
            .with_reference(&cfg.reference),
        );
        qualities.push(quality);
        rendered.push(RenderedSet {
            label: label.clone(),
            predictions,
            timings,
        });
    }
    write_report(dir, cfg, &rows, log)?;
    crate::self_models::saved::save(
        &dir.join("model"),
        &crate::self_models::saved::ToSave {
            kind: M::KIND,
            model: serde_json::to_value(&cfg.model).expect("a model configuration serialises"),
            name: &cfg.name,
            save_weights: &|path| trained.renderers[0].1.save(path),
            camera: cfg.data.camera(&data),
            data: &data,
            data_fingerprint: cfg.data.fingerprint(),
            test_inputs: &test_set.inputs,
            predictions: &rendered[0].predictions,
            psnr_db_test: rows[0].psnr_db_test,
            iou_test: rows[0].iou_test,
            preset: &cfg.preset,
            git_revision,
        },
    )?;
    let ctx = ReportContext {
        dir,
        name: &cfg.name,
        spec: &cfg.data,
        data: &data,
        test: &test_range,
        truth: (&truth, &truth_depth),
        rendered: &rendered,
        paper_subset: cfg.paper_subset,
        device: &device,
        git_revision,
        device_name: device_choice.to_string(),
        preset: &cfg.preset,
    };
    for (_, renderer) in &trained.renderers {
        renderer.extra_reports(&ctx)?;
    }
    qualitative_figure(
        &dir.join("qualitative.png"),
        &truth,
        &truth_depth,
        &rendered[0].predictions,
        [data.height, data.width],
    )?;
    let (result, quality) = (rows[0].clone(), qualities.swap_remove(0));
    Ok(RunOutcome {
        result,
        quality,
        rows,
        log: trained.log,
    })
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
pub(crate) fn nth_image(v: &[f32], i: usize, px: usize) -> &[f32] {
    &v[i * px..(i + 1) * px]
}

/// The (at most) six samples of `n` a qualitative grid shows, spread evenly.
pub(crate) fn grid_picks(n: usize) -> Vec<usize> {
    (0..6.min(n)).map(|k| k * n / 6.min(n).max(1)).collect()
}
