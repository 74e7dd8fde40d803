//! Full-pose inverse kinematics: the pose error, the pose Jacobian against finite differences,
//! Levenberg-Marquardt within asymmetric limits.

mod common;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use selfmodel::ik::solve::levenberg_marquardt::Answering;
use selfmodel::ik::solve::levenberg_marquardt::{
    LmConfig, PoseTarget, pose_error, solve_batch, solve_from,
};
use selfmodel::ik::solve::solver::IkSolver;
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
            joints: Default::default(),
        },
    )
    .unwrap();
    (dir, robot)
}

#[test]
fn the_pose_error_is_zero_at_the_truth_and_the_angle_of_a_known_rotation() {
    let (_dir, robot) = arm(7);
    let q = [0.3, -0.5, 0.8, -1.0, 0.4, 0.2, -0.6];
    let truth = PoseTarget::of(&robot.chain, &q)[0];
    let (p, r) = pose_error(&robot.chain, &q, &[truth]);
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
    let (p, r) = pose_error(&robot.chain, &q, &[moved]);
    assert!((p - 0.02).abs() < 1e-12, "{p}");
    assert!((r.to_degrees() - 30.0).abs() < 1e-9, "{}", r.to_degrees());
    // Position only: no rotation error.
    let (_, r) = pose_error(&robot.chain, &q, &[moved.position_only()]);
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
    let targets: Vec<Vec<PoseTarget>> = rng_q
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
    let s = solve_from(
        &robot.chain.tip_paths(),
        &targets[0],
        &near,
        &ranges,
        &cfg,
        None,
    );
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
    let targets: Vec<Vec<PoseTarget>> =
        qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    let solved = solve_batch(&robot.chain, &targets, &[], &ranges, &cfg);
    let exact = solved.iter().filter(|s| s.exact(&cfg)).count();
    assert!(exact >= 99, "{exact} of 100 exact");
    assert!(solved.iter().all(|s| within(&s.joints, &ranges, 0.0)));
    // A target 2 m away: its best answer, not exact, still inside the limits.
    let far = PoseTarget {
        position: targets[0][0].position + Vector3::new(2.0, 0.0, 0.0),
        orientation: targets[0][0].orientation,
    };
    let s = &solve_batch(&robot.chain, &[vec![far]], &[], &ranges, &cfg)[0];
    assert!(!s.exact(&cfg) && s.position_error_m > 1.0);
    assert!(within(&s.joints, &ranges, 0.0));
}

fn quick_model(
    dir: &std::path::Path,
    joints: usize,
) -> (
    selfmodel::sim::robots::RobotSpec,
    selfmodel::sim::robot::Robot,
    selfmodel::ik::solve::learned::LearnedIk,
) {
    let urdf = common::write_arm(dir, &format!("arm{joints}"), joints, true);
    let spec = selfmodel::sim::robots::RobotSpec::Urdf {
        path: urdf,
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: Some("hand".into()),
        geometry: GeometryKind::Visual,
        joints: Default::default(),
    };
    let robot = spec.load_kinematics().unwrap();
    let model = common::quick_pose_model(&spec, &robot, dir);
    (spec, robot, model)
}

