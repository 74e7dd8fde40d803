//! Joints: their kinds, limits and motion, mimic joints, and where each joint's value comes
//! from (an input of the joint vector, held, or fixed).

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

/// The URDF joint types the simulator supports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JointKind {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
}

impl JointKind {
    /// Whether the joint has a joint value (everything but `Fixed`).
    pub fn is_movable(self) -> bool {
        self != JointKind::Fixed
    }
    /// Whether the joint value is an angle.
    pub fn is_rotational(self) -> bool {
        matches!(self, JointKind::Revolute | JointKind::Continuous)
    }
}

/// One joint: the child link's frame is `parent * origin * motion(q)`.
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    /// Index of the parent link.
    pub parent: usize,
    /// Index of the child link.
    pub child: usize,
    /// Pose of the joint frame in the parent link's frame.
    pub origin: Isometry3<f64>,
    /// Rotation or translation axis in the joint frame.
    pub axis: Unit<Vector3<f64>>,
    /// Position limits in SI units, where the robot states them.
    pub limits: Option<[f64; 2]>,
    /// A URDF `<mimic>`: this joint's value is `multiplier * leader + offset`, not an input.
    pub mimic: Option<Mimic>,
}

/// A joint that follows another (URDF `<mimic joint multiplier offset>`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mimic {
    /// Index of the leader joint, in the list given to [`KinematicChain::new`] (afterwards in
    /// [`KinematicChain::joints`]).
    pub leader: usize,
    pub multiplier: f64,
    pub offset: f64,
}

/// Where a joint's value comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointValue {
    /// A fixed joint: no value.
    Fixed,
    /// `scale * q[index] + offset` of the joint vector `q` (an input: scale 1, offset 0; a
    /// mimic joint of an input: its multiplier and offset).
    Input {
        index: usize,
        scale: f64,
        offset: f64,
    },
    /// A movable joint held still: off the chain from the root to the tip (a Panda's fingers
    /// when the tip is its hand), or a mimic of one.
    Held(f64),
}

impl JointValue {
    /// The value for the joint vector `q` (SI); 0 for a fixed joint.
    pub fn of(self, q: &[f64]) -> f64 {
        match self {
            JointValue::Fixed => 0.0,
            JointValue::Input {
                index,
                scale,
                offset,
            } => scale * q[index] + offset,
            JointValue::Held(v) => v,
        }
    }
}

impl Joint {
    /// The joint's motion for value `q` (SI).
    pub fn motion(&self, q: f64) -> Isometry3<f64> {
        match self.kind {
            JointKind::Revolute | JointKind::Continuous => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&self.axis, q),
            ),
            JointKind::Prismatic => Isometry3::from_parts(
                Translation3::from(self.axis.into_inner() * q),
                UnitQuaternion::identity(),
            ),
            JointKind::Fixed => Isometry3::identity(),
        }
    }
}

/// Sampling range of rotational joints the robot gives no limits for (continuous joints):
/// +-90 degrees, the workspace of both self-modeling papers.
pub const DEFAULT_ROTATIONAL_RANGE: [f64; 2] =
    [-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2];

/// `limits` narrowed to `[-half, half]` where that is tighter. An end the limits leave wider
/// (within 1e-9) is exactly `-half` or `half`, so a robot without tighter limits samples the
/// very numbers it sampled before limits were read.
pub fn narrow(limits: [f64; 2], half: f64) -> [f64; 2] {
    let lo = if limits[0] > -half + 1e-9 {
        limits[0]
    } else {
        -half
    };
    let hi = if limits[1] < half - 1e-9 {
        limits[1]
    } else {
        half
    };
    [lo, hi]
}

/// A rotational joint's limits as one turn of values: as stated when they span a turn or
/// less; wider, `[-pi, pi]` where they hold it (a wider range repeats poses), else the turn
/// from the lower limit.
pub fn one_turn(limits: [f64; 2]) -> [f64; 2] {
    use std::f64::consts::PI;
    if limits[1] - limits[0] <= 2.0 * PI + 1e-9 {
        limits
    } else if limits[0] <= -PI + 1e-9 && limits[1] >= PI - 1e-9 {
        [-PI, PI]
    } else {
        [limits[0], limits[0] + 2.0 * PI]
    }
}

/// Whether `q` lies within `ranges` (with `tol` of slack, SI units).
pub fn within(q: &[f64], ranges: &[[f64; 2]], tol: f64) -> bool {
    q.iter()
        .zip(ranges)
        .all(|(&v, r)| v >= r[0] - tol && v <= r[1] + tol)
}
