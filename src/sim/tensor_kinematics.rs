//! Forward kinematics in burn tensors, differentiable and batched: the kinematic chain of any
//! robot the foundation loads (`arm4`, a URDF), for models that place geometry on the links
//! (K-3DGS, self-modeling paper section IV-C). The nalgebra forward kinematics of
//! [`crate::sim::kinematics`] is its reference (tested).
//!
//! For joint values `q` `[B, dof]` (SI: radians, metres) it returns every link's world pose as
//! rotations `[B, links, 3, 3]` and translations `[B, links, 3]`: the child link's frame is
//! `parent · origin · motion(q)`, with the motion of a rotational joint about its unit axis
//! `k` by Rodrigues' formula `I + sin q K + (1 − cos q) K²` (`K` the cross-product matrix of
//! `k`) and of a prismatic joint a translation `q k`.

use burn::tensor::{Tensor, TensorData};
use nalgebra::{Isometry3, Matrix3};

use crate::sim::kinematics::{JointKind, JointValue, KinematicChain};

/// A joint's constants as tensors-to-be.
#[derive(Clone, Debug)]
struct JointConstants {
    parent: usize,
    child: usize,
    /// Rotation `[3][3]` (row-major) and translation of the joint origin in the parent frame.
    origin_rotation: [f32; 9],
    origin_translation: [f32; 3],
    axis: [f32; 3],
    kind: JointKind,
    value: JointValue,
}

/// A kinematic chain ready for batched tensor forward kinematics.
#[derive(Clone, Debug)]
pub struct TensorChain {
    joints: Vec<JointConstants>,
    base: Isometry3<f64>,
    links: usize,
    dof: usize,
    tip_link: usize,
    tip_offset: [f32; 3],
    /// Per input: whether it is an angle (degrees in user units).
    rotational: Vec<bool>,
}

fn rotation_rows(m: &Matrix3<f64>) -> [f32; 9] {
    let mut out = [0f32; 9];
    for r in 0..3 {
        for c in 0..3 {
            out[3 * r + c] = m[(r, c)] as f32;
        }
    }
    out
}

impl TensorChain {
    pub fn new(chain: &KinematicChain) -> Self {
        let joints = chain
            .joints
            .iter()
            .enumerate()
            .map(|(j, joint)| JointConstants {
                parent: joint.parent,
                child: joint.child,
                origin_rotation: rotation_rows(joint.origin.rotation.to_rotation_matrix().matrix()),
                origin_translation: joint.origin.translation.vector.map(|v| v as f32).into(),
                axis: joint.axis.into_inner().map(|v| v as f32).into(),
                kind: joint.kind,
                value: chain.joint_value(j),
            })
            .collect();
        TensorChain {
            joints,
            base: chain.base,
            links: chain.links.len(),
            dof: chain.dof(),
            tip_link: chain.tip_link,
            tip_offset: chain.tip_offset.coords.map(|v| v as f32).into(),
            rotational: chain
                .movable_joints()
                .map(|j| j.kind.is_rotational())
                .collect(),
        }
    }

    /// Joint values `[B, dof]` from user units (degrees for rotational joints, metres for
    /// prismatic ones) to SI (radians, metres).
    pub fn from_user(&self, q: Tensor<2>) -> Tensor<2> {
        let degrees = std::f64::consts::PI / 180.0;
        if self.rotational.iter().all(|&r| r) {
            return q.mul_scalar(degrees);
        }
        let scale: Vec<f32> = self
            .rotational
            .iter()
            .map(|&r| if r { degrees as f32 } else { 1.0 })
            .collect();
        let n = scale.len();
        let device = q.device();
        q * Tensor::<2>::from_data(TensorData::new(scale, [1, n]), &device)
    }

    /// Every joint's origin as rows: rotations `[J * 9]` (row-major) and translations
    /// `[J * 3]` (metres), and the end-effector offset `[3]`: the constants
    /// [`TensorChain::end_effector_with`] takes as tensors.
    pub fn origin_rows(&self) -> (Vec<f32>, Vec<f32>, [f32; 3]) {
        (
            self.joints.iter().flat_map(|j| j.origin_rotation).collect(),
            self.joints
                .iter()
                .flat_map(|j| j.origin_translation)
                .collect(),
            self.tip_offset,
        )
    }

    pub fn joint_count(&self) -> usize {
        self.joints.len()
    }

    pub fn links(&self) -> usize {
        self.links
    }

    pub fn dof(&self) -> usize {
        self.dof
    }

    /// World poses of every link: rotations `[B, links, 3, 3]` and translations
    /// `[B, links, 3]` (metres) for joint values `q` `[B, dof]` (SI).
    pub fn link_frames(&self, q: Tensor<2>) -> (Tensor<4>, Tensor<3>) {
        let device = q.device();
        let (r, t, _) = self.origin_rows();
        let n = self.joints.len();
        let origin_r = Tensor::<3>::from_data(TensorData::new(r, [n, 3, 3]), &device);
        let origin_t = Tensor::<2>::from_data(TensorData::new(t, [n, 3]), &device);
        self.link_frames_with(q, origin_r, origin_t)
    }

    /// [`TensorChain::link_frames`] with the joint origins given as tensors (learnable link
    /// parameters, in the order of [`TensorChain::origin_rows`]): rotations `origin_r`
    /// `[J, 3, 3]`, translations `origin_t` `[J, 3]` (metres).
    pub fn link_frames_with(
        &self,
        q: Tensor<2>,
        origin_r: Tensor<3>,
        origin_t: Tensor<2>,
    ) -> (Tensor<4>, Tensor<3>) {
        let (r, t) = self.frames_with(q, origin_r, origin_t);
        (Tensor::stack(r, 1), Tensor::stack(t, 1))
    }

