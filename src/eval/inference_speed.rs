//! Inference speed measured properly: warm-up calls, then timed calls with the device
//! synchronised after each, median of the repeats; at batch 1 (latency) and batch 256
//! (throughput). Training throughput is measured by the training loop itself
//! ([`crate::train::config::TrainLog::images_per_second`]); the paper's "FPS" was that figure.

use burn::tensor::{Device, Distribution, Tensor};

/// One timed batch size.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Timing {
    pub batch: usize,
    /// Median seconds per call.
    pub median_s: f64,
    pub repeats: usize,
}

impl Timing {
    pub fn images_per_second(&self) -> f64 {
        self.batch as f64 / self.median_s
    }
}

/// How long to measure.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SpeedConfig {
    pub warmup: usize,
    /// Timed calls at least this many...
    pub min_repeats: usize,
    /// ...and until this many seconds have passed.
    pub min_seconds: f64,
    pub batches: Vec<usize>,
}

impl SpeedConfig {
    /// Its warm-up and repeats, for the timer.
    pub fn repeats(&self) -> crate::core::timing::Repeats {
        crate::core::timing::Repeats {
            warmup: self.warmup,
            min_repeats: self.min_repeats,
            min_seconds: self.min_seconds,
        }
    }

    pub fn paper() -> Self {
        SpeedConfig {
            warmup: 3,
            min_repeats: 10,
            min_seconds: 2.0,
            batches: vec![1, 256],
        }
    }

    /// The `short` preset (the main command's few minutes): batch 1 only, median of 3 calls
    /// after one warm-up.
    pub fn short() -> Self {
        SpeedConfig {
            warmup: 1,
            min_repeats: 3,
            min_seconds: 0.0,
            batches: vec![1],
        }
    }

    pub fn quick() -> Self {
        SpeedConfig {
            warmup: 1,
            min_repeats: 3,
            min_seconds: 0.0,
            batches: vec![1, 8],
        }
    }
}

/// Time `forward(angles)` for each batch size; inputs are random joint angles in degrees.
pub fn measure<F>(forward: F, dof: usize, device: &Device, cfg: &SpeedConfig) -> Vec<Timing>
where
    F: Fn(Tensor<2>) -> Tensor<4>,
{
    cfg.batches
        .iter()
        .map(|&batch| {
            let q = crate::core::device::with_seed(device, batch as u64, || {
                Tensor::<2>::random([batch, dof], Distribution::Uniform(-90.0, 90.0), device)
            });
            let times = crate::core::timing::time_calls(cfg.repeats(), || {
                let y = forward(q.clone());
                let _ = device.sync();
                drop(y);
            });
            Timing {
                batch,
                median_s: crate::core::timing::median(&times),
                repeats: times.len(),
            }
        })
        .collect()
}
