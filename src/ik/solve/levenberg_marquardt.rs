//! Full-pose inverse kinematics: a target is a position, optionally with an orientation, for
//! each tip of the chain (one, or several: both hands of a humanoid), and an answer is exact
//! when every tip is within 1 mm and 0.572 degrees (0.01 rad), IKFlow's definition. Solved by
//! Levenberg-Marquardt on the 6-D pose error within the joint limits, from given starts (a
//! learned model's samples) and then from random starts when those stall. Exact is the
//! success threshold; a start iterates on to the convergence tolerance (1e-4 mm and 1e-4
//! degrees by default, `LmConfig::converging_to`), where Levenberg-Marquardt converges
//! quadratically: from 1 mm, two or three iterations more.
//!
//! The error of joints `q` for a target `(p_t, R_t)`: position `p_t - p(q)` (m) and rotation the
//! rotation vector of `R_t R(q)^T` (rad, world frame; its norm is the angle of `R_t^T R(q)`).
//! Several tips stack their rows in `e` and `J` (tips may share joints: a torso moving both
//! hands). Each iteration solves `(J^T W J + lambda I) dq = J^T W e` with the analytic pose Jacobian
//! ([`KinematicChain::pose_jacobian`]), `W` weighting rotation by `tolerance_m /
//! tolerance_rad` metres per radian (so both tolerances weigh alike) and `lambda = E + 1e-12`
//! (`E = e^T W e / 2`, Sugihara's choice: Gauss-Newton near the solution, gradient-like far
//! from it; the floor is small so the last iterations to the convergence tolerance stay
//! Gauss-Newton). A joint at a limit the step would push past is held there and the step
//! solved again without it; a step that would leave a joint's range is clamped to it
//! (whole-circle ranges wrap); a step that does not lower `E` is retried with ten times the
//! damping. A start is
//! given up when no step lowers `E` or `E` has not halved in 5 iterations (a local minimum or
//! a limit), for the next start.
//!
//! Collisions ([`Avoid`]): an answer on its target that collides is pushed apart from there.
//! Each contact closer than the margin and 2 mm more (two spheres of a checked pair, or a
//! sphere and an obstacle) adds a row to `J`: the derivative of its gap, its error how far the
//! gap is short, in metres like the position's rows; the redundant joints move the links apart
//! while the tips' rows hold the pose. Only answers found colliding pay for it.

use nalgebra::{DMatrix, DVector, Isometry3, Point3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rayon::prelude::*;

use crate::ik::solve::damped_least_squares::{keep_in, wraps};
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
    /// An answer is exact within these (IKFlow's: 1 mm and 0.01 rad = 0.572 degrees): the
    /// success threshold.
    pub tolerance_m: f64,
    pub tolerance_rad: f64,
    /// A start iterates until every tip is within these (the convergence tolerance, far
    /// tighter than the success threshold: the precision the peers reach), or it stalls.
    /// Models saved before it existed load with the default.
    #[serde(default = "default_convergence_m")]
    pub convergence_m: f64,
    #[serde(default = "default_convergence_rad")]
    pub convergence_rad: f64,
    /// Iterations from one start.
    pub max_iterations: usize,
    /// Random starts tried after the given ones stall (per target).
    pub random_starts: usize,
    pub seed: u64,
}

/// The default convergence tolerance: 1e-4 mm.
pub const CONVERGENCE_M: f64 = 1e-7;
/// The default convergence tolerance: 1e-4 degrees.
pub const CONVERGENCE_DEG: f64 = 1e-4;

fn default_convergence_m() -> f64 {
    CONVERGENCE_M
}

fn default_convergence_rad() -> f64 {
    CONVERGENCE_DEG.to_radians()
}

impl LmConfig {
    /// Exact within 1 mm and 0.01 rad, converged to 1e-4 mm and 1e-4 degrees, 30 iterations
    /// a start, up to 100 random starts (a start that stalls is given up within a few
    /// iterations, so many are cheap; 20 left 0.5% of the Panda's targets unsolved from a
    /// quick model's samples, 100 left 0.02%).
    pub fn standard() -> Self {
        LmConfig {
            tolerance_m: 1e-3,
            tolerance_rad: 0.01,
            convergence_m: default_convergence_m(),
            convergence_rad: default_convergence_rad(),
            max_iterations: 30,
            random_starts: 100,
            seed: 0,
        }
    }

