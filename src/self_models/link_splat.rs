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

use std::path::Path;

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::{Device, Tensor, TensorData};

use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::kernels::cpu_extension::{conv2d_layer, linear_layer, relu, sigmoid};
use crate::kernels::upconv::{UpConv, UpConvConfig};
use crate::self_models::k3dgs::splatting::{camera_rotation, project_centres};
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

/// Anchor points of a robot's links ([`anchors`]): for each, its link, its centre in the
/// link's frame (m) and its cluster's radius (m).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Anchors {
    pub links: Vec<usize>,
    pub centres: Vec<[f32; 3]>,
    pub radii: Vec<f32>,
}

/// How finely a link's surface is sampled for its anchors (m).
const ANCHOR_SPACING_M: f64 = 0.005;

/// `per_link` anchors on every link of `robot` with geometry: its surface's cluster centres.
pub fn anchors(robot: &Robot, per_link: usize) -> Result<Anchors> {
    use crate::sim::collision::spheres::{clusters, surface};
    let mut out = Anchors {
        links: Vec::new(),
        centres: Vec::new(),
        radii: Vec::new(),
    };
    for (l, g) in robot.geometry.iter().enumerate() {
        let shapes = g.shapes();
        if surface::surface_point_count(shapes, ANCHOR_SPACING_M) > surface::MAX_SURFACE_POINTS {
            return Err(Error::Config(format!(
                "link_splat: link \"{}\" is too large to sample for anchors: check its scale",
                robot.chain.links[l]
            )));
        }
        let points = surface::distinct_points(
            surface::surface_points(shapes, ANCHOR_SPACING_M),
            ANCHOR_SPACING_M,
        );
        if points.is_empty() {
            continue;
        }
        for s in clusters::enclosed(&points, per_link) {
            out.links.push(l);
            out.centres.push(s.center.map(|v| v as f32));
            out.radii.push(s.radius as f32);
        }
    }
    if out.links.is_empty() {
        return Err(Error::Config(
            "link_splat: the robot has no link with geometry to anchor on: give a description with <visual> shapes".into(),
        ));
    }
    Ok(out)
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
        let (c, conv3) = (self.features, |cin: usize, cout: usize| {
            Conv2dConfig::new([cin, cout], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(device)
        });
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
                UpConvConfig::new(c, c / 2, 4, 2, 1).init(device),
                UpConvConfig::new(c / 2, (c / 4).max(4), 4, 2, 1).init(device),
            ],
            head: conv3((c / 4).max(4), 1),
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

/// The anchors seen from a camera: image row and column and the splat's width (grid cells),
/// `[B, A]` each, and each anchor's MLP input `[B * A, ANCHOR_INPUTS]`.
struct Seen {
    row: Tensor<2>,
    col: Tensor<2>,
    sigma: Tensor<2>,
    inputs: Tensor<2>,
}

impl LinkSplat {
    /// The anchors for joint angles `angles` `[B, dof]` (degrees) as the camera sees them:
    /// in tensor ops where the angles must carry gradients (reading the body back from an
    /// image, [`BodyFit::differentiable`]), otherwise on the host ([`LinkSplat::see_on_host`]).
    fn see(&self, angles: Tensor<2>) -> Seen {
        if self.through_tensors {
            self.see_in_tensors(angles)
        } else {
            self.see_on_host(angles)
        }
    }

    /// [`LinkSplat::see`] on the host, in f64: forward kinematics of one pose takes
    /// microseconds there, where the tensor chain's hundred small ops dominate a batch of one.
    fn see_on_host(&self, angles: Tensor<2>) -> Seen {
        let [b, dof] = angles.dims();
        let device = angles.device();
        let q: Vec<f32> = angles
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .expect("joint angles as f32");
        let a = self.anchors.links.len();
        let f = self.camera.frame();
        let (cx, cy) = self.camera.principal_point();
        let cell = 1.0 / GRID_DIVISOR as f64;
        let [gh, gw] = self.grid();
        let to_grid = |p: f64| (p + 0.5) * cell - 0.5;
        let (mut row, mut col, mut sigma) = (Vec::new(), Vec::new(), Vec::new());
        let mut inputs = Vec::with_capacity(b * a * ANCHOR_INPUTS);
        for pose in q.chunks(dof) {
            let pose: Vec<f64> = pose.iter().map(|&v| v as f64).collect();
            let frames = self.host.link_frames(&self.host.to_si(&pose));
            for ((&l, c), &radius) in (self.anchors.links.iter())
                .zip(&self.anchors.centres)
                .zip(&self.anchors.radii)
            {
                let p = frames[l] * nalgebra::Point3::new(c[0] as f64, c[1] as f64, c[2] as f64);
                let rel = p - f.eye;
                let z = rel.dot(&f.fwd).max(1e-3);
                let (r, k) = (
                    to_grid(cy - f.focal * rel.dot(&f.up) / z),
                    to_grid(cx + f.focal * rel.dot(&f.right) / z),
                );
                row.push(r as f32);
                col.push(k as f32);
                sigma.push((radius as f64 / z * f.focal * cell).max(self.min_sigma_cells) as f32);
                let m = frames[l].rotation.to_rotation_matrix();
                for axis in [f.right, f.up, f.fwd] {
                    let camera_row = axis.transpose() * m.matrix();
                    inputs.extend(camera_row.iter().map(|&v| v as f32));
                }
                inputs.extend([
                    z as f32,
                    (r * 2.0 / gh as f64 - 1.0) as f32,
                    (k * 2.0 / gw as f64 - 1.0) as f32,
                ]);
            }
        }
        let tensor = |v: Vec<f32>| Tensor::<2>::from_data(TensorData::new(v, [b, a]), &device);
        Seen {
            row: tensor(row),
            col: tensor(col),
            sigma: tensor(sigma),
            inputs: Tensor::from_data(TensorData::new(inputs, [b * a, ANCHOR_INPUTS]), &device),
        }
    }

    /// [`LinkSplat::see`] in tensor ops, differentiable in the angles.
    fn see_in_tensors(&self, angles: Tensor<2>) -> Seen {
        let [b, _] = angles.dims();
        let device = angles.device();
        let a = self.anchors.links.len();
        let (r, t) = self.chain.link_frames(self.chain.from_user(angles));
        let links = Tensor::<1, burn::tensor::Int>::from_data(
            TensorData::new(self.anchors.links.iter().map(|&l| l as i64).collect(), [a]),
            &device,
        );
        let r = r.select(1, links.clone()); // [B, A, 3, 3]
        let t = t.select(1, links); // [B, A, 3]
        let local = Tensor::<2>::from_data(
            TensorData::new(self.anchors.centres.concat(), [a, 3]),
            &device,
        );
        let world = r
            .clone()
            .matmul(local.reshape([1, a, 3, 1]))
            .reshape([b, a, 3])
            + t;
        let ([_, _, z], row, col) = project_centres(world, &self.camera);
        let cell = 1.0 / GRID_DIVISOR as f64;
        // Pixel centres at integer coordinates; grid cell k covers pixels 4k..4k+3.
        let to_grid = |p: Tensor<2>| p.add_scalar(0.5).mul_scalar(cell).sub_scalar(0.5);
        let (row, col) = (to_grid(row), to_grid(col));
        let radii =
            Tensor::<2>::from_data(TensorData::new(self.anchors.radii.clone(), [1, a]), &device);
        let sigma = (radii / z.clone())
            .mul_scalar(self.camera.focal_px() * cell)
            .clamp_min(self.min_sigma_cells);
        // The link's rotation in the camera frame: W R, [B, A, 9].
        let w = camera_rotation(&self.camera, &device);
        let rotation = w.reshape([1, 1, 3, 3]).matmul(r).reshape([b * a, 9]);
        let [gh, gw] = self.grid();
        let inputs = Tensor::cat(
            vec![
                rotation,
                z.reshape([b * a, 1]),
                row.clone()
                    .mul_scalar(2.0 / gh as f64)
                    .sub_scalar(1.0)
                    .reshape([b * a, 1]),
                col.clone()
                    .mul_scalar(2.0 / gw as f64)
                    .sub_scalar(1.0)
                    .reshape([b * a, 1]),
            ],
            1,
        );
        Seen {
            row,
            col,
            sigma,
            inputs,
        }
    }

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

    /// Trainable parameters.
    pub fn trainable_params(&self) -> usize {
        self.num_params()
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
            network.trainable_params(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::robots::BuiltinRobot;
    use nalgebra::Point3;

    fn values(t: Tensor<2>) -> Vec<f32> {
        t.into_data().try_into_vec::<f32>().unwrap()
    }

    /// The anchors as the network sees them, both ways: in tensor ops (tensor forward
    /// kinematics, the camera in tensor ops) against the slow reference (each anchor placed
    /// by the chain's `link_frames` in f64 and projected by [`Camera::project`], scaled to
    /// the grid), and the host's fast path against the tensor ops, every value.
    #[test]
    fn anchors_project_where_the_camera_sees_them() {
        let robot = BuiltinRobot::Arm4.load();
        let camera = Camera::paper();
        let cfg = LinkSplatConfig {
            image: [camera.height, camera.width],
            ..LinkSplatConfig::quick()
        };
        let device = Device::default();
        let anchors = anchors(&robot, 2).unwrap();
        assert!(anchors.links.len() >= 4, "{} anchors", anchors.links.len());
        let mut net = cfg
            .init(&robot, anchors.clone(), &camera, &device, 0)
            .unwrap();
        let poses = [[20.0, -35.0, 50.0, 10.0], [-60.0, 15.0, -20.0, 75.0]];
        let angles = Tensor::<2>::from_data(TensorData::new(poses.concat(), [2, 4]), &device);
        let host = net.see(angles.clone());
        net.through_tensors = true;
        let seen = net.see(angles);
        let rows = values(seen.row.clone());
        let cols = values(seen.col.clone());
        let a = anchors.links.len();
        for (i, q) in poses.iter().enumerate() {
            let frames = robot.chain.link_frames(&q.map(|d: f64| d.to_radians()));
            for (k, (&l, c)) in anchors.links.iter().zip(&anchors.centres).enumerate() {
                let p = frames[l] * Point3::new(c[0] as f64, c[1] as f64, c[2] as f64);
                let (row, col, _) = camera.project(&p).unwrap();
                let grid = |px: f64| (px + 0.5) / GRID_DIVISOR as f64 - 0.5;
                let (r, c) = (rows[i * a + k] as f64, cols[i * a + k] as f64);
                assert!(
                    (r - grid(row)).abs() < 1e-3 && (c - grid(col)).abs() < 1e-3,
                    "pose {i} anchor {k}: ({r}, {c}) against ({}, {})",
                    grid(row),
                    grid(col)
                );
            }
        }
        let pairs = [
            ("row", host.row, seen.row),
            ("col", host.col, seen.col),
            ("sigma", host.sigma, seen.sigma),
            ("inputs", host.inputs, seen.inputs),
        ];
        for (what, fast, slow) in pairs {
            for (k, (x, y)) in values(fast).iter().zip(values(slow)).enumerate() {
                assert!((x - y).abs() < 1e-3, "{what}[{k}]: host {x}, tensors {y}");
            }
        }
    }
}
