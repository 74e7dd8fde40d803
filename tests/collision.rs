//! Collision spheres fitted to the exact collision meshes, the allowed pairs (an SRDF's, or
//! computed as MoveIt computes them) and the check on configurations known to collide.

use std::path::Path;

use selfmodel::ik::solve::levenberg_marquardt::Answering;
use selfmodel::ik::solve::solver::IkSolver;
use selfmodel::sim::collision::model::CollisionModel;
use selfmodel::sim::collision::pairs::{AllowedPairs, PairSampling, Reason};
use selfmodel::sim::collision::sphere_score::score_link;
use selfmodel::sim::collision::spheres::{SphereBudget, SphereFit};
use selfmodel::sim::collision::{computed_pairs, fit_robot};
use selfmodel::sim::robot::Robot;
use selfmodel::sim::shape::Shape;
use selfmodel::sim::srdf::Srdf;
use selfmodel::sim::urdf_loader::{GeometryKind, UrdfOptions, load_urdf_with};

/// A robot description of `../shared/robots`, loaded with its collision geometry.
fn shared_robot(path: &str, tip: &str) -> Option<Robot> {
    let urdf = selfmodel_lab::workspace()
        .join("../shared/robots")
        .join(path);
    if !urdf.is_file() {
        eprintln!("skipped: {} is not beside the repository", urdf.display());
        return None;
    }
    Some(
        load_urdf_with(
            &urdf,
            &UrdfOptions {
                tip: Some(tip.into()),
                geometry: GeometryKind::Collision,
                ..UrdfOptions::default()
            },
        )
        .unwrap(),
    )
}

/// The Panda of `../shared/robots` (its hand the tip, kinematics only), or None (printed) where
/// it is not beside the repository.
fn panda_spec() -> Option<selfmodel::sim::robots::RobotSpec> {
    let path =
        selfmodel_lab::workspace().join("../shared/robots/franka_description/urdf/panda.urdf");
    if !path.is_file() {
        eprintln!("skipped: the Panda's description is not beside the repository");
        return None;
    }
    Some(selfmodel::sim::robots::RobotSpec::Urdf {
        path,
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: Some("panda_hand".into()),
        geometry: GeometryKind::None,
        joints: Default::default(),
    })
}

/// Every vertex of every link's collision mesh inside a sphere of its link, and every point
/// of its surface (sampled at 1.7 mm, points the fit never saw): coverage 100%, no slack.
fn assert_spheres_cover(robot: &Robot, fit: &SphereFit) -> usize {
    let spheres = fit_robot(robot, fit).unwrap();
    let mut total = 0;
    for (link, (geometry, s)) in robot.geometry.iter().zip(&spheres).enumerate() {
        let (shapes, name) = (geometry.shapes(), &robot.chain.links[link]);
        total += s.len();
        assert_eq!(shapes.is_empty(), s.is_empty(), "link {name}");
        for shape in shapes {
            if let Shape::Triangle(t) = shape {
                for v in t {
                    assert!(
                        s.iter().any(|s| s.contains(v, 0.0)),
                        "vertex {v} of {name} outside its spheres"
                    );
                }
            }
        }
        let Some(score) = score_link(name, shapes, s, 0.0017) else {
            continue;
        };
        assert_eq!(score.coverage_pct, 100.0, "{score:?}");
        // The fit's promise: no sphere stands farther out than its target, measured on the
        // exact surface (the cover holds each triangle whole: no samples' reach past it).
        if let SphereBudget::Protrusion { mm, .. } = fit.budget {
            assert!(
                score.protrusion_max_mm <= mm + 1e-3,
                "{name}: {score:?} past {mm} mm"
            );
        }
    }
    total
}

#[test]
fn spheres_cover_the_exact_collision_meshes_of_the_panda_the_ur5_and_the_g1() {
    let shaped = SphereFit::default();
    let bounded = SphereFit::with_budget(None, Some(20.0), false).unwrap();
    for (path, tip) in [
        ("franka_description/urdf/panda.urdf", "panda_hand"),
        ("ur_description/urdf/ur5.urdf", "tool0"),
        (
            "g1_description/urdf/g1_29dof_rev_1_0.urdf",
            "right_rubber_hand",
        ),
    ] {
        let Some(robot) = shared_robot(path, tip) else {
            continue;
        };
        let links = (robot.geometry.iter())
            .filter(|g| !g.shapes().is_empty())
            .count();
        let n = assert_spheres_cover(&robot, &shaped);
        eprintln!("{path}: {n} spheres shaped after the links");
        assert!(
            n >= links && n <= 16 * links,
            "{n} spheres on {links} links"
        );
        if path.starts_with("g1") {
            // The bounded fit of the G1's torso alone takes a minute on 2 cores: the Panda
            // and the UR5 test it.
            continue;
        }
        let m = assert_spheres_cover(&robot, &bounded);
        eprintln!("{path}: {m} spheres within 20 mm");
        assert!(m > n, "{m} spheres within 20 mm, {n} shaped");
    }
}

