//! Forward kinematics of the built-in arm4 against the facts of the papers' URDF.

use nalgebra::{Point3, Vector3};
use selfmodel::sim::arm4::{arm4, chain};

fn close(a: Point3<f64>, b: [f64; 3], tol: f64) -> bool {
    (a - Point3::from(b)).norm() < tol
}

#[test]
fn arm4_joint_positions_and_axes_at_zero() {
    let c = chain();
    let joints = c.joint_frames(&[0.0; 4]);
    let expect = [
        ([0.0, 0.0, -0.040], Some([0.0, 0.0, 1.0])),
        ([0.0, 0.0, 0.000], Some([0.0, -1.0, 0.0])),
        ([0.029, 0.0, 0.135], None),
        ([0.174, 0.0, 0.142], None),
    ];
    for (i, ((p, axis), (want_p, want_axis))) in joints.iter().zip(expect).enumerate() {
        assert!(
            close(*p, want_p, 1.5e-3),
            "joint {i} at {p:?}, expected {want_p:?}"
        );
        if let Some(a) = want_axis {
            assert!(
                (axis - Vector3::from(a)).norm() < 1e-9,
                "joint {i} axis {axis:?}"
            );
        }
    }
    let tip = c.end_effector(&[0.0; 4]);
    assert!(close(tip, [0.240, 0.0, 0.146], 1.5e-3), "tip at {tip:?}");
}

#[test]
fn joints_move_the_tip_as_their_axes_say() {
    let c = chain();
    // Joint 0 is a rotation about +z: 90 degrees turns the tip from +x towards +y.
    let tip = c.end_effector(&[std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0]);
    assert!(close(tip, [0.0, 0.240, 0.146], 1.5e-3), "tip at {tip:?}");
    // Every joint changes the tip position (none is dead).
    let zero = c.end_effector(&[0.0; 4]);
    for j in 0..3 {
        let mut q = [0.0; 4];
        q[j] = 0.5;
        assert!(
            (c.end_effector(&q) - zero).norm() > 1e-3,
            "joint {j} does not move the tip"
        );
    }
}

#[test]
fn batch_equals_single_pose() {
    let c = chain();
    let qs: Vec<Vec<f64>> = (0..20)
        .map(|i| (0..4).map(|j| ((i * 7 + j * 3) as f64).sin()).collect())
        .collect();
    let batch = c.end_effector_batch(&qs);
    let frames = c.link_frames_batch(&qs);
    for (i, q) in qs.iter().enumerate() {
        assert_eq!(batch[i], c.end_effector(q));
        assert_eq!(frames[i], c.link_frames(q));
    }
}

#[test]
fn user_units_round_trip() {
    let c = chain();
    let deg = [10.0, -20.0, 30.0, 45.0];
    let si = c.to_si(&deg);
    assert!((si[3] - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    let back = c.from_si(&si);
    for (a, b) in back.iter().zip(deg) {
        assert!((a - b).abs() < 1e-12);
    }
    assert_eq!(c.joint_ranges_user(), vec![[-90.0, 90.0]; 4]);
}

#[test]
fn the_mesh_urdf_has_the_same_kinematics_as_arm4() {
    let path = selfmodel::sim::robots::shared_arm_urdf();
    if !path.exists() {
        eprintln!("skipped: {} not present", path.display());
        return;
    }
    let mesh =
        selfmodel::sim::urdf_loader::load_urdf(&path, selfmodel::sim::arm4::scene_base()).unwrap();
    let boxes = arm4();
    for q in [[0.0; 4], [0.3, -0.7, 1.1, 0.4]] {
        let a = mesh.link_frames(&q);
        let b = boxes.link_frames(&q);
        for (fa, fb) in a.iter().zip(&b) {
            assert!((fa.translation.vector - fb.translation.vector).norm() < 1e-12);
            assert!(fa.rotation.angle_to(&fb.rotation) < 1e-12);
        }
    }
}
