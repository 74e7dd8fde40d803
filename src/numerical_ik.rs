//! Numerical inverse kinematics, position only: damped least squares (DLS) on the analytic
//! position Jacobian ([`KinematicChain::position_jacobian`]). Beyond the EMSSL paper: the tool
//! a roboticist would reach for instead of a learned model, and the refinement of a learned
//! model's answer (a good start needs few iterations).
//!
//! Each iteration: `e = target - p(q)`, `dq = J^T (J J^T + lambda^2 I)^-1 e`, the step's norm
//! capped at `max_step` radians, `q` clamped to the joint ranges. Stops when `|e|` falls below
//! `tolerance_m` or after `max_iterations`. Targets are solved independently, in parallel.

use nalgebra::{Matrix3, Point3};
use rayon::prelude::*;

use crate::kinematics::KinematicChain;

/// Damped least squares settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DlsConfig {
    /// Damping lambda (m): keeps steps bounded near singularities.
    pub damping: f64,
    /// Converged when the distance to the target is below this (m).
    pub tolerance_m: f64,
    pub max_iterations: usize,
    /// Largest step norm per iteration (rad).
    pub max_step: f64,
}

impl DlsConfig {
    /// Tolerance 0.01 mm, at most 100 iterations, damping 0.01 m, steps of at most 0.5 rad.
    pub fn standard() -> Self {
        DlsConfig {
            damping: 0.01,
            tolerance_m: 1e-5,
            max_iterations: 100,
            max_step: 0.5,
        }
    }
}

/// One solve's answer.
#[derive(Clone, Debug)]
pub struct IkSolution {
    pub joints: Vec<f64>,
    /// Distance (m) from the target at the end.
    pub error_m: f64,
    /// Iterations taken (Jacobian evaluations).
    pub iterations: usize,
}

/// Solve for `target` from `start`, keeping each joint in `ranges`.
pub fn solve(
    chain: &KinematicChain,
    target: &Point3<f64>,
    start: &[f64],
    ranges: &[[f64; 2]],
    cfg: &DlsConfig,
) -> IkSolution {
    let mut q: Vec<f64> = start.to_vec();
    let mut iterations = 0;
    loop {
        let e = target - chain.end_effector(&q);
        let error_m = e.norm();
        if error_m < cfg.tolerance_m || iterations >= cfg.max_iterations {
            return IkSolution {
                joints: q,
                error_m,
                iterations,
            };
        }
        let j = chain.position_jacobian(&q);
        let damped = &j * j.transpose() + Matrix3::identity() * cfg.damping.powi(2);
        let Some(inv) = damped.try_inverse() else {
            return IkSolution {
                joints: q,
                error_m,
                iterations,
            };
        };
        let mut dq = j.transpose() * (inv * e);
        let norm = dq.norm();
        if norm > cfg.max_step {
            dq *= cfg.max_step / norm;
        }
        for (k, v) in q.iter_mut().enumerate() {
            let [lo, hi] = ranges[k];
            *v = (*v + dq[k]).clamp(lo, hi);
        }
        iterations += 1;
    }
}

/// [`solve`] for every target from its start (`starts[i]`), in parallel.
pub fn solve_batch(
    chain: &KinematicChain,
    targets: &[Point3<f64>],
    starts: &[Vec<f64>],
    ranges: &[[f64; 2]],
    cfg: &DlsConfig,
) -> Vec<IkSolution> {
    targets
        .par_iter()
        .zip(starts)
        .map(|(t, s)| solve(chain, t, s, ranges, cfg))
        .collect()
}
