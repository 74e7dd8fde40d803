//! Robot descriptions as ROS ships them: mesh formats, fixed joints with zero axes, mimic and
//! prismatic joints, `--tip`, joint limits in every sampler and solver, automatic framing.

mod common;

use std::path::Path;

use nalgebra::{Isometry3, Point3, Vector3};
use selfmodel::core::preset::Preset;
use selfmodel::data::dataset::{Dataset, DatasetConfig, Framing};
use selfmodel::ik::data::{IkData, IkDataConfig, JointOutput};
use selfmodel::sim::camera::Camera;
use selfmodel::sim::kinematics::within;
use selfmodel::sim::ray_caster::{RayCaster, RenderOptions};
use selfmodel::sim::tensor_kinematics::TensorChain;
use selfmodel::sim::trajectory::{SamplerKind, babbling, grid, lorenz};
use selfmodel::sim::urdf_loader::{GeometryKind, UrdfOptions, load_urdf, load_urdf_with};

/// Load `urdf` with its end effector at `tip`.
fn tipped(
    urdf: &Path,
    tip: &str,
    geometry: GeometryKind,
) -> selfmodel::Result<selfmodel::sim::robot::Robot> {
    load_urdf_with(
        urdf,
        &UrdfOptions {
            tip: Some(tip.into()),
            geometry,
            ..UrdfOptions::default()
        },
    )
}

/// A one-link robot whose link is the mesh `file` (scaled by `scale`).
fn mesh_robot(dir: &Path, file: &str, scale: f64) -> selfmodel::sim::robot::Robot {
    let urdf = dir.join(format!("{file}.urdf"));
    std::fs::write(
        &urdf,
        format!(
            r#"<robot name="m"><link name="body"><visual><origin xyz="0 0 0" rpy="0.3 0.2 0.1"/><geometry><mesh filename="{file}" scale="{scale} {scale} {scale}"/></geometry></visual></link></robot>"#
        ),
    )
    .unwrap();
    load_urdf(&urdf, Isometry3::identity()).unwrap()
}

#[test]
fn collada_and_obj_meshes_render_the_silhouette_of_the_same_stl() {
    let dir = common::tempdir();
    let d = dir.path();
    std::fs::write(d.join("cube.stl"), common::cube_stl_binary(0.1)).unwrap();
    // The OBJ holds a cube half the size, scaled 2x by the URDF; the COLLADA one is written in
    // centimetres with <unit meter="0.01">.
    std::fs::write(d.join("cube.obj"), common::cube_obj(0.05)).unwrap();
    std::fs::write(d.join("cube.dae"), common::cube_collada(0.1, 0.01)).unwrap();
    let camera = Camera::paper();
    let render = |robot: &selfmodel::sim::robot::Robot| {
        RayCaster::new(robot, camera.clone(), RenderOptions::default())
            .render(&[])
            .silhouette
    };
    let stl = render(&mesh_robot(d, "cube.stl", 1.0));
    let robot_pixels = stl.iter().filter(|&&v| v > 0).count();
    assert!(robot_pixels > 500, "the cube covers {robot_pixels} pixels");
    for (file, scale) in [("cube.obj", 2.0), ("cube.dae", 1.0)] {
        let other = render(&mesh_robot(d, file, scale));
        let differ = stl.iter().zip(&other).filter(|(a, b)| a != b).count();
        assert!(
            differ <= 2,
            "{file}: {differ} of {robot_pixels} robot pixels differ from the STL's silhouette"
        );
    }
}

