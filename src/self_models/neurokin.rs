//! NeuroKin: a direct joint-angles-to-silhouette decoder (self-modeling paper, Section IV-C).
//!
//! Two architectures share this file, because the paper's text and the code that produced its
//! numbers disagree:
//! - [`NeuroKinArch::Code`] (the `paper` preset, the notebook's facts): encoder
//!   4->128->256->latent (ReLUs between, none on the output), Linear(latent, 4096)+ReLU reshaped
//!   to 256x4x4, transposed convolutions k4/s2/p1 with BatchNorm+ReLU (256->128->64->32, 4->32 px),
//!   ConvTranspose2d(32->16, k3, s1, p2)+BN+ReLU (30x30), a bilinear resize of the 16 feature
//!   channels to 100x100 (align_corners false), Conv3x3(16->8)+ReLU, Conv1x1(8->1). 5,189,857
//!   parameters at latent 1024.
//! - [`NeuroKinArch::Text64`] (variant `neurokin64`, as the paper's text describes it): Linear
//!   4->512->4096 (ReLU) -> 256x4x4, four ConvTranspose2d(k4, s2, p1)+ReLU to 16x64x64,
//!   Conv1x1 -> 1. Trained at 64x64; its predictions are resized bilinearly to 100x100 for
//!   evaluation.
//!
//! Input: joint angles in degrees, `[batch, dof]`. Output: silhouette logits `[batch, 1, H, W]`
//! (the sigmoid is applied by [`NeuroKin::predict`] and inside the loss, where it is stable).
//!
//! The ablation knobs (`upsampling_layers`, `latent`) follow the paper's Section V-C: the
//! decoder has `upsampling_layers` transposed convolutions; all but the last double the
//! resolution (channels halve from 256 down to a floor of 16); the last is the k3/s1/p2 layer.

use std::path::Path;

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::{Device, Tensor};

use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::kernels::cpu_extension::{conv2d_layer, linear_layer, relu, sigmoid};
use crate::kernels::upconv::{UpConv, UpConvConfig};
use crate::self_models::tree_encoder::TreeEncoder;
use crate::self_models::{
    model::{
        BodyFit, Fit, LoadContext, Loaded, Render, SelfModel, Trained, load_network, train_network,
    },
    run_config::{SelfModelRun, model_preset},
};
use crate::train::losses::{bce_with_logits, mse};
use crate::train::{
    batcher::{Batch, TrainSet},
    config::TrainConfig,
};

/// Which of the two published NeuroKin architectures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NeuroKinArch {
    /// The notebook's architecture (BatchNorm, 30x30 features resized to 100x100, conv head).
    Code,
    /// The paper text's architecture (no BatchNorm, 64x64 output, 1x1 head).
    Text64,
}

/// NeuroKin's architecture. Presets: `paper` (the code's facts), `quick` (tiny, for tests),
/// [`NeuroKinConfig::text64`] (the paper text's variant).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NeuroKinConfig {
    pub arch: NeuroKinArch,
    /// Joints (input width).
    pub dof: usize,
    /// Hidden widths of the joint encoder before the latent layer.
    pub encoder_hidden: Vec<usize>,
    /// Latent width `z` (Section V-C3 ablates 256..2048).
    pub latent: usize,
    /// Channels of the 4x4 seed feature map.
    pub seed_channels: usize,
    /// Transposed convolutions in the decoder (Section V-C2 ablates 2, 4, 6).
    pub upsampling_layers: usize,
    /// Output image size `[height, width]` in pixels (evaluation size).
    pub image: [usize; 2],
    /// The training loss (the notebook's BCE; the paper text's MSE).
    #[serde(default)]
    pub loss: NeuroKinLoss,
    /// How the camera enters, on a multi-view dataset (the paper's NeuroKin: not at all).
    #[serde(default, skip_serializing_if = "CameraUse::is_none")]
    pub camera: CameraUse,
    /// The joint encoder: the paper's flat MLP, or one that follows the kinematic tree.
    #[serde(default, skip_serializing_if = "JointEncoder::is_flat")]
    pub encoder: JointEncoder,
}

/// How NeuroKin encodes the joints (Section VI-D4's proposal for robots of many joints).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointEncoder {
    /// The paper's MLP on the joint vector (`encoder_hidden`, then `latent`).
    #[default]
    Flat,
    /// Message passing down the kinematic tree ([`crate::self_models::tree_encoder`]), at
    /// the flat MLP's parameter count: each joint's parent in the joint vector (`None`: a
    /// root joint; filled from the robot), and the state width.
    Tree {
        parents: Vec<Option<usize>>,
        width: usize,
    },
}

