//! The accelerated ray marcher of FFKSM's occupancy field: empty-space skipping with a
//! per-pose occupancy grid ([`crate::self_models::ffksm::grid`]) and early ray termination. Its slow
//! reference is [`crate::self_models::ffksm::marcher::render_dense`]: with every cell occupied and no
//! termination it evaluates the same samples (the bin centres) and gives the same image, which
//! a test checks.
//!
//! 1. Build the grid for the pose (one probe per cell).
//! 2. Each ray keeps only its samples in occupied cells; skipped samples count as empty
//!    (they add nothing to the pixel, as a negative density does in the dense sum).
//! 3. The kept samples are evaluated front to back, `round` per ray per network call, and a
//!    ray stops once its transmittance `Π (1 − α_k)` falls below `termination`: it has hit
//!    something opaque. The reimplementation's pixel rule is a plain sum `Σ α_k v_k` with no
//!    transmittance, so samples behind an opaque surface could still add to it; a trained
//!    field has learned `v ≈ 0` there (the sum must stay near 1 on the arm), and the run that
//!    reports this renderer measures how far its image is from dense marching's.

use burn::tensor::{Device, TensorData};

use crate::self_models::ffksm::field::OccupancyField;
use crate::self_models::ffksm::grid::{FrustumGrid, GridConfig};
use crate::self_models::ffksm::marcher::{MarchConfig, sample_points};
use crate::sim::camera::Camera;

/// Settings of the accelerated marcher.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AcceleratedConfig {
    pub grid: GridConfig,
    /// Stop a ray once its transmittance is below this; `None` marches every kept sample.
    pub termination: Option<f64>,
    /// Kept samples evaluated per ray per round (the granularity of early termination).
    pub round: usize,
}

impl AcceleratedConfig {
    /// The grid's paper settings, termination at transmittance 1e-3, rounds of 4 samples.
    pub fn paper() -> Self {
        AcceleratedConfig {
            grid: GridConfig::paper(),
            termination: Some(1e-3),
            round: 4,
        }
    }
}

/// One image from the accelerated marcher, on the host.
#[derive(Clone, Debug)]
pub struct AcceleratedImage {
    /// `[H * W]` pixel values (row-major).
    pub silhouette: Vec<f32>,
    /// `[H * W]` expected depth (m), 0 where no sample weighs anything.
    pub depth: Vec<f32>,
    /// Network evaluations: the grid's probes plus the marched samples.
    pub evaluations: usize,
    pub grid_evaluations: usize,
    /// Fraction of grid cells occupied.
    pub grid_occupancy: f64,
}

/// Render the whole image of `camera` for joint angles `angles` (radians).
pub fn render_accelerated(
    field: &OccupancyField,
    view: (&Camera, &[f64]),
    march: &MarchConfig,
    cfg: &AcceleratedConfig,
    device: &Device,
) -> AcceleratedImage {
    let (camera, angles) = view;
    let grid = FrustumGrid::build(field, view, march, &cfg.grid, device);
    let (w, pixels) = (camera.width, camera.width * camera.height);
    // Kept samples of every ray, front to back.
    let kept: Vec<Vec<usize>> = (0..pixels)
        .map(|px| {
            (0..march.samples)
                .filter(|&k| grid.contains(px / w, px % w, k))
                .collect()
        })
        .collect();
    let step = (march.far - march.near) / march.samples as f64;
    let depth_of = |k: usize| march.near + (k as f64 + 0.5) * step;
    let mut value = vec![0f64; pixels];
    let mut transmittance = vec![1f64; pixels];
    let mut weight = vec![0f64; pixels];
    let mut weighted_depth = vec![0f64; pixels];
    let mut cursor = vec![0usize; pixels];
    let mut active: Vec<usize> = (0..pixels).filter(|&p| !kept[p].is_empty()).collect();
    let round = match cfg.termination {
        Some(_) => cfg.round.max(1),
        None => march.samples,
    };
    let pose = &angles.iter().map(|&v| v as f32).collect::<Vec<f32>>();
    let mut evaluations = grid.evaluations;
    while !active.is_empty() {
        // This round's samples: up to `round` per active ray.
        let mut rays = Vec::new();
        let mut depths = Vec::new();
        let mut owner = Vec::new();
        for &p in &active {
            let take = &kept[p][cursor[p]..(cursor[p] + round).min(kept[p].len())];
            for &k in take {
                rays.push(p);
                depths.push(depth_of(k));
                owner.push(p);
            }
            cursor[p] += take.len();
        }
        for (start, end) in chunks(rays.len(), cfg.grid.chunk.max(1)) {
            let points = sample_points(camera, &rays[start..end], &depths[start..end], device);
            let raw = field.forward_pose(points, pose).into_data();
            let raw = TensorData::try_into_vec::<f32>(raw).expect("float tensor");
            for (i, r) in raw.chunks(2).enumerate() {
                let p = owner[start + i];
                let alpha = 1.0 - (-(r[0] as f64).max(0.0)).exp();
                let v = r[1] as f64;
                value[p] += alpha * v;
                let wgt = alpha * v.max(0.0);
                weight[p] += wgt;
                weighted_depth[p] += wgt * depths[start + i];
                transmittance[p] *= 1.0 - alpha;
            }
        }
        evaluations += rays.len();
        active.retain(|&p| {
            cursor[p] < kept[p].len() && cfg.termination.is_none_or(|eps| transmittance[p] >= eps)
        });
    }
    AcceleratedImage {
        silhouette: value.iter().map(|&v| v as f32).collect(),
        depth: weight
            .iter()
            .zip(&weighted_depth)
            .map(|(&w, &wd)| (wd / (w + 1e-8)) as f32)
            .collect(),
        evaluations,
        grid_evaluations: grid.evaluations,
        grid_occupancy: grid.occupancy(),
    }
}

