//! The loss and gradients of one dense-marching training step of FFKSM's occupancy field,
//! written out by hand on the CPU: the fast path of FFKSM's paper-preset training (self-modeling
//! paper section IV-B).
//!
//! The reference is burn's autodiff through [`crate::self_models::ffksm::marcher::render_silhouette`] and
//! [`crate::self_models::ffksm::weighted_mse`]; `tests/ffksm.rs` checks that both give the same loss and
//! the same gradient for every parameter, for both architectures.
//!
//! Why: a dense step evaluates the field at every sample of every ray (10,000 rays x 64
//! samples = 640,000 points for a 100x100 image) and back-propagates through all of them.
//! Through burn's graph, each activation is a `[640,000 x 128]` tensor (328 MB), and about half
//! of a step goes to copying, allocating and handing those between threads rather than to
//! matrix products (perf). Here a block of rays goes forward and backward through the whole
//! network while its activations stay in cache, with single-threaded GEMMs, one group of
//! blocks per task. The groups' gradients are summed in a fixed order. A step therefore gives
//! the same numbers whatever the number of threads.
//!
//! The step, for rays `r` with truth `t_r` and weight `w_r` (the robot-pixel weight or 1):
//! - points `p` (world, metres) at the stratified depths of [`MarchConfig::depths`], taken into
//!   the virtual frame `p' = p Mᵀ + t` and encoded ([`crate::self_models::ffksm::encoding`]);
//! - coordinate encoder `a = relu(E W₁ + b₁) W₂ + b₂`; the kinematic encoder `k` and its half
//!   of the first predictive layer are computed once per pose: `x₀ = a W_a + (k W_b + b)`;
//! - predictive layers with their ReLUs, output `[density d, visibility v]` per point;
//! - pixel `ŷ_r = Σ_s (1 − exp(−relu d_s)) v_s`; loss `L = (1/R) Σ_r w_r (ŷ_r − t_r)²`.

use burn::nn::Linear;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;

use crate::kernels::conv_gemm::{Layout, matmul};
use crate::self_models::ffksm::encoding::{encode_into, encoded_width};
use crate::self_models::ffksm::field::{OccupancyField, distal_of};
use crate::self_models::ffksm::marcher::MarchConfig;
use crate::sim::camera::Camera;

/// Rays per block: 16 rays of 64 samples keep a block's activations (~3 MB for the paper's
/// widths) within the caches.
const BLOCK_RAYS: usize = 16;

/// Tasks per step. Fixed, so the order in which gradients are summed does not depend on the
/// number of threads.
const GROUPS: usize = 32;

/// One step's loss and gradients.
pub struct DenseStep {
    pub loss: f64,
    /// One gradient per parameter of the field, on the non-autodiff `device` given to
    /// [`dense_step`], ready for the optimiser.
    pub gradients: GradientsParams,
}

/// A linear layer on the host: `y = x W + b`, `W` `[inputs, outputs]` row-major.
struct HostLinear {
    w: Vec<f32>,
    b: Vec<f32>,
    inputs: usize,
    outputs: usize,
}

impl HostLinear {
    fn of(layer: &Linear) -> Self {
        let w = layer.weight.val();
        let [inputs, outputs] = w.dims();
        let host = |t: Tensor<1>| t.into_data().try_into_vec::<f32>().expect("float");
        let w = host(w.reshape([inputs * outputs]));
        let b = layer
            .bias
            .as_ref()
            .map_or(vec![0.0; outputs], |b| host(b.val()));
        HostLinear {
            w,
            b,
            inputs,
            outputs,
        }
    }

    /// `y` `[n, outputs]` = `x` `[n, inputs]` `W` + `b`.
    fn forward(&self, x: &[f32], n: usize, y: &mut [f32]) {
        for row in y[..n * self.outputs].chunks_mut(self.outputs) {
            row.copy_from_slice(&self.b);
        }
        matmul(
            (
                &mut y[..n * self.outputs],
                Layout::row_major(n, self.outputs),
            ),
            (&x[..n * self.inputs], Layout::row_major(n, self.inputs)),
            (&self.w, Layout::row_major(self.inputs, self.outputs)),
            true,
            gemm::Parallelism::None,
        );
    }

