//! FFKSM's virtual frame: the query point expressed in the frame of the first two joints, so
//! the network sees only the two distal joints (self-modeling paper section IV-B).
//!
//! Two conventions, both with angles in radians (z up, joint 0 about z, joint 1 about y):
//! - [`VirtualFrame::Reimplementation`]: `p' = Rz(a0)ᵀ Ry(a1)ᵀ p` (the reimplementation's code);
//! - [`VirtualFrame::Original`]: `p' = Ry(a1) Rz(-a0) p` (the original authors' trained model).
//!
//! [`to_virtual`] works on tensors `[n, 3]`; [`to_virtual_reference`] on one point with
//! nalgebra's rotations, as the slow reference the tests compare against.

use burn::tensor::Tensor;
use nalgebra::{Rotation3, Vector3};

/// Which rotation takes world points into the virtual frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VirtualFrame {
    /// `p' = Rz(a0)ᵀ Ry(a1)ᵀ p`.
    Reimplementation,
    /// `p' = Ry(a1) Rz(-a0) p`.
    Original,
}

/// Points `[n, 3]` (metres) into the virtual frame of joint angles `a0`, `a1` `[n]`
/// (radians), one pair per point.
pub fn to_virtual(frame: VirtualFrame, p: Tensor<2>, a0: Tensor<1>, a1: Tensor<1>) -> Tensor<2> {
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
    };
    Tensor::stack(vec![px, py, pz], 1)
}

/// The slow reference of [`to_virtual`] for one point, with nalgebra's rotations.
pub fn to_virtual_reference(frame: VirtualFrame, p: [f64; 3], a0: f64, a1: f64) -> [f64; 3] {
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), a0);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), a1);
    let p = Vector3::from(p);
    let v = match frame {
        VirtualFrame::Reimplementation => rz.inverse() * (ry.inverse() * p),
        VirtualFrame::Original => ry * (rz.inverse() * p),
    };
    [v.x, v.y, v.z]
}