#[test]
fn a_saved_model_solves_identically_after_loading_and_refuses_another_robot() {
    use selfmodel::ik::solve::learned::LearnedIk;
    let dir = common::tempdir();
    let (_spec, robot, model) = quick_model(dir.path(), 6);
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let ranges = &model.saved.ranges;
    let qs = selfmodel::sim::trajectory::babbling(40, ranges, 5);
    let targets: Vec<Vec<PoseTarget>> =
        qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    let before = model
        .solve(&robot.chain, &targets, 3, &model.answering())
        .unwrap();
    let loaded = LearnedIk::load(&dir.path().join("model"), &device).unwrap();
    loaded.check_robot(&robot).unwrap();
    let after = loaded
        .solve(&robot.chain, &targets, 3, &loaded.answering())
        .unwrap();
    assert_eq!(before, after);
    assert_eq!(
        model.sample(&targets, &device),
        loaded.sample(&targets, &device)
    );
    // Every answer inside the limits; most targets solved exactly.
    let cfg = &loaded.saved.config.lm;
    assert!(
        after
            .iter()
            .flatten()
            .all(|s| within(&s.joints, ranges, 0.0))
    );
    let solved = after
        .iter()
        .filter(|s| s.iter().any(|a| a.exact(cfg)))
        .count();
    assert!(solved >= 30, "{solved} of 40 solved");
    // Another robot (one joint more) is refused, naming what the model was trained for.
    let other_dir = common::tempdir();
    let load = |path: &std::path::Path| {
        load_urdf_with(
            path,
            &UrdfOptions {
                tip: Some("hand".into()),
                geometry: GeometryKind::None,
                base: Isometry3::identity(),
                joints: Default::default(),
            },
        )
        .unwrap()
    };
    let other = load(&common::write_arm(other_dir.path(), "other", 7, true));
    let err = loaded.check_robot(&other).unwrap_err().to_string();
    assert!(
        err.contains("j1, j2, j3, j4, j5, j6]")
            && err.contains("j6, j7]")
            && err.contains("ik train"),
        "{err}"
    );
    // The same robot with one joint renamed: refused, both lists shown.
    let renamed = other_dir.path().join("renamed.urdf");
    std::fs::write(
        &renamed,
        common::arm_urdf(6, true).replace("name=\"j2\"", "name=\"shoulder\""),
    )
    .unwrap();
    let renamed = load(&renamed);
    let err = loaded.check_robot(&renamed).unwrap_err().to_string();
    assert!(
        err.contains("[j1, j2, j3, j4, j5, j6]") && err.contains("[j1, shoulder, j3, j4, j5, j6]"),
        "{err}"
    );
    // The same names in another order along the chain (j2 and j3 swapped): refused too.
    let reordered = other_dir.path().join("reordered.urdf");
    std::fs::write(
        &reordered,
        common::arm_urdf(6, true)
            .replace("name=\"j2\"", "name=\"tmp\"")
            .replace("name=\"j3\"", "name=\"j2\"")
            .replace("name=\"tmp\"", "name=\"j3\""),
    )
    .unwrap();
    let reordered = load(&reordered);
    let err = loaded.check_robot(&reordered).unwrap_err().to_string();
    assert!(
        err.contains("[j1, j2, j3, j4, j5, j6]") && err.contains("[j1, j3, j2, j4, j5, j6]"),
        "{err}"
    );
}

#[test]
fn malformed_target_files_fail_naming_the_line() {
    use selfmodel::ik::solve::learned::read_targets;
    let dir = common::tempdir();
    let path = dir.path().join("t.csv");
    let cases = [
        (
            "x,y,z,qw,qx,qy,qz\n0.1,0.2,0.3,1,0,0,0\n0.1,abc,0.3,1,0,0,0\n",
            "line 3",
            "abc",
        ),
        ("x,y,z,qw,qx,qy,qz\n0.1,0.2,0.3,2,0,0,0\n", "line 2", "norm"),
        ("x,y,z\n0.1,0.2,0.3\n", "line 1", "qw"),
        ("x,y,z,qw,qx,qy,qz\n0.1,0.2,NaN,1,0,0,0\n", "line 2", "NaN"),
        ("x,y,z,qw,qx,qy,qz\n", "no targets", ""),
        (
            "x,y,z,qw,qx,qy,qz,x\n0.1,0.2,0.3,1,0,0,0,9\n",
            "line 1",
            "\"x\" appears twice",
        ),
        (
            "x,y,z,qw,qx,qy,qz\n1e39,0.2,0.3,1,0,0,0\n",
            "line 2",
            "metres",
        ),
    ];
    for (text, needle, also) in cases {
        std::fs::write(&path, text).unwrap();
        let err = read_targets(&path, false, &[]).unwrap_err().to_string();
        assert!(err.contains(needle) && err.contains(also), "{err}");
        assert!(err.contains("t.csv") && !err.contains('\n'), "{err}");
    }
    // Other columns are ignored; a position-only model reads x,y,z.
    std::fs::write(&path, "id,x,y,z,note\n7,0.1,0.2,0.3,hello\n").unwrap();
    let t = read_targets(&path, true, &[]).unwrap();
    assert_eq!(t.len(), 1);
    assert!(t[0][0].orientation.is_none());
    // Several tips: each tip's columns prefixed with its name.
    let tips = ["a".to_string(), "b".to_string()];
    std::fs::write(&path, "b.x,b.y,b.z,a.x,a.y,a.z\n1,2,3,4,5,6\n").unwrap();
    let t = read_targets(&path, true, &tips).unwrap();
    assert_eq!(t[0][0].position, nalgebra::Point3::new(4.0, 5.0, 6.0));
    assert_eq!(t[0][1].position, nalgebra::Point3::new(1.0, 2.0, 3.0));
    let err = read_targets(&path, false, &tips).unwrap_err().to_string();
    assert!(err.contains("no column \"a.qw\""), "{err}");
}

