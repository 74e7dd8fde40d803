//! Beyond the EMSSL paper: a learned inverse kinematics that returns many solutions. A
//! conditional normalizing flow in the style of IKFlow (Ames et al. 2022, jstmn/ikflow):
//! RealNVP affine coupling layers whose scale and shift networks read the target position, an
//! invertible map between joint vectors and a standard normal, trained by maximum likelihood
//! on the random (joints, position) pairs. Sampling the normal and inverting the map draws
//! solutions for a target; k draws give k different answers from the family of solutions a
//! redundant arm has, where every regression (DRL, EMSSL) returns one.
//!
//! - Joints are scaled to [-1, 1] over the joint range; samples are clamped back into it.
//! - Each coupling layer permutes the joints (a fixed, seeded permutation), keeps the first
//!   half and scales and shifts the second: `y2 = x2 * exp(s) + t`, `(s, t) = net(x1, c)`,
//!   `s` soft-clamped to `[-clamp, clamp]` by `clamp * tanh(s / clamp)`; the last layer of
//!   each net starts at zero, so the untrained flow is the identity.
//! - SoftFlow (Kim et al. 2020), as IKFlow uses it: the solutions of one position lie on a
//!   surface of zero volume in joint space, where a likelihood is unbounded. Training adds
//!   Gaussian noise of a scale `c` drawn per sample from `[0, softflow_max]` to the joints and
//!   tells the networks `c`; sampling asks for `c = 0`.
//! - The loss is the negative log-likelihood per joint vector (up to a constant):
//!   `0.5 |z|^2 - log|det dz/dx|`.

use burn::module::Module;
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Int, Tensor, TensorData};
use nalgebra::Point3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand_distr::{Distribution, Normal, Uniform};

use crate::core::error::{Error, Result};
use crate::ik::data::{DistanceErrors, IkData, reach_errors};
use crate::ik::learning::{FitConfig, row_set};
use crate::sim::kinematics::KinematicChain;
use crate::train::{
    batcher::Batch,
    convergence::{ConvergenceLog, train_to_convergence},
    trainer::autodiff_device,
};

/// The flow's shape and training.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FlowConfig {
    /// Affine coupling layers, each with its own permutation.
    pub couplings: usize,
    /// Hidden widths of each coupling's scale-and-shift network.
    pub hidden: Vec<usize>,
    /// The log-scale is soft-clamped to `[-clamp, clamp]`.
    pub clamp: f64,
    /// Training noise scales are drawn from `[0, softflow_max]` (joint units scaled to
    /// [-1, 1]).
    pub softflow_max: f64,
    /// Epochs (or convergence), batch, learning rate, seed.
    pub fit: FitConfig,
    /// Samples per target for the best-of-k answer and the diversity.
    pub best_of: usize,
}

impl FlowConfig {
    /// 12 couplings of 3 -> 256 -> 256 -> 256 networks (IKFlow's are 1024 wide; 256 fits a
    /// 2-core CPU), clamp 2, noise up to 0.01, Adam 5e-4, batch 256, best of 10.
    pub fn standard() -> Self {
        FlowConfig {
            couplings: 12,
            hidden: vec![256, 256, 256],
            clamp: 2.0,
            softflow_max: 0.01,
            fit: FitConfig {
                epochs: 40,
                batch: 256,
                learning_rate: 5e-4,
                ..FitConfig::paper()
            },
            best_of: 10,
        }
    }
}

/// One affine coupling layer: its permutation and its scale-and-shift network.
#[derive(Module, Debug)]
pub struct Coupling {
    layers: Vec<Linear>,
}

impl Coupling {
    /// `(s, t)`, each `[n, width]`, of the kept half `x1` and the condition.
    fn scale_shift(&self, x1: Tensor<2>, cond: Tensor<2>, clamp: f64) -> (Tensor<2>, Tensor<2>) {
        let mut h = Tensor::cat(vec![x1, cond], 1);
        let last = self.layers.len() - 1;
        for (i, l) in self.layers.iter().enumerate() {
            h = l.forward(h);
            if i < last {
                h = relu(h);
            }
        }
        let [n, w2] = h.dims();
        let w = w2 / 2;
        let s = h.clone().slice([0..n, 0..w]);
        let t = h.slice([0..n, w..w2]);
        ((s / clamp).tanh() * clamp, t)
    }
}

/// The conditional flow: joints (scaled to [-1, 1]) <-> a standard normal, given the target.
#[derive(Module, Debug)]
pub struct FlowIk {
    couplings: Vec<Coupling>,
    #[module(skip)]
    permutations: Vec<Vec<i64>>,
    #[module(skip)]
    clamp: f64,
    /// Width of the condition: the target's values and the SoftFlow noise scale.
    #[module(skip)]
    condition: usize,
}

