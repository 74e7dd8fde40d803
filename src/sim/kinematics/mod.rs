//! Kinematic chains (trees) on nalgebra and their forward kinematics.
//!
//! Joint values are in SI units inside the library: radians for revolute and continuous
//! joints, metres for prismatic ones. Datasets and command lines use degrees for rotational
//! joints; [`KinematicChain::to_si`] and [`KinematicChain::from_si`] convert.
//!
//! `joint.rs` (joints, limits, where a joint's value comes from), `group.rs` (which joints
//! make the joint vector), `chain.rs` (the tree and its joint vector), `forward.rs` (poses and
//! Jacobians), `tip_path.rs` (the fast path to a tip), `fingerprint.rs` (a stable hash of the
//! chain).

mod chain;
mod fingerprint;
mod forward;
mod group;
mod joint;
mod tip_path;

pub use chain::KinematicChain;
pub use group::JointGroup;
pub use joint::{
    DEFAULT_ROTATIONAL_RANGE, Joint, JointKind, JointValue, Mimic, narrow, one_turn, within,
};
pub use tip_path::TipPath;
