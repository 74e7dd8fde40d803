//! The training data on the device and the batches drawn from it: epoch permutations
//! seeded by `(seed, epoch)`, input noise by `(seed, step)`, so a resumed run sees the same
//! batches as an uninterrupted one.

use burn::tensor::{Tensor, TensorData};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand_distr::{Distribution, Normal};

use super::config::TrainConfig;

/// The training data on the device: inputs `[n, dof]` and any targets `[n, ...]`.
#[derive(Clone, Debug)]
pub struct TrainSet {
    pub inputs: Tensor<2>,
    /// Image-like targets, each `[n, channels, H, W]` (silhouettes, depth, ...).
    pub targets: Vec<Tensor<4>>,
}

impl TrainSet {
    pub fn len(&self) -> usize {
        self.inputs.dims()[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One batch: noisy inputs and the matching targets.
pub struct Batch {
    pub inputs: Tensor<2>,
    pub targets: Vec<Tensor<4>>,
    /// The step (0-based) this batch is drawn for: for schedules (curricula) and per-step
    /// random draws that must be the same after a resume.
    pub step: usize,
    /// The samples of the training set in this batch, in its row order (on the host, so a
    /// loss that needs a sample's values on the host can keep its own copy of the training
    /// set instead of reading the batch back from the device).
    pub indices: Vec<usize>,
}

impl Batch {
    /// This batch with its inputs cast to `dtype` (a lower precision's: the targets stay f32,
    /// the losses widen the network's output to meet them).
    pub fn with_inputs_in(&self, dtype: burn::tensor::FloatDType) -> Batch {
        Batch {
            inputs: self.inputs.clone().cast(dtype),
            targets: self.targets.clone(),
            step: self.step,
            indices: self.indices.clone(),
        }
    }
}

/// Draws batches: epoch permutations seeded by `(seed, epoch)`, noise by `(seed, step)`.
///
/// What a batch needs from the host is uploaded once per epoch, not once per step: the
/// epoch's permutation as one index tensor, and the epoch's input noise (each step's rows
/// drawn from that step's own seed, as before, so the numbers are the same) as one tensor.
/// A step then only slices them on the device.
pub struct Batcher<'a> {
    data: &'a TrainSet,
    batch: usize,
    seed: u64,
    noise: f64,
    /// The epoch last asked for: its permutation, on the host and on the device, and its
    /// noise rows on the device (drawn once per epoch, not per batch).
    epoch: std::cell::RefCell<Option<EpochDraw>>,
}

struct EpochDraw {
    epoch: usize,
    perm: Vec<usize>,
    index: Tensor<1, burn::tensor::Int>,
    noise: Option<Tensor<2>>,
}

impl<'a> Batcher<'a> {
    pub fn new(data: &'a TrainSet, cfg: &TrainConfig) -> Self {
        Batcher {
            data,
            batch: cfg.batch.min(data.len()).max(1),
            seed: cfg.seed,
            noise: cfg.input_noise,
            epoch: std::cell::RefCell::new(None),
        }
    }

    fn steps_per_epoch(&self) -> usize {
        self.data.len().div_ceil(self.batch)
    }

    /// The input noise of step `step`'s `n` rows: seeded by `(seed, step)`.
    fn step_noise(&self, step: usize, n: usize, dof: usize, out: &mut Vec<f32>) {
        let mut rng = StdRng::seed_from_u64(
            self.seed.wrapping_add(1) ^ (step as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
        );
        let normal = Normal::new(0.0, self.noise).expect("noise sigma is finite");
        out.extend((0..n * dof).map(|_| normal.sample(&mut rng) as f32));
    }

    /// Draw epoch `epoch` if it is not the one held: its permutation, uploaded once, and
    /// the noise of all its steps, uploaded once.
    fn draw_epoch(&self, epoch: usize) -> std::cell::RefMut<'_, EpochDraw> {
        let mut held = self.epoch.borrow_mut();
        if held.as_ref().is_none_or(|e| e.epoch != epoch) {
            let n = self.data.len();
            let mut perm: Vec<usize> = (0..n).collect();
            let mut rng = StdRng::seed_from_u64(
                self.seed ^ (epoch as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            perm.shuffle(&mut rng);
            let device = self.data.inputs.device();
            let index = Tensor::<1, burn::tensor::Int>::from_data(
                TensorData::new(perm.iter().map(|&i| i as i64).collect::<Vec<_>>(), [n]),
                &device,
            );
            let noise = (self.noise > 0.0).then(|| {
                let dof = self.data.inputs.dims()[1];
                let spe = self.steps_per_epoch();
                let mut rows = Vec::with_capacity(n * dof);
                for k in 0..spe {
                    let rows_k = ((k + 1) * self.batch).min(n) - k * self.batch;
                    self.step_noise(epoch * spe + k, rows_k, dof, &mut rows);
                }
                Tensor::<2>::from_data(TensorData::new(rows, [n, dof]), &device)
            });
            *held = Some(EpochDraw {
                epoch,
                perm,
                index,
                noise,
            });
        }
        std::cell::RefMut::map(held, |h| h.as_mut().expect("just drawn"))
    }

    /// The rows of batch `step` (0-based) within its epoch's permutation.
    fn rows(&self, step: usize) -> (usize, std::ops::Range<usize>) {
        let spe = self.steps_per_epoch();
        let (epoch, k) = (step / spe, step % spe);
        (
            epoch,
            k * self.batch..((k + 1) * self.batch).min(self.data.len()),
        )
    }

    /// The indices of batch `step` (0-based).
    pub fn indices(&self, step: usize) -> Vec<usize> {
        let (epoch, rows) = self.rows(step);
        self.draw_epoch(epoch).perm[rows].to_vec()
    }

    /// Batch `step` on the data's device: slices of the epoch's index and noise tensors, so
    /// nothing crosses from the host within an epoch.
    pub fn batch(&self, step: usize) -> Batch {
        let (epoch, rows) = self.rows(step);
        let draw = self.draw_epoch(epoch);
        let indices = draw.perm[rows.clone()].to_vec();
        let index = draw.index.clone().slice(rows.clone());
        let mut inputs = self.data.inputs.clone().select(0, index.clone());
        if let Some(noise) = &draw.noise {
            inputs = inputs + noise.clone().slice(rows);
        }
        let targets = self
            .data
            .targets
            .iter()
            .map(|t| t.clone().select(0, index.clone()))
            .collect();
        Batch {
            inputs,
            targets,
            step,
            indices,
        }
    }
}