/// Width of a position target's condition: the normalised position and the noise scale.
const CONDITION: usize = 4;

impl FlowIk {
    /// A fresh flow for a `dof`-joint arm conditioned on a normalised position (seeded
    /// weights and permutations).
    pub fn new(cfg: &FlowConfig, dof: usize, device: &Device, seed: u64) -> Result<Self> {
        Self::conditioned(cfg, dof, CONDITION - 1, device, seed)
    }

    /// A fresh flow conditioned on `target` values per target (3: a position; 7: a position
    /// and a unit quaternion), plus the SoftFlow noise scale.
    pub fn conditioned(
        cfg: &FlowConfig,
        dof: usize,
        target: usize,
        device: &Device,
        seed: u64,
    ) -> Result<Self> {
        let condition = target + 1;
        if dof < 2 {
            return Err(Error::Config(format!(
                "the learned inverse kinematics needs at least 2 joints and this joint vector has {dof}: choose a tip below more joints (`tip`), or more joints (`joints`, `group`)"
            )));
        }
        if cfg.couplings == 0 || cfg.hidden.contains(&0) {
            return Err(Error::Config(format!(
                "the flow's configuration has {} couplings of widths {:?}: it needs at least one coupling, every width positive",
                cfg.couplings, cfg.hidden
            )));
        }
        let keep = dof / 2;
        let mut rng = StdRng::seed_from_u64(seed ^ 0xF10);
        let permutations = (0..cfg.couplings)
            .map(|_| {
                let mut p: Vec<i64> = (0..dof as i64).collect();
                p.shuffle(&mut rng);
                p
            })
            .collect();
        let couplings = crate::core::device::seeded(device, seed, |d| {
            (0..cfg.couplings)
                .map(|_| {
                    let mut widths = vec![keep + condition];
                    widths.extend(&cfg.hidden);
                    let n = widths.len();
                    let mut layers: Vec<Linear> = widths
                        .windows(2)
                        .map(|w| LinearConfig::new(w[0], w[1]).init(d))
                        .collect();
                    layers.push(
                        LinearConfig::new(widths[n - 1], 2 * (dof - keep))
                            .with_initializer(Initializer::Zeros)
                            .init(d),
                    );
                    Coupling { layers }
                })
                .collect()
        });
        Ok(FlowIk {
            couplings,
            permutations,
            clamp: cfg.clamp,
            condition,
        })
    }

    pub fn dof(&self) -> usize {
        self.permutations[0].len()
    }

    /// The target values it is conditioned on (3 or 7), without the noise scale.
    pub fn target_width(&self) -> usize {
        self.condition - 1
    }

    fn index(&self, p: &[i64], device: &Device) -> Tensor<1, Int> {
        Tensor::from_data(TensorData::new(p.to_vec(), [p.len()]), device)
    }

    /// Joints `x` `[n, dof]` to the latent `z`, with `log|det dz/dx|` `[n]`.
    pub fn forward(&self, x: Tensor<2>, cond: Tensor<2>) -> (Tensor<2>, Tensor<1>) {
        let [n, dof] = x.dims();
        let keep = dof / 2;
        let device = x.device();
        let mut x = x;
        let mut logdet = Tensor::<1>::zeros([n], &device);
        for (c, p) in self.couplings.iter().zip(&self.permutations) {
            x = x.select(1, self.index(p, &device));
            let x1 = x.clone().slice([0..n, 0..keep]);
            let x2 = x.slice([0..n, keep..dof]);
            let (s, t) = c.scale_shift(x1.clone(), cond.clone(), self.clamp);
            logdet = logdet + s.clone().sum_dim(1).reshape([n]);
            x = Tensor::cat(vec![x1, x2 * s.exp() + t], 1);
        }
        (x, logdet)
    }

    /// The latent `z` `[n, dof]` back to joints (the inverse of [`FlowIk::forward`]).
    pub fn inverse(&self, z: Tensor<2>, cond: Tensor<2>) -> Tensor<2> {
        let [n, dof] = z.dims();
        let keep = dof / 2;
        let device = z.device();
        let mut y = z;
        for (c, p) in self.couplings.iter().zip(&self.permutations).rev() {
            let y1 = y.clone().slice([0..n, 0..keep]);
            let y2 = y.slice([0..n, keep..dof]);
            let (s, t) = c.scale_shift(y1.clone(), cond.clone(), self.clamp);
            y = Tensor::cat(vec![y1, (y2 - t) * s.neg().exp()], 1);
            let mut inv = vec![0i64; dof];
            for (k, &v) in p.iter().enumerate() {
                inv[v as usize] = k as i64;
            }
            y = y.select(1, self.index(&inv, &device));
        }
        y
    }

