//! K-3DGS's model (self-modeling paper section IV-C): 3-D Gaussians attached to the links of
//! the robot's real kinematic chain ([`crate::tensor_kinematics`]), splatted into the shared
//! camera ([`crate::gaussian_splatting`]).
//!
//! Each Gaussian belongs to one link and has a learnable position in that link's frame
//! (metres), an isotropic log-scale (standard deviation, initially 0.025 m) and an opacity
//! logit. The paper preset's 600: 100 on the base, 200 on each of the two long links, 100 on
//! the last link. `arm4` has five links where the paper counted four: its 100 base Gaussians
//! are split 50/50 between the fixed base and the shoulder link `L1`, which turns with joint 0
//! (a choice of ours). Initial positions are drawn uniformly inside each link's geometry
//! bounds (seeded), so they start spread along the link's extent.

use burn::module::{Module, Param};
use burn::tensor::{Device, Int, Tensor, TensorData};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussian_splatting::{Compositing, ImageGaussians, project_isotropic, render_culled, render_dense};
use crate::robot::Robot;
use crate::tensor_kinematics::TensorChain;

/// How many Gaussians start on each link, and how they start.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GaussianInit {
    /// `(link name, count)`.
    pub per_link: Vec<(String, usize)>,
    /// Initial standard deviation (m).
    pub scale: f64,
    /// Initial opacity in (0, 1).
    pub opacity: f64,
}

impl GaussianInit {
    /// The paper's 600 on `arm4` (see the module documentation for `L1`).
    pub fn paper() -> Self {
        GaussianInit {
            per_link: [("base", 50), ("L1", 50), ("L2", 200), ("L3", 200), ("L4", 100)]
                .map(|(l, n)| (l.to_string(), n))
                .to_vec(),
            scale: 0.025,
            opacity: 0.5,
        }
    }

    /// A fifth of the paper's, for tests.
    pub fn quick() -> Self {
        let mut g = Self::paper();
        for (_, n) in &mut g.per_link {
            *n /= 5;
        }
        g
    }

    /// The Gaussians' link indices and initial link-frame positions, drawn from `seed`.
    pub fn positions(&self, robot: &Robot, seed: u64) -> Result<(Vec<usize>, Vec<[f32; 3]>)> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut links = Vec::new();
        let mut points = Vec::new();
        for (name, count) in &self.per_link {
            let l = robot
                .chain
                .links
                .iter()
                .position(|n| n == name)
                .ok_or_else(|| {
                    Error::Config(format!(
                        "K-3DGS: the robot has no link \"{name}\" (links: {})",
                        robot.chain.links.join(", ")
                    ))
                })?;
            let b = robot.geometry[l].bounds();
            if b.is_empty() {
                return Err(Error::Config(format!(
                    "K-3DGS: link \"{name}\" has no geometry to place Gaussians on"
                )));
            }
            for _ in 0..*count {
                let u: [f64; 3] = [rng.random(), rng.random(), rng.random()];
                links.push(l);
                points.push([0, 1, 2].map(|k| (b.min[k] + u[k] * (b.max[k] - b.min[k])) as f32));
            }
        }
        Ok((links, points))
    }
}

/// Gaussians on a kinematic chain.
#[derive(Module, Debug)]
pub struct KinematicGaussians {
    /// `[N, 3]` positions in their links' frames (m).
    pub positions: Param<Tensor<2>>,
    /// `[N]` natural log of the standard deviation (m).
    pub log_scales: Param<Tensor<1>>,
    /// `[N]` opacity logits.
    pub opacity_logits: Param<Tensor<1>>,
    /// `[N]` the link each Gaussian belongs to.
    pub links: Tensor<1, Int>,
}

fn logit(p: f64) -> f32 {
    (p / (1.0 - p)).ln() as f32
}

impl KinematicGaussians {
    /// Gaussians on `links` at link-frame `positions`, all with the same scale and opacity.
    pub fn new(
        links: &[usize],
        positions: &[[f32; 3]],
        scale: f64,
        opacity: f64,
        device: &Device,
    ) -> Self {
        let n = links.len();
        let pos: Vec<f32> = positions.iter().flatten().copied().collect();
        KinematicGaussians {
            positions: Param::from_tensor(Tensor::from_data(TensorData::new(pos, [n, 3]), device)),
            log_scales: Param::from_tensor(
                Tensor::ones([n], device).mul_scalar(scale.ln() as f32),
            ),
            opacity_logits: Param::from_tensor(
                Tensor::ones([n], device).mul_scalar(logit(opacity)),
            ),
            links: Tensor::from_data(
                TensorData::new(links.iter().map(|&l| l as i64).collect::<Vec<_>>(), [n]),
                device,
            ),
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.links.dims()[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// World centres `[B, N, 3]` for link poses from [`TensorChain::link_frames`].
    pub fn world_means(&self, rotations: Tensor<4>, translations: Tensor<3>) -> Tensor<3> {
        let [b, _, _, _] = rotations.dims();
        let n = self.len();
        let r = rotations.select(1, self.links.clone()); // [B, N, 3, 3]
        let t = translations.select(1, self.links.clone()); // [B, N, 3]
        let local = self.positions.val().reshape([1, n, 3, 1]).repeat_dim(0, b);
        r.matmul(local).reshape([b, n, 3]) + t
    }

    /// The Gaussians projected for joint values `q` `[B, dof]` (radians).
    pub fn project(&self, chain: &TensorChain, q: Tensor<2>, camera: &Camera) -> ImageGaussians {
        let (r, t) = chain.link_frames(q);
        project_isotropic(
            self.world_means(r, t),
            self.log_scales.val().exp(),
            burn::tensor::activation::sigmoid(self.opacity_logits.val()),
            camera,
        )
    }

    /// Silhouettes and depth `[B, H * W]` for joint values `q` `[B, dof]` (radians), culled
    /// at `cull_sigmas` standard deviations, or dense when `None`.
    pub fn render(
        &self,
        chain: &TensorChain,
        q: Tensor<2>,
        camera: &Camera,
        mode: Compositing,
        cull_sigmas: Option<f64>,
    ) -> (Tensor<2>, Tensor<2>) {
        let g = self.project(chain, q, camera);
        match cull_sigmas {
            Some(s) => render_culled(&g, camera.height, camera.width, mode, s),
            None => render_dense(&g, camera.height, camera.width, mode),
        }
    }
}
