//! ResNeuroKin-D: NeuroKin with residual blocks and a second head for depth (self-modeling
//! paper, Section IV-D), built to the notebook's facts.
//!
//! - Encoder Linear 4->256->512->1024->2048 (ReLUs between, none on the output);
//!   Linear(2048, 512*8*8)+ReLU reshaped to `[batch, 512, 8, 8]`.
//! - Residual block at 512 (conv3x3-BN-ReLU-conv3x3-BN plus identity, ReLU), then
//!   ConvTranspose2d(k4, s2, p1)+BN+ReLU to 256 (16x16), residual block, to 128 (32x32),
//!   residual block, to 64 (64x64), residual block.
//! - Two heads, each Conv3x3 64->32, ReLU, Conv3x3 32->16, ReLU, Conv1x1 16->1: the silhouette
//!   through a sigmoid, the depth through a ReLU, both resized bilinearly to 100x100.
//!   78,971,714 parameters in the `paper` preset.
//!
//! The paper trained the depth head on a heuristic blob; ours learns the simulator's metric
//! depth (metres along the camera axis, 0 on background pixels).

use std::path::Path;

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::{Device, Tensor};

use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::kernels::batch_norm;
use crate::kernels::cpu_extension::{conv2d_layer, linear_layer, relu, sigmoid};
use crate::kernels::upconv::{UpConv, UpConvConfig};
use crate::self_models::neurokin::resize_bilinear;
use crate::self_models::{
    model::{
        BodyFit, Fit, LoadContext, Loaded, Render, SelfModel, Trained, load_network, train_network,
    },
    run_config::{SelfModelRun, model_preset},
};
use crate::train::batcher::Batch;
use crate::train::losses::{bce, l1_masked, soft_dice};

/// ResNeuroKin-D's architecture. Presets: `paper` (the code's facts), `quick` (tiny).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ResNeuroKinDConfig {
    pub dof: usize,
    /// Encoder widths after the input (the last is the latent width).
    pub encoder: Vec<usize>,
    /// Channels of the 8x8 seed map, then after each 2x upsampling.
    pub channels: Vec<usize>,
    /// Channels inside each head: `[hidden1, hidden2]`.
    pub head: [usize; 2],
    /// Output image size `[height, width]`.
    pub image: [usize; 2],
    /// The loss is `(BCE + soft Dice) / 2 + depth_weight * L1(depth)`. Our L1 is over the
    /// robot pixels of the true silhouette: over all pixels (the notebook's blob target), the
    /// 95% background pushes the ReLU depth head negative everywhere and it dies (measured:
    /// it predicted 0 on every pixel).
    #[serde(default = "notebook_depth_weight")]
    pub depth_weight: f64,
}

fn notebook_depth_weight() -> f64 {
    0.1
}

impl Preset for ResNeuroKinDConfig {
    fn paper() -> Self {
        ResNeuroKinDConfig {
            dof: 4,
            encoder: vec![256, 512, 1024, 2048],
            channels: vec![512, 256, 128, 64],
            head: [32, 16],
            image: [100, 100],
            depth_weight: notebook_depth_weight(),
        }
    }

    fn quick() -> Self {
        ResNeuroKinDConfig {
            dof: 4,
            encoder: vec![32, 64],
            channels: vec![32, 16, 8],
            head: [8, 8],
            image: [32, 32],
            depth_weight: notebook_depth_weight(),
        }
    }
}

/// conv3x3-BN-ReLU-conv3x3-BN plus identity, then ReLU.
#[derive(Module, Debug)]
pub struct ResidualBlock {
    conv1: Conv2d,
    bn1: BatchNorm,
    conv2: Conv2d,
    bn2: BatchNorm,
}

fn conv3x3(cin: usize, cout: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([cin, cout], [3, 3])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .init(device)
}