    /// The same settings converging to `mm` millimetres and `deg` degrees: refused unless
    /// both are finite, positive and no looser than the success threshold (1 mm and 0.572
    /// degrees by default), nor tighter than float64 can resolve (1e-9 mm, 1e-9 degrees).
    pub fn converging_to(mut self, mm: f64, deg: f64) -> Result<Self, String> {
        let (max_mm, max_deg) = (1e3 * self.tolerance_m, self.tolerance_rad.to_degrees());
        let check = |v: f64, unit: &str, max: f64| {
            if v.is_finite() && (1e-9..=max * (1.0 + 1e-12)).contains(&v) {
                Ok(())
            } else {
                Err(format!(
                    "a tolerance of {} {unit} is not between 1e-9 and {max:.4} {unit} (the success threshold)",
                    crate::core::error::short_number(v)
                ))
            }
        };
        check(mm, "mm", max_mm)?;
        check(deg, "degrees", max_deg)?;
        self.convergence_m = mm * 1e-3;
        self.convergence_rad = deg.to_radians();
        Ok(self)
    }

    /// [`Self::converging_to`] from `MM,DEG` as the command line writes it (`0.0001,0.0001`).
    pub fn converging_to_text(self, text: &str) -> Result<Self, String> {
        let parts: Vec<&str> = text.split(',').map(str::trim).collect();
        let number = |t: &str| t.parse::<f64>().ok();
        match parts.as_slice() {
            [mm, deg] => match (number(mm), number(deg)) {
                (Some(mm), Some(deg)) => self.converging_to(mm, deg),
                _ => Err(format!(
                    "the tolerance \"{text}\" is not two numbers MM,DEG (e.g. 0.0001,0.0001)"
                )),
            },
            _ => Err(format!(
                "the tolerance \"{text}\" is not MM,DEG: millimetres and degrees, comma-separated (e.g. 0.0001,0.0001)"
            )),
        }
    }

    /// Converged: every tip within the convergence tolerance.
    fn converged(&self, position_m: f64, rotation_rad: f64) -> bool {
        position_m <= self.convergence_m && rotation_rad <= self.convergence_rad
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
    /// Whether the answer was checked and found in collision ([`solve`]); never for
    /// an answer nobody checked.
    pub collides: bool,
}

impl PoseSolution {
    /// Within both tolerances, and not in collision.
    pub fn exact(&self, cfg: &LmConfig) -> bool {
        !self.collides
            && self.position_error_m <= cfg.tolerance_m
            && self.rotation_error_rad <= cfg.tolerance_rad
    }
}

/// What an answer must avoid (collisions): [`solve`] returns a converged answer only
/// where `valid` accepts it, and a converged answer it refuses is pushed away by the
/// contacts' rows ([`solve_from`] with `avoid`) before the next start is tried.
pub trait Avoid: Sync {
    /// Whether `q` is acceptable.
    fn valid(&self, q: &[f64]) -> bool;
    /// Adds the Gauss-Newton terms of the contacts at `q` (each a row `dgap/dq` and the
    /// distance it is short of its aim, m) to `jtj` and `g`, and returns their energy
    /// (half the sum of squares, 0 where none is near) and what it would be at a trial step.
    fn push_apart(&self, q: &[f64], jtj: &mut DMatrix<f64>, g: &mut DVector<f64>) -> Pushed<'_>;
}

/// The contacts an iteration pushes apart: their energy, and their energy at a trial step
/// from there (the same contacts, each side's point carried along by its link: a step is
/// judged without a new search of the geometry, and a contact the step runs into is found
/// by the next iteration, before any answer is accepted by [`Avoid::valid`]).
pub struct Pushed<'a> {
    pub energy: f64,
    pub at: Box<dyn Fn(&[f64]) -> f64 + 'a>,
}

/// How a batch of targets is answered: the solver's settings, when to stop, what to avoid.
#[derive(Clone, Copy)]
pub struct Answering<'a> {
    pub lm: &'a LmConfig,
    /// Asked before each block of targets: `true` ends the batch.
    pub stop: &'a dyn Fn() -> bool,
    /// A collision check an answer must pass.
    pub avoid: Option<&'a dyn Avoid>,
}

impl<'a> Answering<'a> {
    /// `Ok` unless `stop` asks to end the batch, then [`crate::Error::Interrupted`] saying how
    /// far it came (`answered` of `total` targets).
    pub fn go_on(&self, answered: usize, total: usize) -> crate::Result<()> {
        if (self.stop)() {
            return Err(crate::Error::Interrupted(format!(
                "stopped after {answered} of {total} targets; nothing was written"
            )));
        }
        Ok(())
    }

