//! Full-pose inverse kinematics: the pose error, the pose Jacobian against finite differences,
//! Levenberg-Marquardt within asymmetric limits.

mod common;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use selfmodel::ik::pose::{LmConfig, PoseTarget, pose_error, solve_batch, solve_from};
use selfmodel::sim::kinematics::within;
use selfmodel::sim::urdf_loader::{GeometryKind, UrdfOptions, load_urdf_with};

fn arm(joints: usize) -> (common::TempDir, selfmodel::sim::robot::Robot) {
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", joints, true);
    let robot = load_urdf_with(
        &urdf,
        &UrdfOptions {
            tip: Some("hand".into()),
            geometry: GeometryKind::None,
            base: Isometry3::identity(),
        },
    )
    .unwrap();
    (dir, robot)
}

#[test]
fn the_pose_error_is_zero_at_the_truth_and_the_angle_of_a_known_rotation() {
    let (_dir, robot) = arm(7);
    let q = [0.3, -0.5, 0.8, -1.0, 0.4, 0.2, -0.6];
    let truth = PoseTarget::of(&robot.chain, &q);
    let (p, r) = pose_error(&robot.chain, &q, &truth);
    assert!(p < 1e-12 && r < 1e-12, "{p} {r}");
    // The target turned 30 degrees about some axis and moved 2 cm: errors 30 degrees, 2 cm.
    let turn = UnitQuaternion::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::new(0.3, -1.0, 0.5)),
        30f64.to_radians(),
    );
    let moved = PoseTarget {
        position: truth.position + Vector3::new(0.0, 0.02, 0.0),
        orientation: Some(turn * truth.orientation.unwrap()),
    };
    let (p, r) = pose_error(&robot.chain, &q, &moved);
    assert!((p - 0.02).abs() < 1e-12, "{p}");
    assert!((r.to_degrees() - 30.0).abs() < 1e-9, "{}", r.to_degrees());
    // Position only: no rotation error.
    let (_, r) = pose_error(&robot.chain, &q, &moved.position_only());
    assert_eq!(r, 0.0);
}

#[test]
fn the_pose_jacobian_matches_finite_differences() {
    let (_dir, robot) = arm(7);
    let q = [0.3, -0.5, 0.8, -1.0, 0.4, 0.2, -0.6];
    let jac = robot.chain.pose_jacobian(&q);
    let here = robot.chain.tip_pose(&q);
    for k in 0..7 {
        let mut up = q.to_vec();
        up[k] += 1e-7;
        let there = robot.chain.tip_pose(&up);
        let linear = (there.translation.vector - here.translation.vector) / 1e-7;
        let angular = (there.rotation * here.rotation.inverse()).scaled_axis() / 1e-7;
        assert!(
            (jac.fixed_view::<3, 1>(0, k) - linear).norm() < 1e-5,
            "linear {k}"
        );
        assert!(
            (jac.fixed_view::<3, 1>(3, k) - angular).norm() < 1e-5,
            "angular {k}"
        );
    }
}

#[test]
fn levenberg_marquardt_converges_within_asymmetric_limits() {
    // A 3-joint chain reaches a 3-D family of poses: targets made by its own forward
    // kinematics, so every one is reachable, from random starts only.
    let (_dir, robot) = arm(3);
    let ranges = robot.chain.joint_ranges();
    assert_eq!(ranges[0], [-1.2, 1.9]);
    let cfg = LmConfig::standard();
    let mut rng_q = selfmodel::sim::trajectory::babbling(200, &ranges, 7);
    let targets: Vec<PoseTarget> = rng_q
        .iter_mut()
        .map(|q| PoseTarget::of(&robot.chain, q))
        .collect();
    let solved = solve_batch(&robot.chain, &targets, &[], &ranges, &cfg);
    let exact = solved.iter().filter(|s| s.exact(&cfg)).count();
    assert!(exact >= 198, "{exact} of 200 exact");
    assert!(solved.iter().all(|s| within(&s.joints, &ranges, 0.0)));
    // The errors it reports are the real ones.
    for (s, t) in solved.iter().zip(&targets) {
        let (p, r) = pose_error(&robot.chain, &s.joints, t);
        assert!((p - s.position_error_m).abs() < 1e-12 && (r - s.rotation_error_rad).abs() < 1e-12);
    }
    // From a start near a solution it takes a handful of iterations.
    let near: Vec<f64> = rng_q[0].iter().map(|v| v + 0.05).collect();
    let s = solve_from(&robot.chain, &targets[0], &near, &ranges, &cfg);
    assert!(
        s.exact(&cfg) && s.iterations <= 6,
        "{} iterations",
        s.iterations
    );
}

#[test]
fn a_redundant_arm_reaches_full_poses_and_a_target_outside_the_limits_is_not_exact() {
    let (_dir, robot) = arm(7);
    let ranges = robot.chain.joint_ranges();
    let cfg = LmConfig::standard();
    let qs = selfmodel::sim::trajectory::babbling(100, &ranges, 3);
    let targets: Vec<PoseTarget> = qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    let solved = solve_batch(&robot.chain, &targets, &[], &ranges, &cfg);
    let exact = solved.iter().filter(|s| s.exact(&cfg)).count();
    assert!(exact >= 99, "{exact} of 100 exact");
    assert!(solved.iter().all(|s| within(&s.joints, &ranges, 0.0)));
    // A target 2 m away: its best answer, not exact, still inside the limits.
    let far = PoseTarget {
        position: targets[0].position + Vector3::new(2.0, 0.0, 0.0),
        orientation: targets[0].orientation,
    };
    let s = &solve_batch(&robot.chain, &[far], &[], &ranges, &cfg)[0];
    assert!(!s.exact(&cfg) && s.position_error_m > 1.0);
    assert!(within(&s.joints, &ranges, 0.0));
}
