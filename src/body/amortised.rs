//! The amortised pose estimator: a small CNN that maps a silhouette to joint angles in one
//! pass, trained on the self-model's own renderings (binarised at 0.5, as a camera's
//! silhouette is) of poses drawn uniformly within the joint ranges. It needs no simulator:
//! only the self-model. Used alone, and as the start of [`crate::body::pose`]'s refinement.
//!
//! Architecture: stride-2 3x3 convolutions with ReLU (`channels`), a hidden linear layer and
//! a linear output per joint, in [-1, 1] of each joint's range (tanh-free: the loss is mean
//! squared error on the normalised angles).

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use crate::body::observations::{Observed, host};
use crate::core::error::{Error, Result};
use crate::kernels::cpu_extension::conv2d_layer;
use crate::self_models::model::Render;
use crate::train::losses::mse;
use crate::train::{
    batcher::TrainSet,
    config::{LrSchedule, TrainConfig},
    trainer::{Trainer, autodiff_device},
};

/// The estimator and how it is trained.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AmortisedConfig {
    /// Output channels of the stride-2 convolutions.
    pub channels: Vec<usize>,
    /// Width of the hidden linear layer.
    pub hidden: usize,
    /// Poses rendered by the self-model to train on: the poses it was trained on, each moved
    /// by up to `jitter_deg` per joint (uniformly), so they stay where the model is reliable.
    pub renders: usize,
    pub jitter_deg: f64,
    /// Adam with a cosine schedule.
    pub train: TrainConfig,
}

impl AmortisedConfig {
    pub fn paper() -> Self {
        AmortisedConfig {
            channels: vec![16, 32, 64, 64],
            hidden: 256,
            renders: 20_000,
            jitter_deg: 5.0,
            train: TrainConfig {
                precision: Default::default(),
                schedule: Default::default(),
                steps: 6000,
                batch: 64,
                learning_rate: 1e-3,
                grad_clip_norm: Some(1.0),
                input_noise: 0.0,
                seed: 0,
                checkpoint_every: 0,
                log_every: 0,
            },
        }
    }

    pub fn quick() -> Self {
        AmortisedConfig {
            channels: vec![8, 16, 16],
            hidden: 64,
            renders: 2000,
            jitter_deg: 5.0,
            train: TrainConfig {
                steps: 1000,
                batch: 32,
                ..Self::paper().train
            },
        }
    }

    fn init(&self, image: [usize; 2], dof: usize, device: &Device) -> Result<PoseCnn> {
        if self.channels.is_empty() || self.hidden == 0 || dof == 0 {
            return Err(Error::Config(
                "the pose estimator needs at least one convolution, a hidden width and a joint"
                    .into(),
            ));
        }
        let build = |d: &Device| {
            let mut convs = Vec::new();
            let mut cin = 1;
            let [mut h, mut w] = image;
            for &c in &self.channels {
                convs.push(
                    Conv2dConfig::new([cin, c], [3, 3])
                        .with_stride([2, 2])
                        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                        .init(d),
                );
                cin = c;
                h = h.div_ceil(2);
                w = w.div_ceil(2);
            }
            PoseCnn {
                convs,
                hidden: LinearConfig::new(cin * h * w, self.hidden).init(d),
                out: LinearConfig::new(self.hidden, dof).init(d),
            }
        };
        Ok(crate::core::device::seeded(device, self.train.seed, build))
    }
}

/// The CNN: silhouettes `[n, 1, H, W]` -> normalised joint angles `[n, dof]`.
#[derive(Module, Debug)]
pub struct PoseCnn {
    convs: Vec<Conv2d>,
    hidden: Linear,
    out: Linear,
}

impl PoseCnn {
    pub fn forward(&self, images: Tensor<4>) -> Tensor<2> {
        let mut x = images;
        for c in &self.convs {
            x = relu(conv2d_layer(c, x));
        }
        let [n, c, h, w] = x.dims();
        let x = relu(self.hidden.forward(x.reshape([n, c * h * w])));
        self.out.forward(x)
    }
}

/// A trained estimator with the joint ranges it maps into.
pub struct PoseEstimator {
    pub model: PoseCnn,
    /// Joint ranges (degrees).
    pub ranges: Vec<[f64; 2]>,
    pub image: [usize; 2],
    /// Mean squared error (normalised angles) over the last tenth of training.
    pub final_loss: f64,
    pub train_seconds: f64,
}

