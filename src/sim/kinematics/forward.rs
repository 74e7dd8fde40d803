//! Forward kinematics of a [`KinematicChain`]: every link's pose, the tip's position and pose,
//! their Jacobians, several tips, and batches in parallel.

use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use rayon::prelude::*;

use super::tip_path::PathStep;
use super::{JointKind, JointValue, KinematicChain, TipPath};

impl KinematicChain {
    /// World pose of every link for joint values `q` (SI, length [`Self::dof`]).
    pub fn link_frames(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        assert_eq!(
            q.len(),
            self.dof(),
            "joint vector length must equal the robot's DOF"
        );
        let mut frames = vec![self.base; self.links.len()];
        for (joint, value) in self.joints.iter().zip(&self.values) {
            frames[joint.child] = frames[joint.parent] * joint.origin * joint.motion(value.of(q));
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
    /// prismatic one, zero for a joint that does not move the tip; a mimic joint on the path
    /// adds its own column, times its multiplier, to its leader's. The first three rows of
    /// [`Self::pose_jacobian`].
    pub fn position_jacobian(&self, q: &[f64]) -> nalgebra::Matrix3xX<f64> {
        self.pose_jacobian(q).fixed_rows::<3>(0).into_owned()
    }

    /// World pose of the end effector: the tip link's orientation at the tip point.
    pub fn tip_pose(&self, q: &[f64]) -> Isometry3<f64> {
        let frame = self.link_frames(q)[self.tip_link];
        Isometry3::from_parts(
            Translation3::from((frame * self.tip_offset).coords),
            frame.rotation,
        )
    }

    /// The end effector's pose Jacobian `[6, dof]` at `q`, analytic: rows 0-2 the position
    /// Jacobian ([`Self::position_jacobian`]), rows 3-5 the angular velocity per unit joint
    /// speed (the world axis of a rotational joint, zero for a prismatic one), a mimic
    /// joint's part added to its leader's column times its multiplier.
    pub fn pose_jacobian(&self, q: &[f64]) -> nalgebra::Matrix6xX<f64> {
        let frames = self.link_frames(q);
        let tip = frames[self.tip_link] * self.tip_offset;
        let mut moves_tip = vec![false; self.joints.len()];
        let mut link = self.tip_link;
        while let Some(j) = self.joints.iter().position(|j| j.child == link) {
            moves_tip[j] = true;
            link = self.joints[j].parent;
        }
        let mut jac = nalgebra::Matrix6xX::zeros(self.dof());
        for (j, joint) in self.joints.iter().enumerate() {
            let (JointValue::Input { index, scale, .. }, true) = (self.values[j], moves_tip[j])
            else {
                continue;
            };
            let f = frames[joint.parent] * joint.origin;
            let axis = f * joint.axis.into_inner();
            let (linear, angular) = if joint.kind.is_rotational() {
                (axis.cross(&(tip - f * Point3::origin())), axis)
            } else {
                (axis, Vector3::zeros())
            };
            let mut column = jac.column(index).into_owned();
            column.fixed_rows_mut::<3>(0).axpy(scale, &linear, 1.0);
            column.fixed_rows_mut::<3>(3).axpy(scale, &angular, 1.0);
            jac.set_column(index, &column);
        }
        jac
    }

    /// The end effectors inverse kinematics drives, as (link, point in its frame): the links
    /// a [`JointGroup::Tips`] group names, at their origins (the tip's own point where one is
    /// the tip link), else the one tip.
    pub fn tips(&self) -> Vec<(usize, Point3<f64>)> {
        if self.group_tips.is_empty() {
            return vec![(self.tip_link, self.tip_offset)];
        }
        self.group_tips
            .iter()
            .map(|&l| {
                let at = if l == self.tip_link {
                    self.tip_offset
                } else {
                    Point3::origin()
                };
                (l, at)
            })
            .collect()
    }

    /// The names of the links of [`Self::tips`].
    pub fn tip_names(&self) -> Vec<String> {
        self.tips()
            .iter()
            .map(|&(l, _)| self.links[l].clone())
            .collect()
    }

    /// World pose of each tip ([`Self::tips`]): its link's orientation at its point.
    pub fn tip_poses(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        let frames = self.link_frames(q);
        self.tips()
            .iter()
            .map(|&(l, p)| {
                Isometry3::from_parts(
                    Translation3::from((frames[l] * p).coords),
                    frames[l].rotation,
                )
            })
            .collect()
    }

    /// The joints from the root to the tip, for the fast pose and Jacobian of
    /// [`TipPath`] (what an IK solver evaluates thousands of times a target).
    pub fn tip_path(&self) -> TipPath {
        self.path_to(self.tip_link, self.tip_offset)
    }

    /// A [`TipPath`] to each of [`Self::tips`].
    pub fn tip_paths(&self) -> Vec<TipPath> {
        self.tips()
            .into_iter()
            .map(|(l, p)| self.path_to(l, p))
            .collect()
    }

    /// The joints from the root to the point `at` of `link`, constant parts folded.
    pub fn path_to(&self, link: usize, at: Point3<f64>) -> TipPath {
        let mut on_path = Vec::new();
        let mut link = link;
        while let Some(j) = self.joints.iter().position(|j| j.child == link) {
            on_path.push(j);
            link = self.joints[j].parent;
        }
        on_path.reverse();
        // Constant transforms (fixed and held joints) fold into the next joint's origin.
        let mut pending = self.base;
        let mut steps = Vec::new();
        for j in on_path {
            let joint = &self.joints[j];
            match (self.values[j], joint.kind) {
                (
                    JointValue::Input {
                        index,
                        scale,
                        offset,
                    },
                    kind,
                ) if kind != JointKind::Fixed => {
                    steps.push(PathStep {
                        origin: pending * joint.origin,
                        axis: joint.axis.into_inner(),
                        rotational: kind.is_rotational(),
                        index,
                        scale,
                        offset,
                    });
                    pending = Isometry3::identity();
                }
                (value, _) => pending = pending * joint.origin * joint.motion(value.of(&[])),
            }
        }
        TipPath {
            steps,
            tip: pending * Translation3::from(at.coords),
            dof: self.dof(),
        }
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