/// An arm whose limits are offset around pi (as some makers state them: 0.82 to 5.46 rad) with
/// continuous joints beside them: the solver's ranges keep the limits as stated (they were cut
/// at pi, and poses that need the rest went unanswered), and random reachable poses over the
/// whole limits are answered exactly.
#[test]
fn limits_offset_around_pi_are_kept_and_answered() {
    use selfmodel::core::preset::Preset;
    use std::f64::consts::PI;
    let dir = common::tempdir();
    let text = common::arm_urdf(6, true)
        .replace(
            "name=\"j1\" type=\"revolute\"",
            "name=\"j1\" type=\"continuous\"",
        )
        .replace(
            "name=\"j4\" type=\"revolute\"",
            "name=\"j4\" type=\"continuous\"",
        );
    // j2 and j3 (odd joints: -1.9..0.7) and j5 offset around pi.
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    for (joint, lo, hi) in [("j2", 0.82, 5.46), ("j3", 0.33, 5.95), ("j5", 0.52, 5.76)] {
        let line = lines
            .iter_mut()
            .find(|l| l.contains(&format!("name=\"{joint}\"")))
            .unwrap();
        let at = line.find("lower=").unwrap();
        let end = line[at..].find(" effort").unwrap() + at;
        line.replace_range(at..end, &format!("lower=\"{lo}\" upper=\"{hi}\""));
    }
    let path = dir.path().join("offset.urdf");
    std::fs::write(&path, lines.join("\n")).unwrap();
    let spec = selfmodel::sim::robots::RobotSpec::Urdf {
        path,
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: Some("hand".into()),
        geometry: GeometryKind::None,
        joints: Default::default(),
    };
    let robot = spec.load_kinematics().unwrap();
    let ranges = robot.chain.ranges_within(PI);
    assert_eq!(ranges[1], [0.82, 5.46]);
    assert_eq!(ranges[2], [0.33, 5.95]);
    assert_eq!(ranges[4], [0.52, 5.76]);
    assert_eq!(ranges[0], [-PI, PI]);
    let cfg = selfmodel::ik::solve::learned::LearnedIkConfig::quick();
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let model = selfmodel::ik::solve::learned::train(
        &spec,
        &robot,
        &cfg,
        &dir.path().join("model"),
        &device,
    )
    .unwrap();
    assert_eq!(model.saved.ranges, ranges);
    // Poses over the whole limits.
    let qs = selfmodel::sim::trajectory::babbling(300, &ranges, 11);
    assert!(qs.iter().filter(|q| q[1] > PI).count() > 100);
    let targets: Vec<Vec<PoseTarget>> =
        qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    let answers = model
        .solve(&robot.chain, &targets, 1, &model.answering())
        .unwrap();
    let exact = answers
        .iter()
        .filter(|a| a.iter().any(|s| s.exact(&model.saved.config.lm)))
        .count();
    assert!(exact >= 297, "{exact} of 300 answered exactly");
}

