//! What a new self-model implements (start here): [`SelfModel`] on its config (data, network,
//! loss, training, loading), [`Render`] on its trained network (joint angles in, silhouette
//! and depth out), and what the harness hands them ([`Fit`], [`LoadContext`],
//! [`ReportContext`]). [`crate::self_models::harness::run`] does the rest.

use std::ops::Range;
use std::path::Path;

use burn::tensor::{Device, Tensor};

use crate::core::device::DeviceChoice;
use crate::core::error::Result;
use crate::data::dataset::Dataset;
use crate::eval::evaluation::{DepthPixels, Predictions};
use crate::eval::inference_speed::Timing;
use crate::self_models::data_spec::DataSpec;
use crate::sim::camera::Camera;
use crate::sim::robot::Robot;
use crate::train::{
    batcher::{Batch, TrainSet},
    checkpoint::CheckpointPlan,
    config::{TrainConfig, TrainLog},
    trainer::{StepLoss, Trainer},
};

/// A visual self-model: joint angles in, the robot's silhouette (and depth) out. Implement
/// it on the model's config; [`crate::self_models::harness::run`] does the rest.
pub trait SelfModel: Clone + std::fmt::Debug + PartialEq + serde::Serialize {
    /// Its kind in a saved model's `model.json` ([`crate::self_models::saved`]), which
    /// picks its loader ([`crate::self_models::loading`]).
    const KIND: &'static str;
    /// What its training hands back to render (its network, or its renderers).
    type Renderer: Render + 'static;
    /// The image it renders, `[height, width]` (the dataset's camera must match).
    fn image(&self) -> [usize; 2];
    /// Train on `fit.train_set` and hand back what renders.
    fn fit(&self, fit: &Fit) -> Result<Trained<Self::Renderer>>;
    /// What a checkpoint must match to be resumed.
    fn fingerprint(&self, train: &TrainConfig, data: &DataSpec) -> serde_json::Value {
        serde_json::json!({"model": self, "train": train, "data": data.fingerprint()})
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
    /// Whether it trains in a lower precision (`precision`, [`crate::train::precision`]):
    /// a network whose every op follows its input's dtype.
    fn autocasts(&self) -> bool {
        false
    }
    /// Whether it takes the camera as input: each sample's inputs are then its joint angles
    /// followed by its camera's [`crate::self_models::camera_input::camera_input`] (`[n, dof + 9]`).
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
    fn load(&self, _weights: &Path, _ctx: &LoadContext) -> Result<Loaded> {
        Ok(None)
    }
}

/// A saved self-model's renderer, rebuilt ([`SelfModel::load`]); `None`: its kind saves no
/// weights that load.
pub type Loaded = Option<Box<dyn Render + Send + Sync>>;

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
pub fn load_network<R>(template: R, weights: &Path) -> Result<Loaded>
where
    R: Render + burn::module::Module + Send + Sync + 'static,
{
    let network = crate::train::checkpoint::load_module(template, weights)?;
    Ok(Some(Box::new(network)))
}

/// [`SelfModel::fit`] for a burn network: `network` (untrained, on `fit.train_device`, with
/// `parameters` trainable parameters) trained by the one training loop on `set` with `loss`,
/// checkpointed as `fit` plans, then moved off the autodiff graph to render.
pub fn train_network<N, L, S>(
    parameters: usize,
    network: N,
    fit: &Fit,
    set: &TrainSet,
    loss: L,
) -> Result<Trained<N>>
where
    N: burn::module::Module + Render + 'static,
    L: Fn(&N, &Batch) -> S,
    S: Into<StepLoss>,
{
    let (network, log) = Trainer::new(fit.train, fit.label)
        .checkpoint(Some(fit.plan))
        .fit(network, set, loss)?;
    Ok(Trained::one(network.valid(), parameters, log))
}

/// What a self-model trains with.
pub struct Fit<'a> {
    /// On the training (autodiff) device: inputs `[n, dof]` joint angles in degrees, targets
    /// silhouettes and depth (metres), each `[n, 1, H, W]`.
    pub train_set: &'a TrainSet,
    pub train: &'a TrainConfig,
    /// Checkpoints (`resume`), for the shared training loop.
    pub plan: &'a CheckpointPlan,
    /// The run's name, for progress bars.
    pub label: &'a str,
    /// Where the model trains (autodiff, seeded) and where the trained model renders.
    pub train_device: &'a Device,
    pub device: &'a Device,
    /// The robot and the camera the dataset was rendered with (for models with geometry).
    pub robot: &'a Robot,
    pub camera: &'a Camera,
    /// The device as chosen (`device`): CPU-only fast paths check it.
    pub device_choice: DeviceChoice,
    /// Whether each sample's inputs end with its camera's [`crate::self_models::camera_input::camera_input`] (a
    /// camera-conditioned model, or a 3-D model on a multi-view dataset): split them with
    /// [`crate::self_models::camera_input::views_of_rows`].
    pub cameras_in_inputs: bool,
}