impl JointEncoder {
    pub fn is_flat(&self) -> bool {
        *self == JointEncoder::Flat
    }
}

/// How a NeuroKin sees the camera (the self-modeling paper's Section VI-D1 proposals).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraUse {
    /// One camera, the one it was trained on (the paper's).
    #[default]
    None,
    /// Camera conditioning, f(theta, c): the camera's pose vector
    /// ([`crate::self_models::camera_input::camera_input`]) joins the joint angles at the encoder's
    /// input; any camera renders.
    Input,
    /// Multi-head: one output channel per fixed camera (these, as their pose vectors), the
    /// encoder and decoder shared and blind to the camera; a sample's image is the channel of
    /// the camera nearest its own (a camera not trained on gets the nearest trained view).
    Heads(Vec<[f32; 9]>),
}

impl CameraUse {
    pub fn is_none(&self) -> bool {
        *self == CameraUse::None
    }
}

/// NeuroKin's training loss on the silhouette.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NeuroKinLoss {
    /// Binary cross-entropy (the notebook's).
    #[default]
    Bce,
    /// Mean squared error on the probabilities (the paper text's).
    Mse,
}

impl Preset for NeuroKinConfig {
    fn paper() -> Self {
        NeuroKinConfig {
            arch: NeuroKinArch::Code,
            dof: 4,
            encoder_hidden: vec![128, 256],
            latent: 1024,
            seed_channels: 256,
            upsampling_layers: 4,
            image: [100, 100],
            loss: NeuroKinLoss::Bce,
            camera: CameraUse::None,
            encoder: JointEncoder::Flat,
        }
    }

    fn quick() -> Self {
        NeuroKinConfig {
            encoder_hidden: vec![32],
            latent: 64,
            seed_channels: 32,
            image: [32, 32],
            ..Self::paper()
        }
    }
}

impl NeuroKinConfig {
    /// The paper text's architecture: 4->512->4096, four ConvT+ReLU to 16x64x64, 1x1 head.
    pub fn text64() -> Self {
        NeuroKinConfig {
            arch: NeuroKinArch::Text64,
            dof: 4,
            encoder_hidden: vec![],
            latent: 512,
            seed_channels: 256,
            upsampling_layers: 4,
            image: [100, 100],
            loss: NeuroKinLoss::Mse,
            camera: CameraUse::None,
            encoder: JointEncoder::Flat,
        }
    }

    /// The tree encoder for the joints whose parents are `parents` (the robot's
    /// [`crate::sim::kinematics::KinematicChain::input_parents`]), at the flat MLP's size.
    pub fn use_tree(&mut self, parents: &[Option<usize>]) {
        self.encoder = JointEncoder::Tree {
            parents: parents.to_vec(),
            width: crate::self_models::tree_encoder::matched_width(
                parents.len(),
                &self.encoder_hidden,
                self.latent,
            ),
        };
    }

    /// Resolution the network is trained at (`image`, except 64x64-style native outputs of
    /// the text variant, which are `4 * 2^layers`).
    /// A training set (silhouettes at the evaluation size) as the decoder trains on it: the
    /// targets at its native size.
    pub fn training_set(&self, set: &TrainSet) -> TrainSet {
        let mut set = set.clone();
        let native = self.native_size();
        if native != self.image {
            set.targets[0] = resize_bilinear(set.targets[0].clone(), native);
        }
        set
    }

    /// The loss a batch of [`NeuroKinConfig::training_set`] trains with (the config's).
    pub fn training_loss(&self) -> impl Fn(&NeuroKin, &Batch) -> Tensor<1> + use<> {
        let loss = self.loss;
        move |m: &NeuroKin, b: &Batch| {
            let z = m.forward(b.inputs.clone());
            match loss {
                NeuroKinLoss::Mse => mse(sigmoid(z), b.targets[0].clone()),
                NeuroKinLoss::Bce => bce_with_logits(z, b.targets[0].clone()),
            }
        }
    }

    pub fn native_size(&self) -> [usize; 2] {
        match self.arch {
            NeuroKinArch::Code => self.image,
            NeuroKinArch::Text64 => {
                let s = 4 << self.upsampling_layers;
                [s, s]
            }
        }
    }