/// Normalised angles in [-1, 1] of their ranges and back.
fn normalise(q: &[f64], ranges: &[[f64; 2]]) -> Vec<f32> {
    q.iter()
        .zip(ranges)
        .map(|(v, r)| ((2.0 * (v - r[0]) / (r[1] - r[0])) - 1.0) as f32)
        .collect()
}

fn denormalise(z: &[f32], ranges: &[[f64; 2]]) -> Vec<f64> {
    z.iter()
        .zip(ranges)
        .map(|(&v, r)| r[0] + (v as f64 + 1.0) * 0.5 * (r[1] - r[0]))
        .collect()
}

/// Train the estimator on `cfg.renders` renderings by `renderer` (on `device`, not
/// differentiated) of the self-model's training poses `seen` (degrees) jittered, clamped to
/// the joint `ranges` (degrees).
pub fn train_estimator(
    cfg: &AmortisedConfig,
    renderer: &dyn Render,
    device: &Device,
    image: [usize; 2],
    ranges: &[[f64; 2]],
    seen: &[Vec<f64>],
) -> Result<PoseEstimator> {
    let dof = ranges.len();
    if seen.is_empty() {
        return Err(Error::Config(
            "the pose estimator needs the poses the self-model was trained on".into(),
        ));
    }
    crate::body::observations::check_angles(seen, dof, "training pose")?;
    let mut rng = StdRng::seed_from_u64(cfg.train.seed ^ 0xB0D1);
    let j = cfg.jitter_deg.abs();
    let poses: Vec<Vec<f64>> = (0..cfg.renders)
        .map(|_| {
            let base = &seen[rng.random_range(0..seen.len())];
            base.iter()
                .zip(ranges)
                .map(|(v, r)| (v + rng.random_range(-j..=j)).clamp(r[0], r[1]))
                .collect()
        })
        .collect();
    let [h, w] = image;
    let mut pixels = Vec::with_capacity(cfg.renders * h * w);
    for chunk in poses.chunks(256) {
        let q: Vec<f32> = chunk.iter().flatten().map(|&v| v as f32).collect();
        let q = Tensor::<2>::from_data(TensorData::new(q, [chunk.len(), dof]), device);
        let s = renderer.render(q).0;
        if s.dims()[2..] != image {
            return Err(Error::Config(format!(
                "the self-model renders {:?} images, not {h}x{w}",
                &s.dims()[2..]
            )));
        }
        pixels.extend(host(s.greater_equal_elem(0.5).float())?);
    }
    let tdev = autodiff_device(device, cfg.train.seed);
    let targets: Vec<f32> = poses.iter().flat_map(|q| normalise(q, ranges)).collect();
    // The batch's inputs are the normalised angles (what the CNN answers), its target the
    // image (what the CNN reads).
    let set = TrainSet {
        inputs: Tensor::from_data(TensorData::new(targets, [cfg.renders, dof]), &tdev),
        targets: vec![Tensor::from_data(
            TensorData::new(pixels, [cfg.renders, 1, h, w]),
            &tdev,
        )],
    };
    let model = cfg.init(image, dof, &tdev)?;
    let train = TrainConfig {
        schedule: LrSchedule::Cosine,
        ..cfg.train.clone()
    };
    let (model, log) =
        Trainer::new(&train, "pose estimator (CNN)").fit(model, &set, |m: &PoseCnn, b| {
            mse(m.forward(b.targets[0].clone()), b.inputs.clone())
        })?;
    let tail = (log.curve.len() / 10).max(1);
    let final_loss = log.curve.iter().rev().take(tail).map(|c| c.1).sum::<f64>()
        / tail.min(log.curve.len()).max(1) as f64;
    Ok(PoseEstimator {
        model: model.valid(),
        ranges: ranges.to_vec(),
        image,
        final_loss,
        train_seconds: log.train_seconds,
    })
}

impl PoseEstimator {
    /// Joint angles (degrees) of every observed image, in batches of `batch`.
    pub fn estimate(
        &self,
        observed: &Observed,
        device: &Device,
        batch: usize,
    ) -> Result<Vec<Vec<f64>>> {
        observed.check_for(self.image)?;
        let dof = self.ranges.len();
        let mut out = Vec::with_capacity(observed.n);
        let mut first = 0;
        while first < observed.n {
            let end = (first + batch.max(1)).min(observed.n);
            let z = host(
                self.model
                    .forward(observed.select(first..end).tensor(device)),
            )?;
            out.extend(z.chunks(dof).map(|z| denormalise(z, &self.ranges)));
            first = end;
        }
        Ok(out)
    }
}