    /// `lm`'s settings, stopped by Ctrl-C ([`crate::core::interrupt`]), nothing avoided.
    pub fn with(lm: &'a LmConfig) -> Self {
        Answering {
            lm,
            stop: &crate::core::interrupt::requested,
            avoid: None,
        }
    }
}

/// Iterations without the error halving after which a start is given up.
const STALL: usize = 5;

/// Iterations a start may take beyond `max_iterations` once inside the success threshold, to
/// converge.
const POLISH_ITERATIONS: usize = 5;

/// Levenberg-Marquardt from `start` (clamped into `ranges` first), on the paths to the
/// chain's tips ([`KinematicChain::tip_paths`]), `target` holding one pose per path: the
/// rows of every tip stacked, exact when every tip is within the tolerances. With `avoid`, the
/// contacts' rows join the tips' (each pushes its pair of spheres apart, metres weighing as
/// the position's) and a start converges only once `avoid` also accepts it.
pub fn solve_from(
    paths: &[TipPath],
    target: &[PoseTarget],
    start: &[f64],
    ranges: &[[f64; 2]],
    cfg: &LmConfig,
    avoid: Option<&dyn Avoid>,
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
    // The energy at a trial step: poses only, no Jacobian (the step loop's hot path), and
    // the contacts' by the iteration's contacts.
    let trial_energy = |q: &[f64], contacts: &Option<Pushed>| {
        let contacts = contacts.as_ref().map_or(0.0, |c| (c.at)(q));
        paths
            .iter()
            .zip(target)
            .map(|(p, t)| tip_energy(errors_at(&p.pose(q), t)))
            .sum::<f64>()
            + contacts
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
        // Inside the success threshold a start may take a few iterations more to converge
        // (quadratically there).
        let exact = p_worst <= cfg.tolerance_m && r_worst <= cfg.tolerance_rad;
        let limit = cfg.max_iterations + if exact { POLISH_ITERATIONS } else { 0 };
        let converged = cfg.converged(p_worst, r_worst) && avoid.is_none_or(|a| a.valid(&q));
        if converged || given_up || iterations >= limit {
            return PoseSolution {
                collides: false,
                joints: q,
                position_error_m: p_worst,
                rotation_error_rad: r_worst,
                iterations,
                starts: 1,
            };
        }
        fill_rows(&mut j, &mut e, &jacs, &err, full, w);
        let mut jtj = j.tr_mul(&j);
        let mut g = j.tr_mul(&e);
        let mut e_now = energy(&err);
        let contacts = avoid.map(|a| a.push_apart(&q, &mut jtj, &mut g));
        e_now += contacts.as_ref().map_or(0.0, |c| c.energy);
        // A start whose error has not halved in the last STALL iterations is in a local
        // minimum or against a limit: give it up for the next start.
        if history.len() >= STALL && e_now > 0.5 * history[history.len() - STALL] {
            given_up = true;
            continue;
        }
        history.push(e_now);
        iterations += 1;
        let mut lambda = e_now + 1e-12;
        let mut improved = false;
        for _ in 0..8 {
            let Some(dq) = limited_step(&jtj, &g, lambda, &q, ranges) else {
                lambda *= 10.0;
                continue;
            };
            for (t, ((&v, &d), &r)) in trial.iter_mut().zip(q.iter().zip(dq.iter()).zip(ranges)) {
                *t = keep_in(v + d, r);
            }
            if trial_energy(&trial, &contacts) < e_now {
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

/// The tips' rows of the Jacobian and error: position, then the rotation weighted by `w`
/// (left out for position-only targets).
fn fill_rows(
    j: &mut DMatrix<f64>,
    e: &mut DVector<f64>,
    jacs: &[nalgebra::Matrix6xX<f64>],
    err: &[(Vector3<f64>, Vector3<f64>)],
    full: bool,
    w: f64,
) {
    let per_tip = if full { 6 } else { 3 };
    for (t, (jac, (p_err, r_err))) in jacs.iter().zip(err).enumerate() {
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
}

/// The damped step `(A + lambda I) dq = g`, a joint at a limit that the step would push
/// past held there: the step is solved again without it (an active set), so the other joints
/// converge instead of a clamped step stalling against the limit. `None` where the system is
/// not positive definite.
fn limited_step(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    lambda: f64,
    q: &[f64],
    ranges: &[[f64; 2]],
) -> Option<DVector<f64>> {
    let n = q.len();
    let mut held = vec![false; n];
    // Each pass holds at least one more joint, so n + 1 passes suffice; two nearly always do.
    for _ in 0..=n {
        let mut m = a.clone();
        let mut rhs = g.clone();
        for d in 0..n {
            if held[d] {
                m.row_mut(d).fill(0.0);
                m.column_mut(d).fill(0.0);
                m[(d, d)] = 1.0;
                rhs[d] = 0.0;
            } else {
                m[(d, d)] += lambda;
            }
        }
        let dq = m.cholesky()?.solve(&rhs);
        let mut more = false;
        for d in 0..n {
            let [lo, hi] = ranges[d];
            let at_limit =
                !wraps(ranges[d]) && ((q[d] <= lo && dq[d] < 0.0) || (q[d] >= hi && dq[d] > 0.0));
            if at_limit && !held[d] {
                held[d] = true;
                more = true;
            }
        }
        if !more {
            return Some(dq);
        }
    }
    None
}

/// Solve `target` from each of `starts` in turn, then from random joint vectors in `ranges`
/// (seeded by `cfg.seed` and `salt`), until one converges; the best answer otherwise. A start
/// that stalls inside the success threshold without converging (a local minimum a fraction of
/// a millimetre from the target, or a singularity: the UR5's wrist at q5 = 0) is exact but
/// kept only if no later start converges.
///
/// With `avoid` (a collision check), an answer counts only if it accepts it: a converged
/// answer it refuses is pushed apart from where it is ([`solve_from`] with the contacts' rows,
/// the pose held by the tips' rows); if that fails, it is marked `collides` and the next start
/// is tried. The answer returned is the best accepted one, else the best refused one, marked.
// The target, its starts and ranges, the settings, the seed's salt and the check, each named
// at its callers.
#[allow(clippy::too_many_arguments)]
pub fn solve(
    paths: &[TipPath],
    target: &[PoseTarget],
    starts: &[Vec<f64>],
    ranges: &[[f64; 2]],
    cfg: &LmConfig,
    salt: u64,
    avoid: Option<&dyn Avoid>,
) -> PoseSolution {
    let mut rng = StdRng::seed_from_u64(cfg.seed ^ salt.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let w = cfg.tolerance_m / cfg.tolerance_rad;
    let cost = |s: &PoseSolution| s.position_error_m.powi(2) + (w * s.rotation_error_rad).powi(2);
    // Refused answers rank after every accepted one.
    let rank = |s: &PoseSolution| (s.collides, cost(s));
    // The best answer so far, and whether it has been checked.
    let mut best: Option<(PoseSolution, bool)> = None;
    let (mut iterations, mut tried) = (0, 0);
    let random =
        (0..cfg.random_starts).map(|_| crate::sim::trajectory::uniform_in(&mut rng, ranges));
    for start in starts.iter().cloned().chain(random) {
        // A start with a collision check can take tens of milliseconds on a humanoid: Ctrl-C
        // ends the search (the caller throws the answer away: `LearnedIk`'s `IkSolver::solve`),
        // after the first start, so that there is an answer to throw away.
        if avoid.is_some() && tried > 0 && crate::core::interrupt::requested() {
            break;
        }
        let mut s = solve_from(paths, target, &start, ranges, cfg, None);
        iterations += s.iterations;
        tried += 1;
        // Only answers that could count are checked here; the one returned is checked last.
        let checked = avoid.is_some()
            && (cfg.converged(s.position_error_m, s.rotation_error_rad) || s.exact(cfg));
        if let Some(valid) = avoid.filter(|_| checked) {
            s.collides = !valid.valid(&s.joints);
            // On the target but in collision: pushed apart from there, the pose held.
            if s.collides {
                let pushed = solve_from(paths, target, &s.joints, ranges, cfg, Some(valid));
                iterations += pushed.iterations;
                if pushed.exact(cfg) && valid.valid(&pushed.joints) {
                    s = pushed;
                }
            }
        }
        let done = cfg.converged(s.position_error_m, s.rotation_error_rad) && !s.collides;
        if best.as_ref().is_none_or(|(b, _)| rank(&s) < rank(b)) {
            best = Some((s, checked));
        }
        if done {
            break;
        }
    }
    let (mut best, checked) = best.expect("at least one start");
    if let Some(valid) = avoid.filter(|_| !checked) {
        best.collides = !valid.valid(&best.joints);
    }
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
            solve(&paths, t, s, ranges, cfg, i as u64, None)
        })
        .collect()
}