    /// Reject impossible shapes with a message that says what to change.
    pub fn validate(&self) -> Result<()> {
        if self.dof == 0 || self.latent == 0 || self.seed_channels == 0 {
            return Err(Error::Config(
                "neurokin: dof, latent and seed_channels must be positive".into(),
            ));
        }
        if !(1..=7).contains(&self.upsampling_layers) {
            return Err(Error::Config(format!(
                "neurokin: upsampling_layers must be 1..7, got {}",
                self.upsampling_layers
            )));
        }
        if matches!(&self.camera, CameraUse::Heads(h) if h.is_empty()) {
            return Err(Error::Config(
                "neurokin: a multi-head decoder needs at least one camera".into(),
            ));
        }
        if let JointEncoder::Tree { parents, .. } = &self.encoder {
            if parents.len() != self.dof {
                return Err(Error::Config(format!(
                    "neurokin: the tree encoder knows {} joints' parents for {} joints: it needs the robot's description (`urdf`), not only a dataset",
                    parents.len(),
                    self.dof
                )));
            }
            if !self.camera.is_none() {
                return Err(Error::Config(
                    "neurokin: the tree encoder takes joints only, not a camera".into(),
                ));
            }
            crate::self_models::tree_encoder::check_tree(parents)?;
        }
        if self.arch == NeuroKinArch::Code && self.upsampling_layers < 2 {
            return Err(Error::Config(
                "neurokin: the code architecture needs at least 2 upsampling layers".into(),
            ));
        }
        Ok(())
    }

    /// Channels after each transposed convolution.
    fn decoder_channels(&self) -> Vec<usize> {
        let doubling = match self.arch {
            NeuroKinArch::Code => self.upsampling_layers - 1,
            NeuroKinArch::Text64 => self.upsampling_layers,
        };
        let mut chans: Vec<usize> = (1..=doubling)
            .map(|i| (self.seed_channels >> i).max(16))
            .collect();
        if self.arch == NeuroKinArch::Code {
            chans.push(16);
        }
        chans
    }

    /// Build the model on a device, its parameters drawn from the generator seeded with
    /// `seed` (see [`crate::core::device::seeded`]).
    pub fn init(&self, device: &Device, seed: u64) -> Result<NeuroKin> {
        self.validate()?;
        Ok(crate::core::device::seeded(device, seed, |d| self.build(d)))
    }

    /// Input values the network reads: the joints, and the camera's 9 where it is an input.
    fn input_width(&self) -> usize {
        self.dof
            + match self.camera {
                CameraUse::Input => 9,
                _ => 0,
            }
    }

    /// Output channels: one, or one per head.
    fn outputs(&self) -> usize {
        match &self.camera {
            CameraUse::Heads(h) => h.len(),
            _ => 1,
        }
    }

    fn build(&self, device: &Device) -> NeuroKin {
        let mut widths = vec![self.input_width()];
        widths.extend(&self.encoder_hidden);
        widths.push(self.latent);
        let (encoder, tree) = match &self.encoder {
            JointEncoder::Flat => (
                widths
                    .windows(2)
                    .map(|w| LinearConfig::new(w[0], w[1]).init(device))
                    .collect(),
                None,
            ),
            JointEncoder::Tree { parents, width } => {
                let readout = &widths[widths.len().saturating_sub(2).max(1)..];
                (
                    Vec::new(),
                    Some(
                        TreeEncoder::new(parents, *width, readout, device)
                            .expect("a validated tree"),
                    ),
                )
            }
        };
        let seed = LinearConfig::new(self.latent, self.seed_channels * 16).init(device);
        let chans = self.decoder_channels();
        let mut ups = Vec::new();
        let mut norms = Vec::new();
        let mut cin = self.seed_channels;
        for (i, &cout) in chans.iter().enumerate() {
            let last_code_layer = self.arch == NeuroKinArch::Code && i + 1 == chans.len();
            let cfg = if last_code_layer {
                UpConvConfig::new(cin, cout, 3, 1, 2)
            } else {
                UpConvConfig::new(cin, cout, 4, 2, 1)
            };
            ups.push(cfg.init(device));
            if self.arch == NeuroKinArch::Code {
                norms.push(BatchNormConfig::new(cout).init(device));
            }
            cin = cout;
        }
        let head = match self.arch {
            NeuroKinArch::Code => vec![
                Conv2dConfig::new([cin, 8], [3, 3])
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .init(device),
                Conv2dConfig::new([8, self.outputs()], [1, 1]).init(device),
            ],
            NeuroKinArch::Text64 => {
                vec![Conv2dConfig::new([cin, self.outputs()], [1, 1]).init(device)]
            }
        };
        NeuroKin {
            encoder,
            tree,
            seed,
            ups,
            norms,
            head,
            seed_channels: self.seed_channels,
            arch: self.arch,
            image: self.image,
            dof: self.dof,
            heads: match &self.camera {
                CameraUse::Heads(h) => h.clone(),
                _ => Vec::new(),
            },
        }
    }
}

