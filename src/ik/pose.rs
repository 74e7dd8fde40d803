//! Full-pose inverse kinematics: a target is a position, optionally with an orientation, for
//! each tip of the chain (one, or several: both hands of a humanoid), and an answer is exact
//! when every tip is within 1 mm and 0.572 degrees (0.01 rad), IKFlow's definition. Solved by
//! Levenberg-Marquardt on the 6-D pose error within the joint limits, from given starts (a
//! learned model's samples) and then from random starts when those stall.
//!
//! The error of joints `q` for a target `(p_t, R_t)`: position `p_t - p(q)` (m) and rotation the
//! rotation vector of `R_t R(q)^T` (rad, world frame; its norm is the angle of `R_t^T R(q)`).
//! Several tips stack their rows in `e` and `J` (tips may share joints: a torso moving both
//! hands). Each iteration solves `(J^T W J + lambda I) dq = J^T W e` with the analytic pose Jacobian
//! ([`KinematicChain::pose_jacobian`]), `W` weighting rotation by `tolerance_m /
//! tolerance_rad` metres per radian (so both tolerances weigh alike) and `lambda = E + 1e-6`
//! (`E = e^T W e / 2`, Sugihara's choice: Gauss-Newton near the solution, gradient-like far
//! from it). A step that would leave a joint's range is clamped to it (whole-circle ranges
//! wrap); a step that does not lower `E` is retried with ten times the damping. A start is
//! given up when no step lowers `E` or `E` has not halved in 5 iterations (a local minimum or
//! a limit), for the next start.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;

use crate::ik::dls::keep_in;
use crate::sim::kinematics::{KinematicChain, TipPath};

/// The pose of one tip an inverse-kinematics target asks for: a position (m) and, for a
/// full-pose target, an orientation. A target is one of these per tip of the chain
/// ([`KinematicChain::tips`]), in their order: `&[PoseTarget]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseTarget {
    pub position: Point3<f64>,
    pub orientation: Option<UnitQuaternion<f64>>,
}

impl PoseTarget {
    /// Where each tip of `chain` is at `q`, with its orientation: the target `q` reaches.
    pub fn of(chain: &KinematicChain, q: &[f64]) -> Vec<Self> {
        chain
            .tip_poses(q)
            .iter()
            .map(|pose| PoseTarget {
                position: Point3::from(pose.translation.vector),
                orientation: Some(pose.rotation),
            })
            .collect()
    }

    /// The same target without its orientation.
    pub fn position_only(self) -> Self {
        PoseTarget {
            orientation: None,
            ..self
        }
    }
}

/// The largest position error (m) and rotation error (rad, the angle of `R_target^T R`; 0
/// for a position-only target) over the tips of `chain` at `q`.
pub fn pose_error(chain: &KinematicChain, q: &[f64], target: &[PoseTarget]) -> (f64, f64) {
    chain
        .tip_poses(q)
        .iter()
        .zip(target)
        .map(|(pose, t)| {
            let (p, r) = errors_at(pose, t);
            (p.norm(), r.norm())
        })
        .fold((0.0, 0.0), |(p, r), (a, b)| (p.max(a), r.max(b)))
}

/// The error vectors of the tip at `pose`.
fn errors_at(pose: &Isometry3<f64>, target: &PoseTarget) -> (Vector3<f64>, Vector3<f64>) {
    let position = target.position.coords - pose.translation.vector;
    let rotation = target.orientation.map_or(Vector3::zeros(), |t| {
        (t * pose.rotation.inverse()).scaled_axis()
    });
    (position, rotation)
}

/// Levenberg-Marquardt settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LmConfig {
    /// An answer is exact within these (IKFlow's: 1 mm and 0.01 rad = 0.572 degrees).
    pub tolerance_m: f64,
    pub tolerance_rad: f64,
    /// Iterations from one start.
    pub max_iterations: usize,
    /// Random starts tried after the given ones stall (per target).
    pub random_starts: usize,
    pub seed: u64,
}

impl LmConfig {
    /// 1 mm, 0.01 rad, 30 iterations a start, up to 100 random starts (a start that stalls
    /// is given up within a few iterations, so many are cheap; 20 left 0.5% of the Panda's
    /// targets unsolved from a quick model's samples, 100 left 0.02%).
    pub fn standard() -> Self {
        LmConfig {
            tolerance_m: 1e-3,
            tolerance_rad: 0.01,
            max_iterations: 30,
            random_starts: 100,
            seed: 0,
        }
    }
}