/// On an arm whose second link swings down onto its base, spheres fine where the links come
/// close (`--where-close`) call fewer of the configurations free on the exact shapes
/// colliding than spheres standing out the same 20 mm everywhere (by over a fifth), miss
/// none that collide, and cover every link.
#[test]
fn spheres_fine_where_links_come_close_raise_fewer_false_alarms() {
    use rand::SeedableRng;
    let dir = common::tempdir();
    let urdf = dir.path().join("swing.urdf");
    let link = |name: &str, geometry: &str, z: f64| {
        format!(
            "<link name=\"{name}\"><visual><origin xyz=\"0 0 {z}\"/><geometry>{geometry}</geometry></visual></link>"
        )
    };
    let joint = |name: &str, parent: &str, child: &str, z: f64, axis: &str| {
        format!(
            "<joint name=\"{name}\" type=\"revolute\"><parent link=\"{parent}\"/><child link=\"{child}\"/><origin xyz=\"0 0 {z}\"/><axis xyz=\"{axis}\"/><limit lower=\"-2.6\" upper=\"2.6\" effort=\"1\" velocity=\"1\"/></joint>"
        )
    };
    let text = [
        "<robot name=\"swing\">".to_string(),
        link("base", "<box size=\"0.3 0.3 0.1\"/>", 0.05),
        link("post", "<cylinder radius=\"0.03\" length=\"0.2\"/>", 0.1),
        link("swing", "<box size=\"0.06 0.06 0.3\"/>", 0.15),
        joint("turn", "base", "post", 0.1, "0 0 1"),
        joint("tilt", "post", "swing", 0.2, "0 1 0"),
        "</robot>".to_string(),
    ]
    .concat();
    std::fs::write(&urdf, text).unwrap();
    let robot = load_urdf_with(
        &urdf,
        &UrdfOptions {
            geometry: GeometryKind::Visual,
            ..UrdfOptions::default()
        },
    )
    .unwrap();
    let sampling = PairSampling {
        samples: 2_000,
        ..PairSampling::default()
    };
    let model = |close: bool| {
        let fit = SphereFit::with_budget(None, Some(20.0), close).unwrap();
        selfmodel::sim::collision::model_for(&robot, None, &fit, &sampling).unwrap()
    };
    let (uniform, close) = (model(false), model(true));
    assert_eq!(uniform.pairs, close.pairs);
    assert!(!close.pairs.is_empty());
    for (g, s) in robot.geometry.iter().zip(&close.spheres) {
        for p in selfmodel::sim::collision::spheres::surface_points(g.shapes(), 0.002) {
            assert!(s.iter().any(|x| x.contains(&p, 0.0)), "{p} uncovered");
        }
    }
    let exact = close
        .clone()
        .with_exact(selfmodel::sim::collision::exact_links(&robot), Some(0.0));
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let ranges = robot.chain.joint_ranges();
    let (mut free, mut alarms) = (0, [0, 0]);
    for _ in 0..2_000 {
        let q = selfmodel::sim::trajectory::uniform_in(&mut rng, &ranges);
        let frames = robot.chain.link_frames(&q);
        let colliding = exact.self_collides(&frames, 0.0);
        for (k, m) in [&uniform, &close].into_iter().enumerate() {
            let says = m.self_collides(&frames, 0.0);
            assert!(says || !colliding, "a collision missed at {q:?}");
            alarms[k] += usize::from(says && !colliding);
        }
        free += usize::from(!colliding);
    }
    eprintln!("{free} free; false alarms: {alarms:?} (20 mm everywhere, fine where close)");
    assert!(free > 100 && alarms[0] > 20, "{free} {alarms:?}");
    // Fine where close, the base's wide top face (close to the swinging link wherever it
    // passes) takes thousands of spheres: at 256 a link it was covered coarser than its
    // allowances asked, and raised 71 false alarms to 103.
    assert!(10 * alarms[1] < 3 * alarms[0], "{alarms:?}");
}

