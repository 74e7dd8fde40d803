//! Dense ray marching of FFKSM's occupancy field (self-modeling paper section IV-B): the
//! renderer every pixel of a predicted silhouette goes through.
//!
//! Rays follow the shared camera convention ([`crate::sim::camera`]): direction `forward + …` with
//! forward component 1, so the ray parameter `t` is depth along the camera axis (metres). Each
//! ray is sampled at `samples` stratified depths in `[near, far]` (the paper: 64 in
//! [0.6, 1.4]): sample `k` at `near + (k + u) (far − near) / samples`, `u` uniform in [0, 1)
//! when training and 0.5 (bin centres) when evaluating. The pixel is
//! `Σ_k (1 − exp(−ReLU(density_k))) · visibility_k`, the reimplementation's rule.

use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use crate::self_models::ffksm::field::OccupancyField;
use crate::sim::camera::Camera;

/// Where along each ray to sample.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MarchConfig {
    pub samples: usize,
    /// Depth range along the camera axis (m).
    pub near: f64,
    pub far: f64,
}

impl MarchConfig {
    /// The paper's: 64 samples in [0.6, 1.4] m.
    pub fn paper() -> Self {
        MarchConfig {
            samples: 64,
            near: 0.6,
            far: 1.4,
        }
    }

    /// Depths `[rays * samples]` (ray-major): stratified with `jitter` (a seed), else the bin
    /// centres.
    pub fn depths(&self, rays: usize, jitter: Option<u64>) -> Vec<f64> {
        let step = (self.far - self.near) / self.samples as f64;
        let mut rng = jitter.map(StdRng::seed_from_u64);
        (0..rays * self.samples)
            .map(|i| {
                let u = rng.as_mut().map_or(0.5, |r| r.random::<f64>());
                self.near + ((i % self.samples) as f64 + u) * step
            })
            .collect()
    }
}

/// The sample points `[rays * samples, 3]` (world, metres) of the pixels `pixels` (row-major
/// indices into the camera's image) at `depths` (from [`MarchConfig::depths`]).
pub fn sample_points(
    camera: &Camera,
    pixels: &[usize],
    depths: &[f64],
    device: &Device,
) -> Tensor<2> {
    let frame = camera.frame();
    let samples = depths.len() / pixels.len().max(1);
    let mut points = Vec::with_capacity(depths.len() * 3);
    for (r, &px) in pixels.iter().enumerate() {
        let ray = frame.ray((px / camera.width) as f64, (px % camera.width) as f64);
        for &t in &depths[r * samples..(r + 1) * samples] {
            let p = ray.origin + ray.dir * t;
            points.extend([p.x as f32, p.y as f32, p.z as f32]);
        }
    }
    Tensor::from_data(TensorData::new(points, [depths.len(), 3]), device)
}

/// The raw output `[rays * samples, 2]` (ray-major) as per-sample opacity
/// `1 − exp(−ReLU(density))` and visibility, each `[rays, samples]`.
fn opacity_and_visibility(raw: Tensor<2>, samples: usize) -> (Tensor<2>, Tensor<2>) {
    let n = raw.dims()[0];
    let rays = n / samples;
    let density = raw.clone().slice([0..n, 0..1]).reshape([rays, samples]);
    let visibility = raw.slice([0..n, 1..2]).reshape([rays, samples]);
    (relu(density).neg().exp().neg().add_scalar(1.0), visibility)
}

/// Pixels `[rays]` from the field's raw output `[rays * samples, 2]` (density, visibility),
/// ray-major: `Σ_k (1 − exp(−ReLU(density_k))) · visibility_k`.
pub fn composite(raw: Tensor<2>, samples: usize) -> Tensor<1> {
    let (opacity, visibility) = opacity_and_visibility(raw, samples);
    let rays = opacity.dims()[0];
    (opacity * visibility).sum_dim(1).reshape([rays])
}

/// The slow reference of [`composite`] for one ray's `(density, visibility)` samples.
pub fn composite_reference(raw: &[(f64, f64)]) -> f64 {
    raw.iter()
        .map(|&(d, v)| (1.0 - (-d.max(0.0)).exp()) * v)
        .sum()
}

/// Expected depth `[rays]` (m) from the raw output `[rays * samples, 2]` and the sample depths
/// `[rays * samples]`: `Σ w_k t_k / Σ w_k` with `w_k = (1 − exp(−ReLU(density_k))) ·
/// ReLU(visibility_k)`, 0 where no sample weighs anything.
pub fn expected_depth(raw: Tensor<2>, depths: &[f64], samples: usize) -> Tensor<1> {
    assert_eq!(raw.dims()[0], depths.len());
    let (opacity, visibility) = opacity_and_visibility(raw, samples);
    let rays = opacity.dims()[0];
    let weights = opacity * relu(visibility);
    let t: Vec<f32> = depths.iter().map(|&t| t as f32).collect();
    let t = Tensor::<2>::from_data(TensorData::new(t, [rays, samples]), &weights.device());
    let total = weights.clone().sum_dim(1);
    let weighted = (weights * t).sum_dim(1);
    (weighted / total.add_scalar(1e-8)).reshape([rays])
}

/// The field's raw output `[rays * samples, 2]` at `depths` along the rays of `pixels`, all
/// in one pose `angles` (radians).
fn march_chunk(
    field: &OccupancyField,
    (camera, angles): (&Camera, &[f64]),
    pixels: &[usize],
    depths: &[f64],
    device: &Device,
) -> Tensor<2> {
    let points = sample_points(camera, pixels, depths, device);
    field.forward_pose(
        points,
        &angles.iter().map(|&v| v as f32).collect::<Vec<f32>>(),
    )
}

/// The silhouette `[rays]` of `pixels` in one graph (for training: gradients reach the
/// field), with stratified depths drawn from `jitter`.
pub fn render_silhouette(
    field: &OccupancyField,
    view: (&Camera, &[f64]),
    pixels: &[usize],
    march: &MarchConfig,
    jitter: Option<u64>,
    device: &Device,
) -> Tensor<1> {
    let depths = march.depths(pixels.len(), jitter);
    composite(
        march_chunk(field, view, pixels, &depths, device),
        march.samples,
    )
}

/// Render `pixels` (row-major indices) of `camera` through `field` for joint angles
/// `[4]` (radians), marching `chunk` rays at a time (memory stays `chunk * samples` points):
/// `(silhouette [rays], expected depth [rays], network evaluations)`.
pub fn render_dense(
    field: &OccupancyField,
    view: (&Camera, &[f64]),
    pixels: &[usize],
    march: &MarchConfig,
    jitter: Option<u64>,
    chunk: usize,
    device: &Device,
) -> (Tensor<1>, Tensor<1>, usize) {
    let mut silhouettes = Vec::new();
    let mut depths_out = Vec::new();
    let mut evaluations = 0;
    for (i, part) in pixels.chunks(chunk.max(1)).enumerate() {
        let depths = march.depths(part.len(), jitter.map(|s| s.wrapping_add(i as u64)));
        let raw = march_chunk(field, view, part, &depths, device);
        evaluations += depths.len();
        silhouettes.push(composite(raw.clone(), march.samples));
        depths_out.push(expected_depth(raw, &depths, march.samples));
    }
    (
        Tensor::cat(silhouettes, 0),
        Tensor::cat(depths_out, 0),
        evaluations,
    )
}
