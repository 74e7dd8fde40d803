//! Robots from Denavit-Hartenberg parameters, and the built-in UR5 (the EMSSL paper does not
//! name its 6-DOF arm; we use the UR5 with its standard DH parameters, position only, so it
//! has three redundant degrees of freedom).
//!
//! Standard DH: link `i`'s frame is its parent's times `Rz(q_i) Tz(d_i) Tx(a_i) Rx(α_i)`. In
//! the foundation's chains a child frame is `parent · origin · motion(q)`, so joint `i` (a
//! rotation about z) has as its origin the previous joint's fixed part
//! `Tz(d_{i−1}) Tx(a_{i−1}) Rx(α_{i−1})` (identity for the first), and the end effector is the
//! last fixed part's origin, `(a_n, 0, d_n)` in the last link's frame.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::sim::bvh::Bvh;
use crate::sim::kinematics::{Joint, JointKind, KinematicChain};
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;
use std::f64::consts::PI;

/// One joint's standard DH parameters (metres, radians).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DhJoint {
    pub d: f64,
    pub a: f64,
    pub alpha: f64,
}

/// The UR5's standard DH parameters.
pub fn ur5_parameters() -> [DhJoint; 6] {
    use std::f64::consts::FRAC_PI_2;
    [
        DhJoint {
            d: 0.089159,
            a: 0.0,
            alpha: FRAC_PI_2,
        },
        DhJoint {
            d: 0.0,
            a: -0.425,
            alpha: 0.0,
        },
        DhJoint {
            d: 0.0,
            a: -0.39225,
            alpha: 0.0,
        },
        DhJoint {
            d: 0.10915,
            a: 0.0,
            alpha: FRAC_PI_2,
        },
        DhJoint {
            d: 0.09465,
            a: 0.0,
            alpha: -FRAC_PI_2,
        },
        DhJoint {
            d: 0.0823,
            a: 0.0,
            alpha: 0.0,
        },
    ]
}

/// `Tz(d) Tx(a) Rx(α)`.
fn fixed_part(j: &DhJoint) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(0.0, 0.0, j.d), UnitQuaternion::identity())
        * Isometry3::from_parts(
            Translation3::new(j.a, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), j.alpha),
        )
}

/// A chain of revolute joints from standard DH parameters, every joint limited to `range`
/// (radians), placed at the world origin.
pub fn chain_from_dh(params: &[DhJoint], range: [f64; 2]) -> KinematicChain {
    let n = params.len();
    let links: Vec<String> = std::iter::once("base".to_string())
        .chain((1..=n).map(|i| format!("link{i}")))
        .collect();
    let joints: Vec<Joint> = (0..n)
        .map(|i| Joint {
            name: format!("joint{}", i + 1),
            kind: JointKind::Revolute,
            parent: i,
            child: i + 1,
            origin: if i == 0 {
                Isometry3::identity()
            } else {
                fixed_part(&params[i - 1])
            },
            axis: Unit::new_normalize(Vector3::z()),
            limits: Some(range),
            mimic: None,
        })
        .collect();
    let last = &params[n - 1];
    KinematicChain::new(
        links,
        joints,
        Isometry3::identity(),
        Some((n, Point3::new(last.a, 0.0, last.d))),
    )
    .expect("a DH chain is a valid chain")
}

/// A cylinder of `radius` from `a` to `b` (in a link's frame); `None` when they coincide.
fn segment(a: Vector3<f64>, b: Vector3<f64>, radius: f64) -> Option<Shape> {
    let along = b - a;
    let length = along.norm();
    (length > 1e-9).then(|| Shape::Cylinder {
        pose: Isometry3::from_parts(
            Translation3::from((a + b) / 2.0),
            UnitQuaternion::rotation_between(&Vector3::z(), &along)
                .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI)),
        ),
        radius,
        half_length: length / 2.0,
    })
}

/// Geometry for a DH chain: on every link a joint housing (a cylinder along its joint's
/// axis) and the link itself, cylinders along `d` then `a` to the next joint (to the end
/// effector on the last link), with the base a wider cylinder. The UR5's proportions: housing
/// radius 0.05 m and length 0.12 m, links of radius 0.04 m.
pub fn dh_geometry(params: &[DhJoint]) -> Vec<Bvh> {
    let (housing_r, housing_l, link_r) = (0.05, 0.12, 0.04);
    let mut links = vec![Bvh::new(vec![Shape::Cylinder {
        pose: Isometry3::translation(0.0, 0.0, -0.02),
        radius: 0.075,
        half_length: 0.04,
    }])];
    for p in params {
        let mut shapes = vec![Shape::Cylinder {
            pose: Isometry3::identity(),
            radius: housing_r,
            half_length: housing_l / 2.0,
        }];
        let (o, up, end) = (
            Vector3::zeros(),
            Vector3::new(0.0, 0.0, p.d),
            Vector3::new(p.a, 0.0, p.d),
        );
        shapes.extend(segment(o, up, link_r));
        shapes.extend(segment(up, end, link_r));
        links.push(Bvh::new(shapes));
    }
    links
}

/// The UR5 with every joint in `range` (radians), drawn by [`dh_geometry`] (cylinders of the
/// UR5's proportions along its DH links: for self-models of the built-in UR5; the ROS UR5's
/// meshes load with `urdf`).
pub fn ur5(range: [f64; 2]) -> Robot {
    let chain = chain_from_dh(&ur5_parameters(), range);
    let geometry = dh_geometry(&ur5_parameters());
    Robot {
        name: "ur5".into(),
        label: "ur5".into(),
        chain,
        geometry,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The usual DH forward kinematics, matrix by matrix, as the reference.
    fn reference(q: &[f64]) -> Vector3<f64> {
        let mut t = Isometry3::identity();
        for (j, &qi) in ur5_parameters().iter().zip(q) {
            t =
                t * Isometry3::from_parts(
                    Translation3::identity(),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), qi),
                ) * fixed_part(j);
        }
        t.translation.vector
    }

    #[test]
    fn the_ur5_chain_is_the_dh_product_and_its_home_position_is_known() {
        let chain = chain_from_dh(&ur5_parameters(), [-3.2, 3.2]);
        // All joints at zero: x = a2 + a3, y = -(d4 + d6), z = d1 - d5.
        let home = chain.end_effector(&[0.0; 6]);
        let expected = [-0.81725, -0.19145, 0.089159 - 0.09465];
        for k in 0..3 {
            assert!((home[k] - expected[k]).abs() < 1e-9, "{home:?}");
        }
        for i in 0..20 {
            let q: Vec<f64> = (0..6)
                .map(|k| ((i * 5 + k * 3) % 13) as f64 * 0.45 - 2.7)
                .collect();
            let ours = chain.end_effector(&q);
            let r = reference(&q);
            assert!((ours.coords - r).norm() < 1e-12, "pose {i}");
        }
    }
}