/// The NeuroKin network (either architecture).
#[derive(Module, Debug)]
pub struct NeuroKin {
    encoder: Vec<Linear>,
    /// The tree encoder, in place of `encoder` ([`JointEncoder::Tree`]).
    tree: Option<TreeEncoder>,
    seed: Linear,
    ups: Vec<UpConv>,
    norms: Vec<BatchNorm>,
    head: Vec<Conv2d>,
    #[module(skip)]
    seed_channels: usize,
    #[module(skip)]
    arch: NeuroKinArch,
    #[module(skip)]
    image: [usize; 2],
    /// Joints (the inputs' first columns).
    #[module(skip)]
    dof: usize,
    /// The multi-head decoder's cameras (pose vectors); empty: one output.
    #[module(skip)]
    heads: Vec<[f32; 9]>,
}

/// Bilinear resize with align_corners false (PyTorch's `F.interpolate(..., "bilinear")`).
pub fn resize_bilinear(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    if [h, w] == size {
        return x;
    }
    crate::kernels::cpu_extension::resize_bilinear(x, size)
}

impl NeuroKin {
    /// Latent code `z`: `[batch, dof]` degrees -> `[batch, latent]`.
    pub fn encode(&self, angles: Tensor<2>) -> Tensor<2> {
        if let Some(tree) = &self.tree {
            return tree.forward(angles);
        }
        let mut x = angles;
        let last = self.encoder.len() - 1;
        for (i, layer) in self.encoder.iter().enumerate() {
            x = linear_layer(layer, x);
            // The code's encoder has no activation on its output; the text variant's has.
            if i < last || self.arch == NeuroKinArch::Text64 {
                x = relu(x);
            }
        }
        x
    }

    /// Silhouette logits at the training resolution: `[batch, dof]` (joint angles in degrees,
    /// then the camera's input where it takes one) -> `[batch, 1, H, W]`.
    pub fn forward(&self, angles: Tensor<2>) -> Tensor<4> {
        if self.heads.is_empty() {
            return self.decode(angles);
        }
        // Multi-head: the joints decode to one image per head; each sample takes the head
        // whose camera is nearest its own.
        let [b, _] = angles.dims();
        let (v, dof) = (self.heads.len(), self.dof);
        let device = angles.device();
        let camera = angles.clone().slice([0..b, dof..dof + 9]);
        let heads = Tensor::<2>::from_data(
            burn::tensor::TensorData::new(self.heads.concat(), [v, 9]),
            &device,
        );
        let nearest = (camera.unsqueeze_dim::<3>(1) - heads.unsqueeze_dim::<3>(0))
            .powi_scalar(2)
            .sum_dim(2)
            .reshape([b, v])
            .argmin(1);
        let logits = self.decode(angles.slice([0..b, 0..dof]));
        let [_, _, h, w] = logits.dims();
        logits.gather(1, nearest.reshape([b, 1, 1, 1]).expand([b, 1, h, w]))
    }

    /// The decoder's logits, one channel per head: `[batch, inputs]` -> `[batch, heads, H, W]`.
    fn decode(&self, angles: Tensor<2>) -> Tensor<4> {
        let z = self.encode(angles);
        let [b, _] = z.dims();
        let mut x = relu(linear_layer(&self.seed, z)).reshape([b, self.seed_channels, 4, 4]);
        for (i, up) in self.ups.iter().enumerate() {
            x = up.forward(x);
            x = match self.norms.get(i) {
                Some(norm) => crate::kernels::batch_norm(norm, x, true),
                None => relu(x),
            };
        }
        match self.arch {
            NeuroKinArch::Code => {
                x = resize_bilinear(x, self.image);
                x = relu(conv2d_layer(&self.head[0], x));
                conv2d_layer(&self.head[1], x)
            }
            NeuroKinArch::Text64 => conv2d_layer(&self.head[0], x),
        }
    }

    /// Trainable parameters (PyTorch's count: BatchNorm running statistics excluded).
    pub fn trainable_params(&self) -> usize {
        crate::train::trainer::trainable_params(self, &self.norms.iter().collect::<Vec<_>>())
    }

