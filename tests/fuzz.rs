//! Bounded fuzzing (stable Rust, seeded, no extra crate): valid inputs of the targets CSV
//! reader, the URDF loader, the SRDF reader, the saved IK model loader, a saved
//! self-model's `model.json`, and the collision work's readers (a cuRobo scene, a spheres
//! file, the collision model kept beside an IK model), mutated thousands of times (bytes
//! flipped, dropped, repeated, spliced with tokens a parser trips on), must each be read or
//! refused with one line: never a panic, never a hang. Each target runs for a bounded time.

mod common;

use std::time::{Duration, Instant};

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// How long each target is fuzzed (more mutations on a faster machine, the same seeds).
const BUDGET: Duration = Duration::from_secs(15);

/// Tokens that have broken parsers before: huge and odd numbers, separators, markup.
const TOKENS: &[&str] = &[
    "1e308",
    "-1e308",
    "1e39",
    "NaN",
    "inf",
    "-0",
    "0",
    "18446744073709551615",
    "-1",
    ",",
    "\n",
    "\r\n",
    "\"",
    "<",
    ">",
    "/>",
    "<link name=\"x\"/>",
    "<joint",
    "</robot>",
    "<!--",
    "-->",
    "\u{feff}",
    "\u{0}",
    "{",
    "}",
    "[",
    "]",
    ":",
    "null",
    "true",
    "é",
    "<g>",
];

/// One mutation of `input`.
fn mutate(input: &[u8], rng: &mut StdRng) -> Vec<u8> {
    let mut out = input.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        let at = if out.is_empty() {
            0
        } else {
            rng.random_range(0..out.len())
        };
        match rng.random_range(0..5) {
            0 if !out.is_empty() => out[at] ^= 1 << rng.random_range(0..8),
            1 if !out.is_empty() => {
                let end = (at + rng.random_range(1..16)).min(out.len());
                out.drain(at..end);
            }
            2 => {
                let t = TOKENS[rng.random_range(0..TOKENS.len())];
                out.splice(at..at, t.bytes());
            }
            3 if !out.is_empty() => {
                let end = (at + rng.random_range(1..64)).min(out.len());
                let piece = out[at..end].to_vec();
                out.splice(at..at, piece);
            }
            _ => out.truncate(at),
        }
    }
    out
}

/// Run `check` on mutations of `seed_input` for [`BUDGET`]; every call must return (a panic
/// fails the test, naming the input); an error must be one line. Returns (inputs, accepted).
fn fuzz(
    name: &str,
    seed_input: &[u8],
    mut check: impl FnMut(&[u8]) -> Result<(), String>,
) -> (usize, usize) {
    let mut rng = StdRng::seed_from_u64(0xF022);
    let start = Instant::now();
    let (mut tried, mut accepted) = (0, 0);
    check(seed_input).unwrap_or_else(|e| panic!("{name}: the valid input is refused: {e}"));
    while start.elapsed() < BUDGET {
        let input = mutate(seed_input, &mut rng);
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(&input)));
        match outcome {
            Err(_) => panic!(
                "{name}: panicked on input {tried}: {:?}",
                String::from_utf8_lossy(&input)
            ),
            Ok(Ok(())) => accepted += 1,
            Ok(Err(msg)) => assert!(
                !msg.trim().is_empty() && !msg.trim().contains('\n'),
                "{name}: not one line: {msg:?}"
            ),
        }
        tried += 1;
    }
    eprintln!("{name}: {tried} mutated inputs, {accepted} accepted, the rest refused in one line");
    (tried, accepted)
}