/// A trained self-model, rendered by `R`.
pub struct Trained<R> {
    /// What renders, each with its label (empty for a model's one renderer; otherwise its
    /// row is "name (label)"). The first draws the qualitative figure.
    pub renderers: Vec<(String, R)>,
    /// Trainable parameters (PyTorch's count).
    pub parameters: usize,
    pub log: TrainLog,
    /// Said in the results row before the run's own note (empty: nothing).
    pub note: String,
}

impl<R> Trained<R> {
    /// A model with one renderer and nothing of its own to say in its row.
    pub fn one(renderer: R, parameters: usize, log: TrainLog) -> Self {
        Trained {
            renderers: vec![(String::new(), renderer)],
            parameters,
            log,
            note: String::new(),
        }
    }
}

/// Rendering with a trained self-model (and what reading the body back needs of it,
/// [`BodyFit`]).
pub trait Render: BodyFit {
    /// `[n, dof]` joint angles (degrees) -> silhouette probabilities in [0, 1]
    /// `[n, 1, H, W]`, and depth in metres where the model predicts it.
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>);
    /// The pixels its depth error counts (where the true silhouette is the robot, unless
    /// the model draws depth only where it draws the robot).
    fn depth_pixels(&self) -> DepthPixels {
        DepthPixels::TrueRobot
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
}

/// What reading a robot's body back from images ([`crate::body`]: pose, drift, link
/// lengths) needs of a trained renderer besides rendering: a copy differentiable in the joint
/// angles, and for a model that hangs on the kinematic chain (K-3DGS) its joint origins and
/// renders with others in their place. Every default says the model cannot.
pub trait BodyFit {
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

/// A renderer of any kind renders, as what it holds does (a study holding trained models of
/// several kinds together, [`crate::self_models::harness::Fitted::erased`]).
impl Render for Box<dyn Render> {
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        self.as_ref().render(angles)
    }
    fn depth_pixels(&self) -> DepthPixels {
        self.as_ref().depth_pixels()
    }
    fn render_view(&self, camera: &Camera, angles: Tensor<2>) -> Option<Tensor<4>> {
        self.as_ref().render_view(camera, angles)
    }
    fn save(&self, path: &Path) -> Result<Option<serde_json::Value>> {
        self.as_ref().save(path)
    }
}

impl BodyFit for Box<dyn Render> {
    fn differentiable(&self, autodiff: &Device) -> Option<Box<dyn Render>> {
        self.as_ref().differentiable(autodiff)
    }
    fn joint_origins(&self) -> Option<Vec<[f32; 3]>> {
        self.as_ref().joint_origins()
    }
    fn render_with_origins(&self, angles: Tensor<2>, origin_t: Tensor<2>) -> Option<Tensor<4>> {
        self.as_ref().render_with_origins(angles, origin_t)
    }
}

/// One renderer's test predictions and inference timings.
pub struct RenderedSet {
    pub label: String,
    pub predictions: Predictions,
    pub timings: Vec<Timing>,
}

/// A run evaluated, before its rows are written: what a study's reports of its own use
/// ([`crate::self_models::harness::run_with`]), the trained renderers `R` included.
pub struct ReportContext<'a, R> {
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
    /// What renders, each with its label, as [`Trained::renderers`].
    pub renderers: &'a [(String, R)],
}