#[test]
fn a_fixed_joint_with_a_zero_axis_loads_and_mimic_fingers_follow_their_leader() {
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 3, true);
    // Default tip: the end of the longest chain, a finger: three arm joints and the finger.
    let robot = load_urdf(&urdf, Isometry3::identity()).unwrap();
    assert_eq!(
        robot.chain.joint_names(),
        ["j1", "j2", "j3", "finger_a_joint"]
    );
    let q = [0.3, -0.4, 0.5, 0.03];
    let frames = robot.link_frames(&q);
    let link = |name: &str| robot.chain.links.iter().position(|l| l == name).unwrap();
    let hand = frames[link("hand")];
    let a = hand.inverse() * frames[link("finger_a")];
    let b = hand.inverse() * frames[link("finger_b")];
    // finger_a moves +0.03 along y, its mimic -y by the same amount.
    assert!((a.translation.vector - Vector3::new(0.0, 0.03, 0.04)).norm() < 1e-12);
    assert!((b.translation.vector - Vector3::new(0.0, -0.03, 0.04)).norm() < 1e-12);
    // The tensor kinematics agrees, mimic included.
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let chain = TensorChain::new(&robot.chain);
    let qt = burn::tensor::Tensor::<2>::from_data(
        burn::tensor::TensorData::new(q.map(|v| v as f32).to_vec(), [1, 4]),
        &device,
    );
    let (_, t) = chain.link_frames(qt);
    let t: Vec<f32> = t.into_data().try_to_vec::<f32>().unwrap();
    for (l, f) in frames.iter().enumerate() {
        for k in 0..3 {
            assert!((t[3 * l + k] as f64 - f.translation.vector[k]).abs() < 1e-5);
        }
    }
    // A mimic on the path adds its motion to its leader's Jacobian column: check against
    // finite differences with the tip on the mimic finger.
    let tipped = tipped(&urdf, "finger_b", GeometryKind::Visual).unwrap();
    // finger_b mimics finger_a, which is off the path to finger_b: its leader is still the
    // input that moves it (-1 m of tip per m of finger_a along y).
    assert_eq!(tipped.dof(), 4);
    let jac = tipped.chain.position_jacobian(&q);
    for k in 0..4 {
        let mut up = q.to_vec();
        up[k] += 1e-6;
        let fd = (tipped.chain.end_effector(&up) - tipped.chain.end_effector(&q)) / 1e-6;
        assert!(
            (jac.column(k) - fd).norm() < 1e-4,
            "column {k}: {} vs {fd}",
            jac.column(k)
        );
    }
    assert!(jac.column(3).norm() > 0.99);
}

#[test]
fn tip_chooses_the_chain_and_joints_off_it_are_held() {
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 7, true);
    let robot = tipped(&urdf, "hand", GeometryKind::Visual).unwrap();
    assert_eq!(robot.dof(), 7);
    let frames = robot.link_frames(&[0.1; 7]);
    let link = |name: &str| robot.chain.links.iter().position(|l| l == name).unwrap();
    let offset = frames[link("hand")].inverse() * frames[link("finger_a")];
    assert!((offset.translation.vector - Vector3::new(0.0, 0.0, 0.04)).norm() < 1e-12);
    let err = tipped(&urdf, "gripper", GeometryKind::Visual)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`tip` \"gripper\" is not a link")
            && err.contains("hand")
            && err.contains("finger_a"),
        "{err}"
    );
}

#[test]
fn a_prismatic_joint_moves_the_tip_by_metres() {
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 2, true);
    let robot = tipped(&urdf, "finger_a", GeometryKind::Visual).unwrap();
    assert_eq!(robot.dof(), 3);
    let closed = robot.end_effector(&[0.0, 0.0, 0.0]);
    let open = robot.end_effector(&[0.0, 0.0, 0.04]);
    assert!(((open - closed).norm() - 0.04).abs() < 1e-12);
    // Its range is the limits in metres, in every sampler.
    assert_eq!(robot.chain.joint_ranges()[2], [0.0, 0.04]);
    assert_eq!(robot.chain.joint_ranges_user()[2], [0.0, 0.04]);
    let ik = IkData::generate(&robot.chain, &IkDataConfig::quick(90.0)).unwrap();
    assert!(ik.joints.iter().all(|q| (0.0..=0.04).contains(&q[2])));
    assert!(ik.joints.iter().any(|q| q[2] > 0.03));
}