/// IK with several tips: a model of both hands of a two-armed robot (a shared waist) answers
/// targets giving both hands' poses, read from and written to the `A.x,...,B.x,...` columns;
/// an answer is exact only when each hand is within the tolerances.
#[test]
fn two_tips_are_solved_together() {
    use selfmodel::core::preset::Preset;
    use selfmodel::ik::solve::learned::{LearnedIk, read_targets};
    use selfmodel::sim::kinematics::JointGroup;
    let dir = common::tempdir();
    let path = dir.path().join("two_arms.urdf");
    std::fs::write(&path, common::two_armed_urdf()).unwrap();
    let spec = selfmodel::sim::robots::RobotSpec::Urdf {
        path,
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: None,
        geometry: GeometryKind::None,
        joints: JointGroup::Tips(vec!["left_hand".into(), "right_hand".into()]),
    };
    let robot = spec.load_kinematics().unwrap();
    assert_eq!(robot.chain.tip_names(), ["left_hand", "right_hand"]);
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let model_dir = dir.path().join("model");
    let cfg = selfmodel::ik::solve::learned::LearnedIkConfig::quick();
    selfmodel::ik::solve::learned::train(&spec, &robot, &cfg, &model_dir, &device).unwrap();
    let model = LearnedIk::load(&model_dir, &device).unwrap();
    model.check_robot(&robot).unwrap();
    assert_eq!(model.tips(), ["left_hand", "right_hand"]);
    // Two tips, twice the solver's budget.
    assert_eq!(
        model.saved.config.lm,
        LmConfig::standard().for_tips(2),
        "the budget of two tips"
    );
    assert_eq!(model.saved.config.lm.max_iterations, 60);
    let (targets, joints) =
        selfmodel::ik::solve::targets::random_targets(&robot, &model.saved.ranges, 100, 3);
    let text = selfmodel::ik::solve::targets::targets_csv(
        &targets,
        &joints,
        &model.saved.joint_names,
        model.tips(),
    );
    assert!(text.starts_with("left_hand.x,left_hand.y,left_hand.z,left_hand.qw,"));
    assert!(
        text.lines()
            .next()
            .unwrap()
            .contains("right_hand.qz,waist,r1,r2,l1,l2")
    );
    let file = dir.path().join("targets.csv");
    std::fs::write(&file, text).unwrap();
    let read = read_targets(&file, false, model.tips()).unwrap();
    assert_eq!(read.len(), 100);
    let answers = model
        .solve(&robot.chain, &read, 1, &model.answering())
        .unwrap();
    let lm = &model.saved.config.lm;
    let mut exact = 0;
    for (a, t) in answers.iter().map(|a| &a[0]).zip(&targets) {
        // Each hand on its own.
        let poses = robot.chain.tip_poses(&a.joints);
        let each: Vec<(f64, f64)> = poses
            .iter()
            .zip(t)
            .map(|(p, t)| {
                (
                    (p.translation.vector - t.position.coords).norm(),
                    p.rotation.angle_to(&t.orientation.unwrap()),
                )
            })
            .collect();
        let both = each
            .iter()
            .all(|&(p, r)| p <= lm.tolerance_m && r <= lm.tolerance_rad);
        assert_eq!(a.exact(lm), both, "{each:?}");
        exact += usize::from(both);
    }
    assert!(exact >= 98, "{exact} of 100 targets exact");
    // The tips moved apart: a single hand's pose is not an answer to both.
    let one = PoseTarget::of(&robot.chain, &joints[0]);
    let mut swapped = one.clone();
    swapped.swap(0, 1);
    let (p, _) = pose_error(&robot.chain, &joints[0], &swapped);
    assert!(p > 0.1, "{p}");
}

/// A long solve asks its `stop` between blocks of targets (Ctrl-C on the command line, Python's
/// signal check in Python) and ends with `Interrupted`, saying how far it got: every 256 answers
/// (128 targets of 2 answers).
#[test]
fn a_solve_stops_between_blocks_when_asked() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let dir = common::tempdir();
    let (_spec, robot, model) = quick_model(dir.path(), 4);
    let qs = selfmodel::sim::trajectory::babbling(3000, &model.saved.ranges, 9);
    let targets: Vec<Vec<PoseTarget>> =
        qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    let calls = AtomicUsize::new(0);
    let stop = || calls.fetch_add(1, Ordering::Relaxed) >= 1;
    let lm = model.saved.config.lm.clone();
    let err = model
        .solve(
            &robot.chain,
            &targets,
            2,
            &Answering {
                stop: &stop,
                ..Answering::with(&lm)
            },
        )
        .unwrap_err();
    assert!(matches!(err, selfmodel::Error::Interrupted(_)), "{err}");
    assert!(
        err.to_string().contains("after 128 of 3000 targets"),
        "{err}"
    );
    assert_eq!(calls.load(Ordering::Relaxed), 2);
}

