//! LinkSplat: a direct decoder that sees where each link is (issue 75's answer to NeuroKin on
//! robots of many joints).
//!
//! NeuroKin reads the joint vector through an MLP and must learn forward kinematics and the
//! camera from pixels; on the 29-joint G1 it barely clears the constant image. LinkSplat
//! computes what a robot knows of itself from its description (forward kinematics, as K-3DGS
//! does) and learns only how each link looks:
//!
//! 1. **Anchors.** Each link with geometry gets `anchors_per_link` points: the centres of
//!    clusters of its surface (Lloyd's iterations from farthest-point seeds,
//!    [`crate::sim::collision::spheres::clusters`]), each with its cluster's radius. They
//!    are fixed once, from the description.
//! 2. **Where they are.** Forward kinematics ([`TensorChain`]) places them in the world; the
//!    camera projects each to (row, column, depth). Differentiable in the joint angles, so
//!    reading the body back from an image works as with the other decoders.
//! 3. **What each says.** A small MLP turns each anchor's link rotation in the camera frame
//!    (9 values), its depth and its image position into `features` values; a learned
//!    embedding per anchor (added before the ReLU) lets every part of every link speak for
//!    itself.
//! 4. **Splat.** Each anchor's features are spread on a grid of a quarter of the image's
//!    resolution by a Gaussian as wide as its cluster seen from the camera (at least
//!    `min_sigma_cells` cells): one batched matrix product, `[C, A] x [A, cells]`.
//! 5. **Decode.** `convs` 3x3 convolutions on the grid, two transposed convolutions (k4, s2)
//!    to the image, a 3x3 head: silhouette logits.
//!
//! Trained as NeuroKin is (BCE, Adam, the same steps), on the same data.

mod anchors;

use anchors::Seen;
pub use anchors::{Anchors, anchors};

use std::path::Path;

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::{Device, Tensor, TensorData};

use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::kernels::cpu_extension::{conv2d_layer, linear_layer, relu, sigmoid};
use crate::kernels::upconv::{UpConv, UpConvConfig};
use crate::self_models::model::{
    BodyFit, Fit, LoadContext, Loaded, Render, SelfModel, Trained, train_network,
};
use crate::self_models::run_config::{SelfModelRun, model_preset};
use crate::sim::camera::Camera;
use crate::sim::kinematics::KinematicChain;
use crate::sim::robot::Robot;
use crate::sim::tensor_kinematics::TensorChain;
use crate::train::batcher::Batch;
use crate::train::losses::bce_with_logits;

/// How many grid cells an image pixel row holds: the splatting grid is a quarter of the image.
const GRID_DIVISOR: usize = 4;

/// LinkSplat's architecture. Presets: `paper` (the G1-scale decoder), `quick` (tiny, tests).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinkSplatConfig {
    /// Joints (input width; the robot's).
    pub dof: usize,
    /// Anchor points a link (fewer where a link has fewer surface samples).
    pub anchors_per_link: usize,
    /// Hidden width of each anchor's MLP.
    pub hidden: usize,
    /// Feature channels splatted on the grid (and the grid convolutions' width).
    pub features: usize,
    /// 3x3 convolutions on the grid before upsampling.
    pub convs: usize,
    /// The narrowest splat (grid cells, standard deviation).
    pub min_sigma_cells: f64,
    /// Output image `[height, width]` (each a multiple of 4).
    pub image: [usize; 2],
}

impl Preset for LinkSplatConfig {
    fn paper() -> Self {
        LinkSplatConfig {
            dof: 4,
            anchors_per_link: 4,
            hidden: 64,
            features: 48,
            convs: 3,
            min_sigma_cells: 0.75,
            image: [100, 100],
        }
    }

    fn quick() -> Self {
        LinkSplatConfig {
            anchors_per_link: 2,
            hidden: 16,
            features: 16,
            convs: 1,
            image: [32, 32],
            ..Self::paper()
        }
    }
}