#[test]
fn xacro_files_are_refused_with_how_to_expand_them() {
    let dir = common::tempdir();
    let path = dir.path().join("arm.urdf.xacro");
    std::fs::write(
        &path,
        r#"<robot name="a" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:property name="l" value="1"/><link name="b"/></robot>"#,
    )
    .unwrap();
    let err = load_urdf(&path, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(err.contains("xacro") && err.contains("expand"), "{err}");
    // An expanded file keeps the namespace declaration: it loads.
    let expanded = dir.path().join("arm.urdf");
    std::fs::write(
        &expanded,
        r#"<robot name="a" xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="b"/></robot>"#,
    )
    .unwrap();
    assert!(load_urdf(&expanded, Isometry3::identity()).is_ok());
    // As ROS packages ship expanded descriptions: the namespace, a commented-out macro, an
    // empty texture (urdfdom ignores it). It loads; the same file with a live macro does not.
    let shipped = r#"<?xml version="1.0"?>
<robot name="a" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <!-- <xacro:macro name="leg" params="side"> ${side} </xacro:macro> -->
  <material name="m"><color rgba="1 1 1 1"/><texture/></material>
  <link name="b"><visual><geometry><box size="0.1 0.1 0.1"/></geometry><material name="m"/></visual></link>
</robot>"#;
    std::fs::write(&expanded, shipped).unwrap();
    let robot = load_urdf(&expanded, Isometry3::identity());
    assert!(robot.is_ok(), "{:?}", robot.err());
    std::fs::write(
        &expanded,
        shipped
            .replace("<!-- <xacro:macro", "<xacro:macro")
            .replace("</xacro:macro> -->", "</xacro:macro>"),
    )
    .unwrap();
    let err = load_urdf(&expanded, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("xacro:macro") && err.contains("expand"),
        "{err}"
    );
}

#[test]
fn bad_limits_and_scales_are_errors() {
    let dir = common::tempdir();
    let good = common::arm_urdf(2, false);
    for (from, to, needle) in [
        (
            "lower=\"-1.2\" upper=\"1.9\"",
            "lower=\"1.9\" upper=\"-1.2\"",
            "lower is above upper",
        ),
        (
            "lower=\"-1.2\" upper=\"1.9\"",
            "lower=\"NaN\" upper=\"1.9\"",
            "finite",
        ),
        (
            "lower=\"-1.2\" upper=\"1.9\"",
            "lower=\"-inf\" upper=\"1.9\"",
            "finite",
        ),
    ] {
        let path = dir.path().join("bad.urdf");
        std::fs::write(&path, good.replacen(from, to, 1)).unwrap();
        let err = load_urdf(&path, Isometry3::identity())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("joint \"j1\"") && err.contains(needle),
            "{err}"
        );
    }
    std::fs::write(dir.path().join("cube.stl"), common::cube_stl_binary(0.1)).unwrap();
    let path = dir.path().join("scaled.urdf");
    std::fs::write(
        &path,
        r#"<robot name="m"><link name="b"><visual><geometry><mesh filename="cube.stl" scale="1e300 1 1"/></geometry></visual></link></robot>"#,
    )
    .unwrap();
    let err = load_urdf(&path, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(err.contains("scale"), "{err}");
}

/// A 7-joint arm with asymmetric limits: every sampler, the IK data, learned outputs and DLS.
#[test]
fn samplers_learned_outputs_and_dls_stay_inside_asymmetric_limits() {
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 7, true);
    let robot = tipped(&urdf, "hand", GeometryKind::None).unwrap();
    let chain = &robot.chain;
    let si = chain.joint_ranges();
    let user = chain.joint_ranges_user();
    assert_eq!(si[0], [-1.2, 1.9]);
    assert_eq!(si[1], [-1.9, 0.7]);
    let inside_user = |rows: &[Vec<f64>]| rows.iter().all(|q| within(q, &user, 1e-9));
    assert!(inside_user(&lorenz(2000, &user).unwrap()));
    assert!(inside_user(&babbling(2000, &user, 1)));
    assert!(inside_user(&grid(500, &user, &[30.0; 7], 2).unwrap()));
    // IK data within +-90 degrees: the limits where tighter (-1.2 > -pi/2), +-90 elsewhere.
    let data = IkData::generate(chain, &IkDataConfig::quick(90.0)).unwrap();
    let half = std::f64::consts::FRAC_PI_2;
    assert_eq!(data.ranges[0], [-1.2, half]);
    assert_eq!(data.ranges[1], [-half, 0.7]);
    assert_eq!(data.outside_limits(&data.joints), 0);
    // Any network output decodes inside the limits: the sigmoid's ends and wrapped angles.
    for output in [JointOutput::Sigmoid, JointOutput::Wrapped] {
        for v in [-1.0f32, 0.0, 0.5, 1.0, 2.0] {
            let raw = vec![v; output.width(7)];
            let q = data.decode_joints(&raw, output);
            let clamped: Vec<f32> = raw.iter().map(|x| x.clamp(0.0, 1.0)).collect();
            let q = if output == JointOutput::Sigmoid {
                data.decode_joints(&clamped, output)
            } else {
                q
            };
            assert!(within(&q, &data.ranges, 1e-9), "{output:?} {v}: {q:?}");
        }
    }
    // DLS from home and with restarts: every answer inside the limits.
    let targets: Vec<Point3<f64>> = data.positions[data.test()]
        .iter()
        .take(50)
        .copied()
        .collect();
    let cfg = selfmodel::ik::solve::damped_least_squares::DlsConfig::standard();
    let home = vec![vec![0.0; 7]; targets.len()];
    let home: Vec<Vec<f64>> = home
        .into_iter()
        .map(|q| {
            q.iter()
                .zip(&data.ranges)
                .map(|(v, r): (&f64, _)| v.clamp(r[0], r[1]))
                .collect()
        })
        .collect();
    let solved = selfmodel::ik::solve::damped_least_squares::solve_batch(
        chain,
        &targets,
        &home,
        &data.ranges,
        &cfg,
    );
    assert!(
        solved
            .iter()
            .all(|s| within(&s.joints, &data.ranges, 1e-12))
    );
    let converged = solved.iter().filter(|s| s.error_m < 1e-4).count();
    assert!(
        converged * 2 >= targets.len(),
        "{converged} of {} converged",
        targets.len()
    );
}

