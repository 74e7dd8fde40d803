//! Kinematic chains (trees) on nalgebra and their forward kinematics.
//!
//! Joint values are in SI units inside the library: radians for revolute and continuous
//! joints, metres for prismatic ones. Datasets and command lines use degrees for rotational
//! joints; [`KinematicChain::to_si`] and [`KinematicChain::from_si`] convert.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::core::error::{Error, Result};

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

/// A tree of links connected by joints, placed in the scene by `base`.
#[derive(Clone, Debug)]
pub struct KinematicChain {
    /// Link names; index 0 is the root.
    pub links: Vec<String>,
    /// Joints in an order where every parent link comes before its child.
    pub joints: Vec<Joint>,
    /// Pose of the root link in the world (the scene placement).
    pub base: Isometry3<f64>,
    /// The end effector: a point in the frame of a link.
    pub tip_link: usize,
    pub tip_offset: Point3<f64>,
    /// Indices into `joints` of the movable joints, in the order of the joint vector.
    dofs: Vec<usize>,
    /// For each joint, its index in the joint vector (`None` for fixed joints).
    value_index: Vec<Option<usize>>,
}

impl KinematicChain {
    /// Build a chain from links and joints given in any order. The root is the one link that
    /// is no joint's child; joints are sorted parent-first. `tip` defaults to the origin of
    /// the last link of the longest path from the root.
    pub fn new(
        links: Vec<String>,
        joints: Vec<Joint>,
        base: Isometry3<f64>,
        tip: Option<(usize, Point3<f64>)>,
    ) -> Result<Self> {
        let n = links.len();
        if n == 0 {
            return Err(Error::Config("a robot needs at least one link".into()));
        }
        let mut parent_joint = vec![None; n];
        for (j, joint) in joints.iter().enumerate() {
            if joint.parent >= n || joint.child >= n {
                return Err(Error::Config(format!(
                    "joint \"{}\": link index out of range",
                    joint.name
                )));
            }
            if parent_joint[joint.child].replace(j).is_some() {
                return Err(Error::Config(format!(
                    "link \"{}\" is the child of two joints",
                    links[joint.child]
                )));
            }
        }
        let roots: Vec<usize> = (0..n).filter(|&l| parent_joint[l].is_none()).collect();
        if roots.is_empty() {
            return Err(Error::Config(
                "the links must form one tree, but every link is some joint's child: the joints form a cycle".into(),
            ));
        }
        if roots.len() != 1 {
            return Err(Error::Config(format!(
                "the links must form one tree, found {} roots: {}",
                roots.len(),
                roots
                    .iter()
                    .map(|&r| links[r].as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        // Breadth-first from the root; reorder links so the root is 0.
        let root = roots[0];
        let mut order_links = vec![root];
        let mut order_joints = Vec::with_capacity(joints.len());
        let mut depth = vec![0usize; n];
        let mut i = 0;
        while i < order_links.len() {
            let l = order_links[i];
            for (j, joint) in joints.iter().enumerate() {
                if joint.parent == l {
                    depth[joint.child] = depth[l] + 1;
                    order_links.push(joint.child);
                    order_joints.push(j);
                }
            }
            i += 1;
        }
        if order_links.len() != n {
            return Err(Error::Config("the joints contain a cycle".into()));
        }
        let mut new_index = vec![0; n];
        for (new, &old) in order_links.iter().enumerate() {
            new_index[old] = new;
        }
        let deepest = (0..n).max_by_key(|&l| (depth[l], l)).unwrap_or(root);
        let joints: Vec<Joint> = order_joints
            .iter()
            .map(|&j| {
                let mut joint = joints[j].clone();
                joint.parent = new_index[joint.parent];
                joint.child = new_index[joint.child];
                joint
            })
            .collect();
        // The joint vector keeps the order the joints were given in (the URDF's order).
        let mut dofs: Vec<usize> = (0..joints.len())
            .filter(|&j| joints[j].kind.is_movable())
            .collect();
        dofs.sort_by_key(|&j| order_joints[j]);
        let mut value_index = vec![None; joints.len()];
        for (k, &j) in dofs.iter().enumerate() {
            value_index[j] = Some(k);
        }
        let (tip_link, tip_offset) = match tip {
            Some((l, p)) => (new_index[l], p),
            None => (new_index[deepest], Point3::origin()),
        };
        Ok(KinematicChain {
            links: order_links.iter().map(|&l| links[l].clone()).collect(),
            joints,
            base,
            tip_link,
            tip_offset,
            dofs,
            value_index,
        })
    }

    /// Number of joint values (movable joints).
    pub fn dof(&self) -> usize {
        self.dofs.len()
    }

    /// The index in the joint vector of joint `j` (of [`Self::joints`]); `None` when fixed.
    pub fn value_index(&self, j: usize) -> Option<usize> {
        self.value_index[j]
    }

    /// The movable joints, in joint-vector order.
    pub fn movable_joints(&self) -> impl Iterator<Item = &Joint> {
        self.dofs.iter().map(|&j| &self.joints[j])
    }

    /// Sampling range of each joint value (SI): the stated limits, else
    /// [`DEFAULT_ROTATIONAL_RANGE`] for continuous joints.
    pub fn joint_ranges(&self) -> Vec<[f64; 2]> {
        self.movable_joints()
            .map(|j| j.limits.unwrap_or(DEFAULT_ROTATIONAL_RANGE))
            .collect()
    }

    /// [`Self::joint_ranges`] in user units (degrees for rotational joints).
    pub fn joint_ranges_user(&self) -> Vec<[f64; 2]> {
        self.movable_joints()
            .zip(self.joint_ranges())
            .map(|(j, r)| {
                if j.kind.is_rotational() {
                    r.map(f64::to_degrees)
                } else {
                    r
                }
            })
            .collect()
    }

    /// Joint values from user units (degrees for rotational joints, metres otherwise) to SI.
    pub fn to_si(&self, q: &[f64]) -> Vec<f64> {
        self.movable_joints()
            .zip(q)
            .map(|(j, &v)| {
                if j.kind.is_rotational() {
                    v.to_radians()
                } else {
                    v
                }
            })
            .collect()
    }

    /// Joint values from SI to user units.
    pub fn from_si(&self, q: &[f64]) -> Vec<f64> {
        self.movable_joints()
            .zip(q)
            .map(|(j, &v)| {
                if j.kind.is_rotational() {
                    v.to_degrees()
                } else {
                    v
                }
            })
            .collect()
    }

    /// World pose of every link for joint values `q` (SI, length [`Self::dof`]).
    pub fn link_frames(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        assert_eq!(
            q.len(),
            self.dof(),
            "joint vector length must equal the robot's DOF"
        );
        let mut frames = vec![self.base; self.links.len()];
        for (joint, index) in self.joints.iter().zip(&self.value_index) {
            let value = index.map_or(0.0, |k| q[k]);
            frames[joint.child] = frames[joint.parent] * joint.origin * joint.motion(value);
        }
        frames
    }

    /// World pose of the frame of joint `j` (before its motion) and its axis in the world.
    pub fn joint_frames(&self, q: &[f64]) -> Vec<(Point3<f64>, Vector3<f64>)> {
        let frames = self.link_frames(q);
        self.joints
            .iter()
            .map(|j| {
                let f = frames[j.parent] * j.origin;
                (f * Point3::origin(), f * j.axis.into_inner())
            })
            .collect()
    }

    /// World position of the end effector.
    pub fn end_effector(&self, q: &[f64]) -> Point3<f64> {
        self.link_frames(q)[self.tip_link] * self.tip_offset
    }

    /// The end effector's position Jacobian `[3, dof]` (m per SI unit) at `q`, analytic:
    /// column k is `axis_k x (p_tip - o_k)` for a rotational joint and `axis_k` for a
    /// prismatic one, zero for a joint that does not move the tip.
    pub fn position_jacobian(&self, q: &[f64]) -> nalgebra::Matrix3xX<f64> {
        let frames = self.link_frames(q);
        let tip = frames[self.tip_link] * self.tip_offset;
        // Joints on the path from the root to the tip link.
        let mut moves_tip = vec![false; self.joints.len()];
        let mut link = self.tip_link;
        while let Some(j) = self.joints.iter().position(|j| j.child == link) {
            moves_tip[j] = true;
            link = self.joints[j].parent;
        }
        let mut jac = nalgebra::Matrix3xX::zeros(self.dof());
        for (j, joint) in self.joints.iter().enumerate() {
            let (Some(k), true) = (self.value_index[j], moves_tip[j]) else {
                continue;
            };
            let f = frames[joint.parent] * joint.origin;
            let axis = f * joint.axis.into_inner();
            let column = if joint.kind.is_rotational() {
                axis.cross(&(tip - f * Point3::origin()))
            } else {
                axis
            };
            jac.set_column(k, &column);
        }
        jac
    }

    /// Link frames for a batch of joint vectors (rows of `qs`, SI), in parallel.
    pub fn link_frames_batch(&self, qs: &[Vec<f64>]) -> Vec<Vec<Isometry3<f64>>> {
        qs.par_iter().map(|q| self.link_frames(q)).collect()
    }

    /// End-effector positions for a batch of joint vectors (SI), in parallel.
    pub fn end_effector_batch(&self, qs: &[Vec<f64>]) -> Vec<Point3<f64>> {
        qs.par_iter().map(|q| self.end_effector(q)).collect()
    }
}
