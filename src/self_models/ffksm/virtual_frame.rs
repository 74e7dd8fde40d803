//! FFKSM's virtual frame: the query point expressed in the frame of the first two joints, so
//! the network sees only the distal joints (self-modeling paper section IV-B).
//!
//! Three conventions, all with angles in radians:
//! - [`VirtualFrame::Reimplementation`]: `p' = Rz(a0)ᵀ Ry(a1)ᵀ p` (the reimplementation's code,
//!   z up, joint 0 about z, joint 1 about y, both through the origin);
//! - [`VirtualFrame::Original`]: `p' = Ry(a1) Rz(-a0) p` (the original authors' trained model);
//! - [`VirtualFrame::Joints`]: any robot's: `p' = F(a0, a1)⁻¹ p`, where `F` is the pose of the
//!   second joint's child link as the first two joints place it, with their real axes and
//!   pivots ([`JointsFrame::of_chain`]). A point fixed on that link, or beyond it with the
//!   distal joints still, keeps its virtual coordinates whatever the first two joints do. The
//!   paper's conventions turn about the origin only: on a robot whose shoulder sits above its
//!   base (the Panda's 0.333 m, the UR5's 0.089 m) the upper arm then moves in the virtual
//!   frame with joint 1, which the network does not see.
//!
//! [`to_virtual`] works on tensors `[n, 3]`; [`to_virtual_reference`] on one point with
//! nalgebra's rotations, as the slow reference the tests compare against.

use burn::tensor::{Tensor, TensorData};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::sim::kinematics::{JointKind, JointValue, KinematicChain};

/// Which rotation takes world points into the virtual frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VirtualFrame {
    /// `p' = Rz(a0)ᵀ Ry(a1)ᵀ p`.
    Reimplementation,
    /// `p' = Ry(a1) Rz(-a0) p`.
    Original,
    /// `p' = F(a0, a1)⁻¹ p` with the robot's own first two joints.
    Joints(JointsFrame),
}

/// A rigid placement: rotation (row-major) and translation.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Placement {
    pub rotation: [f64; 9],
    pub translation: [f64; 3],
}

impl Placement {
    fn of(iso: &Isometry3<f64>, per_metre: f64) -> Self {
        let r = iso.rotation.to_rotation_matrix();
        let m = r.matrix();
        Placement {
            rotation: std::array::from_fn(|i| m[(i / 3, i % 3)]),
            translation: (iso.translation.vector * per_metre).into(),
        }
    }

    fn isometry(&self) -> Isometry3<f64> {
        let m = Matrix3::from_row_slice(&self.rotation);
        Isometry3::from_parts(
            Translation3::from(Vector3::from(self.translation)),
            UnitQuaternion::from_matrix(&m),
        )
    }
}

/// The first two joints of a robot, in the field's units: `F(a0, a1) = C0 M0(a0) C1 M1(a1)`
/// with `C` the fixed placement before each joint (from the base, through any fixed or held
/// joints) and `M` its motion about (along) its axis.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JointsFrame {
    pub before: [Placement; 2],
    /// Each joint's axis in its own frame (unit).
    pub axes: [[f64; 3]; 2],
    /// Whether each joint slides (its value in metres) rather than turns.
    pub prismatic: [bool; 2],
    /// Field units per metre of a prismatic joint's value (1 / the scene's shrink).
    pub per_metre: f64,
}

impl JointsFrame {
    /// The frame of `chain`'s first two inputs, for a field that sees the scene shrunk by
    /// `scene_scale` about the world origin. `None` when the chain has no input, or when
    /// another input or a mimic joint lies on the path before its second input (then the frame
    /// would depend on more than two joints).
    pub fn of_chain(chain: &KinematicChain, scene_scale: f64) -> Option<Self> {
        let inputs = chain.dof().min(2);
        if inputs == 0 || !(scene_scale > 0.0) {
            return None;
        }
        // The joints from the root to the last of the (up to) two inputs' child link.
        let last = (0..chain.joints.len()).find(|&j| chain.value_index(j) == Some(inputs - 1))?;
        let mut path = vec![last];
        let mut link = chain.joints[last].parent;
        while let Some(j) = chain.joints.iter().position(|j| j.child == link) {
            path.push(j);
            link = chain.joints[j].parent;
        }
        path.reverse();
        let per_metre = 1.0 / scene_scale;
        let mut placed = chain.base;
        let mut found = Vec::new();
        for j in path {
            let joint = &chain.joints[j];
            placed *= joint.origin;
            match (chain.value_index(j), chain.joint_value(j)) {
                (Some(k), _) if k == found.len() => {
                    found.push((
                        Placement::of(&placed, per_metre),
                        joint.axis.into_inner().into(),
                        joint.kind == JointKind::Prismatic,
                    ));
                    placed = Isometry3::identity();
                }
                (None, JointValue::Fixed) => {}
                (None, JointValue::Held(v)) => placed *= joint.motion(v),
                _ => return None,
            }
        }
        if found.len() == 1 {
            // One joint: the second is a turn about z that never moves (its angle is 0).
            found.push((
                Placement::of(&Isometry3::identity(), 1.0),
                [0.0, 0.0, 1.0],
                false,
            ));
        }
        let [(c0, k0, p0), (c1, k1, p1)]: [_; 2] = found.try_into().ok()?;
        Some(JointsFrame {
            before: [c0, c1],
            axes: [k0, k1],
            prismatic: [p0, p1],
            per_metre,
        })
    }