    /// The mean negative log-likelihood (per joint vector, without the constant) of joints
    /// `x` given `cond`.
    pub fn nll(&self, x: Tensor<2>, cond: Tensor<2>) -> Tensor<1> {
        let (z, logdet) = self.forward(x, cond);
        let [n, _] = z.dims();
        (z.square().sum_dim(1).reshape([n]) * 0.5 - logdet).mean()
    }
}

/// Joints (radians) scaled to [-1, 1] over the data's range.
fn scale_joints(data: &IkData, joints: &[Vec<f64>]) -> Vec<f32> {
    data.joint_rows(joints)
        .into_iter()
        .map(|u| 2.0 * u - 1.0)
        .collect()
}

/// A trained flow and what it needs to answer.
pub struct TrainedFlow {
    pub model: FlowIk,
    pub log: Option<ConvergenceLog>,
}

/// Train the flow on the random training pairs of `data`: `cfg.fit.epochs` epochs, or with
/// `cfg.fit.converge` until the one-sample distance error on the validation targets (through
/// `chain`) stops improving.
pub fn train_flow(
    chain: &KinematicChain,
    data: &IkData,
    cfg: &FlowConfig,
    device: &Device,
) -> Result<TrainedFlow> {
    let train = data.train();
    let batch = cfg.fit.inference_batch;
    fit_flow(
        data,
        data.position_rows(&data.positions[train]),
        3,
        cfg,
        device,
        |m: &FlowIk| {
            let targets = &data.positions[data.validation()];
            let q = sample(m, data, targets, Draws::one(batch, 0x7A1), device)
                .pop()
                .expect("one sample");
            DistanceErrors::from_metres(&reach_errors(chain, targets, &q)).mean_cm
        },
    )
}

/// Train a flow on the training joints of `data` given `targets` (`width` values per
/// training sample: the condition without the noise scale), validated by `validate` (lower
/// is better) when `cfg.fit.converge` is set.
pub fn fit_flow(
    data: &IkData,
    targets: Vec<f32>,
    width: usize,
    cfg: &FlowConfig,
    device: &Device,
    validate: impl Fn(&FlowIk) -> f64,
) -> Result<TrainedFlow> {
    let tdev = autodiff_device(device, cfg.fit.seed);
    let dof = data.joints[0].len();
    let train = data.train();
    // Inputs: the targets; targets: the scaled joints.
    let set = row_set(
        targets,
        width,
        scale_joints(data, &data.joints[train]),
        dof,
        &tdev,
    );
    let model = FlowIk::conditioned(cfg, dof, width, &tdev, cfg.fit.seed)?;
    let softflow = cfg.softflow_max;
    let seed = cfg.fit.seed;
    let loss = move |m: &FlowIk, b: &Batch| {
        let [n, _] = b.inputs.dims();
        let device = b.inputs.device();
        let x = b.targets[0].clone().reshape([n, dof]);
        // SoftFlow: a noise scale per sample, noise of that scale on the joints.
        let mut rng = StdRng::seed_from_u64(seed ^ (b.step as u64).wrapping_mul(0xA076_1D64));
        let scale = Uniform::new_inclusive(0.0f32, softflow as f32).expect("valid range");
        let normal = Normal::new(0.0f32, 1.0).expect("unit normal");
        let c: Vec<f32> = (0..n).map(|_| scale.sample(&mut rng)).collect();
        let eps: Vec<f32> = (0..n * dof)
            .map(|i| c[i / dof] * normal.sample(&mut rng))
            .collect();
        let x = x + Tensor::from_data(TensorData::new(eps, [n, dof]), &device);
        let cond = Tensor::cat(
            vec![
                b.inputs.clone(),
                Tensor::from_data(TensorData::new(c, [n, 1]), &device),
            ],
            1,
        );
        m.nll(x, cond)
    };
    let train_cfg = cfg.fit.train_config(set.len());
    match &cfg.fit.converge {
        Some(conv) => {
            let (model, log) = train_to_convergence(
                model,
                crate::train::adam::adam(),
                &set,
                &train_cfg,
                conv,
                "flow IK",
                loss,
                |m: &FlowIk| validate(&m.valid()),
                cfg.fit.checkpoint_for("flow IK").as_ref(),
            )?;
            Ok(TrainedFlow {
                model: model.valid(),
                log: Some(log),
            })
        }
        None => {
            let (model, _) = crate::train::trainer::Trainer::new(&train_cfg, "flow IK")
                .fit(model, &set, loss)?;
            Ok(TrainedFlow {
                model: model.valid(),
                log: None,
            })
        }
    }
}

