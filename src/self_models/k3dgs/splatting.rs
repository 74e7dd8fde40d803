//! Splatting 3-D Gaussians into the camera (K-3DGS, self-modeling paper section IV-C):
//! projection, two compositing rules and depth, a dense reference that evaluates every
//! (Gaussian, pixel) pair and a culled fast path that evaluates only the pairs within
//! `cull_sigmas` standard deviations of each Gaussian's centre (tested against the dense one).
//!
//! Conventions are the shared camera's ([`crate::sim::camera`]): pixel (row a, column b) is centred
//! on integer coordinates, a world point projects to `row = cy − f y/z`, `col = cx + f x/z` in
//! camera coordinates (x right, y up, z forward, metres). A Gaussian in the image is its centre
//! (px), its depth z (m), its conic (the inverse of its 2-D covariance, `[a, b, c]` for
//! `[[a, b], [b, c]]`, px⁻²) and its opacity; its footprint at a pixel `d` away from the centre
//! is `g = exp(−½ dᵀ conic d)`.
//!
//! Compositing (per pixel, `α_n = opacity_n g_n`):
//! - [`Compositing::SigmoidSum`], the reimplementation's: `sigmoid(T (Σ α_n − 0.5))`, `T` the
//!   temperature (1 rising to 20 in its training);
//! - [`Compositing::Alpha`], the principled one: `1 − Π (1 − α_n)`, which needs no sorting.
//!
//! Depth is front-to-back compositing in either mode: `Σ w_n z_n / Σ w_n` with
//! `w_n = α_n Π_{m nearer} (1 − α_m)`, 0 where no Gaussian weighs anything.

use burn::tensor::{Int, Tensor, TensorData};

use crate::sim::camera::Camera;

/// How the footprints make a silhouette.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Compositing {
    /// `sigmoid(temperature (Σ α − 0.5))`.
    SigmoidSum { temperature: f64 },
    /// `1 − Π (1 − α)`.
    Alpha,
}

/// Largest opacity of one footprint in alpha compositing (keeps `log(1 − α)` finite).
const MAX_ALPHA: f64 = 0.99;

/// Gaussians projected into the image, each tensor `[B, N]`.
#[derive(Clone, Debug)]
pub struct ImageGaussians {
    pub row: Tensor<2>,
    pub col: Tensor<2>,
    /// Depth along the camera axis (m).
    pub depth: Tensor<2>,
    /// Inverse 2-D covariance `[a, b, c]` (px⁻²).
    pub conic: [Tensor<2>; 3],
    /// Opacity in [0, 1].
    pub opacity: Tensor<2>,
    /// Square root of the largest eigenvalue of the 2-D covariance (px): the culling scale.
    pub sigma_px: Tensor<2>,
}

/// The camera rotation `W` `[3, 3]`: rows right, up, forward (world to camera).
pub fn camera_rotation(camera: &Camera, device: &burn::tensor::Device) -> Tensor<2> {
    let f = camera.frame();
    let w: Vec<f32> = [f.right, f.up, f.fwd]
        .iter()
        .flat_map(|v| [v.x as f32, v.y as f32, v.z as f32])
        .collect();
    Tensor::from_data(TensorData::new(w, [3, 3]), device)
}

/// The centres of world points `[B, N, 3]` in the camera: camera coordinates `[x, y, z]`
/// (x right, y up, z forward, m; z clamped to at least 1 mm), and image row and column (px),
/// each `[B, N]`.
pub fn project_centres(
    means: Tensor<3>,
    camera: &Camera,
) -> ([Tensor<2>; 3], Tensor<2>, Tensor<2>) {
    let [b, n, _] = means.dims();
    let f = camera.frame();
    let device = means.device();
    let eye = Tensor::<1>::from_data(
        TensorData::new(vec![f.eye.x as f32, f.eye.y as f32, f.eye.z as f32], [3]),
        &device,
    );
    let rel = means - eye.reshape([1, 1, 3]);
    let cam = rel
        .reshape([b * n, 3])
        .matmul(camera_rotation(camera, &device).transpose());
    let coord = |i: usize| cam.clone().slice([0..b * n, i..i + 1]).reshape([b, n]);
    let (x, y, z) = (coord(0), coord(1), coord(2).clamp_min(1e-3));
    let (cx, cy) = camera.principal_point();
    let col = (x.clone() / z.clone()).mul_scalar(f.focal).add_scalar(cx);
    let row = (y.clone() / z.clone()).mul_scalar(-f.focal).add_scalar(cy);
    ([x, y, z], row, col)
}

