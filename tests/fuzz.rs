//! Bounded fuzzing (stable Rust, seeded, no extra crate): valid inputs of the targets CSV
//! reader, the URDF loader and the saved-model loader, mutated thousands of times (bytes
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
    use selfmodel::ik::pose_model::read_targets;
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
    use selfmodel::ik::pose_model::{PoseModel, PoseModelConfig, train};
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
    let mut cfg = PoseModelConfig::quick();
    cfg.data.samples = 600;
    cfg.data.train = 500;
    cfg.flow.fit.epochs = 1;
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let model = dir.path().join("model");
    train(&spec, &robot, &cfg, &model, &device).unwrap();
    let json = std::fs::read(model.join("model.json")).unwrap();
    let weights = std::fs::read(model.join("model.bpk")).unwrap();
    let target = selfmodel::ik::pose::PoseTarget::of(&robot.chain, &[0.1, -0.2, 0.3]);
    let use_model = |m: &PoseModel| {
        // What loads answers within its ranges, or is refused for another robot.
        if m.check_robot(&robot).is_ok() {
            let a = m
                .solve(&robot.chain, std::slice::from_ref(&target), 1, &device)
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
        PoseModel::load(&model, &device)
            .map(|m| use_model(&m))
            .map_err(|e| e.to_string())
    });
    std::fs::write(model.join("model.json"), &json).unwrap();
    fuzz("model.bpk", &weights, |bytes| {
        std::fs::write(model.join("model.bpk"), bytes).unwrap();
        PoseModel::load(&model, &device)
            .map(|m| use_model(&m))
            .map_err(|e| e.to_string())
    });
}
