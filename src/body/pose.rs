//! Joint angles from a silhouette (`pose_from_image`): find the angles whose rendering by a
//! trained self-model matches the observed silhouette, by Adam on the angles through the
//! frozen model, from several starts per image in one batch, keeping the start that ends
//! with the lowest loss.
//!
//! Starts: the caller's guess for each image (the amortised estimator's answer,
//! [`crate::body::amortised`]) when given, then poses drawn uniformly within the joint
//! ranges (the same draws for every image, seeded). The learning rate falls along a half
//! cosine ([`crate::train::config::LrSchedule`]); the angles are in degrees, so the learning rate is about the
//! largest step in degrees Adam takes.

use burn::module::{Module, Param};
use burn::tensor::{Device, Int, Tensor, TensorData};
use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::body::descent::Descent;
use crate::body::observations::{ImageFit, Observed, check_angles, host};
use crate::core::error::{Error, Result};
use crate::self_models::model::Render;
use crate::train::batcher::TrainSet;

/// What the rendered silhouette is compared with the observed one by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SilhouetteLoss {
    /// Binary cross-entropy per pixel, averaged over the image.
    Bce,
    /// 1 - soft IoU (intersection over union of the probabilities).
    SoftIou,
}

/// How the angles are searched for.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseFitConfig {
    /// Starts per image (the guess, when given, is one of them).
    pub starts: usize,
    /// Adam steps.
    pub steps: usize,
    /// Adam's learning rate at the start (degrees), falling along a half cosine to 1%.
    pub learning_rate: f64,
    pub loss: SilhouetteLoss,
    /// Rows (image x start) rendered in one batch.
    pub batch_rows: usize,
    pub seed: u64,
}

impl PoseFitConfig {
    /// Refinement of a good guess: one start, a short descent.
    pub fn refine(steps: usize) -> Self {
        PoseFitConfig {
            starts: 1,
            steps,
            learning_rate: 1.0,
            loss: SilhouetteLoss::Bce,
            batch_rows: 64,
            seed: 0,
        }
    }

    /// A search without a guess: `starts` draws per image.
    pub fn search(starts: usize, steps: usize) -> Self {
        PoseFitConfig {
            starts,
            steps,
            learning_rate: 5.0,
            ..Self::refine(steps)
        }
    }

    fn validate(&self) -> Result<()> {
        if self.starts == 0 || self.batch_rows == 0 {
            return Err(Error::Config(
                "a pose fit needs at least one start and one row per batch".into(),
            ));
        }
        Descent::checked(self.steps, self.learning_rate, "a pose fit").map(|_| ())
    }
}

/// The joint angles found for each image.
#[derive(Clone, Debug)]
pub struct PoseEstimate {
    /// Degrees (the robot's user units), one vector per image.
    pub angles: Vec<Vec<f64>>,
    /// The loss of the kept start, per image.
    pub loss: Vec<f64>,
}

/// The unknowns: one row of joint angles (degrees) per image and start.
#[derive(Module, Debug)]
struct Angles {
    q: Param<Tensor<2>>,
}

/// The loss of every rendered row against its target: `[rows]`.
pub fn row_losses(loss: SilhouetteLoss, p: Tensor<4>, y: Tensor<4>) -> Tensor<1> {
    let [n, _, h, w] = p.dims();
    let (p, y) = (p.reshape([n, h * w]), y.reshape([n, h * w]));
    match loss {
        SilhouetteLoss::Bce => {
            let p = p.clamp(1e-6, 1.0 - 1e-6);
            let ll = y.clone() * p.clone().log() + (y.neg() + 1.0) * (p.neg() + 1.0).log();
            ll.mean_dim(1).neg().reshape([n])
        }
        SilhouetteLoss::SoftIou => {
            let inter = (p.clone() * y.clone()).sum_dim(1);
            let union = p.sum_dim(1) + y.sum_dim(1) - inter.clone();
            (inter / (union + 1e-6)).neg().add_scalar(1.0).reshape([n])
        }
    }
}

/// The box of the poses a self-model was trained on (degrees, per joint): where its
/// renderings can be trusted, so where the search draws its starts.
pub fn trained_ranges(seen: &[Vec<f64>]) -> Vec<[f64; 2]> {
    let dof = seen.first().map_or(0, Vec::len);
    (0..dof)
        .map(|j| {
            seen.iter()
                .map(|q| q[j])
                .fold([f64::INFINITY, f64::NEG_INFINITY], |r, v| {
                    [r[0].min(v), r[1].max(v)]
                })
        })
        .collect()
}

/// Starting poses for one image: `guess` (when given) and uniform draws within `ranges`
/// (degrees), `starts` in all; the draws depend on `seed` only.
fn starting_poses(
    guess: Option<&[f64]>,
    ranges: &[[f64; 2]],
    starts: usize,
    seed: u64,
) -> Vec<Vec<f64>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out: Vec<Vec<f64>> = guess.map(|g| g.to_vec()).into_iter().collect();
    while out.len() < starts {
        out.push(crate::sim::trajectory::uniform_in(&mut rng, ranges));
    }
    out.truncate(starts);
    out
}