impl LinkSplatConfig {
    /// Reject impossible shapes with a message that says what to change.
    pub fn validate(&self) -> Result<()> {
        if self.dof == 0 || self.anchors_per_link == 0 || self.hidden == 0 || self.features == 0 {
            return Err(Error::Config(
                "link_splat: dof, anchors_per_link, hidden and features must be positive".into(),
            ));
        }
        if self.image.iter().any(|&s| s == 0 || s % GRID_DIVISOR != 0) {
            return Err(Error::Config(format!(
                "link_splat: image {:?}: each side must be a positive multiple of {GRID_DIVISOR}",
                self.image
            )));
        }
        if !(self.min_sigma_cells.is_finite() && self.min_sigma_cells > 0.0) {
            return Err(Error::Config(
                "link_splat: min_sigma_cells must be above 0".into(),
            ));
        }
        Ok(())
    }

    /// The network for `robot` seen from `camera`, on `device`, drawn from `seed`.
    pub fn init(
        &self,
        robot: &Robot,
        anchors: Anchors,
        camera: &Camera,
        device: &Device,
        seed: u64,
    ) -> Result<LinkSplat> {
        self.validate()?;
        Ok(crate::core::device::seeded(device, seed, |d| {
            self.build(robot, anchors, camera, d)
        }))
    }

    fn build(
        &self,
        robot: &Robot,
        anchors: Anchors,
        camera: &Camera,
        device: &Device,
    ) -> LinkSplat {
        let a = anchors.links.len();
        // Features at the grid, halved and quartered (at least 4) at the two upsamplings.
        let (c, half, quarter) = (self.features, self.features / 2, (self.features / 4).max(4));
        let conv3 = |cin: usize, cout: usize| {
            Conv2dConfig::new([cin, cout], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(device)
        };
        let embedding = Tensor::random(
            [1, a, self.hidden],
            burn::tensor::Distribution::Normal(0.0, 0.1),
            device,
        );
        LinkSplat {
            input: LinearConfig::new(ANCHOR_INPUTS, self.hidden).init(device),
            embedding: Param::from_tensor(embedding),
            output: LinearConfig::new(self.hidden, c).init(device),
            convs: (0..self.convs).map(|_| conv3(c, c)).collect(),
            ups: vec![
                UpConvConfig::new(c, half, 4, 2, 1).init(device),
                UpConvConfig::new(half, quarter, 4, 2, 1).init(device),
            ],
            head: conv3(quarter, 1),
            chain: TensorChain::new(&robot.chain),
            host: robot.chain.clone(),
            through_tensors: false,
            camera: camera.clone(),
            min_sigma_cells: self.min_sigma_cells,
            image: self.image,
            anchors,
        }
    }
}

/// What each anchor's MLP reads: its link's rotation in the camera frame (9), its depth and
/// its image row and column (scaled to about [-1, 1]).
const ANCHOR_INPUTS: usize = 12;

/// The LinkSplat network.
#[derive(Module, Debug)]
pub struct LinkSplat {
    input: Linear,
    /// `[1, anchors, hidden]`.
    embedding: Param<Tensor<3>>,
    output: Linear,
    convs: Vec<Conv2d>,
    ups: Vec<UpConv>,
    head: Conv2d,
    #[module(skip)]
    chain: TensorChain,
    /// The same chain for the host's forward kinematics.
    #[module(skip)]
    host: KinematicChain,
    /// Whether the anchors are placed in tensor ops (differentiable in the angles) rather
    /// than on the host.
    #[module(skip)]
    through_tensors: bool,
    #[module(skip)]
    camera: Camera,
    #[module(skip)]
    anchors: Anchors,
    #[module(skip)]
    min_sigma_cells: f64,
    #[module(skip)]
    image: [usize; 2],
}

impl LinkSplat {
    /// The splatting grid `[rows, columns]`.
    fn grid(&self) -> [usize; 2] {
        self.image.map(|s| s / GRID_DIVISOR)
    }