#[test]
fn the_targets_reader_reads_or_refuses_every_mutation() {
    use selfmodel::ik::solve::learned::read_targets;
    let dir = common::tempdir();
    let path = dir.path().join("t.csv");
    let tips = ["left".to_string(), "right".to_string()];
    let one = "x,y,z,qw,qx,qy,qz,q1\n0.1,0.2,0.3,1,0,0,0,5\n0.4,-0.2,0.1,0.7071,0.7071,0,0,6\n";
    let two = "left.x,left.y,left.z,left.qw,left.qx,left.qy,left.qz,right.x,right.y,right.z,right.qw,right.qx,right.qy,right.qz\n0.1,0.2,0.3,1,0,0,0,0.1,-0.2,0.3,0,1,0,0\n";
    for (name, text, tips) in [
        ("targets (one tip)", one, &[][..]),
        ("targets (two tips)", two, &tips[..]),
    ] {
        let (tried, _) = fuzz(name, text.as_bytes(), |bytes| {
            std::fs::write(&path, bytes).unwrap();
            read_targets(&path, false, tips)
                .map(|t| {
                    assert!(t.iter().flatten().all(|p| p.position.coords.amax() <= 1e3));
                })
                .map_err(|e| e.to_string())
        });
        assert!(tried > 100, "{name}: only {tried} inputs");
    }
}

#[test]
fn the_urdf_loader_reads_or_refuses_every_mutation() {
    use selfmodel::sim::urdf_loader::{GeometryKind, UrdfOptions, load_urdf_with};
    let dir = common::tempdir();
    let path = dir.path().join("r.urdf");
    let (tried, accepted) = fuzz("URDF", common::two_armed_urdf().as_bytes(), |bytes| {
        std::fs::write(&path, bytes).unwrap();
        load_urdf_with(
            &path,
            &UrdfOptions {
                geometry: GeometryKind::Visual,
                ..UrdfOptions::default()
            },
        )
        .map(|robot| {
            // What loads is usable: finite poses at the middle of the ranges.
            let q: Vec<f64> = robot
                .chain
                .joint_ranges()
                .iter()
                .map(|[lo, hi]| (lo + hi) / 2.0)
                .collect();
            assert!(
                robot
                    .chain
                    .link_frames(&q)
                    .iter()
                    .all(|f| { f.translation.vector.iter().all(|v| v.is_finite()) })
            );
        })
        .map_err(|e| e.to_string())
    });
    assert!(
        tried > 100 && accepted > 0,
        "{tried} inputs, {accepted} accepted"
    );
}

#[test]
fn the_saved_model_loader_reads_or_refuses_every_mutation() {
    use selfmodel::core::preset::Preset;
    use selfmodel::ik::solve::learned::{LearnedIk, LearnedIkConfig, train};
    use selfmodel::ik::solve::solver::IkSolver;
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", 3, false);
    let spec = selfmodel::sim::robots::RobotSpec::Urdf {
        path: urdf,
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: None,
        geometry: selfmodel::sim::urdf_loader::GeometryKind::None,
        joints: Default::default(),
    };
    let robot = spec.load_kinematics().unwrap();
    let mut cfg = LearnedIkConfig::quick();
    cfg.data.samples = 600;
    cfg.data.train = 500;
    cfg.flow.fit.epochs = 1;
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let model = dir.path().join("model");
    train(&spec, &robot, &cfg, &model, &device).unwrap();
    let json = std::fs::read(model.join("model.json")).unwrap();
    let weights = std::fs::read(model.join("model.bpk")).unwrap();
    let target =
        selfmodel::ik::solve::levenberg_marquardt::PoseTarget::of(&robot.chain, &[0.1, -0.2, 0.3]);
    let use_model = |m: &LearnedIk| {
        // What loads answers within its ranges, or is refused for another robot.
        if m.check_robot(&robot).is_ok() {
            let a = m
                .solve(
                    &robot.chain,
                    std::slice::from_ref(&target),
                    1,
                    &m.answering(),
                )
                .unwrap();
            assert!(selfmodel::sim::kinematics::within(
                &a[0][0].joints,
                &m.saved.ranges,
                1e-9
            ));
        }
    };
    fuzz("model.json", &json, |bytes| {
        std::fs::write(model.join("model.json"), bytes).unwrap();
        LearnedIk::load(&model, &device)
            .map(|m| use_model(&m))
            .map_err(|e| e.to_string())
    });
    std::fs::write(model.join("model.json"), &json).unwrap();
    fuzz("model.bpk", &weights, |bytes| {
        std::fs::write(model.join("model.bpk"), bytes).unwrap();
        LearnedIk::load(&model, &device)
            .map(|m| use_model(&m))
            .map_err(|e| e.to_string())
    });
}

