//! The sampling phase of one EMSSL iteration (EMSSL paper section III-B, Algorithm 1 lines
//! 4-17): the inverse model answers joints for every desired position, then the forward model
//! says where each answer takes the arm. The paper accelerates it two ways, and this module
//! runs any combination:
//!
//! - **batch inference**: the inverse model answers `inference_batch` positions per forward
//!   pass instead of one (a matrix product instead of a matrix-vector product per layer);
//! - **parallel forward model**: `threads` workers call the forward model at once.
//!
//! "No acceleration" is batch 1 and one thread. The paper interleaves the two models target by
//! target in that case; here inference always runs for every target first, then the forward
//! model: the same calls, in another order.
//!
//! The forward model is the arm's kinematics ([`crate::sim::kinematics::KinematicChain`], a few
//! microseconds a call). A real arm or a physics simulator is slower: [`Latency`] adds a
//! per-call delay, either waiting (a real arm: the thread sleeps, the core is free) or
//! computing (a simulator: the thread spins, the core is busy), so the parallel strategy's
//! benefit shows where it matters.

use std::time::{Duration, Instant};

use burn::tensor::Device;
use nalgebra::Point3;
use rayon::prelude::*;

use crate::core::error::{Error, Result};
use crate::ik::data::IkData;
use crate::ik::learning::predict;
use crate::ik::mlp::Mlp;
use crate::sim::kinematics::KinematicChain;

/// The extra time each forward-model call takes.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Latency {
    /// The kinematics alone.
    None,
    /// The thread sleeps this many microseconds per call (waiting on a real arm); the
    /// operating system's timer slack makes the real delay somewhat longer (measured and
    /// reported).
    Sleep { us: u64 },
    /// The thread busy-waits this many microseconds per call (a CPU-bound simulator).
    Spin { us: u64 },
}

impl Latency {
    /// A short name for tables: `none`, `sleep 50 us`, `spin 50 us`.
    pub fn label(&self) -> String {
        match self {
            Latency::None => "none".into(),
            Latency::Sleep { us } => format!("sleep {us} us"),
            Latency::Spin { us } => format!("spin {us} us"),
        }
    }
}

/// The longest per-call latency a measurement takes (10 ms: a paper-preset pass then lasts
/// about 12 minutes on one thread).
pub const MAX_LATENCY_US: u64 = 10_000;

impl std::str::FromStr for Latency {
    type Err = String;

    /// `none`, `sleep:US` or `spin:US` (microseconds per call).
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let us = |v: &str| {
            let us = v
                .parse::<u64>()
                .map_err(|_| format!("\"{s}\": the microseconds must be a whole number"))?;
            if us > MAX_LATENCY_US {
                return Err(format!(
                    "\"{s}\": at most {MAX_LATENCY_US} us a call (a pass calls the forward model once per target, 70,000 times on the paper preset)"
                ));
            }
            Ok(us)
        };
        match s.split_once(':') {
            None if s == "none" => Ok(Latency::None),
            Some(("sleep", v)) => Ok(Latency::Sleep { us: us(v)? }),
            Some(("spin", v)) => Ok(Latency::Spin { us: us(v)? }),
            _ => Err(format!(
                "\"{s}\" is not a latency (none, sleep:US or spin:US)"
            )),
        }
    }
}

/// The forward model the sampling phase calls: a kinematic chain and a per-call latency.
#[derive(Clone, Copy, Debug)]
pub struct ForwardModel<'a> {
    pub chain: &'a KinematicChain,
    pub latency: Latency,
}

impl ForwardModel<'_> {
    /// Where joints `q` (radians) put the end effector (metres), after the latency.
    pub fn reach(&self, q: &[f64]) -> Point3<f64> {
        match self.latency {
            Latency::None => {}
            Latency::Sleep { us } => std::thread::sleep(Duration::from_micros(us)),
            Latency::Spin { us } => {
                let until = Instant::now() + Duration::from_micros(us);
                while Instant::now() < until {
                    std::hint::spin_loop();
                }
            }
        }
        self.chain.end_effector(q)
    }

    /// [`ForwardModel::reach`] for every joint vector, on `workers`.
    pub fn reach_all(&self, joints: &[Vec<f64>], workers: &Workers) -> Vec<Point3<f64>> {
        match &workers.pool {
            None => joints.iter().map(|q| self.reach(q)).collect(),
            // One call per task, as Algorithm 1 pops K answers at a time; rayon's work
            // stealing keeps every worker busy instead of waiting for the slowest of each K.
            Some(pool) => pool.install(|| joints.par_iter().map(|q| self.reach(q)).collect()),
        }
    }
}

/// The forward model's workers, started once and reused by every pass (starting threads is
/// not part of a pass).
pub struct Workers {
    pool: Option<rayon::ThreadPool>,
    pub threads: usize,
}

impl Workers {
    /// `threads` workers; 1 runs on the calling thread, in order.
    pub fn new(threads: usize) -> Result<Self> {
        if threads == 0 {
            return Err(Error::Config(
                "the forward model needs at least one thread".into(),
            ));
        }
        let pool = if threads == 1 {
            None
        } else {
            Some(
                crate::core::denormals::thread_pool(threads)
                    .map_err(|e| Error::Config(format!("cannot start {threads} threads: {e}")))?,
            )
        };
        Ok(Workers { pool, threads })
    }
}

/// How the sampling phase runs.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Strategy {
    /// Positions per inverse-model forward pass (1: no batch inference).
    pub inference_batch: usize,
    /// Forward-model workers (1: no parallel computation).
    pub threads: usize,
}

/// What one sampling pass produced and how long each half took.
#[derive(Clone, Debug)]
pub struct SamplingPass {
    /// The inverse model's answers (radians) and where they took the arm (metres).
    pub joints: Vec<Vec<f64>>,
    pub reached: Vec<Point3<f64>>,
    pub inference_seconds: f64,
    pub forward_seconds: f64,
}

impl SamplingPass {
    pub fn seconds(&self) -> f64 {
        self.inference_seconds + self.forward_seconds
    }
}

/// One sampling pass of `model` (on an inference device) over `desired`: inference in
/// batches of `inference_batch`, then the forward model on `workers`.
pub fn sampling_pass(
    model: &Mlp,
    data: &IkData,
    desired: &[Point3<f64>],
    inference_batch: usize,
    forward: &ForwardModel,
    workers: &Workers,
    device: &Device,
) -> Result<SamplingPass> {
    if inference_batch == 0 {
        return Err(Error::Config(
            "sampling: the inference batch must be positive".into(),
        ));
    }
    let t = Instant::now();
    let joints = predict(model, data, desired, inference_batch, device);
    let inference_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let reached = forward.reach_all(&joints, workers);
    let forward_seconds = t.elapsed().as_secs_f64();
    Ok(SamplingPass {
        joints,
        reached,
        inference_seconds,
        forward_seconds,
    })
}