    fn motion(&self, i: usize, a: f64) -> Isometry3<f64> {
        let axis = Unit::new_normalize(Vector3::from(self.axes[i]));
        if self.prismatic[i] {
            Isometry3::from_parts(
                Translation3::from(axis.into_inner() * a * self.per_metre),
                UnitQuaternion::identity(),
            )
        } else {
            Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&axis, a),
            )
        }
    }

    /// `F(a0, a1)`: the second joint's child link in the field's units.
    pub fn pose(&self, a0: f64, a1: f64) -> Isometry3<f64> {
        self.before[0].isometry()
            * self.motion(0, a0)
            * self.before[1].isometry()
            * self.motion(1, a1)
    }

    /// `F⁻¹ p` for points `[n, 3]` and angles `[n]`: each placement undone, then each motion
    /// (Rodrigues' formula for a turn by `-a`, or a slide by `-a`).
    fn to_virtual(&self, p: Tensor<2>, angles: [Tensor<1>; 2]) -> Tensor<2> {
        let device = p.device();
        let n = p.dims()[0];
        let matrix = |m: [f64; 9]| {
            Tensor::<2>::from_data(
                TensorData::new(m.map(|v| v as f32).to_vec(), [3, 3]),
                &device,
            )
        };
        let row = |v: [f64; 3]| {
            Tensor::<2>::from_data(
                TensorData::new(v.map(|v| v as f32).to_vec(), [1, 3]),
                &device,
            )
        };
        let mut v = p;
        for (i, a) in angles.into_iter().enumerate() {
            let c = &self.before[i];
            // Rᵀ (v - t), in rows: (v - t) R.
            v = (v - row(c.translation)).matmul(matrix(c.rotation));
            let k = Vector3::from(self.axes[i]).normalize();
            let a = a.reshape([n, 1]);
            if self.prismatic[i] {
                v = v - row(k.into()).mul(a.mul_scalar(self.per_metre));
            } else {
                // Rows of k x v are v Kᵀ; rows of k (k . v) are v k kᵀ.
                let cross = Matrix3::new(0.0, -k.z, k.y, k.z, 0.0, -k.x, -k.y, k.x, 0.0);
                let rows = |m: Matrix3<f64>| matrix(std::array::from_fn(|e| m[(e / 3, e % 3)]));
                let across = v.clone().matmul(rows(cross.transpose()));
                let along = v.clone().matmul(rows(k * k.transpose()));
                let (cos, sin) = (a.clone().cos(), a.sin());
                v = v.mul(cos.clone()) - across.mul(sin) + along.mul(cos.neg().add_scalar(1.0));
            }
        }
        v
    }
}

/// Points `[n, 3]` (metres) into the virtual frame of joint angles `a0`, `a1` `[n]`
/// (radians), one pair per point.
pub fn to_virtual(frame: &VirtualFrame, p: Tensor<2>, a0: Tensor<1>, a1: Tensor<1>) -> Tensor<2> {
    if let VirtualFrame::Joints(joints) = frame {
        return joints.to_virtual(p, [a0, a1]);
    }
    let n = p.dims()[0];
    let col = |i: usize| p.clone().slice([0..n, i..i + 1]).reshape([n]);
    let (x, y, z) = (col(0), col(1), col(2));
    let (c0, s0) = (a0.clone().cos(), a0.sin());
    let (c1, s1) = (a1.clone().cos(), a1.sin());
    let (px, py, pz) = match frame {
        VirtualFrame::Reimplementation => {
            // q = Ry(a1)ᵀ p, then p' = Rz(a0)ᵀ q.
            let qx = c1.clone() * x.clone() - s1.clone() * z.clone();
            let qz = s1 * x + c1 * z;
            let px = c0.clone() * qx.clone() + s0.clone() * y.clone();
            let py = c0 * y - s0 * qx;
            (px, py, qz)
        }
        VirtualFrame::Original => {
            // r = Rz(-a0) p = Rz(a0)ᵀ p, then p' = Ry(a1) r.
            let rx = c0.clone() * x.clone() + s0.clone() * y.clone();
            let ry = c0 * y - s0 * x;
            let px = c1.clone() * rx.clone() + s1.clone() * z.clone();
            let pz = c1 * z - s1 * rx;
            (px, ry, pz)
        }
        VirtualFrame::Joints(_) => unreachable!("handled above"),
    };
    Tensor::stack(vec![px, py, pz], 1)
}

/// The slow reference of [`to_virtual`] for one point, with nalgebra's rotations.
pub fn to_virtual_reference(frame: &VirtualFrame, p: [f64; 3], a0: f64, a1: f64) -> [f64; 3] {
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), a0);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), a1);
    let p = Vector3::from(p);
    let v = match frame {
        VirtualFrame::Reimplementation => rz.inverse() * (ry.inverse() * p),
        VirtualFrame::Original => ry * (rz.inverse() * p),
        VirtualFrame::Joints(joints) => {
            joints
                .pose(a0, a1)
                .inverse_transform_point(&p.into())
                .coords
        }
    };
    [v.x, v.y, v.z]
}