/// An SRDF with nested groups, chains, single joints and links, mutated: parsed and every
/// group resolved on the robot's tree, or refused in one line.
#[test]
fn the_srdf_reader_reads_or_refuses_every_mutation() {
    use selfmodel::sim::srdf::Srdf;
    let tree: Vec<(String, String, String)> = ["base", "a", "b", "c", "d"]
        .windows(2)
        .enumerate()
        .map(|(i, w)| (format!("j{i}"), w[0].to_string(), w[1].to_string()))
        .collect();
    let text = r#"<?xml version="1.0"?>
<robot name="r">
  <group name="arm"><chain base_link="base" tip_link="c"/></group>
  <group name="wrist"><joint name="j3"/></group>
  <group name="all"><group name="arm"/><group name="wrist"/></group>
  <group name="links"><link name="b"/><link name="d"/></group>
  <group_state name="home" group="arm"><joint name="j0" value="0"/></group_state>
  <disable_collisions link1="a" link2="b" reason="Adjacent"/>
</robot>
"#;
    let path = std::path::Path::new("robot.srdf");
    let (tried, accepted) = fuzz("SRDF", text.as_bytes(), |bytes| {
        let text = String::from_utf8_lossy(bytes);
        let srdf = Srdf::parse(path, &text).map_err(|e| e.to_string())?;
        for name in srdf.group_names() {
            // A group that resolves names joints of the tree only.
            if let Ok(members) = srdf.resolve(name, &tree) {
                assert!(
                    members
                        .joints
                        .iter()
                        .all(|j| tree.iter().any(|t| &t.0 == j))
                );
            }
        }
        Ok(())
    });
    assert!(
        tried > 100 && accepted > 0,
        "{tried} inputs, {accepted} accepted"
    );
}

/// A saved self-model's `model.json` (NeuroKin, two training steps), mutated: loaded and
/// predicting finite images of its own size, or refused in one line.
#[test]
fn the_saved_self_model_loader_reads_or_refuses_every_mutation() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::harness::run;
    use selfmodel::self_models::loading::load;
    use selfmodel::self_models::neurokin::neurokin_run;
    let mut cfg = neurokin_run("quick").unwrap();
    cfg.train.steps = 2;
    cfg.train.checkpoint_every = 0;
    let dir = common::tempdir();
    run(&cfg, dir.path(), DeviceChoice::Cpu, false).unwrap();
    let device = selfmodel::core::device::select(DeviceChoice::Cpu).unwrap();
    // The run saves its model in `model/` (what `loading::load` finds from the run's folder).
    let path = dir.path().join("model").join("model.json");
    let json = std::fs::read(&path).unwrap();
    fuzz("self-model model.json", &json, |bytes| {
        std::fs::write(&path, bytes).unwrap();
        let model = load(dir.path(), &device).map_err(|e| e.to_string())?;
        let n = 2;
        let poses = vec![0.1f32; n * model.saved.inputs];
        let (silhouettes, _) = model.predict(&poses, n).map_err(|e| e.to_string())?;
        assert!(silhouettes.iter().all(|v| v.is_finite()));
        Ok(())
    });
}