    /// Each anchor's features spread on the grid: `[B, features, rows, columns]`.
    fn splat(&self, seen: Seen) -> Tensor<4> {
        let [b, a] = seen.row.dims();
        let device = seen.row.device();
        let hidden = self.embedding.dims()[2];
        let h =
            linear_layer(&self.input, seen.inputs).reshape([b, a, hidden]) + self.embedding.val();
        let features = linear_layer(&self.output, relu(h).reshape([b * a, hidden]));
        let c = features.dims()[1];
        let [gh, gw] = self.grid();
        let axis = |n: usize| {
            Tensor::<1>::from_data(
                TensorData::new((0..n).map(|k| k as f32).collect(), [n]),
                &device,
            )
        };
        let inv = seen
            .sigma
            .square()
            .recip()
            .mul_scalar(-0.5)
            .reshape([b, a, 1]);
        let along = |p: Tensor<2>, n: usize| {
            let d = axis(n).reshape([1, 1, n]) - p.reshape([b, a, 1]);
            (d.square() * inv.clone()).exp()
        };
        let rows = along(seen.row, gh).reshape([b, a, gh, 1]);
        let cols = along(seen.col, gw).reshape([b, a, 1, gw]);
        let heat = (rows * cols).reshape([b, a, gh * gw]);
        features
            .reshape([b, a, c])
            .swap_dims(1, 2)
            .matmul(heat)
            .reshape([b, c, gh, gw])
    }

    /// Silhouette logits `[B, 1, H, W]` for joint angles `[B, dof]` (degrees).
    pub fn forward(&self, angles: Tensor<2>) -> Tensor<4> {
        let mut x = self.splat(self.see(angles));
        for conv in &self.convs {
            x = relu(conv2d_layer(conv, x));
        }
        for up in &self.ups {
            x = relu(up.forward(x));
        }
        conv2d_layer(&self.head, x)
    }
}

impl Render for LinkSplat {
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        (sigmoid(self.forward(angles)), None)
    }
    fn save(&self, path: &Path) -> Result<Option<serde_json::Value>> {
        crate::train::checkpoint::save_module(self, path)?;
        Ok(Some(
            serde_json::to_value(&self.anchors).expect("anchors serialise"),
        ))
    }
}

impl BodyFit for LinkSplat {
    fn differentiable(&self, autodiff: &Device) -> Option<Box<dyn Render>> {
        let mut network = self.clone().fork(autodiff).freeze();
        network.through_tensors = true;
        Some(Box::new(network))
    }
}

impl SelfModel for LinkSplatConfig {
    const KIND: &'static str = "link_splat";
    type Renderer = LinkSplat;

    fn image(&self) -> [usize; 2] {
        self.image
    }

    fn needs_robot(&self) -> bool {
        true
    }

    fn dof(&self) -> Option<usize> {
        Some(self.dof)
    }

    fn set_dof(&mut self, dof: usize) {
        self.dof = dof;
    }

    fn fit(&self, fit: &Fit) -> Result<Trained<LinkSplat>> {
        if fit.cameras_in_inputs {
            return Err(Error::Config(
                "link_splat: it is trained on one camera: give a single-view dataset".into(),
            ));
        }
        let anchors = anchors(fit.robot, self.anchors_per_link)?;
        let network = self.init(
            fit.robot,
            anchors,
            fit.camera,
            fit.train_device,
            fit.train.seed,
        )?;
        train_network(
            network.num_params(),
            network,
            fit,
            fit.train_set,
            |m: &LinkSplat, b: &Batch| {
                bce_with_logits(m.forward(b.inputs.clone()), b.targets[0].clone())
            },
        )
    }

    /// Its anchors as saved, on the robot's chain, seen from the saved camera.
    fn load(&self, weights: &Path, ctx: &LoadContext) -> Result<Loaded> {
        let anchors: Anchors = serde_json::from_value(ctx.state.clone())
            .map_err(|e| Error::data(weights, format!("its saved anchors: {e}")))?;
        let robot = ctx
            .robot
            .ok_or_else(|| Error::Config("link_splat loads with its robot".into()))?;
        let template = self.init(robot, anchors, ctx.camera, ctx.device, 0)?;
        crate::self_models::model::load_network(template, weights)
    }
}

/// LinkSplat's run on `preset`, trained as NeuroKin is (BCE, Adam 1e-3, batch 32, the
/// notebook's steps, clip 1.0, input noise).
pub fn link_splat_run(preset: &str) -> Result<SelfModelRun<LinkSplatConfig>> {
    let mut model = LinkSplatConfig::preset(model_preset(preset))?;
    model.image = SelfModelRun::<LinkSplatConfig>::image(preset)?;
    let run = SelfModelRun::new(preset, "LinkSplat", model, 256)?;
    Ok(run.shorten(200, 32))
}