#[test]
fn automatic_framing_keeps_every_sampled_pose_inside_the_image() {
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 7, true);
    let robot = tipped(&urdf, "hand", GeometryKind::Visual).unwrap();
    let mut cfg = DatasetConfig::quick();
    cfg.samples = 300;
    cfg.train = 240;
    cfg.sampler = SamplerKind::Babbling;
    cfg.camera.width = 48;
    cfg.camera.height = 40;
    cfg.framing = Some(Framing::default());
    let data = Dataset::generate(&robot, &cfg, None).unwrap();
    let (w, h) = (data.width, data.height);
    let mut used = [usize::MAX, 0, usize::MAX, 0];
    for i in 0..data.len() {
        let img = data.image(i);
        assert!(img.iter().any(|&v| v > 0), "pose {i} is out of view");
        for r in 0..h {
            for c in 0..w {
                if img[r * w + c] > 0 {
                    assert!(
                        r > 0 && c > 0 && r + 1 < h && c + 1 < w,
                        "pose {i} touches the border at ({r}, {c})"
                    );
                    used = [
                        used[0].min(r),
                        used[1].max(r),
                        used[2].min(c),
                        used[3].max(c),
                    ];
                }
            }
        }
    }
    // And it is not framed loosely: the poses together span most of the image one way.
    let span = ((used[1] - used[0]) as f64 / h as f64).max((used[3] - used[2]) as f64 / w as f64);
    assert!(span > 0.7, "the poses span only {span:.2} of the image");
    // The recorded camera is the one it rendered with.
    let camera = data.camera();
    let again = RayCaster::new(&robot, camera, RenderOptions::default())
        .render(&robot.chain.to_si(&data.angles[7]))
        .silhouette;
    let differ = again
        .iter()
        .zip(data.image(7))
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differ <= 1,
        "{differ} pixels differ from the recorded camera's render"
    );
}

