//! Numerical inverse kinematics, position only: damped least squares (DLS) on the analytic
//! position Jacobian ([`KinematicChain::position_jacobian`]). Beyond the EMSSL paper: the tool
//! a roboticist would reach for instead of a learned model, and the refinement of a learned
//! model's answer (a good start needs few iterations).
//!
//! Each iteration: `e = target - p(q)`, `dq = J^T (J J^T + lambda^2 I)^-1 e`, the step's norm
//! capped at `max_step` radians. A joint the step would push past its limit is moved to the
//! limit and dropped from that iteration's step, which is solved again for the other joints
//! (the clamping loop); a whole-circle range wraps instead. Stops when `|e|` falls below
//! `tolerance_m` or after `max_iterations`. Targets are solved independently, in parallel.

use nalgebra::{Matrix3, Point3};
use rayon::prelude::*;

use crate::sim::kinematics::KinematicChain;

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
        // The clamping loop: a joint the step would push past its limit is moved to the limit
        // and left out of the step, which is solved again for the others (a clamped step would
        // waste its push on the limit, and the solve would stall there).
        let mut fixed = vec![false; q.len()];
        let mut e = e;
        for _ in 0..=q.len() {
            let mut j = chain.position_jacobian(&q);
            for (k, &f) in fixed.iter().enumerate() {
                if f {
                    j.column_mut(k).fill(0.0);
                }
            }
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
            let hits: Vec<usize> = (0..q.len())
                .filter(|&k| !fixed[k] && !wraps(ranges[k]))
                .filter(|&k| !(ranges[k][0]..=ranges[k][1]).contains(&(q[k] + dq[k])))
                .collect();
            if hits.is_empty() {
                for (k, v) in q.iter_mut().enumerate() {
                    *v = keep_in(*v + dq[k], ranges[k]);
                }
                break;
            }
            for k in hits {
                q[k] = keep_in(q[k] + dq[k], ranges[k]);
                fixed[k] = true;
            }
            e = target - chain.end_effector(&q);
        }
        iterations += 1;
    }
}

/// Whether a joint range is the whole circle (its ends are one pose).
pub(crate) fn wraps([lo, hi]: [f64; 2]) -> bool {
    hi - lo >= 2.0 * std::f64::consts::PI - 1e-9
}

/// `v` kept in `range`: wrapped around when the range is the whole circle, clamped otherwise.
pub(crate) fn keep_in(v: f64, range: [f64; 2]) -> f64 {
    let [lo, hi] = range;
    if wraps(range) {
        lo + (v - lo).rem_euclid(2.0 * std::f64::consts::PI)
    } else {
        v.clamp(lo, hi)
    }
}

/// Where a solve from a learned answer stalls (a joint limit, a singularity, a local minimum):
/// the starts it tries next, until one converges.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Restarts {
    /// Samples of a many-solution model (the flow), tried closest first.
    pub flow_samples: usize,
    /// Then uniformly random joint vectors in the range (seeded per target).
    pub random: usize,
    pub seed: u64,
}

impl Restarts {
    /// 10 flow samples, then 50 random starts.
    pub fn standard() -> Self {
        Restarts {
            flow_samples: 10,
            random: 50,
            seed: 0,
        }
    }
}

/// [`solve_batch`] from `starts`; every target not within tolerance is solved again from the
/// `restarts.flow_samples` answers `samples(stalled)` gives for the stalled targets (k answer
/// sets, closest first), then from random starts, keeping the first converged (or the closest)
/// answer. Returns the solutions and how many targets were restarted.
pub fn solve_with_restarts(
    chain: &KinematicChain,
    targets: &[Point3<f64>],
    starts: &[Vec<f64>],
    ranges: &[[f64; 2]],
    cfg: &DlsConfig,
    restarts: &Restarts,
    samples: impl FnOnce(&[usize]) -> Vec<Vec<Vec<f64>>>,
) -> (Vec<IkSolution>, usize) {
    use rand::SeedableRng;
    let mut solutions = solve_batch(chain, targets, starts, ranges, cfg);
    let stalled: Vec<usize> = (0..targets.len())
        .filter(|&i| solutions[i].error_m >= cfg.tolerance_m)
        .collect();
    if stalled.is_empty() {
        return (solutions, 0);
    }
    let from_model = if restarts.flow_samples > 0 {
        samples(&stalled)
    } else {
        Vec::new()
    };
    let retried: Vec<IkSolution> = stalled
        .par_iter()
        .enumerate()
        .map(|(j, &i)| {
            let target = &targets[i];
            let mut best = solutions[i].clone();
            let mut tried = best.iterations;
            // The model's samples, closest to the target first.
            let mut candidates: Vec<&Vec<f64>> = from_model.iter().map(|s| &s[j]).collect();
            candidates.sort_by(|a, b| {
                (target - chain.end_effector(a))
                    .norm()
                    .total_cmp(&(target - chain.end_effector(b)).norm())
            });
            let mut rng = rand::rngs::StdRng::seed_from_u64(
                restarts.seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            let random: Vec<Vec<f64>> = (0..restarts.random)
                .map(|_| crate::sim::trajectory::uniform_in(&mut rng, ranges))
                .collect();
            for start in candidates.into_iter().chain(random.iter()) {
                let s = solve(chain, target, start, ranges, cfg);
                tried += s.iterations;
                if s.error_m < best.error_m {
                    best = s;
                }
                if best.error_m < cfg.tolerance_m {
                    break;
                }
            }
            best.iterations = tried;
            best
        })
        .collect();
    for (&i, s) in stalled.iter().zip(retried) {
        solutions[i] = s;
    }
    (solutions, stalled.len())
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

/// How a batch of solutions converged: the share within tolerance, the mean iterations, and
/// how many targets were restarted (where that applies).
pub fn solver_detail(
    solutions: &[IkSolution],
    dls: &DlsConfig,
    restarted: Option<usize>,
) -> String {
    let converged = solutions
        .iter()
        .filter(|x| x.error_m < dls.tolerance_m)
        .count();
    let mean_iterations = solutions.iter().map(|x| x.iterations).sum::<usize>() as f64
        / solutions.len().max(1) as f64;
    format!(
        "{:.2}% within {} mm, {mean_iterations:.1} iterations on average (cap {}){}",
        100.0 * converged as f64 / solutions.len().max(1) as f64,
        dls.tolerance_m * 1e3,
        dls.max_iterations,
        restarted.map_or(String::new(), |n| format!(", {n} targets restarted"))
    )
}
