//! Conditional GAN inverse kinematics, a baseline of the EMSSL paper (section IV-A): a
//! generator from (normalised position, noise) to normalised joints and a discriminator on
//! (position, joints), trained on the random data. It learns the distribution of solutions
//! for a position rather than their average, so unlike direct regression it need not average
//! redundant solutions; its samples are only as precise as the discriminator can tell.
//!
//! Training: the standard non-saturating GAN losses with logits (binary cross-entropy), Adam
//! with beta1 = 0.5 for both networks, one discriminator step then one generator step per
//! batch. Noise is drawn on the host from a seeded generator, so runs repeat exactly.
//! Evaluation: one sample per target, and best-of-k (the sample the forward model says lands
//! closest; an extra column, since it calls the forward model k times per target).

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::Point3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use crate::error::Result;
use crate::ik_data::IkData;
use crate::inverse_learning::{FitConfig, row_set};
use crate::inverse_model::{InverseModelConfig, Mlp};
use crate::kinematics::KinematicChain;
use crate::losses::bce_with_logits;
use crate::training::{Batcher, autodiff_device};

/// The two networks and their training.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GanConfig {
    /// Noise inputs of the generator (standard normal).
    pub noise: usize,
    /// Hidden widths of the generator (3 + noise -> hidden -> dof, sigmoid output).
    pub generator_hidden: Vec<usize>,
    /// Hidden widths of the discriminator (3 + dof -> hidden -> 1 logit).
    pub discriminator_hidden: Vec<usize>,
    /// Epochs, batch, learning rate (both networks) and seed.
    pub fit: FitConfig,
    /// Samples per target for the best-of-k column.
    pub best_of: usize,
}

/// Rows of standard-normal noise `[n, width]`, seeded.
fn noise(n: usize, width: usize, seed: u64, device: &Device) -> Tensor<2> {
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = Normal::new(0.0f32, 1.0).expect("unit normal");
    let v: Vec<f32> = (0..n * width).map(|_| normal.sample(&mut rng)).collect();
    Tensor::from_data(TensorData::new(v, [n, width]), device)
}

/// The trained generator and its noise width.
pub struct Generator {
    pub model: Mlp,
    pub noise: usize,
}

/// Train the conditional GAN on the random training pairs of `data`.
pub fn train_gan(data: &IkData, cfg: &GanConfig, device: &Device) -> Result<Generator> {
    let tdev = autodiff_device(device, cfg.fit.seed);
    let dof = data.joints[0].len();
    let train = data.train();
    let set = row_set(
        data.position_rows(&data.positions[train.clone()]),
        3,
        data.joint_rows(&data.joints[train]),
        dof,
        &tdev,
    );
    let mut generator = InverseModelConfig {
        inputs: 3 + cfg.noise,
        hidden: cfg.generator_hidden.clone(),
        outputs: dof,
        sigmoid_output: true,
    }
    .init(&tdev, cfg.fit.seed)?;
    let mut discriminator = InverseModelConfig {
        inputs: 3 + dof,
        hidden: cfg.discriminator_hidden.clone(),
        outputs: 1,
        sigmoid_output: false,
    }
    .init(&tdev, cfg.fit.seed ^ 0xD15C)?;
    let mut g_optim = AdamConfig::new().with_beta_1(0.5).init();
    let mut d_optim = AdamConfig::new().with_beta_1(0.5).init();
    let train_cfg = cfg.fit.train_config(set.len());
    let batcher = Batcher::new(&set, &train_cfg);
    let bar = crate::training::progress_bar(train_cfg.steps, "CGAN");
    for step in 0..train_cfg.steps {
        let batch = batcher.batch(step);
        let p = batch.inputs;
        let [n, _] = p.dims();
        let real = batch.targets[0].clone().reshape([n, dof]);
        let ones = Tensor::<2>::ones([n, 1], &tdev);
        let zeros = Tensor::<2>::zeros([n, 1], &tdev);
        // The discriminator: real pairs against generated ones (the generator detached).
        let z = noise(n, cfg.noise, cfg.fit.seed ^ (2 * step as u64 + 1), &tdev);
        let fake = generator
            .forward(Tensor::cat(vec![p.clone(), z], 1))
            .detach();
        let d_loss = bce_with_logits(
            discriminator.forward(Tensor::cat(vec![p.clone(), real], 1)),
            ones.clone(),
        ) + bce_with_logits(
            discriminator.forward(Tensor::cat(vec![p.clone(), fake], 1)),
            zeros,
        );
        let grads = GradientsParams::from_grads(d_loss.backward(), &discriminator);
        discriminator = d_optim.step(cfg.fit.learning_rate, discriminator, grads);
        // The generator: make the discriminator call its pairs real (non-saturating loss).
        let z = noise(n, cfg.noise, cfg.fit.seed ^ (2 * step as u64 + 2), &tdev);
        let fake = generator.forward(Tensor::cat(vec![p.clone(), z], 1));
        let g_loss = bce_with_logits(discriminator.forward(Tensor::cat(vec![p, fake], 1)), ones);
        let grads = GradientsParams::from_grads(g_loss.backward(), &generator);
        generator = g_optim.step(cfg.fit.learning_rate, generator, grads);
        bar.inc(1);
    }
    bar.finish();
    Ok(Generator {
        model: generator.valid(),
        noise: cfg.noise,
    })
}

impl Generator {
    /// One sample of joints (radians) per position, noise seeded by `seed`.
    pub fn sample(
        &self,
        data: &IkData,
        positions: &[Point3<f64>],
        batch: usize,
        seed: u64,
        device: &Device,
    ) -> Vec<Vec<f64>> {
        let mut out = Vec::with_capacity(positions.len());
        for (c, part) in positions.chunks(batch.max(1)).enumerate() {
            let n = part.len();
            let p = Tensor::from_data(TensorData::new(data.position_rows(part), [n, 3]), device);
            let z = noise(n, self.noise, seed ^ ((c as u64) << 20), device);
            let q = self.model.forward(Tensor::cat(vec![p, z], 1));
            let [_, dof] = q.dims();
            let v = q.into_data().try_into_vec::<f32>().expect("float");
            out.extend(v.chunks(dof).map(|r| data.joints_from_normalised(r)));
        }
        out
    }

    /// For each position, the one of `k` samples whose forward kinematics lands closest.
    #[allow(clippy::too_many_arguments)]
    pub fn best_of(
        &self,
        chain: &KinematicChain,
        data: &IkData,
        positions: &[Point3<f64>],
        k: usize,
        batch: usize,
        seed: u64,
        device: &Device,
    ) -> Vec<Vec<f64>> {
        let mut best: Vec<(f64, Vec<f64>)> = vec![(f64::INFINITY, Vec::new()); positions.len()];
        for s in 0..k.max(1) {
            let joints = self.sample(data, positions, batch, seed.wrapping_add(s as u64), device);
            let reached = chain.end_effector_batch(&joints);
            for (i, (q, r)) in joints.into_iter().zip(reached).enumerate() {
                let e = (positions[i] - r).norm();
                if e < best[i].0 {
                    best[i] = (e, q);
                }
            }
        }
        best.into_iter().map(|(_, q)| q).collect()
    }
}