impl ResidualBlock {
    fn new(c: usize, device: &Device) -> Self {
        ResidualBlock {
            conv1: conv3x3(c, c, device),
            bn1: BatchNormConfig::new(c).init(device),
            conv2: conv3x3(c, c, device),
            bn2: BatchNormConfig::new(c).init(device),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = batch_norm(&self.bn1, conv2d_layer(&self.conv1, x.clone()), true);
        let y = batch_norm(&self.bn2, conv2d_layer(&self.conv2, y), false);
        relu(y + x)
    }
}

/// One output head: Conv3x3 -> ReLU -> Conv3x3 -> ReLU -> Conv1x1 (pre-activation output).
#[derive(Module, Debug)]
pub struct Head {
    convs: Vec<Conv2d>,
}

impl Head {
    fn new(cin: usize, hidden: [usize; 2], device: &Device) -> Self {
        Head {
            convs: vec![
                conv3x3(cin, hidden[0], device),
                conv3x3(hidden[0], hidden[1], device),
                Conv2dConfig::new([hidden[1], 1], [1, 1]).init(device),
            ],
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = relu(conv2d_layer(&self.convs[0], x));
        let x = relu(conv2d_layer(&self.convs[1], x));
        conv2d_layer(&self.convs[2], x)
    }
}

impl ResNeuroKinDConfig {
    pub fn validate(&self) -> Result<()> {
        if self.encoder.is_empty() || self.channels.is_empty() || self.dof == 0 {
            return Err(Error::Config(
                "resneurokin_d: encoder, channels and dof must not be empty".into(),
            ));
        }
        Ok(())
    }

    /// Build the model on a device, its parameters drawn from the generator seeded with
    /// `seed` (see [`crate::core::device::seeded`]).
    pub fn init(&self, device: &Device, seed: u64) -> Result<ResNeuroKinD> {
        self.validate()?;
        Ok(crate::core::device::seeded(device, seed, |d| self.build(d)))
    }

    fn build(&self, device: &Device) -> ResNeuroKinD {
        let mut widths = vec![self.dof];
        widths.extend(&self.encoder);
        let encoder = widths
            .windows(2)
            .map(|w| LinearConfig::new(w[0], w[1]).init(device))
            .collect();
        let c0 = self.channels[0];
        let seed = LinearConfig::new(*widths.last().unwrap(), c0 * 64).init(device);
        let mut blocks = vec![ResidualBlock::new(c0, device)];
        let mut ups = Vec::new();
        let mut norms = Vec::new();
        for w in self.channels.windows(2) {
            ups.push(UpConvConfig::new(w[0], w[1], 4, 2, 1).init(device));
            norms.push(BatchNormConfig::new(w[1]).init(device));
            blocks.push(ResidualBlock::new(w[1], device));
        }
        let c_last = *self.channels.last().unwrap();
        ResNeuroKinD {
            encoder,
            seed,
            blocks,
            ups,
            norms,
            silhouette_head: Head::new(c_last, self.head, device),
            depth_head: Head::new(c_last, self.head, device),
            seed_channels: c0,
            image: self.image,
        }
    }
}

/// The ResNeuroKin-D network.
#[derive(Module, Debug)]
pub struct ResNeuroKinD {
    encoder: Vec<Linear>,
    seed: Linear,
    blocks: Vec<ResidualBlock>,
    ups: Vec<UpConv>,
    norms: Vec<BatchNorm>,
    silhouette_head: Head,
    depth_head: Head,
    #[module(skip)]
    seed_channels: usize,
    #[module(skip)]
    image: [usize; 2],
}

impl ResNeuroKinD {
    /// Latent code: `[batch, dof]` degrees -> `[batch, 2048]`.
    pub fn encode(&self, angles: Tensor<2>) -> Tensor<2> {
        let mut x = angles;
        let last = self.encoder.len() - 1;
        for (i, layer) in self.encoder.iter().enumerate() {
            x = linear_layer(layer, x);
            if i < last {
                x = relu(x);
            }
        }
        x
    }

