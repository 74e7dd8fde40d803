//! The data of the learned inverse-kinematics experiments (EMSSL paper section IV): joint
//! vectors drawn uniformly from the joint range, their end positions by forward kinematics,
//! a train/test split, and the normalisations the networks see.
//!
//! The paper: 100,000 joint vectors, 70,000 for training and 30,000 for testing, in two joint
//! ranges ([-90, 90] and [-180, 180] degrees). Positions are normalised per axis to [0, 1] over
//! the training positions' bounds; joints to [0, 1] over the joint range (the inverse model's
//! sigmoid output).

use nalgebra::Point3;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use crate::error::{Error, Result};
use crate::kinematics::KinematicChain;

/// How the data is drawn.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IkDataConfig {
    pub samples: usize,
    pub train: usize,
    /// Every joint is drawn from `[-range_deg, range_deg]` degrees.
    pub range_deg: f64,
    pub seed: u64,
}

impl IkDataConfig {
    /// The paper's: 100,000 samples, 70,000 for training, +-90 degrees.
    pub fn paper(range_deg: f64) -> Self {
        IkDataConfig {
            samples: 100_000,
            train: 70_000,
            range_deg,
            seed: 0,
        }
    }

    /// 3,000 samples, 2,000 for training.
    pub fn quick(range_deg: f64) -> Self {
        IkDataConfig {
            samples: 3_000,
            train: 2_000,
            range_deg,
            seed: 0,
        }
    }
}

/// Joint vectors (radians) and their end positions (metres), the first `n_train` for training.
#[derive(Clone, Debug)]
pub struct IkData {
    pub joints: Vec<Vec<f64>>,
    pub positions: Vec<Point3<f64>>,
    pub n_train: usize,
    /// Joint range (radians), the same for every joint.
    pub range: [f64; 2],
    /// Per-axis bounds of the training positions (m): the position normalisation.
    pub position_bounds: [[f64; 3]; 2],
}

impl IkData {
    /// Draw the data for `chain` (seeded), its end positions by forward kinematics.
    pub fn generate(chain: &KinematicChain, cfg: &IkDataConfig) -> Result<Self> {
        if cfg.train == 0 || cfg.train >= cfg.samples {
            return Err(Error::Config(format!(
                "IK data: train ({}) must be between 1 and samples - 1 ({})",
                cfg.train,
                cfg.samples.saturating_sub(1)
            )));
        }
        let r = cfg.range_deg.to_radians();
        let mut rng = StdRng::seed_from_u64(cfg.seed);
        let joints: Vec<Vec<f64>> = (0..cfg.samples)
            .map(|_| (0..chain.dof()).map(|_| rng.random_range(-r..=r)).collect())
            .collect();
        let positions = chain.end_effector_batch(&joints);
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &positions[..cfg.train] {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        Ok(IkData {
            joints,
            positions,
            n_train: cfg.train,
            range: [-r, r],
            position_bounds: [lo, hi],
        })
    }

    pub fn train(&self) -> std::ops::Range<usize> {
        0..self.n_train
    }

    pub fn test(&self) -> std::ops::Range<usize> {
        self.n_train..self.joints.len()
    }

    /// A position normalised to [0, 1] per axis over the training bounds.
    pub fn normalise_position(&self, p: &Point3<f64>) -> [f32; 3] {
        let [lo, hi] = self.position_bounds;
        [0, 1, 2].map(|k| ((p[k] - lo[k]) / (hi[k] - lo[k]).max(1e-9)) as f32)
    }

    /// The inverse of [`IkData::normalise_position`].
    pub fn position_from_normalised(&self, v: &[f32]) -> Point3<f64> {
        let [lo, hi] = self.position_bounds;
        Point3::from([0, 1, 2].map(|k| lo[k] + v[k] as f64 * (hi[k] - lo[k])))
    }

    /// A joint vector normalised to [0, 1] over the joint range.
    pub fn normalise_joints(&self, q: &[f64]) -> Vec<f32> {
        let [lo, hi] = self.range;
        q.iter().map(|&v| ((v - lo) / (hi - lo)) as f32).collect()
    }

    /// `positions` normalised, row after row (`[n * 3]`, the networks' input layout).
    pub fn position_rows(&self, positions: &[Point3<f64>]) -> Vec<f32> {
        positions
            .iter()
            .flat_map(|p| self.normalise_position(p))
            .collect()
    }

    /// `joints` normalised, row after row (`[n * dof]`).
    pub fn joint_rows(&self, joints: &[Vec<f64>]) -> Vec<f32> {
        joints
            .iter()
            .flat_map(|q| self.normalise_joints(q))
            .collect()
    }

    /// The inverse of [`IkData::normalise_joints`].
    pub fn joints_from_normalised(&self, q: &[f32]) -> Vec<f64> {
        let [lo, hi] = self.range;
        q.iter().map(|&v| lo + v as f64 * (hi - lo)).collect()
    }
}

/// Distance errors (cm) between desired positions and those the predicted joints reach.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DistanceErrors {
    pub mean_cm: f64,
    pub median_cm: f64,
    pub p95_cm: f64,
    pub max_cm: f64,
    pub targets: usize,
}

impl DistanceErrors {
    /// Statistics of `errors_m` (metres).
    pub fn from_metres(errors_m: &[f64]) -> Self {
        let mut e: Vec<f64> = errors_m.iter().map(|v| 100.0 * v).collect();
        e.sort_by(f64::total_cmp);
        let at = |q: f64| {
            if e.is_empty() {
                f64::NAN
            } else {
                e[((e.len() - 1) as f64 * q).round() as usize]
            }
        };
        DistanceErrors {
            mean_cm: e.iter().sum::<f64>() / e.len().max(1) as f64,
            median_cm: at(0.5),
            p95_cm: at(0.95),
            max_cm: e.last().copied().unwrap_or(f64::NAN),
            targets: e.len(),
        }
    }
}

/// Distances (m) between `targets` and the end positions `chain` reaches with `joints`.
pub fn reach_errors(
    chain: &KinematicChain,
    targets: &[Point3<f64>],
    joints: &[Vec<f64>],
) -> Vec<f64> {
    distances(targets, &chain.end_effector_batch(joints))
}

/// Distances (m) between `targets` and the positions `reached`, pair by pair.
pub fn distances(targets: &[Point3<f64>], reached: &[Point3<f64>]) -> Vec<f64> {
    targets
        .iter()
        .zip(reached)
        .map(|(t, r)| (t - r).norm())
        .collect()
}