/// How a sampler draws: `k` samples a target, `batch` targets at a time, latent noise seeded
/// by `seed`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Draws {
    pub k: usize,
    pub batch: usize,
    pub seed: u64,
}

impl Draws {
    /// One sample a target: what the validation curves score.
    pub fn one(batch: usize, seed: u64) -> Self {
        Draws { k: 1, batch, seed }
    }
}

/// `k` samples of joints (radians) per position: `k` vectors of one answer per position.
pub fn sample(
    model: &FlowIk,
    data: &IkData,
    positions: &[Point3<f64>],
    draws: Draws,
    device: &Device,
) -> Vec<Vec<Vec<f64>>> {
    sample_rows(model, data, &data.position_rows(positions), draws, device)
}

/// [`sample`] for targets given as condition rows (`model.target_width()` values each).
pub fn sample_rows(
    model: &FlowIk,
    data: &IkData,
    targets: &[f32],
    draws: Draws,
    device: &Device,
) -> Vec<Vec<Vec<f64>>> {
    sample_rows_from(model, data, targets, draws, 0, device)
}

/// [`sample_rows`] of rows that come after `batches_before` batches of the same pass: the
/// seeds those batches would have had in one call, so a pass split into blocks samples as one.
pub fn sample_rows_from(
    model: &FlowIk,
    data: &IkData,
    targets: &[f32],
    draws: Draws,
    batches_before: usize,
    device: &Device,
) -> Vec<Vec<Vec<f64>>> {
    let Draws { k, batch, seed } = draws;
    let dof = model.dof();
    let width = model.target_width();
    let normal = Normal::new(0.0f32, 1.0).expect("unit normal");
    let rows: Vec<&[f32]> = targets.chunks(width).collect();
    (0..k)
        .map(|s| {
            let mut out = Vec::with_capacity(rows.len());
            for (c, part) in rows.chunks(batch.max(1)).enumerate() {
                let c = batches_before + c;
                let n = part.len();
                let mut rng = StdRng::seed_from_u64(seed ^ ((s as u64) << 32) ^ ((c as u64) << 8));
                let z: Vec<f32> = (0..n * dof).map(|_| normal.sample(&mut rng)).collect();
                // Append the noise scale 0 to every row.
                let cond: Vec<f32> = part
                    .iter()
                    .flat_map(|r| r.iter().copied().chain([0.0]))
                    .collect();
                let x = model.inverse(
                    Tensor::from_data(TensorData::new(z, [n, dof]), device),
                    Tensor::from_data(TensorData::new(cond, [n, width + 1]), device),
                );
                let v = x.into_data().try_into_vec::<f32>().expect("float");
                out.extend(v.chunks(dof).map(|r| {
                    let u: Vec<f32> = r
                        .iter()
                        .map(|x| ((x + 1.0) / 2.0).clamp(0.0, 1.0))
                        .collect();
                    data.joints_from_normalised(&u)
                }));
            }
            out
        })
        .collect()
}

/// For each position, the one of `samples` (k answer sets) that `chain` puts closest.
pub fn best_of(
    chain: &KinematicChain,
    positions: &[Point3<f64>],
    samples: &[Vec<Vec<f64>>],
) -> Vec<Vec<f64>> {
    let errors: Vec<Vec<f64>> = samples
        .iter()
        .map(|s| reach_errors(chain, positions, s))
        .collect();
    (0..positions.len())
        .map(|i| {
            let k = (0..samples.len())
                .min_by(|&a, &b| errors[a][i].total_cmp(&errors[b][i]))
                .expect("at least one sample");
            samples[k][i].clone()
        })
        .collect()
}

/// The mean distance (radians, Euclidean in joint space) between two of the k answers of one
/// target, over all pairs and targets: how different the solutions are.
pub fn diversity(samples: &[Vec<Vec<f64>>]) -> f64 {
    let k = samples.len();
    if k < 2 {
        return 0.0;
    }
    let n = samples[0].len();
    let mut total = 0.0;
    for i in 0..n {
        for a in 0..k {
            for b in a + 1..k {
                total += samples[a][i]
                    .iter()
                    .zip(&samples[b][i])
                    .map(|(x, y)| (x - y).powi(2))
                    .sum::<f64>()
                    .sqrt();
            }
        }
    }
    total / (n * k * (k - 1) / 2).max(1) as f64
}