#[test]
fn the_papers_arm_keeps_the_papers_camera() {
    let mut cfg = DatasetConfig::quick();
    let opts = selfmodel::data::dataset::CameraChoice::default();
    opts.apply(&mut cfg, false);
    assert_eq!(cfg.framing, None);
    assert_eq!(cfg.camera, Camera::paper());
}

/// The shipped descriptions, where they sit beside the repository.
#[test]
fn the_panda_and_the_ur5_load_as_ros_ships_them() {
    let shared = selfmodel_lab::workspace().join("../shared/robots");
    let panda = shared.join("franka_description/urdf/panda.urdf");
    if !panda.is_file() {
        eprintln!("skipped: the shared robots are not beside the repository");
        return;
    }
    let robot = tipped(&panda, "panda_hand", GeometryKind::Visual).unwrap();
    assert_eq!(robot.dof(), 7);
    assert!(
        robot.shape_count() > 10_000,
        "{} triangles",
        robot.shape_count()
    );
    // Joint 4 must stay below -0.07 rad: the samplers keep it there.
    assert!(robot.chain.joint_ranges()[3][1] < -0.06);
    let collision = tipped(&panda, "panda_hand", GeometryKind::Collision).unwrap();
    assert!(collision.shape_count() < robot.shape_count());
    let ur5 = tipped(
        &shared.join("ur_description/urdf/ur5.urdf"),
        "tool0",
        GeometryKind::Visual,
    )
    .unwrap();
    assert_eq!(ur5.dof(), 6);
    // Limits of two turns are sampled within one (+-180 degrees).
    assert!(
        ur5.chain
            .joint_ranges()
            .iter()
            .all(|r| r[1] <= std::f64::consts::PI)
    );
    let _ = Vector3::<f64>::zeros();
}

/// The IK solvers' fast path (`TipPath`: one pass over the movable joints to the tip, constant
/// transforms folded) gives the reference's tip pose and pose Jacobian: on a mimic-tipped
/// arm, the Panda as Franka ships it (fingers held, a fixed joint after joint 7) and the UR5.
#[test]
fn the_tip_path_matches_the_full_chain_pose_and_jacobian() {
    use rand::{RngExt, SeedableRng};
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 3, true);
    let mut robots = vec![tipped(&urdf, "finger_b", GeometryKind::Visual).unwrap()];
    let panda =
        selfmodel_lab::workspace().join("../shared/robots/franka_description/urdf/panda.urdf");
    if panda.exists() {
        robots.push(tipped(&panda, "panda_hand", GeometryKind::None).unwrap());
    }
    robots.push(selfmodel::sim::dh_robot::ur5([-3.0, 3.0]));
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    for robot in robots {
        let chain = &robot.chain;
        let path = chain.tip_path();
        let ranges = chain.joint_ranges();
        let mut jac = nalgebra::Matrix6xX::zeros(0);
        for _ in 0..50 {
            let q: Vec<f64> = ranges
                .iter()
                .map(|&[lo, hi]| rng.random_range(lo..=hi))
                .collect();
            let (fast, slow) = (path.pose_and_jacobian(&q, &mut jac), chain.tip_pose(&q));
            assert!((fast.translation.vector - slow.translation.vector).norm() < 1e-12);
            assert!(fast.rotation.angle_to(&slow.rotation) < 1e-9);
            assert!((path.pose(&q).translation.vector - slow.translation.vector).norm() < 1e-12);
            let reference = chain.pose_jacobian(&q);
            assert!(
                (&jac - &reference).norm() < 1e-12,
                "{jac} against {reference}"
            );
        }
    }
}