/// `(start, end)` of consecutive chunks of at most `size` out of `n`.
fn chunks(n: usize, size: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..n.div_ceil(size)).map(move |i| (i * size, ((i + 1) * size).min(n)))
}

/// The silhouette `[rays]` of `pixels` with gradients, for training, marching only the
/// samples in occupied cells of a grid probed from `probe` (the same field without autodiff),
/// at stratified depths drawn from `jitter`; and the network evaluations it took (grid
/// included).
///
/// With the grid's threshold at 0 this gives dense marching's gradients: a sample whose raw
/// density is negative adds nothing to the pixel (its opacity `1 − exp(−ReLU(σ))` is 0) and
/// gets no gradient through the ReLU, in dense marching too. The two differ only where a
/// probe misses positive density inside a cell (the dilation is there for that). Falls back
/// to dense marching when no cell is occupied (a loss must reach the parameters).
// The training step's inputs, each named at its one caller (`ffksm::training`): the field and
// its probe, the view, the rays, the two marching settings, the step's seed and the device.
#[allow(clippy::too_many_arguments)]
pub fn render_silhouette_skipping(
    field: &OccupancyField,
    probe: &OccupancyField,
    (camera, angles): (&Camera, &[f64]),
    pixels: &[usize],
    march: &MarchConfig,
    grid: &GridConfig,
    jitter: Option<u64>,
    device: &Device,
) -> (burn::tensor::Tensor<1>, usize) {
    use burn::tensor::{IndexingUpdateOp, Int, Tensor};
    let probe_device = probe_device(probe, device);
    let occupancy = FrustumGrid::build(probe, (camera, angles), march, grid, &probe_device);
    let depths = march.depths(pixels.len(), jitter);
    let w = camera.width;
    let (mut rays, mut kept_depths, mut owner) = (Vec::new(), Vec::new(), Vec::new());
    for (i, &t) in depths.iter().enumerate() {
        let (r, k) = (i / march.samples, i % march.samples);
        let px = pixels[r];
        if occupancy.contains(px / w, px % w, k) {
            rays.push(px);
            kept_depths.push(t);
            owner.push(r as i64);
        }
    }
    if rays.is_empty() {
        let pred = crate::self_models::ffksm::marcher::render_silhouette(
            field,
            (camera, angles),
            pixels,
            march,
            jitter,
            device,
        );
        return (pred, depths.len() + occupancy.evaluations);
    }
    let points = sample_points(camera, &rays, &kept_depths, device);
    let raw = field.forward_pose(
        points,
        &angles.iter().map(|&v| v as f32).collect::<Vec<f32>>(),
    );
    let m = rays.len();
    let density = raw.clone().slice([0..m, 0..1]).reshape([m]);
    let visibility = raw.slice([0..m, 1..2]).reshape([m]);
    let alpha = burn::tensor::activation::relu(density)
        .neg()
        .exp()
        .neg()
        .add_scalar(1.0);
    let index = Tensor::<1, Int>::from_data(TensorData::new(owner, [m]), device);
    let pred = Tensor::<1>::zeros([pixels.len()], device).select_assign(
        0,
        index,
        alpha * visibility,
        IndexingUpdateOp::Add,
    );
    (pred, m + occupancy.evaluations)
}

/// The device `probe`'s parameters live on (the inner device of an autodiff `device`).
fn probe_device(probe: &OccupancyField, device: &Device) -> Device {
    use burn::module::Module;
    probe
        .devices()
        .into_iter()
        .next()
        .unwrap_or_else(|| device.clone())
}