    /// End-effector positions `[B, 3]` (metres) for joint values `q` `[B, dof]` with the
    /// joint origins and the end-effector offset given as tensors (learnable link parameters):
    /// origin rotations `origin_r` `[J, 3, 3]`, translations `origin_t` `[J, 3]`, in the
    /// order of [`TensorChain::origin_rows`], and the offset `tip` `[1, 3]`.
    pub fn end_effector_with(
        &self,
        q: Tensor<2>,
        origin_r: Tensor<3>,
        origin_t: Tensor<2>,
        tip: Tensor<2>,
    ) -> Tensor<2> {
        let [b, _] = q.dims();
        let (mut r, mut t) = self.frames_with(q, origin_r, origin_t);
        let r = r.swap_remove(self.tip_link);
        let t = t.swap_remove(self.tip_link);
        t + apply(r, tip.repeat_dim(0, b))
    }

    /// Every link's world rotation `[B, 3, 3]` and translation `[B, 3]`, link by link.
    fn frames_with(
        &self,
        q: Tensor<2>,
        origin_r: Tensor<3>,
        origin_t: Tensor<2>,
    ) -> (Vec<Tensor<3>>, Vec<Tensor<2>>) {
        let [b, dof] = q.dims();
        assert_eq!(
            dof, self.dof,
            "joint vector length must equal the robot's DOF"
        );
        let device = q.device();
        let matrix = |m: [f32; 9]| -> Tensor<3> {
            Tensor::<3>::from_data(TensorData::new(m.to_vec(), [1, 3, 3]), &device).repeat_dim(0, b)
        };
        let vector = |v: [f32; 3]| -> Tensor<2> {
            Tensor::<2>::from_data(TensorData::new(v.to_vec(), [1, 3]), &device).repeat_dim(0, b)
        };
        let base_r = rotation_rows(self.base.rotation.to_rotation_matrix().matrix());
        let base_t: [f32; 3] = self.base.translation.vector.map(|v| v as f32).into();
        let mut rotations: Vec<Option<Tensor<3>>> = vec![None; self.links];
        let mut translations: Vec<Option<Tensor<2>>> = vec![None; self.links];
        // Links that no joint moves (the root) sit at the base.
        for l in 0..self.links {
            rotations[l] = Some(matrix(base_r));
            translations[l] = Some(vector(base_t));
        }
        for (i, joint) in self.joints.iter().enumerate() {
            let parent_r = rotations[joint.parent].clone().expect("parent first");
            let parent_t = translations[joint.parent].clone().expect("parent first");
            let own_r = origin_r
                .clone()
                .slice([i..i + 1, 0..3, 0..3])
                .repeat_dim(0, b);
            let own_t = origin_t.clone().slice([i..i + 1, 0..3]).repeat_dim(0, b);
            // Joint frame in the world: parent · origin.
            let frame_r = parent_r.clone().matmul(own_r);
            let frame_t = parent_t + apply(parent_r, own_t);
            let value = match joint.value {
                JointValue::Fixed => None,
                JointValue::Input {
                    index,
                    scale,
                    offset,
                } => {
                    let v = q.clone().slice([0..b, index..index + 1]).reshape([b, 1, 1]);
                    Some(if scale == 1.0 && offset == 0.0 {
                        v
                    } else {
                        v.mul_scalar(scale).add_scalar(offset)
                    })
                }
                JointValue::Held(v) => Some(
                    Tensor::<3>::from_data(TensorData::new(vec![v as f32], [1, 1, 1]), &device)
                        .repeat_dim(0, b),
                ),
            };
            let (child_r, child_t) = match (joint.kind, value) {
                (JointKind::Revolute | JointKind::Continuous, Some(v)) => {
                    let [x, y, z] = joint.axis;
                    let k = [0.0, -z, y, z, 0.0, -x, -y, x, 0.0];
                    let k2 = matmul3(k, k);
                    let eye = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
                    let motion = matrix(eye)
                        + matrix(k) * v.clone().sin()
                        + matrix(k2) * (v.cos().neg().add_scalar(1.0));
                    (frame_r.matmul(motion), frame_t)
                }
                (JointKind::Prismatic, Some(v)) => {
                    let shift = vector(joint.axis) * v.reshape([b, 1]);
                    (frame_r.clone(), frame_t + apply(frame_r, shift))
                }
                _ => (frame_r, frame_t),
            };
            rotations[joint.child] = Some(child_r);
            translations[joint.child] = Some(child_t);
        }
        (
            rotations.into_iter().map(|r| r.expect("set")).collect(),
            translations.into_iter().map(|t| t.expect("set")).collect(),
        )
    }
}

/// `R v` for rotations `[B, 3, 3]` and vectors `[B, 3]`.
fn apply(r: Tensor<3>, v: Tensor<2>) -> Tensor<2> {
    let [b, _] = v.dims();
    r.matmul(v.reshape([b, 3, 1])).reshape([b, 3])
}

/// The product of two row-major 3x3 matrices.
fn matmul3(a: [f32; 9], b: [f32; 9]) -> [f32; 9] {
    let mut out = [0f32; 9];
    for r in 0..3 {
        for c in 0..3 {
            out[3 * r + c] = (0..3).map(|k| a[3 * r + k] * b[3 * k + c]).sum();
        }
    }
    out
}
