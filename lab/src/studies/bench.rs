//! The benchmarks, each a binary of the same name in `experiments/`: the decoders and
//! FFKSM's training step against PyTorch, IK against the references, a collision check, collision-free IK beside cuRobo's published
//! figures, the
//! GPU check, and CPU against GPU on the same model. Each warms up, takes the median of repeats and reports a
//! ratio against a reference measured in the same sitting.

pub mod collision;
pub mod collision_agreement;
pub mod collision_ik;
pub mod decoders;
pub mod ffksm_step;
pub mod gpu_check;
pub mod gpu_summary;
pub mod ik;
pub mod pinocchio;