/// A small sphere on a swinging arm that passes through a solid box (a primitive): where it
/// lies wholly inside, the two surfaces keep apart and spheres fitted to them need not meet,
/// yet the links collide (as coal decides: a primitive is solid). The exact check agrees with
/// the sphere-in-box distance at every configuration, wholly inside included.
#[test]
fn a_link_wholly_inside_another_s_solid_box_collides() {
    use rand::SeedableRng;
    let dir = common::tempdir();
    let urdf = dir.path().join("bead.urdf");
    let (half, bead, reach) = (0.05, 0.006, 0.17);
    let text = format!(
        "<robot name=\"bead\">\
<link name=\"base\"><visual><geometry><box size=\"0.1 0.1 0.1\"/></geometry></visual></link>\
<link name=\"arm\"/>\
<link name=\"bead\"><visual><origin xyz=\"0 0 {reach}\"/><geometry><sphere radius=\"{bead}\"/></geometry></visual></link>\
<joint name=\"turn\" type=\"revolute\"><parent link=\"base\"/><child link=\"arm\"/><axis xyz=\"0 0 1\"/><limit lower=\"-2.6\" upper=\"2.6\" effort=\"1\" velocity=\"1\"/></joint>\
<joint name=\"tilt\" type=\"revolute\"><parent link=\"arm\"/><child link=\"bead\"/><origin xyz=\"0.2 0 0\"/><axis xyz=\"0 1 0\"/><limit lower=\"-2.6\" upper=\"2.6\" effort=\"1\" velocity=\"1\"/></joint>\
</robot>"
    );
    std::fs::write(&urdf, text).unwrap();
    let options = UrdfOptions {
        geometry: GeometryKind::Visual,
        ..UrdfOptions::default()
    };
    let robot = load_urdf_with(&urdf, &options).unwrap();
    let sampling = PairSampling {
        samples: 2_000,
        ..PairSampling::default()
    };
    let fit = SphereFit::with_budget(None, Some(2.0), false).unwrap();
    let model = selfmodel::sim::collision::model_for(&robot, None, &fit, &sampling).unwrap();
    assert_eq!(model.pairs.len(), 1, "the base and the bead are checked");
    let spheres = model.clone().spheres_only();
    let exact = model.with_exact(selfmodel::sim::collision::exact_links(&robot), Some(0.0));
    let bead_link = robot.chain.links.iter().position(|l| l == "bead").unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let ranges = robot.chain.joint_ranges();
    let (mut inside, mut unseen_by_spheres) = (0, 0);
    for _ in 0..4_000 {
        let q = selfmodel::sim::trajectory::uniform_in(&mut rng, &ranges);
        let frames = robot.chain.link_frames(&q);
        let c = frames[bead_link] * Point3::new(0.0, 0.0, reach);
        // The sphere-in-box signed distance (the box at the root, centred, axis-aligned).
        let d = c.coords.abs().add_scalar(-half);
        let gap = d.map(|v| v.max(0.0)).norm() + d.max().min(0.0) - bead;
        if gap.abs() < 1e-6 {
            continue;
        }
        assert_eq!(
            exact.self_collides(&frames, 0.0),
            gap < 0.0,
            "at {q:?}: gap {gap}"
        );
        if gap < -2.0 * bead {
            inside += 1;
            unseen_by_spheres += usize::from(!spheres.self_collides(&frames, 0.0));
        }
    }
    eprintln!("{inside} wholly inside, {unseen_by_spheres} of them with the spheres apart");
    assert!(
        inside > 20 && unseen_by_spheres > 0,
        "{inside} {unseen_by_spheres}"
    );
}

#[test]
fn the_allowed_pairs_read_from_an_srdf_are_the_file_s_pairs() {
    let text = r#"<robot name="r">
  <group name="arm"><chain base_link="a" tip_link="c"/></group>
  <disable_collisions link1="a" link2="b" reason="Adjacent"/>
  <disable_collisions link1="c" link2="b" reason="Never"/>
  <disable_collisions link1="a" link2="d" reason="Because"/>
</robot>"#;
    let srdf = Srdf::parse(Path::new("r.srdf"), text).unwrap();
    let allowed = AllowedPairs::from_srdf(srdf.disabled_collisions());
    let pairs: Vec<_> = allowed
        .pairs
        .iter()
        .map(|((a, b), r)| (a.as_str(), b.as_str(), *r))
        .collect();
    assert_eq!(
        pairs,
        vec![
            ("a", "b", Reason::Adjacent),
            ("a", "d", Reason::User),
            ("b", "c", Reason::Never),
        ]
    );
    assert!(allowed.allows("b", "a") && allowed.allows("c", "c") && !allowed.allows("a", "c"));
    let bad = r#"<robot name="r"><disable_collisions link1="a"/></robot>"#;
    let err = Srdf::parse(Path::new("r.srdf"), bad)
        .unwrap_err()
        .to_string();
    assert!(err.contains("link1 and link2"), "{err}");
}