/// Project isotropic Gaussians: centres `[B, N, 3]` (world, m), scales `[N]` (standard
/// deviation, m) and opacities `[N]` in [0, 1]. The footprint's standard deviation is
/// `f s / z` pixels.
pub fn project_isotropic(
    means: Tensor<3>,
    scales: Tensor<1>,
    opacity: Tensor<1>,
    camera: &Camera,
) -> ImageGaussians {
    let [b, n, _] = means.dims();
    let ([_, _, z], row, col) = project_centres(means, camera);
    let sigma = (scales.reshape([1, n]) / z.clone()).mul_scalar(camera.focal_px());
    let inv = sigma.clone().square().recip();
    ImageGaussians {
        row,
        col,
        depth: z,
        conic: [inv.clone(), inv.zeros_like(), inv],
        opacity: opacity.reshape([1, n]).repeat_dim(0, b),
        sigma_px: sigma,
    }
}

/// Variance (px²) added to every projected footprint of an anisotropic Gaussian, so none is
/// thinner than about a pixel (3DGS's low-pass filter).
const LOW_PASS_PX2: f64 = 0.3;

/// Project anisotropic Gaussians: centres `[B, N, 3]` (world, m), axes `[B, N, 3, 3]` (world;
/// column `k` is the Gaussian's `k`-th principal axis times its standard deviation, so the
/// covariance is `A Aᵀ`) and opacities `[N]`. The 2-D covariance is `J W A Aᵀ Wᵀ Jᵀ` (the
/// paper's equation 4) with `W` the camera rotation and `J` the Jacobian of (row, column) with
/// respect to camera coordinates at the centre, plus [`LOW_PASS_PX2`].
pub fn project_anisotropic(
    means: Tensor<3>,
    axes: Tensor<4>,
    opacity: Tensor<1>,
    camera: &Camera,
) -> ImageGaussians {
    let [b, n, _] = means.dims();
    let ([x, y, z], row, col) = project_centres(means, camera);
    let focal = camera.focal_px();
    // Axes in camera coordinates: W A, [B, N, 3, 3].
    let w = camera_rotation(camera, &axes.device()).reshape([1, 1, 3, 3]);
    let cam_axes = w.repeat_dim(0, b).repeat_dim(1, n).matmul(axes);
    // Rows of J: d row / d(x, y, z) = (0, −f/z, f y/z²); d col = (f/z, 0, −f x/z²).
    let axis_row = |i: usize| {
        cam_axes
            .clone()
            .slice([0..b, 0..n, i..i + 1, 0..3])
            .reshape([b, n, 3])
    };
    let (ax, ay, az) = (axis_row(0), axis_row(1), axis_row(2));
    let inv_z = z.clone().recip().mul_scalar(focal).reshape([b, n, 1]);
    let y_z2 = (y / z.clone().square())
        .mul_scalar(focal)
        .reshape([b, n, 1]);
    let x_z2 = (x / z.clone().square())
        .mul_scalar(focal)
        .reshape([b, n, 1]);
    // Image-space axes: J (W A), one row for image rows and one for columns, [B, N, 3] each.
    let u_row = ay.neg() * inv_z.clone() + az.clone() * y_z2;
    let u_col = ax * inv_z - az * x_z2;
    let srr = u_row
        .clone()
        .square()
        .sum_dim(2)
        .reshape([b, n])
        .add_scalar(LOW_PASS_PX2);
    let scc = u_col
        .clone()
        .square()
        .sum_dim(2)
        .reshape([b, n])
        .add_scalar(LOW_PASS_PX2);
    let src = (u_row * u_col).sum_dim(2).reshape([b, n]);
    let det = srr.clone() * scc.clone() - src.clone().square();
    let half_trace = (srr.clone() + scc.clone()).mul_scalar(0.5);
    let spread =
        ((srr.clone() - scc.clone()).square().mul_scalar(0.25) + src.clone().square()).sqrt();
    let sigma_px = (half_trace + spread).sqrt();
    ImageGaussians {
        row,
        col,
        depth: z,
        conic: [scc / det.clone(), src.neg() / det.clone(), srr / det],
        opacity: opacity.reshape([1, n]).repeat_dim(0, b),
        sigma_px,
    }
}