/// Exact means converged: every exact answer's pose error, recomputed here by the robot's own
/// forward kinematics, is below the convergence tolerance (1e-4 mm and 1e-4 degrees), far
/// inside the success threshold; on the UR5 and, where the shared descriptions sit beside the
/// repository, the Panda as Franka ships it.
#[test]
fn exact_answers_are_converged_below_the_tolerance() {
    let mut robots = vec![(
        "UR5",
        selfmodel::sim::dh_robot::ur5([-std::f64::consts::PI, std::f64::consts::PI]),
    )];
    let panda =
        selfmodel_lab::workspace().join("../shared/robots/franka_description/urdf/panda.urdf");
    if panda.is_file() {
        let options = UrdfOptions {
            tip: Some("panda_hand".into()),
            geometry: GeometryKind::None,
            base: Isometry3::identity(),
            joints: Default::default(),
        };
        robots.push(("Panda", load_urdf_with(&panda, &options).unwrap()));
    } else {
        eprintln!("the Panda left out: ../shared/robots is not beside the repository");
    }
    let cfg = LmConfig::standard();
    for (name, robot) in robots {
        let ranges = robot.chain.joint_ranges();
        let qs = selfmodel::sim::trajectory::babbling(300, &ranges, 11);
        let targets: Vec<Vec<PoseTarget>> =
            qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
        let solved = solve_batch(&robot.chain, &targets, &[], &ranges, &cfg);
        let mut exact = 0;
        let (mut worst_p, mut worst_r) = (0f64, 0f64);
        for (s, t) in solved.iter().zip(&targets) {
            let (p, r) = pose_error(&robot.chain, &s.joints, t);
            assert!(
                (p - s.position_error_m).abs() < 1e-12 && (r - s.rotation_error_rad).abs() < 1e-12,
                "{name}: the answer says {} m and {} rad, forward kinematics {p} m and {r} rad",
                s.position_error_m,
                s.rotation_error_rad
            );
            if s.exact(&cfg) {
                exact += 1;
                worst_p = worst_p.max(p);
                worst_r = worst_r.max(r);
                assert!(
                    p <= cfg.convergence_m && r <= cfg.convergence_rad,
                    "{name}: an exact answer {:.3e} mm and {:.3e} degrees from its target ({} iterations, {} starts, at {:?})",
                    1e3 * p,
                    r.to_degrees(),
                    s.iterations,
                    s.starts,
                    s.joints
                );
            }
        }
        eprintln!(
            "{name}: {exact} of 300 exact, the worst {:.2e} mm and {:.2e} degrees",
            1e3 * worst_p,
            worst_r.to_degrees()
        );
        assert!(exact >= 297, "{name}: {exact} of 300 exact");
    }
}

/// The tolerance is checked: finite, positive, no looser than the success threshold.
#[test]
fn a_tolerance_outside_its_range_is_refused() {
    let cfg = LmConfig::standard();
    let ok = cfg.clone().converging_to(1e-3, 1e-3).unwrap();
    assert_eq!(
        (ok.convergence_m, ok.convergence_rad),
        (1e-6, 1e-3f64.to_radians())
    );
    for (mm, deg) in [
        (f64::NAN, 1e-4),
        (1e-4, f64::INFINITY),
        (-1e-4, 1e-4),
        (0.0, 1e-4),
        (1.5, 1e-4),
        (1e-4, 1.0),
        (1e-12, 1e-4),
    ] {
        let e = cfg.clone().converging_to(mm, deg).unwrap_err();
        assert!(e.contains("tolerance"), "{e}");
    }
    assert!(cfg.clone().converging_to_text("0.001, 0.01").is_ok());
    for bad in ["", "1", "1,2,3", "a,b", "0.001;0.01"] {
        assert!(cfg.clone().converging_to_text(bad).is_err(), "{bad}");
    }
}