/// The joint vector runs root to tip whatever order the file lists the joints in (a hobby arm
/// that lists them tip first): the same names, order and forward kinematics as the same robot
/// listed root first.
#[test]
fn joints_listed_tip_first_are_ordered_root_to_tip() {
    let dir = common::tempdir();
    let text = common::arm_urdf(4, false);
    let root_first = dir.path().join("root_first.urdf");
    std::fs::write(&root_first, &text).unwrap();
    // The same elements, the joints in reverse order.
    let lines: Vec<&str> = text.lines().collect();
    let (joints, others): (Vec<&str>, Vec<&str>) = lines
        .iter()
        .partition(|l| l.trim_start().starts_with("<link name=\"l"));
    let mut reversed: Vec<String> = others
        .iter()
        .filter(|l| !l.contains("</robot>"))
        .map(|l| l.to_string())
        .collect();
    reversed.extend(joints.iter().rev().map(|l| l.to_string()));
    reversed.push("</robot>".into());
    let tip_first = dir.path().join("tip_first.urdf");
    std::fs::write(&tip_first, reversed.join("\n")).unwrap();
    let a = load_urdf(&root_first, Isometry3::identity()).unwrap();
    let b = load_urdf(&tip_first, Isometry3::identity()).unwrap();
    assert_eq!(a.chain.joint_names(), ["j1", "j2", "j3", "j4"]);
    assert_eq!(b.chain.joint_names(), a.chain.joint_names());
    assert_eq!(b.chain.joint_ranges(), a.chain.joint_ranges());
    for q in [[0.3, -0.5, 1.1, 0.2], [-1.0, 0.4, -0.7, 1.5]] {
        let (pa, pb) = (a.chain.tip_pose(&q), b.chain.tip_pose(&q));
        assert!(
            (pa.translation.vector - pb.translation.vector).norm() < 1e-12
                && pa.rotation.angle_to(&pb.rotation) < 1e-12,
            "{pa} vs {pb}"
        );
    }
}