/// Row and column coordinates `[P]` of every pixel, row-major.
fn pixel_grid(
    height: usize,
    width: usize,
    device: &burn::tensor::Device,
) -> (Tensor<1>, Tensor<1>) {
    let rows: Vec<f32> = (0..height * width).map(|p| (p / width) as f32).collect();
    let cols: Vec<f32> = (0..height * width).map(|p| (p % width) as f32).collect();
    let n = height * width;
    (
        Tensor::from_data(TensorData::new(rows, [n]), device),
        Tensor::from_data(TensorData::new(cols, [n]), device),
    )
}

/// Silhouette and depth `[B, H * W]` evaluating every (Gaussian, pixel) pair: the reference.
pub fn render_dense(
    g: &ImageGaussians,
    height: usize,
    width: usize,
    mode: Compositing,
) -> (Tensor<2>, Tensor<2>) {
    let [b, n] = g.row.dims();
    let p = height * width;
    let device = g.row.device();
    let (pr, pc) = pixel_grid(height, width, &device);
    // Front to back: every per-Gaussian quantity in depth order.
    let order = g.depth.clone().argsort(1);
    let sorted = |t: &Tensor<2>| t.clone().gather(1, order.clone()).reshape([b, n, 1]);
    let dr = sorted(&g.row) - pr.reshape([1, 1, p]);
    let dc = sorted(&g.col) - pc.reshape([1, 1, p]);
    let [a, bb, c] = &g.conic;
    let power = (sorted(a) * dr.clone().square()
        + sorted(bb) * (dr * dc.clone()).mul_scalar(2.0)
        + sorted(c) * dc.square())
    .mul_scalar(-0.5);
    let alpha = sorted(&g.opacity) * power.exp(); // [B, N, P]
    let sil = match mode {
        Compositing::SigmoidSum { temperature } => {
            let sum = alpha.clone().sum_dim(1).reshape([b, p]);
            burn::tensor::activation::sigmoid(sum.sub_scalar(0.5).mul_scalar(temperature))
        }
        Compositing::Alpha => {
            let log_t = alpha.clone().clamp_max(MAX_ALPHA).neg().log1p();
            log_t.sum_dim(1).reshape([b, p]).exp().neg().add_scalar(1.0)
        }
    };
    let log_t = alpha.clone().clamp_max(MAX_ALPHA).neg().log1p();
    let before = log_t.clone().cumsum(1) - log_t; // exclusive: the Gaussians in front
    let w = alpha * before.exp();
    let z = sorted(&g.depth);
    let depth =
        (w.clone() * z).sum_dim(1).reshape([b, p]) / w.sum_dim(1).reshape([b, p]).add_scalar(1e-8);
    (sil, depth)
}

/// The (image, Gaussian, pixel) pairs within `cull_sigmas` standard deviations of each
/// Gaussian's centre (a square box), grouped by pixel and front to back within a pixel:
/// flat Gaussian indices `b N + n`, flat pixel indices `b P + p`.
fn culled_pairs(
    g: &ImageGaussians,
    height: usize,
    width: usize,
    cull_sigmas: f64,
) -> (Vec<i64>, Vec<i64>) {
    use rayon::prelude::*;
    let [b, n] = g.row.dims();
    let host = |t: &Tensor<2>| t.clone().into_data().try_into_vec::<f32>().expect("float");
    let (row, col, depth, sigma) = (
        host(&g.row),
        host(&g.col),
        host(&g.depth),
        host(&g.sigma_px),
    );
    let p = height * width;
    // One image per task; pixel indices are image-major, so the images' lists concatenate in
    // order.
    let per_image: Vec<Vec<(usize, f32, usize)>> = (0..b)
        .into_par_iter()
        .map(|image| {
            let mut pairs = Vec::new(); // (flat pixel, depth, flat Gaussian)
            for i in image * n..(image + 1) * n {
                let r = cull_sigmas as f32 * sigma[i];
                if !r.is_finite() {
                    continue;
                }
                let (r0, r1) = (
                    (row[i] - r).ceil().max(0.0),
                    (row[i] + r).floor().min(height as f32 - 1.0),
                );
                let (c0, c1) = (
                    (col[i] - r).ceil().max(0.0),
                    (col[i] + r).floor().min(width as f32 - 1.0),
                );
                if r0 > r1 || c0 > c1 {
                    continue;
                }
                for pr in r0 as usize..=r1 as usize {
                    for pc in c0 as usize..=c1 as usize {
                        pairs.push((image * p + pr * width + pc, depth[i], i));
                    }
                }
            }
            pairs.sort_unstable_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)));
            pairs
        })
        .collect();
    let total: usize = per_image.iter().map(Vec::len).sum();
    let (mut gaussians, mut pixels) = (Vec::with_capacity(total), Vec::with_capacity(total));
    for pairs in per_image {
        for (px, _, gi) in pairs {
            gaussians.push(gi as i64);
            pixels.push(px as i64);
        }
    }
    (gaussians, pixels)
}