    /// Accumulate `dW += xᵀ dy` and `db += Σ_rows dy`; with `dx`, also `dx = dy Wᵀ`.
    fn backward(
        &self,
        x: &[f32],
        dy: &[f32],
        n: usize,
        grad: &mut LayerGrad,
        dx: Option<&mut [f32]>,
    ) {
        let (i, o) = (self.inputs, self.outputs);
        matmul(
            (&mut grad.w, Layout::row_major(i, o)),
            (&x[..n * i], Layout::row_major(n, i).t()),
            (&dy[..n * o], Layout::row_major(n, o)),
            true,
            gemm::Parallelism::None,
        );
        for row in dy[..n * o].chunks(o) {
            for (g, v) in grad.b.iter_mut().zip(row) {
                *g += v;
            }
        }
        if let Some(dx) = dx {
            matmul(
                (&mut dx[..n * i], Layout::row_major(n, i)),
                (&dy[..n * o], Layout::row_major(n, o)),
                (&self.w, Layout::row_major(i, o).t()),
                false,
                gemm::Parallelism::None,
            );
        }
    }
}

/// The gradient of one linear layer.
#[derive(Clone)]
struct LayerGrad {
    w: Vec<f32>,
    b: Vec<f32>,
}

impl LayerGrad {
    fn zeros(l: &HostLinear) -> Self {
        LayerGrad {
            w: vec![0.0; l.inputs * l.outputs],
            b: vec![0.0; l.outputs],
        }
    }

    fn add(&mut self, other: &LayerGrad) {
        for (a, b) in self.w.iter_mut().zip(&other.w) {
            *a += b;
        }
        for (a, b) in self.b.iter_mut().zip(&other.b) {
            *a += b;
        }
    }
}

/// What the blocks accumulate: the coordinate encoder's two layers, the predictive layers
/// (of the first one the coordinate half of the weight, and as its bias gradient
/// `Σ_rows ∂L/∂x₀`, which also gives the pose half and the kinematic encoder), and the loss.
#[derive(Clone)]
struct Accumulated {
    coordinates: [LayerGrad; 2],
    predictive: Vec<LayerGrad>,
    loss: f64,
}

impl Accumulated {
    fn add(&mut self, other: &Accumulated) {
        for (a, b) in self.coordinates.iter_mut().zip(&other.coordinates) {
            a.add(b);
        }
        for (a, b) in self.predictive.iter_mut().zip(&other.predictive) {
            a.add(b);
        }
        self.loss += other.loss;
    }
}

/// The field on the host, for one pose.
struct HostField<'a> {
    field: &'a OccupancyField,
    coordinates: [HostLinear; 2],
    /// The predictive layers; the first one's weight holds only its coordinate half `W_a`.
    predictive: Vec<HostLinear>,
    /// `k W_b + b` of the first predictive layer, the same for every point of the pose.
    pose_part: Vec<f32>,
    rotation: [f32; 9],
    /// The virtual frame's shift `t` (`p' = p Mᵀ + t`).
    shift: [f32; 3],
    bands: usize,
}

/// Reusable buffers of one block.
struct Scratch {
    encoded: Vec<f32>,
    hidden: Vec<f32>,
    coordinate: Vec<f32>,
    /// Post-activation outputs of each predictive layer.
    predictive: Vec<Vec<f32>>,
    grad_a: Vec<f32>,
    grad_b: Vec<f32>,
}