#[test]
fn the_panda_folded_onto_itself_collides_and_its_home_pose_does_not() {
    let Some(robot) = shared_robot("franka_description/urdf/panda.urdf", "panda_hand") else {
        return;
    };
    let spheres = fit_robot(&robot, &SphereFit::default()).unwrap();
    let sampling = PairSampling {
        samples: 2000,
        ..PairSampling::default()
    };
    let slack = Some(0.0);
    let allowed = computed_pairs(&robot, &spheres, slack, &sampling).unwrap();
    // Every joint's parent and child are allowed, as adjacent (or for a reason found first).
    for j in &robot.chain.joints {
        assert!(allowed.allows(&robot.chain.links[j.parent], &robot.chain.links[j.child]));
    }
    let model = CollisionModel::new(&robot.chain, spheres, &allowed);
    assert!(!model.pairs.is_empty());
    // The Panda's ready pose (as its MoveIt config names it) is free with a centimetre to
    // spare; the elbow folded back until the hand meets the base is not.
    let ready = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let frames = robot.chain.link_frames(&ready[..robot.dof()]);
    assert!(
        !model.self_collides(&frames, 0.0),
        "ready pose: {:?}",
        model.colliding_pairs(&frames, 0.0)
    );
    let folded = [0.0, 1.7, 0.0, -3.0, 0.0, 0.5, 0.0];
    let frames = robot.chain.link_frames(&folded[..robot.dof()]);
    let hits = model.colliding_pairs(&frames, 0.0);
    assert!(!hits.is_empty(), "the folded arm collides with nothing");
}

mod common;

use nalgebra::Point3;
use selfmodel::sim::collision::scene::Scene;

const EVERY_KIND: &str = r#"
cuboid:
  table:
    dims: [2.0, 2.0, 0.2]   # x, y, z
    pose: [0.0, 0.0, -0.1, 1, 0, 0, 0.0]
    color: [0.6, 0.6, 0.6, 1.0]
sphere:
  ball: {radius: 0.05, position: [0.5, 0.0, 0.4]}
capsule:
  bar: {radius: 0.03, base: [0, 0, 0], tip: [0, 0, 0.5], pose: [0.4, 0.3, 0, 1, 0, 0, 0]}
cylinder:
  post: {radius: 0.05, height: 0.6, pose: [0.4, -0.3, 0.3, 0.7071068, 0, 0, 0.7071068]}
mesh:
  bin: {file_path: cube.stl, pose: [0.0, 0.8, 0.1, 1, 0, 0, 0], scale: [1, 1, 1]}
"#;

#[test]
fn a_scene_with_every_kind_of_entry_loads_and_measures_distances() {
    let dir = common::tempdir();
    std::fs::write(dir.path().join("cube.stl"), common::cube_stl_binary(0.1)).unwrap();
    let path = dir.path().join("scene.yml");
    std::fs::write(&path, EVERY_KIND).unwrap();
    let scene = Scene::read(&path).unwrap();
    let names: Vec<&str> = scene.obstacles.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["table", "ball", "bar", "post", "bin"]);
    let at = |name: &str, p: [f64; 3]| {
        let o = &scene.obstacles.iter().find(|(n, _)| n == name).unwrap().1;
        o.distance(&Point3::from(p))
    };
    // The table's top is at z = 0; inside it the distance is negative.
    assert!((at("table", [0.3, 0.2, 0.25]) - 0.25).abs() < 1e-12);
    assert!((at("table", [0.0, 0.0, -0.05]) + 0.05).abs() < 1e-12);
    assert!((at("ball", [0.5, 0.0, 0.6]) - 0.15).abs() < 1e-12);
    assert!((at("bar", [0.5, 0.3, 0.25]) - 0.07).abs() < 1e-12);
    assert!((at("bar", [0.4, 0.3, 0.7]) - 0.17).abs() < 1e-12);
    // The post stands along z (a turn about z changes nothing), its top at 0.6.
    assert!((at("post", [0.4, -0.3, 0.8]) - 0.2).abs() < 1e-9);
    assert!((at("post", [0.5, -0.3, 0.3]) - 0.05).abs() < 1e-9);
    // The mesh is covered by spheres: conservative, within the fit's tolerance plus.
    let d = at("bin", [0.0, 0.8, 0.35]);
    assert!(d <= 0.15 + 1e-9 && d > 0.05, "{d}");
    assert!(at("bin", [0.0, 0.8, 0.1]) < 0.0);
    assert!(scene.gap(&Point3::new(0.5, 0.0, 0.5), 0.04) > 0.0);
    assert!(scene.gap(&Point3::new(0.5, 0.0, 0.5), 0.06) < 0.0);
}