impl LmConfig {
    /// The budget for a target of `tips` tips: the iterations a start and the random starts
    /// times the tips (their rows stack, and a start takes more iterations to converge: on the
    /// G1 humanoid's two hands, 17 joints, 30 iterations a start and 100 random starts left
    /// 1.3% of 1,000 random reachable targets unsolved, 60 and 200 left 0.2%, and answered
    /// faster). One tip keeps the standard budget.
    pub fn for_tips(mut self, tips: usize) -> Self {
        let tips = tips.max(1);
        self.max_iterations *= tips;
        self.random_starts *= tips;
        self
    }
}

/// One answer.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseSolution {
    /// Joint values (SI), inside the ranges.
    pub joints: Vec<f64>,
    pub position_error_m: f64,
    pub rotation_error_rad: f64,
    /// Iterations over every start tried.
    pub iterations: usize,
    /// Starts tried (given and random).
    pub starts: usize,
}

impl PoseSolution {
    /// Within both tolerances.
    pub fn exact(&self, cfg: &LmConfig) -> bool {
        self.position_error_m <= cfg.tolerance_m && self.rotation_error_rad <= cfg.tolerance_rad
    }
}

/// Iterations without the error halving after which a start is given up.
const STALL: usize = 5;

/// Levenberg-Marquardt from `start` (clamped into `ranges` first), on the paths to the
/// chain's tips ([`KinematicChain::tip_paths`]), `target` holding one pose per path: the
/// rows of every tip stacked, exact when every tip is within the tolerances.
pub fn solve_from(
    paths: &[TipPath],
    target: &[PoseTarget],
    start: &[f64],
    ranges: &[[f64; 2]],
    cfg: &LmConfig,
) -> PoseSolution {
    assert_eq!(paths.len(), target.len(), "one pose per tip");
    let n = start.len();
    let w = cfg.tolerance_m / cfg.tolerance_rad;
    let full = target.iter().any(|t| t.orientation.is_some());
    // Each tip's error vectors at `q`, its Jacobian written into `jacs`.
    let errors = |q: &[f64], jacs: &mut [nalgebra::Matrix6xX<f64>]| {
        paths
            .iter()
            .zip(jacs.iter_mut())
            .zip(target)
            .map(|((p, jac), t)| errors_at(&p.pose_and_jacobian(q, jac), t))
            .collect::<Vec<_>>()
    };
    let tip_energy =
        |(p, r): (Vector3<f64>, Vector3<f64>)| 0.5 * (p.norm_squared() + w * w * r.norm_squared());
    let energy = |e: &[(Vector3<f64>, Vector3<f64>)]| e.iter().map(|&e| tip_energy(e)).sum::<f64>();
    // The energy at a trial step: poses only, no Jacobian (the step loop's hot path).
    let trial_energy = |q: &[f64]| {
        paths
            .iter()
            .zip(target)
            .map(|(p, t)| tip_energy(errors_at(&p.pose(q), t)))
            .sum::<f64>()
    };
    let worst = |e: &[(Vector3<f64>, Vector3<f64>)]| {
        e.iter().fold((0f64, 0f64), |(a, b), (p, r)| {
            (a.max(p.norm()), b.max(r.norm()))
        })
    };
    let mut q: Vec<f64> = start
        .iter()
        .zip(ranges)
        .map(|(&v, &r)| keep_in(v, r))
        .collect();
    let mut jacs = vec![nalgebra::Matrix6xX::zeros(n); paths.len()];
    let mut iterations = 0;
    let mut given_up = false;
    // Rows per tip: position, then the weighted rotation (left out for position-only targets).
    let per_tip = if full { 6 } else { 3 };
    let mut j = DMatrix::<f64>::zeros(per_tip * paths.len(), n);
    let mut e = DVector::<f64>::zeros(per_tip * paths.len());
    let mut trial = q.clone();
    // The energy at each iteration, for the stall test.
    let mut history: Vec<f64> = Vec::with_capacity(cfg.max_iterations + 1);
    loop {
        let err = errors(&q, &mut jacs);
        let (p_worst, r_worst) = worst(&err);
        let done = p_worst <= cfg.tolerance_m && r_worst <= cfg.tolerance_rad;
        if done || given_up || iterations >= cfg.max_iterations {
            return PoseSolution {
                joints: q,
                position_error_m: p_worst,
                rotation_error_rad: r_worst,
                iterations,
                starts: 1,
            };
        }
        let e_now = energy(&err);
        // A start whose error has not halved in the last STALL iterations is in a local
        // minimum or against a limit: give it up for the next start.
        if history.len() >= STALL && e_now > 0.5 * history[history.len() - STALL] {
            given_up = true;
            continue;
        }
        history.push(e_now);
        iterations += 1;
        for (t, (jac, (p_err, r_err))) in jacs.iter().zip(&err).enumerate() {
            let o = t * per_tip;
            for r in 0..3 {
                j.row_mut(o + r).copy_from(&jac.row(r));
                e[o + r] = p_err[r];
                if full {
                    j.row_mut(o + 3 + r).copy_from(&(jac.row(3 + r) * w));
                    e[o + 3 + r] = r_err[r] * w;
                }
            }
        }
        let jtj = j.tr_mul(&j);
        let g = j.tr_mul(&e);
        let mut lambda = e_now + 1e-6;
        let mut improved = false;
        for _ in 0..8 {
            let mut a = jtj.clone();
            for d in 0..n {
                a[(d, d)] += lambda;
            }
            let Some(dq) = a.cholesky().map(|c| c.solve(&g)) else {
                lambda *= 10.0;
                continue;
            };
            for (t, ((&v, &d), &r)) in trial.iter_mut().zip(q.iter().zip(dq.iter()).zip(ranges)) {
                *t = keep_in(v + d, r);
            }
            if trial_energy(&trial) < e_now {
                std::mem::swap(&mut q, &mut trial);
                improved = true;
                break;
            }
            lambda *= 10.0;
        }
        // No step lowers the error (a limit, a local minimum): give up this start.
        given_up |= !improved;
    }
}

