//! The data of the learned inverse-kinematics experiments (EMSSL paper section IV): joint
//! vectors drawn uniformly from the joint range, their end positions by forward kinematics,
//! a train/test split, and the normalisations the networks see.
//!
//! The paper: 100,000 joint vectors, 70,000 for training and 30,000 for testing, in two joint
//! ranges ([-90, 90] and [-180, 180] degrees). Positions are normalised per axis to [0, 1] over
//! the training positions' bounds; joints to [0, 1] over the joint range (the inverse model's
//! sigmoid output), or to (cos, sin) per joint ([`JointOutput::Wrapped`]).
//!
//! A validation split (beyond the paper) is carved from the end of the training samples:
//! `train()` is what models fit, `validation()` what they stop on, `test()` is untouched.

use nalgebra::Point3;
use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::core::error::{Error, Result};
use crate::sim::kinematics::KinematicChain;

/// How the data is drawn.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IkDataConfig {
    pub samples: usize,
    pub train: usize,
    /// Every joint is drawn from its limits narrowed to `[-range_deg, range_deg]` degrees
    /// (a rotational joint without limits: that range; a prismatic joint: its limits, metres).
    pub range_deg: f64,
    pub seed: u64,
    /// The last `validation` of the `train` samples are held out for early stopping (0: none,
    /// the paper's split).
    #[serde(default)]
    pub validation: usize,
}

impl IkDataConfig {
    /// The paper's: 100,000 samples, 70,000 for training, +-90 degrees.
    pub fn paper(range_deg: f64) -> Self {
        IkDataConfig {
            samples: 100_000,
            train: 70_000,
            range_deg,
            seed: 0,
            validation: 0,
        }
    }

    /// 3,000 samples, 2,000 for training.
    pub fn quick(range_deg: f64) -> Self {
        IkDataConfig {
            samples: 3_000,
            train: 2_000,
            range_deg,
            seed: 0,
            validation: 0,
        }
    }
}

/// How a network writes joint angles.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum JointOutput {
    /// One value per joint in [0, 1] over the joint range, behind a sigmoid (the paper's).
    /// At +-180 degrees the two ends of the sigmoid are one pose.
    #[default]
    Sigmoid,
    /// (cos, sin) per joint on the unit circle, decoded with atan2 (and clamped into the range
    /// where it is not the whole circle): +179 and -179 degrees are neighbours.
    Wrapped,
}

impl JointOutput {
    /// Network outputs for `dof` joints.
    pub fn width(self, dof: usize) -> usize {
        match self {
            JointOutput::Sigmoid => dof,
            JointOutput::Wrapped => 2 * dof,
        }
    }

    /// The suffix of a method's name in the tables: "" or " (wrapped)".
    pub fn suffix(self) -> &'static str {
        match self {
            JointOutput::Sigmoid => "",
            JointOutput::Wrapped => " (wrapped)",
        }
    }
}

/// Joint vectors (radians) and their end positions (metres), the first `n_train` for training.
#[derive(Clone, Debug)]
pub struct IkData {
    pub joints: Vec<Vec<f64>>,
    pub positions: Vec<Point3<f64>>,
    pub n_train: usize,
    /// The last `n_validation` of the first `n_train` samples are the validation split.
    pub n_validation: usize,
    /// Each joint's range (SI: radians, metres for a prismatic joint).
    pub ranges: Vec<[f64; 2]>,
    /// Per-axis bounds of the training positions (m): the position normalisation.
    pub position_bounds: [[f64; 3]; 2],
}

/// Which joint samples [`IkData::generate_where`] keeps (collision-free ones).
pub type Keep<'a> = dyn Fn(&[f64]) -> bool + 'a;

impl IkData {
    /// Draw the data for `chain` (seeded), its end positions by forward kinematics.
    pub fn generate(chain: &KinematicChain, cfg: &IkDataConfig) -> Result<Self> {
        Self::generate_where(chain, cfg, None)
    }