#[test]
fn bad_scenes_are_refused_in_one_line() {
    let dir = common::tempdir();
    let cases = [
        (
            "cuboid:\n  a: {dims: [.nan, 1, 1], pose: [0, 0, 0, 1, 0, 0, 0]}\n",
            "side (dims) of \"a\" is NaN",
        ),
        (
            "sphere:\n  s: {radius: -0.1, position: [0, 0, 0]}\n",
            "radius of \"s\" is -0.1",
        ),
        (
            "cuboid:\n  a: {dims: [1, 1, 1], pose: [0, 0, 0, 1, 0, 0, 0], mass: 2}\n",
            "mass",
        ),
        ("capsules:\n  a: {radius: 1}\n", "capsules"),
        (
            "mesh:\n  m: {file_path: nowhere.stl, pose: [0, 0, 0, 1, 0, 0, 0]}\n",
            "is not a file",
        ),
        (
            "cuboid:\n  a: {dims: [1, 1, 1], pose: [0, 0, 0, 0, 0, 0, 0]}\n",
            "no rotation",
        ),
        ("sphere:\n  s: {radius: 0.1}\n", "no pose or position"),
        ("cuboid: [1, 2\n", "not a scene"),
    ];
    for (i, (text, says)) in cases.iter().enumerate() {
        let path = dir.path().join(format!("bad{i}.yml"));
        std::fs::write(&path, text).unwrap();
        let err = Scene::read(&path).unwrap_err().to_string();
        assert!(err.contains(says), "case {i}: {err}");
        assert!(!err.contains('\n'), "case {i}: more than one line: {err}");
    }
}

#[test]
fn the_panda_clears_a_table_below_it_and_hits_a_box_at_its_hand() {
    let Some(robot) = shared_robot("franka_description/urdf/panda.urdf", "panda_hand") else {
        return;
    };
    let spheres = fit_robot(&robot, &SphereFit::default()).unwrap();
    let allowed = computed_pairs(
        &robot,
        &spheres,
        Some(0.0),
        &PairSampling {
            samples: 500,
            ..PairSampling::default()
        },
    )
    .unwrap();
    let model = CollisionModel::new(&robot.chain, spheres, &allowed);
    assert!(!model.moving[0], "the Panda's base does not move");
    let ready = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let frames = robot.chain.link_frames(&ready);
    let table = Scene::parse(
        Path::new("table.yml"),
        "cuboid:\n  table: {dims: [2, 2, 0.2], pose: [0, 0, -0.1, 1, 0, 0, 0]}\n",
    )
    .unwrap();
    assert!(!model.collides(&frames, Some(&table), 0.0));
    let hand = frames[robot
        .chain
        .links
        .iter()
        .position(|l| l == "panda_hand")
        .unwrap()]
    .translation;
    let text = format!(
        "cuboid:\n  table: {{dims: [2, 2, 0.2], pose: [0, 0, -0.1, 1, 0, 0, 0]}}\n  box: {{dims: [0.05, 0.05, 0.05], pose: [{}, {}, {}, 1, 0, 0, 0]}}\n",
        hand.x, hand.y, hand.z
    );
    let with_box = Scene::parse(Path::new("box.yml"), &text).unwrap();
    assert!(model.collides(&frames, Some(&with_box), 0.0));
    assert!(model.clearance(&frames, Some(&with_box), 1.0) < 0.0);
}