/// Every solver answers through one trait: on the same targets of a 6-joint arm,
/// Levenberg-Marquardt (random starts) and the learned model (its samples as starts) answer
/// full poses exactly and inside the limits, the learned one in fewer iterations; damped least
/// squares answers the positions and refuses a target with an orientation; each gives `k`
/// answers a target, in target order, and stops between blocks when asked.
#[test]
fn every_solver_answers_through_the_one_trait() {
    use selfmodel::ik::solve::solver::{DampedLeastSquares, LevenbergMarquardt};
    let dir = common::tempdir();
    let (_spec, robot, model) = quick_model(dir.path(), 6);
    let ranges = model.saved.ranges.clone();
    let qs = selfmodel::sim::trajectory::babbling(24, &ranges, 3);
    let targets: Vec<Vec<PoseTarget>> =
        qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    let lm = model.saved.config.lm.clone();
    let how = Answering::with(&lm);
    let lm_solver = LevenbergMarquardt::within(ranges.clone());
    let dls = DampedLeastSquares {
        cfg: selfmodel::ik::solve::damped_least_squares::DlsConfig::standard(),
        ranges: ranges.clone(),
    };
    let solvers: [(&str, &dyn IkSolver); 2] = [("LM", &lm_solver), ("learned", &model)];
    let mut iterations = Vec::new();
    for (name, solver) in solvers {
        let answers = solver.solve(&robot.chain, &targets, 2, &how).unwrap();
        assert_eq!(answers.len(), targets.len(), "{name}");
        assert!(answers.iter().all(|a| a.len() == 2), "{name}");
        for (t, a) in targets.iter().zip(&answers) {
            for s in a {
                assert!(within(&s.joints, &ranges, 0.0), "{name}");
                // The answer's own errors are those of the joints it gives.
                let (p, r) = pose_error(&robot.chain, &s.joints, t);
                assert!((p - s.position_error_m).abs() < 1e-9, "{name}");
                assert!((r - s.rotation_error_rad).abs() < 1e-9, "{name}");
            }
        }
        let exact = answers.iter().flatten().filter(|s| s.exact(&lm)).count();
        assert!(exact >= 44, "{name}: {exact} of 48 exact");
        iterations.push(
            answers
                .iter()
                .flatten()
                .map(|s| s.iterations)
                .sum::<usize>(),
        );
    }
    assert!(
        iterations[1] < iterations[0],
        "the learned starts took {} iterations, random starts {}",
        iterations[1],
        iterations[0]
    );
    // Damped least squares: positions only.
    let err = dls.solve(&robot.chain, &targets, 1, &how).unwrap_err();
    assert!(err.to_string().contains("positions"), "{err}");
    let positions: Vec<Vec<PoseTarget>> = targets
        .iter()
        .map(|t| t.iter().map(|p| p.position_only()).collect())
        .collect();
    let answers = dls.solve(&robot.chain, &positions, 2, &how).unwrap();
    let reached = answers
        .iter()
        .filter(|a| a.iter().any(|s| s.position_error_m <= dls.cfg.tolerance_m))
        .count();
    assert!(reached >= 20, "DLS reached {reached} of 24 positions");
    for (t, a) in positions.iter().zip(&answers) {
        for s in a {
            let (p, _) = pose_error(&robot.chain, &s.joints, t);
            assert!((p - s.position_error_m).abs() < 1e-9);
        }
    }
    // Asked to stop: an interruption, whichever solver.
    let stop = || true;
    let stopped = Answering {
        stop: &stop,
        ..Answering::with(&lm)
    };
    let asked: [(&dyn IkSolver, &[Vec<PoseTarget>]); 3] = [
        (&lm_solver, &targets),
        (&dls, &positions),
        (&model, &targets),
    ];
    for (solver, these) in asked {
        let err = solver.solve(&robot.chain, these, 1, &stopped).unwrap_err();
        assert!(matches!(err, selfmodel::Error::Interrupted(_)), "{err}");
    }
    // A full-pose model asked for positions alone says so (it cannot be conditioned on them).
    let err = model.solve(&robot.chain, &positions, 1, &how).unwrap_err();
    assert!(err.to_string().contains("no orientation"), "{err}");
}