impl HostField<'_> {
    fn scratch(&self, n: usize) -> Scratch {
        let widest = self
            .predictive
            .iter()
            .map(|l| l.outputs)
            .chain([self.coordinates[0].outputs, self.coordinates[1].outputs])
            .max()
            .unwrap_or(1);
        Scratch {
            encoded: vec![0.0; n * self.coordinates[0].inputs],
            hidden: vec![0.0; n * self.coordinates[0].outputs],
            coordinate: vec![0.0; n * self.coordinates[1].outputs],
            predictive: self
                .predictive
                .iter()
                .map(|l| vec![0.0; n * l.outputs])
                .collect(),
            grad_a: vec![0.0; n * widest],
            grad_b: vec![0.0; n * widest],
        }
    }

    fn zero_grads(&self) -> Accumulated {
        Accumulated {
            coordinates: [
                LayerGrad::zeros(&self.coordinates[0]),
                LayerGrad::zeros(&self.coordinates[1]),
            ],
            predictive: self.predictive.iter().map(LayerGrad::zeros).collect(),
            loss: 0.0,
        }
    }

    /// Forward and backward through one block of rays: `points` `[n, 3]` (world), `truth` and
    /// `weight` per ray, `scale` = 1/R of the whole step. Adds the block's gradients and loss.
    // The hot loop's block (see `dense_step`): its slices, the scratch buffers it reuses and
    // the sums it adds to, each named at its one caller.
    #[allow(clippy::too_many_arguments)]
    fn block(
        &self,
        points: &[f32],
        truth: &[f32],
        weight: &[f32],
        samples: usize,
        scale: f64,
        s: &mut Scratch,
        acc: &mut Accumulated,
    ) {
        let n = points.len() / 3;
        let rays = n / samples;
        // Virtual frame and positional encoding:
        // [x, sin(2⁰x), cos(2⁰x), …] with each term a 3-vector.
        let width = encoded_width(3, self.bands);
        let (m, t) = (&self.rotation, &self.shift);
        for (p, e) in points.chunks(3).zip(s.encoded.chunks_mut(width)) {
            let v = [0, 1, 2].map(|j| p[0] * m[j] + p[1] * m[3 + j] + p[2] * m[6 + j] + t[j]);
            encode_into(&v, self.bands, e);
        }
        // Coordinate encoder.
        let [c0, c1] = &self.coordinates;
        c0.forward(&s.encoded, n, &mut s.hidden);
        relu_in_place(&mut s.hidden[..n * c0.outputs]);
        c1.forward(&s.hidden, n, &mut s.coordinate);
        // Predictive module: the first layer adds the pose part instead of its bias.
        let last = self.predictive.len() - 1;
        for i in 0..=last {
            let (before, rest) = s.predictive.split_at_mut(i);
            let out = &mut rest[0];
            let layer = &self.predictive[i];
            if i == 0 {
                layer.forward(&s.coordinate, n, out);
                for row in out[..n * layer.outputs].chunks_mut(layer.outputs) {
                    for (v, p) in row.iter_mut().zip(&self.pose_part) {
                        *v += p;
                    }
                }
            } else {
                layer.forward(&before[i - 1], n, out);
            }
            if self.field.relu_after(i) {
                relu_in_place(&mut out[..n * layer.outputs]);
            }
        }
        // Compositing and the loss; the output's gradient `[n, 2]` into grad_a.
        let raw = &s.predictive[last];
        let grad_out = &mut s.grad_a[..2 * n];
        for r in 0..rays {
            let span = r * samples..(r + 1) * samples;
            let pixel: f64 = span
                .clone()
                .map(|k| {
                    let (d, v) = (raw[2 * k], raw[2 * k + 1]);
                    ((1.0 - (-d.max(0.0)).exp()) * v) as f64
                })
                .sum();
            let residual = pixel - truth[r] as f64;
            acc.loss += weight[r] as f64 * residual * residual * scale;
            let g = (2.0 * weight[r] as f64 * residual * scale) as f32;
            for k in span {
                let (d, v) = (raw[2 * k], raw[2 * k + 1]);
                let transmit = (-d.max(0.0)).exp();
                grad_out[2 * k] = if d > 0.0 { g * v * transmit } else { 0.0 };
                grad_out[2 * k + 1] = g * (1.0 - transmit);
            }
        }
        // Back through the predictive layers: ∂L/∂(layer i's output) is in grad_a.
        for i in (0..=last).rev() {
            let layer = &self.predictive[i];
            let o = layer.outputs;
            if self.field.relu_after(i) {
                mask_by_relu(&mut s.grad_a[..n * o], &s.predictive[i][..n * o]);
            }
            let input = if i == 0 {
                &s.coordinate
            } else {
                &s.predictive[i - 1]
            };
            layer.backward(
                input,
                &s.grad_a,
                n,
                &mut acc.predictive[i],
                Some(&mut s.grad_b),
            );
            std::mem::swap(&mut s.grad_a, &mut s.grad_b);
        }
        // Coordinate encoder: ∂L/∂a in grad_a.
        c1.backward(
            &s.hidden,
            &s.grad_a,
            n,
            &mut acc.coordinates[1],
            Some(&mut s.grad_b),
        );
        mask_by_relu(&mut s.grad_b[..n * c0.outputs], &s.hidden[..n * c0.outputs]);
        c0.backward(&s.encoded, &s.grad_b, n, &mut acc.coordinates[0], None);
    }
}