/// Collision-free IK on the Panda with a table and a box: answers that collide are never
/// exact, and the targets drawn collision-free are answered exactly and collision-free.
#[test]
fn collision_free_ik_on_the_panda_answers_without_touching_the_scene() {
    use selfmodel::ik::solve::collision::CollisionCheck;
    use selfmodel::ik::solve::levenberg_marquardt::PoseTarget;
    let Some(spec) = panda_spec() else {
        return;
    };
    let dir = common::tempdir();
    let robot = spec.load_kinematics().unwrap();
    let model = common::quick_pose_model(&spec, &robot, dir.path());
    let scene = Scene::parse(
        Path::new("scene.yml"),
        "cuboid:\n  table: {dims: [2, 2, 0.2], pose: [0, 0, -0.1, 1, 0, 0, 0]}\n  box: {dims: [0.1, 0.1, 0.3], pose: [0.45, 0.3, 0.15, 1, 0, 0, 0]}\n",
    )
    .unwrap();
    let check = CollisionCheck::for_robot(&spec, None, Some(scene), true, 0.005).unwrap();
    let free: Vec<Vec<f64>> = selfmodel::sim::trajectory::babbling_rows(&model.saved.ranges, 4)
        .filter(|q| check.valid(q))
        .take(60)
        .collect();
    let targets: Vec<Vec<PoseTarget>> = free
        .iter()
        .map(|q| PoseTarget::of(&robot.chain, q))
        .collect();
    let lm = model.saved.config.lm.clone();
    let answers = model
        .solve(
            &robot.chain,
            &targets,
            2,
            &Answering {
                lm: &lm,
                stop: &|| false,
                avoid: Some(&check),
            },
        )
        .unwrap();
    let (mut exact, mut total) = (0, 0);
    for a in answers.iter().flatten() {
        total += 1;
        assert_eq!(
            a.collides,
            !check.valid(&a.joints),
            "the mark is the check's"
        );
        if a.exact(&lm) {
            exact += 1;
            assert!(
                check.clearance(&a.joints, 1.0) >= 0.005,
                "an exact answer collides"
            );
        }
    }
    assert!(
        exact as f64 >= 0.95 * total as f64,
        "{exact} of {total} exact and free"
    );
    // Without the check, the same solver knows nothing of the scene: no answer is marked.
    let plain = model
        .solve(
            &robot.chain,
            &targets,
            1,
            &Answering {
                stop: &|| false,
                ..Answering::with(&lm)
            },
        )
        .unwrap();
    assert!(plain.iter().flatten().all(|a| !a.collides));
}

#[test]
fn spheres_a_user_supplies_in_curobo_s_format_are_read() {
    use selfmodel::sim::collision::user_spheres;
    let dir = common::tempdir();
    let d = dir.path();
    std::fs::create_dir_all(d.join("spheres")).unwrap();
    std::fs::write(
        d.join("spheres/arm.yml"),
        "collision_spheres:\n  a:\n    - \"center\": [0.0, 0.0, 0.1]\n      \"radius\": 0.05\n    - center: [0.0, 0.0, 0.2]\n      radius: -0.01\n  c:\n    - {center: [0.1, 0, 0], radius: 0.02}\n",
    )
    .unwrap();
    // A robot file naming its spheres file, as cuRobo's configs do.
    std::fs::write(
        d.join("robot.yml"),
        "robot_cfg:\n  kinematics:\n    base_link: a\n    collision_spheres: spheres/arm.yml\n",
    )
    .unwrap();
    let links: Vec<String> = ["a", "b", "c"].map(String::from).to_vec();
    let spheres = user_spheres::read(&d.join("robot.yml"), &links).unwrap();
    assert_eq!(
        spheres[0].len(),
        1,
        "the placeholder (radius -0.01) is skipped"
    );
    assert_eq!(spheres[0][0].center, [0.0, 0.0, 0.1]);
    assert!(spheres[1].is_empty());
    assert_eq!(spheres[2][0].radius, 0.02);
    let err = user_spheres::read(&d.join("spheres/arm.yml"), &links[..2])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("\"c\", a link the robot does not have"),
        "{err}"
    );
    std::fs::write(
        d.join("none.yml"),
        "robot_cfg:\n  kinematics:\n    base_link: a\n",
    )
    .unwrap();
    let err = user_spheres::read(&d.join("none.yml"), &links)
        .unwrap_err()
        .to_string();
    assert!(err.contains("no collision_spheres block"), "{err}");
}

/// cuRobo's own Franka file (its 61 hand-placed spheres, `data/fixtures/curobo`) loads onto the
/// Panda as ROS ships it, and scored against the exact meshes it leaves part of every link
/// uncovered (its spheres are not conservative: they miss collisions), where ours cover all.
#[test]
fn curobo_s_own_franka_spheres_load_and_leave_part_of_every_link_uncovered() {
    use selfmodel::sim::collision::{sphere_score::score_robot, user_spheres};
    let urdf =
        selfmodel_lab::workspace().join("../shared/robots/franka_description/urdf/panda.urdf");
    if !urdf.is_file() {
        eprintln!("skipped: {} is not beside the repository", urdf.display());
        return;
    }
    let options = UrdfOptions {
        geometry: GeometryKind::Collision,
        ..UrdfOptions::default()
    };
    let robot = load_urdf_with(&urdf, &options).unwrap();
    let file = selfmodel_lab::workspace().join("data/fixtures/curobo/franka.yml");
    let theirs = user_spheres::read(&file, &robot.chain.links).unwrap();
    assert_eq!(theirs.iter().map(Vec::len).sum::<usize>(), 61);
    let scored = score_robot(&robot, &theirs, 0.003, "cuRobo");
    assert_eq!(scored.len(), 11, "{scored:?}");
    for s in &scored {
        assert!(s.coverage_pct < 50.0, "{s:?}");
    }
    let ours = fit_robot(&robot, &SphereFit::default()).unwrap();
    for s in score_robot(&robot, &ours, 0.003, "fitted") {
        assert_eq!(s.coverage_pct, 100.0, "{s:?}");
    }
}