/// Joint groups: the chains to several tips (both hands, with the waist they share), every
/// movable joint, joints by name; each joint of the group moves what hangs from it and
/// nothing else, and the joints keep the tree's depth-first order.
#[test]
fn joint_groups_drive_several_tips_and_every_joint() {
    use selfmodel::sim::kinematics::JointGroup;
    use selfmodel::sim::urdf_loader::{GeometryKind, UrdfOptions, load_urdf_with};
    let dir = common::tempdir();
    let path = dir.path().join("two_arms.urdf");
    std::fs::write(&path, common::two_armed_urdf()).unwrap();
    let load = |joints: JointGroup| {
        load_urdf_with(
            &path,
            &UrdfOptions {
                geometry: GeometryKind::None,
                joints,
                ..UrdfOptions::default()
            },
        )
    };
    let both = load(JointGroup::Tips(vec![
        "left_hand".into(),
        "right_hand".into(),
    ]))
    .unwrap();
    assert_eq!(both.chain.joint_names(), ["waist", "r1", "r2", "l1", "l2"]);
    let hand = |robot: &selfmodel::sim::robot::Robot, q: &[f64], name: &str| {
        let l = robot.chain.links.iter().position(|l| l == name).unwrap();
        robot.chain.link_frames(q).remove(l).translation.vector
    };
    let zero = [0.0; 5];
    for (k, moves_left, moves_right) in [
        (0, true, true),
        (1, false, true),
        (2, false, true),
        (3, true, false),
        (4, true, false),
    ] {
        let mut q = zero;
        q[k] = 0.7;
        let dl = (hand(&both, &q, "left_hand") - hand(&both, &zero, "left_hand")).norm();
        let dr = (hand(&both, &q, "right_hand") - hand(&both, &zero, "right_hand")).norm();
        assert_eq!(
            (dl > 1e-6, dr > 1e-6),
            (moves_left, moves_right),
            "joint {k}: {dl} {dr}"
        );
    }
    let all = load(JointGroup::All).unwrap();
    assert_eq!(
        all.chain.joint_names(),
        ["waist", "r1", "r2", "l1", "l2", "grip"]
    );
    for k in 0..6 {
        let mut q = [0.0; 6];
        q[k] = 0.02;
        let before = all.chain.link_frames(&[0.0; 6]);
        let after = all.chain.link_frames(&q);
        assert!(
            before
                .iter()
                .zip(&after)
                .any(
                    |(a, b)| (a.translation.vector - b.translation.vector).norm() > 1e-4
                        || a.rotation.angle_to(&b.rotation) > 1e-4
                ),
            "joint {k} moves nothing"
        );
    }
    // The joint vector as a tree: each joint's parent joint.
    assert_eq!(
        all.chain.input_parents(),
        [None, Some(0), Some(1), Some(0), Some(3), Some(4)]
    );
    // Cut into chains at the branch point (the waist holds two arms): the per-group errors'
    // groups.
    assert_eq!(
        all.chain.input_chains(),
        [vec![0], vec![1, 2], vec![3, 4, 5]]
    );
    let named = load(JointGroup::Named(vec!["l2".into(), "waist".into()])).unwrap();
    assert_eq!(named.chain.input_parents(), [None, Some(0)]);
    assert_eq!(named.chain.input_chains(), [vec![0, 1]]);
    assert_eq!(named.chain.joint_names(), ["waist", "l2"]);
    let err = load(JointGroup::Tips(vec!["left_foot".into()]))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("left_foot") && err.contains("right_hand"),
        "{err}"
    );
    let err = load(JointGroup::Named(vec!["r_wrist".into()]))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("not a movable joint") && err.contains("grip"),
        "{err}"
    );
}

/// A dataset names its joints; trained on with another description (a joint renamed), it is
/// refused with both lists.
#[test]
fn a_dataset_is_read_only_with_the_robot_whose_joints_it_names() {
    use selfmodel::core::preset::Preset;
    use selfmodel::data::dataset::{Dataset, DatasetConfig};
    use selfmodel::self_models::data_spec::DataSpec;
    use selfmodel::sim::robots::RobotSpec;
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 3, false);
    let spec = |path: std::path::PathBuf| RobotSpec::Urdf {
        path,
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: None,
        geometry: GeometryKind::Visual,
        joints: Default::default(),
    };
    let robot = spec(urdf.clone()).load().unwrap();
    let mut cfg = DatasetConfig::quick();
    cfg.framing = Some(Default::default());
    let data = Dataset::generate(&robot, &cfg, None).unwrap();
    assert_eq!(data.joint_names, ["j1", "j2", "j3"]);
    let file = dir.path().join("d.npz");
    data.save(&file).unwrap();
    let mut same = DataSpec::quick();
    same.file = Some(file.clone());
    same.robot = spec(urdf);
    same.load_with_robot().unwrap();
    let renamed = dir.path().join("renamed.urdf");
    std::fs::write(
        &renamed,
        common::arm_urdf(3, false).replace("\"j2\"", "\"elbow\""),
    )
    .unwrap();
    let mut other = same.clone();
    other.robot = spec(renamed);
    let err = other.load_with_robot().unwrap_err().to_string();
    assert!(
        err.contains("[j1, j2, j3]") && err.contains("[j1, elbow, j3]"),
        "{err}"
    );
}