/// A cuRobo scene with one obstacle of each kind (a mesh among them), mutated: read with every
/// obstacle at a finite distance from the origin, or refused in one line.
#[test]
fn the_scene_reader_reads_or_refuses_every_mutation() {
    use selfmodel::sim::collision::scene::Scene;
    let dir = common::tempdir();
    std::fs::write(dir.path().join("bin.stl"), common::cube_stl_binary(0.05)).unwrap();
    let path = dir.path().join("scene.yml");
    let text = "cuboid:
  table: {dims: [2.0, 2.0, 0.2], pose: [0.0, 0.0, -0.1, 1, 0, 0, 0], color: [0.5, .nan, 0.5, 1]}
sphere:
  ball: {radius: 0.05, position: [0.5, 0.0, 0.4]}
capsule:
  bar: {radius: 0.03, base: [0, 0, 0], tip: [0, 0, 0.5], pose: [0.4, 0.3, 0, 1, 0, 0, 0]}
cylinder:
  post: {radius: 0.05, height: 0.6, pose: [0.4, -0.3, 0.3, 0.7071, 0, 0.7071, 0]}
mesh:
  bin: {file_path: bin.stl, pose: [0.6, 0, 0, 1, 0, 0, 0], scale: [1, 2, 1]}
";
    let (tried, accepted) = fuzz("scene", text.as_bytes(), |bytes| {
        let text = String::from_utf8_lossy(bytes);
        let scene = Scene::parse(&path, &text).map_err(|e| e.to_string())?;
        let origin = nalgebra::Point3::origin();
        assert!(
            scene
                .obstacles
                .iter()
                .all(|(_, o)| o.distance(&origin).is_finite())
        );
        Ok(())
    });
    assert!(
        tried > 100 && accepted > 0,
        "{tried} inputs, {accepted} accepted"
    );
}

/// A cuRobo spheres file, mutated: read with finite spheres of links the robot has, or
/// refused in one line.
#[test]
fn the_spheres_reader_reads_or_refuses_every_mutation() {
    use selfmodel::sim::collision::user_spheres;
    let dir = common::tempdir();
    let path = dir.path().join("spheres.yml");
    let links: Vec<String> = ["base", "l1", "l2", "hand"].map(String::from).to_vec();
    let text = "robot_cfg:
  kinematics:
    collision_spheres:
      l1:
        - {center: [0, 0, 0.02], radius: 0.03}
        - {center: [0, 0, 0.05], radius: 0.03}
      hand:
        - {center: [0.01, -0.02, 0], radius: 0.02}
        - {center: [0, 0, 0], radius: -10}
";
    let (tried, accepted) = fuzz("spheres file", text.as_bytes(), |bytes| {
        std::fs::write(&path, bytes).unwrap();
        let spheres = user_spheres::read(&path, &links).map_err(|e| e.to_string())?;
        assert_eq!(spheres.len(), links.len());
        assert!(spheres.iter().flatten().all(|s| {
            s.radius > 0.0 && s.radius <= 10.0 && s.center.iter().all(|c| c.is_finite())
        }));
        Ok(())
    });
    assert!(
        tried > 100 && accepted > 0,
        "{tried} inputs, {accepted} accepted"
    );
}

/// The collision model `ik train` keeps beside a model, mutated: read back as written (the
/// seed), ignored as another robot's, or refused in one line; never a model whose spheres
/// leave the links uncovered.
#[test]
fn the_kept_collision_model_reads_or_refuses_every_mutation() {
    use selfmodel::ik::solve::collision::{CollisionCheck, Spheres};
    use selfmodel::sim::collision::{cache, pairs::PairSampling, spheres::SphereFit};
    let dir = common::tempdir();
    let urdf = dir.path().join("arm.urdf");
    std::fs::write(&urdf, common::collision_arm_urdf()).unwrap();
    let spec = selfmodel::sim::robots::RobotSpec::Urdf {
        path: urdf,
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: Some("hand".into()),
        geometry: selfmodel::sim::urdf_loader::GeometryKind::Collision,
        joints: Default::default(),
    };
    let check = CollisionCheck::with_spheres(
        &spec,
        Spheres::Fitted(Default::default()),
        None,
        None,
        true,
        0.0,
    )
    .unwrap();
    check.keep_in(dir.path()).unwrap();
    let file = dir.path().join(cache::FILE);
    let text = std::fs::read(&file).unwrap();
    let robot = spec.load().unwrap();
    let (fit, sampling) = (SphereFit::default(), PairSampling::default());
    let key = cache::key(&robot, None, &fit, &sampling);
    let (tried, _) = fuzz("kept collision model", &text, |bytes| {
        std::fs::write(&file, bytes).unwrap();
        match cache::read(dir.path(), &key, &robot, &fit).map_err(|e| e.to_string())? {
            Some(model) => assert_eq!(model.spheres, check.model.spheres),
            None => {}
        }
        Ok(())
    });
    assert!(tried > 100, "{tried} inputs");
}