    /// Trainable parameters (PyTorch's count: BatchNorm running statistics excluded).
    pub fn trainable_params(&self) -> usize {
        let mut norms: Vec<&BatchNorm> = self.norms.iter().collect();
        for b in &self.blocks {
            norms.push(&b.bn1);
            norms.push(&b.bn2);
        }
        crate::train::trainer::trainable_params(self, &norms)
    }

    /// `[batch, dof]` degrees -> (silhouette probabilities, depth in metres), each
    /// `[batch, 1, H, W]`.
    pub fn forward(&self, angles: Tensor<2>) -> (Tensor<4>, Tensor<4>) {
        let z = self.encode(angles);
        let [b, _] = z.dims();
        let mut x = relu(linear_layer(&self.seed, z)).reshape([b, self.seed_channels, 8, 8]);
        x = self.blocks[0].forward(x);
        for (i, up) in self.ups.iter().enumerate() {
            x = batch_norm(&self.norms[i], up.forward(x), true);
            x = self.blocks[i + 1].forward(x);
        }
        let silhouette =
            resize_bilinear(sigmoid(self.silhouette_head.forward(x.clone())), self.image);
        let depth = resize_bilinear(relu(self.depth_head.forward(x)), self.image);
        (silhouette, depth)
    }
}

impl Render for ResNeuroKinD {
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        let (s, d) = self.forward(angles);
        (s, Some(d))
    }
    fn save(&self, path: &Path) -> Result<Option<serde_json::Value>> {
        crate::train::checkpoint::save_module(self, path)?;
        Ok(Some(serde_json::Value::Null))
    }
}

/// Not differentiable here, no chain of its own: nothing for reading the body back.
impl BodyFit for ResNeuroKinD {}

/// The robot pixels of a silhouette batch (1 where the true silhouette is >= 0.5).
fn robot_mask(silhouettes: &Tensor<4>) -> Tensor<4> {
    silhouettes.clone().greater_equal_elem(0.5).float()
}

impl SelfModel for ResNeuroKinDConfig {
    const KIND: &'static str = "resneurokin_d";
    type Renderer = ResNeuroKinD;

    fn image(&self) -> [usize; 2] {
        self.image
    }

    fn fit(&self, fit: &Fit) -> Result<Trained<ResNeuroKinD>> {
        let network = self.init(fit.train_device, fit.train.seed)?;
        let w = self.depth_weight;
        let loss = move |m: &ResNeuroKinD, b: &Batch| {
            let (s, d) = m.forward(b.inputs.clone());
            let y = b.targets[0].clone();
            let sil = (bce(s.clone(), y.clone()) + soft_dice(s, y)).div_scalar(2.0);
            sil + l1_masked(d, b.targets[1].clone(), robot_mask(&b.targets[0])).mul_scalar(w)
        };
        train_network(
            network.trainable_params(),
            network,
            fit,
            fit.train_set,
            loss,
        )
    }

    fn dof(&self) -> Option<usize> {
        Some(self.dof)
    }

    fn set_dof(&mut self, dof: usize) {
        self.dof = dof;
    }

    fn load(&self, weights: &Path, ctx: &LoadContext) -> Result<Loaded> {
        load_network(self.init(ctx.device, 0)?, weights)
    }

    fn autocasts(&self) -> bool {
        true
    }
}

/// ResNeuroKin-D as the notebook trained it, with the simulator's metric depth.
pub fn resneurokin_d_run(preset: &str) -> Result<SelfModelRun<ResNeuroKinDConfig>> {
    let mut model = ResNeuroKinDConfig::preset(model_preset(preset))?;
    model.image = SelfModelRun::<ResNeuroKinDConfig>::image(preset)?;
    Ok(SelfModelRun::new(preset, "ResNeuroKin-D", model, 64)?
        .shorten(40, 12)
        .short_test_set(100))
}
