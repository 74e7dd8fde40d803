//! Inverse kinematics. `solve` is the front door: every solver behind one trait
//! (`solve::solver::IkSolver`): Levenberg-Marquardt on full-pose targets within the joint
//! limits (`solve::levenberg_marquardt`), damped least squares on positions
//! (`solve::damped_least_squares`), a learned model whose samples seed them
//! (`solve::learned::LearnedIk`, what `ik train` saves), the collision check an answer must
//! pass (`solve::collision`) and random reachable targets (`solve::targets`). `paper` holds the
//! EMSSL paper's methods and what its tables run (Table II's `IkMethod`, direct regression,
//! distal learning, the conditional GAN, EMSSL, the sampling pass, link calibration). Beneath
//! both: the joint samples (`data`), the inverse MLP (`mlp`), the fitting they share
//! (`learning`) and the normalizing flow (`flow`).

pub mod data;
pub mod flow;
pub mod learning;
pub mod mlp;
pub mod paper;
pub mod solve;