    /// Silhouette probabilities at the evaluation size: `[batch, dof]` -> `[batch, 1, H, W]`
    /// in [0, 1].
    pub fn predict(&self, angles: Tensor<2>) -> Tensor<4> {
        resize_bilinear(sigmoid(self.forward(angles)), self.image)
    }
}

impl Render for NeuroKin {
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        (self.predict(angles), None)
    }
    fn save(&self, path: &Path) -> Result<Option<serde_json::Value>> {
        crate::train::checkpoint::save_module(self, path)?;
        Ok(Some(serde_json::Value::Null))
    }
}

impl BodyFit for NeuroKin {
    fn differentiable(&self, autodiff: &Device) -> Option<Box<dyn Render>> {
        Some(Box::new(self.clone().fork(autodiff).freeze()))
    }
}

impl SelfModel for NeuroKinConfig {
    const KIND: &'static str = "neurokin";
    type Renderer = NeuroKin;

    fn image(&self) -> [usize; 2] {
        self.image
    }

    fn fit(&self, fit: &Fit) -> Result<Trained<NeuroKin>> {
        let network = self.init(fit.train_device, fit.train.seed)?;
        let set = self.training_set(fit.train_set);
        train_network(
            network.trainable_params(),
            network,
            fit,
            &set,
            self.training_loss(),
        )
    }

    fn dof(&self) -> Option<usize> {
        Some(self.dof)
    }

    fn set_dof(&mut self, dof: usize) {
        self.dof = dof;
    }

    fn set_joint_tree(&mut self, parents: &[Option<usize>]) {
        if !self.encoder.is_flat() {
            self.use_tree(parents);
        }
    }

    fn camera_input(&self) -> bool {
        !self.camera.is_none()
    }

    fn load(&self, weights: &Path, ctx: &LoadContext) -> Result<Loaded> {
        load_network(self.init(ctx.device, 0)?, weights)
    }

    /// The flat encoder follows its input's dtype; the tree encoder's messages are f32 only.
    fn autocasts(&self) -> bool {
        self.encoder.is_flat()
    }
}

/// NeuroKin's run on `preset`, as the notebook trained it: BCE, Adam 1e-3, batch 32, 3,000
/// steps, clip 1.0, N(0, 0.01) noise on the angles in degrees.
pub fn neurokin_run(preset: &str) -> Result<SelfModelRun<NeuroKinConfig>> {
    let mut model = NeuroKinConfig::preset(model_preset(preset))?;
    model.image = SelfModelRun::<NeuroKinConfig>::image(preset)?;
    let run = SelfModelRun::new(preset, "NeuroKin", model, 256)?;
    Ok(run.shorten(200, 32))
}

/// NeuroKin with the tree encoder in place of the flat MLP, at its parameter count; the rest
/// as [`neurokin_run`]. The joints' parents come from the robot ([`SelfModel::set_joint_tree`]).
pub fn neurokin_tree_run(preset: &str) -> Result<SelfModelRun<NeuroKinConfig>> {
    let mut cfg = neurokin_run(preset)?;
    cfg.name = "NeuroKin (tree encoder)".into();
    // A chain (the papers' arm) until the robot's tree replaces it.
    let chain: Vec<Option<usize>> = (0..cfg.model.dof).map(|i| i.checked_sub(1)).collect();
    cfg.model.use_tree(&chain);
    Ok(cfg)
}

/// The paper text's NeuroKin: 64x64 output, MSE, batch 128, 50 epochs.
pub fn neurokin64_run(preset: &str) -> Result<SelfModelRun<NeuroKinConfig>> {
    let quick = preset == "quick";
    let mut model = NeuroKinConfig::text64();
    model.image = SelfModelRun::<NeuroKinConfig>::image(preset)?;
    if quick {
        model.latent = 64;
        model.seed_channels = 32;
        model.upsampling_layers = 3;
    }
    let mut cfg = SelfModelRun::new(preset, "NeuroKin-64 (paper text)", model, 256)?;
    cfg.train.batch = if quick { 32 } else { 128 };
    cfg.train.steps = TrainConfig::steps_for_epochs(
        if quick { 30 } else { 50 },
        cfg.data.dataset.train,
        cfg.train.batch,
    );
    cfg.train.grad_clip_norm = None;
    let steps = cfg.train.steps / 4;
    Ok(cfg.shorten(steps, 128))
}