fn relu_in_place(x: &mut [f32]) {
    for v in x {
        *v = v.max(0.0);
    }
}

/// Zero the gradient where the ReLU's output is 0 (its input was not positive). A select,
/// not a conditional store: the compiler vectorises it (the branchy form was a quarter of the
/// original model's step, perf).
fn mask_by_relu(grad: &mut [f32], activated: &[f32]) {
    for (g, a) in grad.iter_mut().zip(activated) {
        *g = if *a > 0.0 { *g } else { 0.0 };
    }
}

/// The loss and gradients of one dense training step: the rays of `pixels` (row-major indices
/// into `camera`'s image) in the pose `angles` (radians), every sample of every ray marched, at
/// depths stratified by `jitter` exactly as [`crate::self_models::ffksm::marcher::render_silhouette`] draws
/// them, against `truth` (one value in [0, 1] per pixel), robot pixels (`truth >= 0.5`)
/// weighted by `robot_weight`. The gradients are tensors on `device` (not an autodiff one).
// A hot kernel, kept whole (170 lines): the forward pass of every ray and its hand-written
// backward pass share buffers laid out for one sweep each, and the reference beside it
// (`tests/ffksm.rs` against burn's autodiff) checks it as one unit; its arguments are the
// step's inputs, each named at its one caller.
#[allow(clippy::too_many_arguments)]
pub fn dense_step(
    field: &OccupancyField,
    (camera, angles): (&Camera, &[f64]),
    pixels: &[usize],
    truth: &[f32],
    robot_weight: f64,
    march: &MarchConfig,
    jitter: Option<u64>,
    device: &Device,
) -> DenseStep {
    assert_eq!(pixels.len(), truth.len());
    let angles32: Vec<f32> = angles.iter().map(|&v| v as f32).collect();
    let (coordinates, kinematics, predictive) = field.layers();
    let bands = field.bands();

    // The kinematic encoder and the first layer's pose half, once for the pose.
    let distal = distal_of(&angles32);
    let mut k_in = vec![0.0; encoded_width(distal.len(), bands)];
    encode_into(&distal, bands, &mut k_in);
    let [k0, k1] = [
        HostLinear::of(&kinematics[0]),
        HostLinear::of(&kinematics[1]),
    ];
    let mut k_hidden = vec![0.0; k0.outputs];
    k0.forward(&k_in, 1, &mut k_hidden);
    relu_in_place(&mut k_hidden);
    let mut k_out = vec![0.0; k1.outputs];
    k1.forward(&k_hidden, 1, &mut k_out);
    let first = HostLinear::of(&predictive[0]);
    let half = coordinates[1].weight.val().dims()[1];
    let (w_a, w_b) = first.w.split_at(half * first.outputs);
    let pose_half = HostLinear {
        w: w_b.to_vec(),
        b: first.b.clone(),
        inputs: first.inputs - half,
        outputs: first.outputs,
    };
    let mut pose_part = vec![0.0; first.outputs];
    pose_half.forward(&k_out, 1, &mut pose_part);
    let mut host_predictive = vec![HostLinear {
        w: w_a.to_vec(),
        b: vec![0.0; first.outputs],
        inputs: half,
        outputs: first.outputs,
    }];
    host_predictive.extend(predictive[1..].iter().map(HostLinear::of));
    let (rotation, shift) = field.affine_rows(&angles32);
    let host = HostField {
        field,
        coordinates: [
            HostLinear::of(&coordinates[0]),
            HostLinear::of(&coordinates[1]),
        ],
        predictive: host_predictive,
        pose_part,
        rotation,
        shift,
        bands,
    };

    // Every sample point of the step, as render_silhouette draws them.
    let samples = march.samples;
    let depths = march.depths(pixels.len(), jitter);
    let frame = camera.frame();
    let weights: Vec<f32> = truth
        .iter()
        .map(|&t| if t >= 0.5 { robot_weight as f32 } else { 1.0 })
        .collect();
    let scale = 1.0 / pixels.len().max(1) as f64;

    // Groups of blocks in parallel; blocks within a group in order.
    let per_group = pixels.len().div_ceil(GROUPS).max(1);
    // Each worker's buffers are reused across its groups; every block overwrites them.
    let groups: Vec<Accumulated> = (0..GROUPS)
        .into_par_iter()
        .map_init(
            || {
                (
                    host.scratch(BLOCK_RAYS * samples),
                    Vec::with_capacity(BLOCK_RAYS * samples * 3),
                )
            },
            |(scratch, points), g| {
                let mut acc = host.zero_grads();
                let start = (g * per_group).min(pixels.len());
                let end = ((g + 1) * per_group).min(pixels.len());
                let mut r0 = start;
                while r0 < end {
                    let r1 = (r0 + BLOCK_RAYS).min(end);
                    points.clear();
                    for r in r0..r1 {
                        let px = pixels[r];
                        let ray = frame.ray((px / camera.width) as f64, (px % camera.width) as f64);
                        for &t in &depths[r * samples..(r + 1) * samples] {
                            let p = ray.origin + ray.dir * t;
                            points.extend([p.x as f32, p.y as f32, p.z as f32]);
                        }
                    }
                    host.block(
                        points,
                        &truth[r0..r1],
                        &weights[r0..r1],
                        samples,
                        scale,
                        scratch,
                        &mut acc,
                    );
                    r0 = r1;
                }
                acc
            },
        )
        .collect();
    let mut total = host.zero_grads();
    for g in &groups {
        total.add(g);
    }

    // The first predictive layer's pose half and bias, and the kinematic encoder.
    let rows = &total.predictive[0].b;
    let mut first_w = total.predictive[0].w.clone();
    for k in &k_out {
        first_w.extend(rows.iter().map(|g| k * g));
    }
    let first_grad = LayerGrad {
        w: first_w,
        b: rows.clone(),
    };
    let mut d_k_out = vec![0.0; pose_half.inputs];
    matmul(
        (&mut d_k_out, Layout::row_major(1, pose_half.inputs)),
        (rows, Layout::row_major(1, pose_half.outputs)),
        (
            &pose_half.w,
            Layout::row_major(pose_half.inputs, pose_half.outputs).t(),
        ),
        false,
        gemm::Parallelism::None,
    );
    let mut k1_grad = LayerGrad::zeros(&k1);
    let mut d_k_hidden = vec![0.0; k1.inputs];
    k1.backward(&k_hidden, &d_k_out, 1, &mut k1_grad, Some(&mut d_k_hidden));
    mask_by_relu(&mut d_k_hidden, &k_hidden);
    let mut k0_grad = LayerGrad::zeros(&k0);
    k0.backward(&k_in, &d_k_hidden, 1, &mut k0_grad, None);

    // Into burn's gradients, keyed by the parameters' ids.
    let mut gradients = GradientsParams::new();
    let mut register = |layer: &Linear, g: &LayerGrad| {
        let [i, o] = layer.weight.val().dims();
        let w = Tensor::<2>::from_data(TensorData::new(g.w.clone(), [i, o]), device);
        gradients.register(layer.weight.id, w);
        if let Some(bias) = &layer.bias {
            let b = Tensor::<1>::from_data(TensorData::new(g.b.clone(), [o]), device);
            gradients.register(bias.id, b);
        }
    };
    register(&coordinates[0], &total.coordinates[0]);
    register(&coordinates[1], &total.coordinates[1]);
    register(&kinematics[0], &k0_grad);
    register(&kinematics[1], &k1_grad);
    register(&predictive[0], &first_grad);
    for (layer, g) in predictive[1..].iter().zip(&total.predictive[1..]) {
        register(layer, g);
    }
    DenseStep {
        loss: total.loss,
        gradients,
    }
}