/// Silhouette and depth `[B, H * W]` from only the pairs within `cull_sigmas` standard
/// deviations (the fast path; [`render_dense`] is its reference).
pub fn render_culled(
    g: &ImageGaussians,
    height: usize,
    width: usize,
    mode: Compositing,
    cull_sigmas: f64,
) -> (Tensor<2>, Tensor<2>) {
    use burn::tensor::IndexingUpdateOp::Add;
    let [b, n] = g.row.dims();
    let p = height * width;
    let device = g.row.device();
    let (gaussian, pixel) = culled_pairs(g, height, width, cull_sigmas);
    let m = gaussian.len();
    let zero = || Tensor::<1>::zeros([b * p], &device);
    if m == 0 {
        let empty = match mode {
            Compositing::SigmoidSum { temperature } => {
                burn::tensor::activation::sigmoid(zero().sub_scalar(0.5).mul_scalar(temperature))
            }
            Compositing::Alpha => zero(),
        };
        return (empty.reshape([b, p]), zero().reshape([b, p]));
    }
    let gi = Tensor::<1, Int>::from_data(TensorData::new(gaussian, [m]), &device);
    let pi = Tensor::<1, Int>::from_data(TensorData::new(pixel.clone(), [m]), &device);
    let per_pair = |t: &Tensor<2>| t.clone().reshape([b * n]).select(0, gi.clone());
    let (pr, pc) = pixel_grid(height, width, &device);
    let local = Tensor::<1, Int>::from_data(
        TensorData::new(pixel.iter().map(|&q| q % p as i64).collect::<Vec<_>>(), [m]),
        &device,
    );
    let dr = per_pair(&g.row) - pr.select(0, local.clone());
    let dc = per_pair(&g.col) - pc.select(0, local);
    let [a, bb, c] = &g.conic;
    let power = (per_pair(a) * dr.clone().square()
        + per_pair(bb) * (dr * dc.clone()).mul_scalar(2.0)
        + per_pair(c) * dc.square())
    .mul_scalar(-0.5);
    let alpha = per_pair(&g.opacity) * power.exp(); // [m]
    let log_t = alpha.clone().clamp_max(MAX_ALPHA).neg().log1p();
    let sil = match mode {
        Compositing::SigmoidSum { temperature } => {
            let sum = zero().select_assign(0, pi.clone(), alpha.clone(), Add);
            burn::tensor::activation::sigmoid(sum.sub_scalar(0.5).mul_scalar(temperature))
        }
        Compositing::Alpha => zero()
            .select_assign(0, pi.clone(), log_t.clone(), Add)
            .exp()
            .neg()
            .add_scalar(1.0),
    };
    // Exclusive cumulative sum of log(1 − α) within each pixel's run of pairs: the global
    // inclusive cumsum, less its value just before the run starts.
    let inclusive = log_t.clone().cumsum(0);
    let run_start: Vec<i64> = {
        let mut starts = Vec::with_capacity(m);
        let mut start = 0usize;
        for k in 0..m {
            if k > 0 && pixel[k] != pixel[k - 1] {
                start = k;
            }
            starts.push(start as i64);
        }
        starts
    };
    let starts = Tensor::<1, Int>::from_data(TensorData::new(run_start, [m]), &device);
    let run_base = (inclusive.clone() - log_t.clone()).select(0, starts);
    let before = inclusive - log_t - run_base;
    let w = alpha * before.exp();
    let z = per_pair(&g.depth);
    let wz = zero().select_assign(0, pi.clone(), w.clone() * z, Add);
    let ws = zero().select_assign(0, pi, w, Add);
    (
        sil.reshape([b, p]),
        (wz / ws.add_scalar(1e-8)).reshape([b, p]),
    )
}