/// The loss of each pose of `angles` (degrees, one per image) against its image in
/// `observed`, through `renderer` (no gradients), in batches of 64: what a fit minimises, so
/// a pose with a lower loss than the true one says the model prefers it.
pub fn pose_losses(
    renderer: &dyn Render,
    device: &Device,
    observed: &Observed,
    angles: &[Vec<f64>],
    loss: SilhouetteLoss,
) -> Result<Vec<f64>> {
    if angles.len() != observed.n {
        return Err(Error::Config(format!(
            "{} poses for {} images",
            angles.len(),
            observed.n
        )));
    }
    let dof = angles.first().map_or(0, Vec::len);
    check_angles(angles, dof, "pose")?;
    let mut out = Vec::with_capacity(observed.n);
    for first in (0..observed.n).step_by(64) {
        let end = (first + 64).min(observed.n);
        let q: Vec<f32> = angles[first..end]
            .iter()
            .flatten()
            .map(|&v| v as f32)
            .collect();
        let q = Tensor::<2>::from_data(TensorData::new(q, [end - first, dof]), device);
        let target = observed.select(first..end).tensor(device);
        let l = host(row_losses(loss, renderer.render(q).0, target))?;
        out.extend(l.into_iter().map(f64::from));
    }
    Ok(out)
}

/// Fit joint angles to the silhouettes `fit` observes, through its renderer, for a robot
/// with joint `ranges` (degrees). `guesses`: one starting pose per image, or none.
/// `progress(done)` is told how many images are finished.
pub fn pose_from_image(
    fit: ImageFit,
    ranges: &[[f64; 2]],
    guesses: Option<&[Vec<f64>]>,
    cfg: &PoseFitConfig,
    mut progress: impl FnMut(usize),
) -> Result<PoseEstimate> {
    let (renderer, device, image, observed) = fit.parts();
    cfg.validate()?;
    let descent = Descent::checked(cfg.steps, cfg.learning_rate, "pose from image")?;
    observed.check_for(image)?;
    let dof = ranges.len();
    if let Some(g) = guesses {
        if g.len() != observed.n {
            return Err(Error::Config(format!(
                "{} starting poses for {} images",
                g.len(),
                observed.n
            )));
        }
        check_angles(g, dof, "starting pose")?;
    }
    let starts = cfg.starts;
    let images_per_batch = (cfg.batch_rows / starts).max(1);
    let mut angles = Vec::with_capacity(observed.n);
    let mut losses = Vec::with_capacity(observed.n);
    let mut first = 0;
    while first < observed.n {
        let end = (first + images_per_batch).min(observed.n);
        let chunk = observed.select(first..end);
        let mut init = Vec::with_capacity(chunk.n * starts * dof);
        for i in first..end {
            let guess = guesses.map(|g| g[i].as_slice());
            for q in starting_poses(guess, ranges, starts, cfg.seed) {
                init.extend(q.iter().map(|&v| v as f32));
            }
        }
        let rows = chunk.n * starts;
        let q0 = Tensor::<2>::from_data(TensorData::new(init, [rows, dof]), device);
        let module = Angles {
            q: Param::from_tensor(q0),
        };
        // The batch's inputs are the row numbers, its target each row's image; every step
        // takes all rows (in an order that does not matter).
        let set = TrainSet {
            inputs: Tensor::from_data(
                TensorData::new((0..rows).map(|r| r as f32).collect::<Vec<_>>(), [rows, 1]),
                device,
            ),
            targets: vec![chunk.repeated(starts).tensor(device)],
        };
        let loss_kind = cfg.loss;
        let fitted = descent.run(module, &set, |m: &Angles, b| {
            let n = b.inputs.dims()[0];
            let rows: Tensor<1, Int> = b.inputs.clone().reshape([n]).int();
            let q = m.q.val().select(0, rows);
            row_losses(loss_kind, renderer.render(q).0, b.targets[0].clone()).sum()
        })?;
        // Score every row at its final angles, keep each image's best start.
        let q = fitted.q.val().detach();
        let rendered = renderer.render(q.clone()).0.detach();
        let target = chunk.repeated(starts).tensor(device);
        let row_loss = host(row_losses(loss_kind, rendered, target))?;
        let q = host(q)?;
        for i in 0..chunk.n {
            let best = (0..starts)
                .min_by(|&a, &b| row_loss[i * starts + a].total_cmp(&row_loss[i * starts + b]))
                .expect("at least one start");
            let r = i * starts + best;
            angles.push(
                q[r * dof..(r + 1) * dof]
                    .iter()
                    .map(|&v| v as f64)
                    .collect(),
            );
            losses.push(row_loss[r] as f64);
        }
        first = end;
        progress(first);
    }
    Ok(PoseEstimate {
        angles,
        loss: losses,
    })
}