/// Solve `target` from each of `starts` in turn, then from random joint vectors in `ranges`
/// (seeded by `cfg.seed` and `salt`), until one is exact; the best answer otherwise.
pub fn solve(
    paths: &[TipPath],
    target: &[PoseTarget],
    starts: &[Vec<f64>],
    ranges: &[[f64; 2]],
    cfg: &LmConfig,
    salt: u64,
) -> PoseSolution {
    let mut rng = StdRng::seed_from_u64(cfg.seed ^ salt.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let w = cfg.tolerance_m / cfg.tolerance_rad;
    let cost = |s: &PoseSolution| s.position_error_m.powi(2) + (w * s.rotation_error_rad).powi(2);
    let mut best: Option<PoseSolution> = None;
    let (mut iterations, mut tried) = (0, 0);
    let random = (0..cfg.random_starts).map(|_| {
        ranges
            .iter()
            .map(|&[lo, hi]| rng.random_range(lo..=hi))
            .collect::<Vec<f64>>()
    });
    for start in starts.iter().cloned().chain(random) {
        let s = solve_from(paths, target, &start, ranges, cfg);
        iterations += s.iterations;
        tried += 1;
        let exact = s.exact(cfg);
        if best.as_ref().is_none_or(|b| cost(&s) < cost(b)) {
            best = Some(s);
        }
        if exact {
            break;
        }
    }
    let mut best = best.expect("at least one start");
    best.iterations = iterations;
    best.starts = tried;
    best
}

/// [`solve`] for many targets in parallel, each from its own starts (`starts[i]`, may be
/// empty: random starts only).
pub fn solve_batch(
    chain: &KinematicChain,
    targets: &[Vec<PoseTarget>],
    starts: &[Vec<Vec<f64>>],
    ranges: &[[f64; 2]],
    cfg: &LmConfig,
) -> Vec<PoseSolution> {
    let paths = chain.tip_paths();
    targets
        .par_iter()
        .enumerate()
        .map(|(i, t)| {
            let empty = Vec::new();
            let s = starts.get(i).unwrap_or(&empty);
            solve(&paths, t, s, ranges, cfg, i as u64)
        })
        .collect()
}
