//! The one way every inverse-kinematics solver answers: [`IkSolver`]. A target is one pose
//! per tip of the chain ([`PoseTarget`]); a solver gives `k` answers per target
//! ([`PoseSolution`]: joints, errors, whether a collision check refused it), as an
//! [`Answering`] says (the Levenberg-Marquardt settings every answer is refined or judged by,
//! when to stop, what to avoid). The solvers:
//! - [`LevenbergMarquardt`]: from random starts within the joint ranges, exact to the
//!   tolerances ([`crate::ik::solve::levenberg_marquardt`]);
//! - [`DampedLeastSquares`]: positions only, from the home pose and then random starts
//!   ([`crate::ik::solve::damped_least_squares`]);
//! - [`crate::ik::solve::learned::LearnedIk`]: a trained model's samples as the starts of
//!   Levenberg-Marquardt (its implementation sits with the model).
//!
//! # Examples
//!
//! The built-in UR5's tip sent to where its joints at 0.3 rad put it, answered exactly from
//! random starts:
//!
//! ```
//! use selfmodel::ik::solve::levenberg_marquardt::{Answering, LmConfig, PoseTarget};
//! use selfmodel::ik::solve::solver::{IkSolver, LevenbergMarquardt};
//! use selfmodel::{BuiltinRobot, RobotSpec};
//!
//! let robot = RobotSpec::Builtin(BuiltinRobot::Ur5).load_kinematics()?;
//! let target = PoseTarget::of(&robot.chain, &[0.3; 6]);
//! let solver = LevenbergMarquardt::within(robot.chain.joint_ranges());
//! let lm = LmConfig::standard();
//! let answers = solver.solve(&robot.chain, &[target], 2, &Answering::with(&lm))?;
//! assert_eq!(answers[0].len(), 2);
//! assert!(answers[0].iter().all(|a| a.exact(&lm)));
//! # Ok::<(), selfmodel::Error>(())
//! ```

use rayon::prelude::*;

use crate::core::error::{Error, Result};
use crate::ik::solve::damped_least_squares::{self, DlsConfig};
use crate::ik::solve::levenberg_marquardt::{self, Answering, PoseSolution, PoseTarget};
use crate::sim::kinematics::KinematicChain;

/// Inverse kinematics, however it is answered.
pub trait IkSolver {
    /// `k` answers (at least one) for each of `targets` (one pose per tip of `chain`), in
    /// target order, refined or judged by `how.lm`'s tolerances; where `how.avoid` is given,
    /// an answer it refuses is marked `collides`. `how.stop` is asked between blocks of
    /// targets: `true` ends the call with [`Error::Interrupted`].
    fn solve(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        k: usize,
        how: &Answering,
    ) -> Result<Vec<Vec<PoseSolution>>>;
}

/// Targets answered between two questions to `how.stop`.
const BLOCK: usize = 64;

/// Answer every target in blocks, in parallel within a block, asking `stop` before each.
fn by_blocks(
    targets: &[Vec<PoseTarget>],
    how: &Answering,
    answer: impl Fn(usize, &[PoseTarget]) -> Vec<PoseSolution> + Sync,
) -> Result<Vec<Vec<PoseSolution>>> {
    let mut out = Vec::with_capacity(targets.len());
    for (b, block) in targets.chunks(BLOCK).enumerate() {
        how.go_on(out.len(), targets.len())?;
        let first = b * BLOCK;
        out.par_extend(
            block
                .par_iter()
                .enumerate()
                .map(|(i, t)| answer(first + i, t)),
        );
    }
    Ok(out)
}

/// Levenberg-Marquardt from random starts within `ranges` (each answer its own seed).
#[derive(Clone, Debug)]
pub struct LevenbergMarquardt {
    pub ranges: Vec<[f64; 2]>,
}

impl LevenbergMarquardt {
    /// Solving within `ranges` (the chain's, [`KinematicChain::joint_ranges`], or narrower).
    pub fn within(ranges: Vec<[f64; 2]>) -> Self {
        LevenbergMarquardt { ranges }
    }
}

impl IkSolver for LevenbergMarquardt {
    fn solve(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        k: usize,
        how: &Answering,
    ) -> Result<Vec<Vec<PoseSolution>>> {
        let k = k.max(1);
        let paths = chain.tip_paths();
        let (lm, avoid) = (how.lm, how.avoid);
        by_blocks(targets, how, |i, target| {
            (0..k)
                .map(|j| {
                    let salt = (i * k + j) as u64;
                    levenberg_marquardt::solve(&paths, target, &[], &self.ranges, lm, salt, avoid)
                })
                .collect()
        })
    }
}

/// Damped least squares on the tips' positions: the first answer from the home pose (every
/// joint 0, kept in range), the others from random starts within `ranges` (seeded by
/// `how.lm.seed`). A target with an orientation is refused: it answers positions only.
#[derive(Clone, Debug)]
pub struct DampedLeastSquares {
    pub cfg: DlsConfig,
    pub ranges: Vec<[f64; 2]>,
}

impl IkSolver for DampedLeastSquares {
    fn solve(
        &self,
        chain: &KinematicChain,
        targets: &[Vec<PoseTarget>],
        k: usize,
        how: &Answering,
    ) -> Result<Vec<Vec<PoseSolution>>> {
        use rand::SeedableRng;
        if targets
            .iter()
            .any(|t| t.len() != 1 || t[0].orientation.is_some())
        {
            return Err(Error::Config(
                "damped least squares answers positions of one tip: give position-only targets of a chain with one tip (or use Levenberg-Marquardt)".into(),
            ));
        }
        let k = k.max(1);
        let home: Vec<f64> = self
            .ranges
            .iter()
            .map(|&r| damped_least_squares::keep_in(0.0, r))
            .collect();
        let (seed, avoid) = (how.lm.seed, how.avoid);
        by_blocks(targets, how, |i, target| {
            let mut rng = rand::rngs::StdRng::seed_from_u64(
                seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            (0..k)
                .map(|j| {
                    let start = match j {
                        0 => home.clone(),
                        _ => crate::sim::trajectory::uniform_in(&mut rng, &self.ranges),
                    };
                    let s = damped_least_squares::solve(
                        chain,
                        &target[0].position,
                        &start,
                        &self.ranges,
                        &self.cfg,
                    );
                    PoseSolution {
                        collides: avoid.is_some_and(|a| !a.valid(&s.joints)),
                        joints: s.joints,
                        position_error_m: s.error_m,
                        rotation_error_rad: 0.0,
                        iterations: s.iterations,
                        starts: 1,
                    }
                })
                .collect()
        })
    }
}