/// The contacts' rows the solver pushes apart by (analytic: each link's Jacobian at its
/// sphere's centre, or at its exact closest point, along the direction apart) equal central
/// differences of the same contacts' gaps, for the Panda folded onto itself and reaching into
/// a box and a ball, on the spheres alone and on the exact shapes; and pushing a colliding
/// answer apart keeps its pose and ends collision-free.
#[test]
fn contact_rows_match_finite_differences_and_push_an_answer_apart() {
    use selfmodel::ik::solve::collision::CollisionCheck;
    use selfmodel::ik::solve::levenberg_marquardt::{LmConfig, PoseTarget, solve_from};
    let Some(spec) = panda_spec() else {
        return;
    };
    let scene = Scene::parse(
        Path::new("scene.yml"),
        "cuboid:\n  box: {dims: [0.1, 0.1, 0.3], pose: [0.45, 0.1, 0.4, 0.9238795, 0, 0.3826834, 0]}\nsphere:\n  ball: {radius: 0.06, position: [0.3, -0.2, 0.5]}\n",
    )
    .unwrap();
    let exact = CollisionCheck::for_robot(&spec, None, Some(scene), true, 0.005).unwrap();
    let spheres =
        (exact.clone()).deciding(selfmodel::sim::collision::model::CollisionMode::Spheres);
    let folded = [0.3, 1.5, 0.2, -2.9, 0.4, 0.8, 0.1];
    let reach = [0.2, 0.6, 0.0, -1.4, 0.0, 2.0, 0.7];
    let h = 1e-6;
    // Contacts compared: spheres with spheres, spheres with obstacles, links with links, and
    // links with obstacles where one keeps apart from them (an obstacle a link overlaps is
    // pushed out by the link's spheres).
    let mut compared = [0; 4];
    for (check, q) in [&spheres, &exact]
        .into_iter()
        .flat_map(|c| [(c, &folded[..]), (c, &reach[..])])
    {
        let rows = check.contact_rows(q, 0.02);
        assert!(!rows.is_empty(), "no contact at {q:?}");
        for (c, row) in &rows {
            let gap_at = |q: &[f64]| {
                let near = check.contact_rows(q, 0.05);
                near.iter()
                    .find(|(d, _)| d.contact == c.contact)
                    .unwrap()
                    .0
                    .gap
            };
            for k in 0..q.len() {
                let (mut up, mut down) = (q.to_vec(), q.to_vec());
                up[k] += h;
                down[k] -= h;
                let numeric = (gap_at(&up) - gap_at(&down)) / (2.0 * h);
                assert!(
                    (numeric - row[k]).abs() < 1e-5,
                    "{:?} joint {k}: analytic {} numeric {numeric}",
                    c.contact,
                    row[k]
                );
            }
            use selfmodel::sim::collision::contacts::Contact;
            compared[match c.contact {
                Contact::Spheres { .. } => 0,
                Contact::Obstacle { .. } => 1,
                Contact::Links { .. } => 2,
                Contact::LinkObstacle { .. } => 3,
            }] += 1;
        }
    }
    assert!(compared[..3].iter().all(|&n| n > 0), "{compared:?}");
    // A ball at the elbow of an answer whose hand is free: the solver swings the elbow out
    // of it (the Panda has one joint to spare) and keeps the hand's pose.
    let robot = spec.load_kinematics().unwrap();
    let ready = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let elbow = robot.chain.link_frames(&ready)[robot
        .chain
        .links
        .iter()
        .position(|l| l == "panda_link4")
        .unwrap()]
    .translation;
    let ball = format!(
        "sphere:\n  ball: {{radius: 0.03, position: [{}, {}, {}]}}\n",
        elbow.x, elbow.y, elbow.z
    );
    let scene = Scene::parse(Path::new("ball.yml"), &ball).unwrap();
    let check = CollisionCheck::for_robot(&spec, None, Some(scene), true, 0.005).unwrap();
    let target = PoseTarget::of(&robot.chain, &ready);
    assert!(!check.valid(&ready));
    let cfg = LmConfig::standard();
    let paths = robot.chain.tip_paths();
    let ranges = robot.chain.joint_ranges();
    let pushed = solve_from(&paths, &target, &ready, &ranges, &cfg, Some(&check));
    assert!(pushed.exact(&cfg), "{pushed:?}");
    assert!(check.valid(&pushed.joints), "{pushed:?}");
}

