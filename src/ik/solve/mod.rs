//! Inverse kinematics to use, every solver answering through
//! [`solver::IkSolver`]: Levenberg-Marquardt ([`levenberg_marquardt`]: full-pose targets,
//! exact within the joint limits), damped least squares ([`damped_least_squares`]: positions),
//! a learned model whose samples seed Levenberg-Marquardt ([`learned`]), the collision check
//! an answer must pass ([`collision`]) and random reachable targets ([`targets`]).

pub mod collision;
pub mod damped_least_squares;
pub mod learned;
pub mod levenberg_marquardt;
pub mod solver;
pub mod targets;
