//! LinkSplat's anchors: points on every link with geometry (its surface's cluster centres,
//! each with its cluster's radius), and where they are for given joint angles as the camera
//! sees them, on the host (fast) or in tensor ops (differentiable in the angles).

use burn::tensor::{Tensor, TensorData};

use super::{ANCHOR_INPUTS, GRID_DIVISOR, LinkSplat};
use crate::core::error::{Error, Result};
use crate::self_models::k3dgs::splatting::{camera_rotation, project_centres};
use crate::sim::robot::Robot;

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

/// The least depth an anchor is projected at (m), as
/// [`crate::self_models::k3dgs::splatting::project_centres`] clamps it.
const MIN_DEPTH_M: f64 = 1e-3;

/// The anchors seen from a camera: image row and column and the splat's width (grid cells),
/// `[B, A]` each, and each anchor's MLP input `[B * A, ANCHOR_INPUTS]`.
pub(super) struct Seen {
    pub(super) row: Tensor<2>,
    pub(super) col: Tensor<2>,
    pub(super) sigma: Tensor<2>,
    pub(super) inputs: Tensor<2>,
}

impl LinkSplat {
    /// The anchors for joint angles `angles` `[B, dof]` (degrees) as the camera sees them:
    /// in tensor ops where the angles must carry gradients (reading the body back from an
    /// image, [`BodyFit::differentiable`]), otherwise on the host ([`LinkSplat::see_on_host`]).
    pub(super) fn see(&self, angles: Tensor<2>) -> Seen {
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
                let (r, k, z) = f.project_clamped(&p, MIN_DEPTH_M);
                let (r, k) = (to_grid(r), to_grid(k));
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::preset::Preset;
    use crate::self_models::link_splat::LinkSplatConfig;
    use crate::sim::camera::Camera;
    use crate::sim::robots::BuiltinRobot;
    use burn::tensor::Device;
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