    /// [`Self::generate`] keeping only the joint samples `keep` accepts (collision-free
    /// ones): each sample is drawn again until it does, at most a thousand times.
    pub fn generate_where(
        chain: &KinematicChain,
        cfg: &IkDataConfig,
        keep: Option<&Keep>,
    ) -> Result<Self> {
        if cfg.train == 0 || cfg.train >= cfg.samples {
            return Err(Error::Config(format!(
                "IK data: train ({}) must be between 1 and samples - 1 ({})",
                cfg.train,
                cfg.samples.saturating_sub(1)
            )));
        }
        if cfg.validation >= cfg.train {
            return Err(Error::Config(format!(
                "IK data: the validation split ({}) must be smaller than train ({})",
                cfg.validation, cfg.train
            )));
        }
        if !(cfg.range_deg > 0.0 && cfg.range_deg <= 180.0) {
            return Err(Error::Config(format!(
                "IK data: the joint range +-{} degrees must be within (0, 180]",
                cfg.range_deg
            )));
        }
        let ranges = chain.ranges_within(cfg.range_deg.to_radians());
        if let Some((j, _)) = chain
            .movable_joints()
            .zip(&ranges)
            .find(|(_, r)| !(r[1] > r[0]))
        {
            return Err(Error::Config(format!(
                "IK data: joint \"{}\" has no range to sample (a prismatic joint needs <limit lower upper>)",
                j.name
            )));
        }
        let mut rng = StdRng::seed_from_u64(cfg.seed);
        /// Draws a kept sample may take.
        const MAX_DRAWS: usize = 1000;
        let mut draw = || {
            (0..MAX_DRAWS)
                .map(|_| crate::sim::trajectory::uniform_in(&mut rng, &ranges))
                .find(|q| keep.is_none_or(|k| k(q)))
        };
        let mut joints: Vec<Vec<f64>> = Vec::with_capacity(cfg.samples);
        for _ in 0..cfg.samples {
            if keep.is_some() {
                // A collision check can take milliseconds a draw: Ctrl-C is looked at each.
                crate::core::interrupt::check(|| {
                    format!(
                        "stopped drawing collision-free joint samples ({} of {} drawn); nothing was written",
                        joints.len(),
                        cfg.samples
                    )
                })?;
            }
            joints.push(draw().ok_or_else(|| {
                Error::Config(format!(
                    "IK data: {MAX_DRAWS} joint samples in a row were in collision: the scene leaves the robot little room"
                ))
            })?);
        }
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
            n_validation: cfg.validation,
            ranges,
            position_bounds: [lo, hi],
        })
    }

    /// The samples models fit (the paper's training split less the validation split).
    pub fn train(&self) -> std::ops::Range<usize> {
        0..self.n_train - self.n_validation
    }

    /// The held-out samples early stopping watches (empty without a validation split).
    pub fn validation(&self) -> std::ops::Range<usize> {
        self.n_train - self.n_validation..self.n_train
    }

    /// Whether every joint's range is the whole circle (+-180 degrees): its ends are one pose.
    pub fn full_circle(&self) -> bool {
        self.ranges.iter().all(|&r| whole_circle(r))
    }

    /// The ranges as the settings of a trained model record them: one `[lo, hi]` when every
    /// joint shares it (as before per-joint ranges), else the list.
    pub fn range_record(&self) -> serde_json::Value {
        match self.ranges.first() {
            Some(first) if self.ranges.iter().all(|r| r == first) => serde_json::json!(first),
            _ => serde_json::json!(self.ranges),
        }
    }

    /// How many of `answers` (joint vectors, SI) leave some joint's range (beyond 1e-9).
    pub fn outside_limits(&self, answers: &[Vec<f64>]) -> usize {
        answers
            .iter()
            .filter(|q| !crate::sim::kinematics::within(q, &self.ranges, 1e-9))
            .count()
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

    /// A joint vector normalised to [0, 1] over each joint's range.
    pub fn normalise_joints(&self, q: &[f64]) -> Vec<f32> {
        q.iter()
            .zip(&self.ranges)
            .map(|(&v, &[lo, hi])| ((v - lo) / (hi - lo)) as f32)
            .collect()
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
        q.iter()
            .zip(&self.ranges)
            .map(|(&v, &[lo, hi])| lo + v as f64 * (hi - lo))
            .collect()
    }

    /// A joint vector as a network writes it under `output`.
    pub fn encode_joints(&self, q: &[f64], output: JointOutput) -> Vec<f32> {
        match output {
            JointOutput::Sigmoid => self.normalise_joints(q),
            JointOutput::Wrapped => q
                .iter()
                .flat_map(|&v| [v.cos() as f32, v.sin() as f32])
                .collect(),
        }
    }

    /// `joints` under `output`, row after row (`[n * output.width(dof)]`).
    pub fn joint_rows_as(&self, joints: &[Vec<f64>], output: JointOutput) -> Vec<f32> {
        joints
            .iter()
            .flat_map(|q| self.encode_joints(q, output))
            .collect()
    }

    /// Joints (radians, inside the range) from a network's output under `output`.
    pub fn decode_joints(&self, v: &[f32], output: JointOutput) -> Vec<f64> {
        match output {
            JointOutput::Sigmoid => self.joints_from_normalised(v),
            JointOutput::Wrapped => v
                .chunks(2)
                .zip(&self.ranges)
                .map(|(cs, &[lo, hi])| (cs[1] as f64).atan2(cs[0] as f64).clamp(lo, hi))
                .collect(),
        }
    }
}

/// Whether a joint range is the whole circle (+-180 degrees): its ends are one pose.
pub fn whole_circle([lo, hi]: [f64; 2]) -> bool {
    hi - lo >= 2.0 * std::f64::consts::PI - 1e-9
}

/// Distance errors (cm) between desired positions and those the predicted joints reach.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DistanceErrors {
    pub mean_cm: f64,
    pub median_cm: f64,
    pub p95_cm: f64,
    pub max_cm: f64,
    /// Share of targets (%) more than 10 cm off: the tail a mean hides (a joint-space
    /// regression averaging across two solution branches lands between them). NaN where
    /// not recorded (saved before it was; JSON writes it as null).
    #[serde(default = "not_recorded", deserialize_with = "nan_if_null")]
    pub above_10cm_pct: f64,
    pub targets: usize,
}

fn not_recorded() -> f64 {
    f64::NAN
}

fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
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
            above_10cm_pct: 100.0 * e.iter().filter(|&&v| v > 10.0).count() as f64
                / e.len().max(1) as f64,
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