/// `--group NAME`: a planning group of the SRDF file beside the URDF (MoveIt's format) names
/// the joint vector (chains, links, joints, subgroups) and its tips; the file is found beside
/// the URDF, and a missing group, a cycle or a missing file is one line that says what to do.
#[test]
fn srdf_groups_name_the_joint_vector_and_its_tips() {
    use selfmodel::sim::kinematics::JointGroup;
    use selfmodel::sim::srdf::find_beside;
    use selfmodel::sim::urdf_loader::{GeometryKind, UrdfOptions, load_urdf_with};
    let dir = common::tempdir();
    let path = dir.path().join("two_arms.urdf");
    std::fs::write(&path, common::two_armed_urdf()).unwrap();
    // No SRDF yet: --group says where it looked and how to give one.
    let err = find_beside(&path).unwrap_err().to_string();
    assert!(
        err.contains("no SRDF file") && err.contains("`srdf`"),
        "{err}"
    );
    let srdf = dir.path().join("two_arms.srdf");
    std::fs::write(
        &srdf,
        r#"<?xml version="1.0"?>
<robot name="two_arms">
  <virtual_joint name="world_joint" type="fixed" parent_frame="world" child_link="base"/>
  <group name="left_arm"><chain base_link="torso" tip_link="left_hand"/></group>
  <group name="right_arm"><chain base_link="torso" tip_link="right_hand"/></group>
  <group name="trunk"><joint name="world_joint"/><joint name="waist"/></group>
  <group name="arms"><group name="right_arm"/><group name="trunk"/><group name="left_arm"/></group>
  <group name="hand"><link name="finger"/></group>
  <group name="loop"><group name="loop"/></group>
  <group_state name="home" group="arms"><joint name="waist" value="0"/></group_state>
  <disable_collisions link1="base" link2="torso" reason="Adjacent"/>
</robot>"#,
    )
    .unwrap();
    assert_eq!(find_beside(&path).unwrap(), srdf);
    let load = |group: &str| {
        load_urdf_with(
            &path,
            &UrdfOptions {
                geometry: GeometryKind::None,
                joints: JointGroup::Srdf {
                    file: srdf.clone(),
                    group: group.into(),
                },
                ..UrdfOptions::default()
            },
        )
    };
    // One chain: its joints (the fixed wrist skipped), its tip link the tip.
    let left = load("left_arm").unwrap();
    assert_eq!(left.chain.joint_names(), ["l1", "l2"]);
    assert_eq!(left.chain.tip_names(), ["left_hand"]);
    // Subgroups: the union in the tree's depth-first order, both chains' tips.
    let arms = load("arms").unwrap();
    assert_eq!(arms.chain.joint_names(), ["waist", "r1", "r2", "l1", "l2"]);
    assert_eq!(arms.chain.tip_names(), ["right_hand", "left_hand"]);
    // The same joints as --tips gives, and the same hands' poses.
    let tips = load_urdf_with(
        &path,
        &UrdfOptions {
            geometry: GeometryKind::None,
            joints: JointGroup::Tips(vec!["right_hand".into(), "left_hand".into()]),
            ..UrdfOptions::default()
        },
    )
    .unwrap();
    let q = [0.3, -0.2, 0.5, 0.1, -0.4];
    assert_eq!(tips.chain.joint_names(), arms.chain.joint_names());
    for ((a, pa), (b, pb)) in arms.chain.tips().into_iter().zip(tips.chain.tips()) {
        let fa = arms.chain.link_frames(&q)[a] * pa;
        let fb = tips.chain.link_frames(&q)[b] * pb;
        assert!((fa - fb).norm() < 1e-12);
    }
    // A link: the joint that moves it.
    assert_eq!(load("hand").unwrap().chain.joint_names(), ["grip"]);
    let err = load("legs").unwrap_err().to_string();
    assert!(
        err.contains("\"legs\" is not a group") && err.contains("left_arm, right_arm, trunk"),
        "{err}"
    );
    let err = load("loop").unwrap_err().to_string();
    assert!(err.contains("cycle"), "{err}");
    // A second SRDF beside it: the user chooses.
    std::fs::copy(&srdf, dir.path().join("other.srdf")).unwrap();
    let err = find_beside(&path).unwrap_err().to_string();
    assert!(
        err.contains("several SRDF files") && err.contains("`srdf`"),
        "{err}"
    );
}
