//! Changes to an arm's geometry that a learned inverse model must adapt to (EMSSL paper section
//! IV-C): every link lengthened by the same amount (the paper's Table IV), and, beyond the
//! paper, one link bent at its base (a changed joint offset).
//!
//! "A link" of a general kinematic chain is a joint origin's translation (the vector from one
//! joint to the next, in the parent link's frame) and the end-effector offset (the last link).
//! For the UR5 from DH parameters these are d1, a2, a3, d4, d5 and d6: six lengths.

use nalgebra::{Isometry3, Unit, UnitQuaternion, Vector3};

use crate::core::error::{Error, Result};
use crate::sim::kinematics::KinematicChain;

/// Links shorter than this (metres) are joints that share a place; they are not lengthened.
const MIN_LINK_M: f64 = 1e-3;

/// One change of the arm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ArmChange {
    /// Every link (every joint origin's translation and the end-effector offset longer than
    /// 1 mm) lengthened by `cm` along itself.
    Lengthen { cm: f64 },
    /// The link that carries movable joint `joint` (0-based, joint-vector order) to its place
    /// rotated by `deg` at its base: the joint's origin turned about the axis perpendicular to
    /// the link and to the previous joint's axis, so the link leaves the plane that joint
    /// moves it in.
    Bend { joint: usize, deg: f64 },
}

impl ArmChange {
    /// A short label for tables: `links +3 cm`, `link to joint 3 bent 3 deg`.
    pub fn label(&self) -> String {
        match self {
            ArmChange::Lengthen { cm } => format!("links +{cm} cm"),
            ArmChange::Bend { joint, deg } => format!("link to joint {} bent {deg} deg", joint + 1),
        }
    }

    /// The changed arm.
    pub fn apply(&self, chain: &KinematicChain) -> Result<KinematicChain> {
        let mut changed = chain.clone();
        match *self {
            ArmChange::Lengthen { cm } => {
                let grow = |v: Vector3<f64>| {
                    let n = v.norm();
                    if n > MIN_LINK_M {
                        v * ((n + cm / 100.0) / n)
                    } else {
                        v
                    }
                };
                for joint in &mut changed.joints {
                    joint.origin.translation.vector = grow(joint.origin.translation.vector);
                }
                changed.tip_offset = grow(changed.tip_offset.coords).into();
            }
            ArmChange::Bend { joint, deg } => {
                let j = chain
                    .joints
                    .iter()
                    .enumerate()
                    .filter(|(_, jt)| jt.kind.is_movable())
                    .map(|(j, _)| j)
                    .find(|&j| chain.value_index(j) == Some(joint))
                    .ok_or_else(|| {
                        Error::Config(format!(
                            "bend: the arm has {} movable joints, not {}",
                            chain.dof(),
                            joint + 1
                        ))
                    })?;
                let link = chain.joints[j].origin.translation.vector;
                if link.norm() <= MIN_LINK_M {
                    return Err(Error::Config(format!(
                        "bend: the link to joint {} has no length to bend",
                        joint + 1
                    )));
                }
                // The previous joint's axis, in the frame the link is expressed in.
                let parent = chain.joints[j].parent;
                let previous_axis = chain
                    .joints
                    .iter()
                    .find(|jt| jt.child == parent)
                    .map_or(Vector3::z(), |jt| jt.axis.into_inner());
                let axis = perpendicular(&link, &previous_axis);
                let bend = Isometry3::from_parts(
                    nalgebra::Translation3::identity(),
                    UnitQuaternion::from_axis_angle(&axis, deg.to_radians()),
                );
                changed.joints[j].origin = bend * chain.joints[j].origin;
            }
        }
        Ok(changed)
    }
}

/// A unit vector perpendicular to `link` and, where they are not parallel, to `other`.
fn perpendicular(link: &Vector3<f64>, other: &Vector3<f64>) -> Unit<Vector3<f64>> {
    let c = link.cross(other);
    if c.norm() > 1e-9 * link.norm() {
        return Unit::new_normalize(c);
    }
    let any = if link.x.abs() < 0.9 * link.norm() {
        Vector3::x()
    } else {
        Vector3::y()
    };
    Unit::new_normalize(link.cross(&any))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::dh_robot::{chain_from_dh, ur5_parameters};

    #[test]
    fn lengthening_adds_to_every_ur5_length_and_bending_moves_the_tip_out_of_plane() {
        let chain = chain_from_dh(&ur5_parameters(), [-3.2, 3.2]);
        let longer = ArmChange::Lengthen { cm: 3.0 }.apply(&chain).unwrap();
        // All joints at zero: x = a2 + a3, y = -(d4 + d6), z = d1 - d5 (see dh_robot).
        let home = longer.end_effector(&[0.0; 6]);
        let expected = [
            -(0.425 + 0.03) - (0.39225 + 0.03),
            -(0.10915 + 0.03) - (0.0823 + 0.03),
            (0.089159 + 0.03) - (0.09465 + 0.03),
        ];
        for k in 0..3 {
            assert!((home[k] - expected[k]).abs() < 1e-9, "{home:?}");
        }
        // Bending the upper arm (the link to joint 3) by 3 degrees at the shoulder moves the
        // tip about 3 degrees of the arm's reach, and not in the shoulder's plane only.
        let bent = ArmChange::Bend { joint: 2, deg: 3.0 }
            .apply(&chain)
            .unwrap();
        let q = [0.3, -0.4, 0.5, 0.2, 0.1, 0.0];
        let moved = (bent.end_effector(&q) - chain.end_effector(&q)).norm();
        assert!(moved > 0.01 && moved < 0.06, "moved {moved} m");
        assert!(
            ArmChange::Bend { joint: 6, deg: 1.0 }
                .apply(&chain)
                .is_err()
        );
    }
}