/// The collision model kept beside a saved model is read back as it was written, a file
/// edited by hand is refused, and a file whose key does not match the robot (another
/// description, SRDF or fit) is ignored.
#[test]
fn a_kept_collision_model_is_read_back_and_a_stale_one_ignored() {
    use selfmodel::ik::solve::collision::{CollisionCheck, Spheres};
    let Some(spec) = panda_spec() else {
        return;
    };
    let dir = common::tempdir();
    let check =
        |spheres| CollisionCheck::with_spheres(&spec, spheres, None, None, true, 0.0).unwrap();
    let fitted = check(Spheres::Fitted(Default::default()));
    fitted.keep_in(dir.path()).unwrap();
    let file = dir.path().join(selfmodel::sim::collision::cache::FILE);
    // Read back: the same spheres and pairs.
    let kept = check(Spheres::KeptIn(dir.path(), Default::default()));
    assert_eq!(kept.model.spheres, fitted.model.spheres);
    assert_eq!(kept.model.pairs, fitted.model.pairs);
    // A radius changed in it by hand: refused (its hash no longer matches), never used.
    let text = std::fs::read_to_string(&file).unwrap();
    let r = fitted.model.spheres.iter().flatten().next().unwrap().radius;
    let edited = text.replacen(&format!("\"radius\": {r}"), "\"radius\": 0.5", 1);
    assert_ne!(edited, text);
    std::fs::write(&file, &edited).unwrap();
    let Err(err) = CollisionCheck::with_spheres(
        &spec,
        Spheres::KeptIn(dir.path(), Default::default()),
        None,
        None,
        true,
        0.0,
    ) else {
        panic!("an edited collision model was used");
    };
    assert!(err.to_string().contains("cannot be used"), "{err}");
    // Another key (as another robot or SRDF would give): ignored, the spheres fitted again.
    let stale = edited.replacen("\"key\": \"", "\"key\": \"0", 1);
    std::fs::write(&file, stale).unwrap();
    let refit = check(Spheres::KeptIn(dir.path(), Default::default()));
    assert_eq!(refit.model.spheres, fitted.model.spheres);
}

/// `ik train --scene` trains on collision-free samples only (every joint sample keeps the
/// margin, where plain samples do not), says so in model.json, and keeps the collision model
/// beside the model.
#[test]
fn ik_train_with_a_scene_samples_only_collision_free_joints_and_keeps_its_spheres() {
    use selfmodel::ik::data::{IkData, IkDataConfig};
    use selfmodel::ik::solve::collision::CollisionCheck;
    let Some(spec) = panda_spec() else {
        return;
    };
    let robot = spec.load_kinematics().unwrap();
    let check = CollisionCheck::for_robot(&spec, None, None, true, 0.005).unwrap();
    let cfg = IkDataConfig {
        samples: 400,
        train: 300,
        range_deg: 180.0,
        seed: 3,
        validation: 0,
    };
    let keep = |q: &[f64]| check.valid(q);
    let free = IkData::generate_where(&robot.chain, &cfg, Some(&keep)).unwrap();
    let plain = IkData::generate(&robot.chain, &cfg).unwrap();
    assert!(free.joints.iter().all(|q| check.valid(q)));
    assert!(
        plain.joints.iter().any(|q| !check.valid(q)),
        "no plain sample collides"
    );

    let dir = common::tempdir();
    let scene = dir.path().join("table.yml");
    std::fs::write(
        &scene,
        "cuboid:\n  table: {dims: [2, 2, 0.2], pose: [0, 0, -0.1, 1, 0, 0, 0]}\n",
    )
    .unwrap();
    let out = dir.path().join("model");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_ik"))
        .args([
            "train",
            "--preset",
            "quick",
            "--tip",
            "panda_hand",
            "--geometry",
            "none",
        ])
        .arg("--urdf")
        .arg(spec.files().first().unwrap())
        .arg("--scene")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    common::assert_ok(&run);
    assert!(String::from_utf8_lossy(&run.stdout).contains("collision-free poses"));
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    assert_eq!(
        saved["config"]["collisions"]["scene"].as_str(),
        Some(scene.to_str().unwrap())
    );
    assert!(out.join(selfmodel::sim::collision::cache::FILE).is_file());
}
