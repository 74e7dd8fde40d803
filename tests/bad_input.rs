//! Bad input, round 4 (issue 59): every reader of a file a user names refuses what is not a
//! bounded regular file in one line, and the SRDF reader refuses or resolves quickly what
//! would have exhausted the stack or the machine. Each case is a row: the input, and the
//! refusal expected (a fragment of its one line).

mod common;

use std::path::Path;

use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::sim::srdf::Srdf;

/// Every reader of a user's file, on `path`: its error, one line.
fn readers(path: &Path) -> Vec<(&'static str, String)> {
    let device = select(DeviceChoice::Cpu).unwrap();
    let dir = path.parent().unwrap();
    let one_line = |r: Result<String, selfmodel::core::error::Error>| match r {
        Ok(what) => format!("accepted: {what}"),
        Err(e) => e.to_string(),
    };
    vec![
        (
            "--targets",
            one_line(
                selfmodel::ik::solve::learned::read_targets(path, false, &["tool".into()])
                    .map(|t| format!("{} targets", t.len())),
            ),
        ),
        (
            "--angles",
            one_line(
                selfmodel::data::dataset::read_angles(path, 4).map(|a| format!("{} rows", a.len())),
            ),
        ),
        (
            ".npz",
            one_line(selfmodel::data::npz::read_npz(path).map(|a| format!("{} arrays", a.len()))),
        ),
        (
            "--srdf",
            one_line(Srdf::read(path).map(|s| format!("{:?}", s.group_names()))),
        ),
        (
            "model.json of an IK model",
            one_line(
                selfmodel::ik::solve::learned::LearnedIk::load(dir, &device)
                    .map(|_| "a model".into()),
            ),
        ),
        (
            "model.json of a self-model",
            one_line(selfmodel::self_models::loading::load(dir, &device).map(|_| "a model".into())),
        ),
    ]
}

fn assert_refused(cases: Vec<(&'static str, String)>, expected: &str) {
    for (reader, err) in cases {
        eprintln!("{reader}: {err}");
        assert!(
            err.contains(expected) && !err.contains('\n'),
            "{reader}: {err:?} (expected one line with {expected:?})"
        );
    }
}

#[cfg(unix)]
#[test]
fn every_reader_refuses_a_fifo_and_a_device_without_blocking() {
    let dir = common::tempdir();
    for name in ["model.json", "targets.csv"] {
        let fifo = dir.path().join(name);
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
    }
    // Nothing writes to the FIFOs: a reader that opened one would block this test forever.
    assert_refused(
        readers(&dir.path().join("targets.csv")),
        "not a regular file",
    );
    // The readers of a file named as such (the model readers take a folder).
    let named = readers(Path::new("/dev/zero"))
        .into_iter()
        .filter(|(reader, _)| !reader.starts_with("model.json"))
        .collect();
    assert_refused(named, "not a regular file");
}

#[test]
fn every_reader_refuses_a_folder() {
    let dir = common::tempdir();
    let folder = dir.path().join("model.json");
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::create_dir_all(dir.path().join("model.bpk")).unwrap();
    assert_refused(readers(&folder), "a folder");
}

/// An SRDF of `groups` (each `(name, body)`), around the robot element.
fn srdf(groups: &[(String, String)]) -> String {
    let mut text = String::from("<?xml version=\"1.0\"?>\n<robot name=\"r\">\n");
    for (name, body) in groups {
        text += &format!("<group name=\"{name}\">{body}</group>\n");
    }
    text + "</robot>\n"
}

/// A three-joint chain `base - a - b - c`.
fn tree() -> Vec<(String, String, String)> {
    ["base", "a", "b", "c"]
        .windows(2)
        .enumerate()
        .map(|(i, w)| (format!("j{i}"), w[0].to_string(), w[1].to_string()))
        .collect()
}

#[test]
fn srdf_groups_that_would_explode_or_overflow_are_resolved_or_refused() {
    let path = Path::new("robot.srdf");
    // Each of 40 levels lists the level below twice: 2^40 visits expanded naively.
    let mut groups: Vec<(String, String)> = (0..40)
        .map(|i| {
            let below = format!("level{}", i + 1);
            (
                format!("level{i}"),
                format!("<group name=\"{below}\"/><group name=\"{below}\"/>"),
            )
        })
        .collect();
    groups.push(("level40".into(), "<joint name=\"j1\"/>".into()));
    let t0 = std::time::Instant::now();
    let members = Srdf::parse(path, &srdf(&groups))
        .unwrap()
        .resolve("level0", &tree())
        .unwrap();
    assert_eq!(members.joints, ["j1"]);
    assert!(t0.elapsed().as_secs_f64() < 1.0, "{:?}", t0.elapsed());

    // 100,000 groups each listing the next: refused at a stated depth, not a stack overflow.
    let chain: Vec<(String, String)> = (0..100_000)
        .map(|i| (format!("g{i}"), format!("<group name=\"g{}\"/>", i + 1)))
        .chain([("g100000".to_string(), "<joint name=\"j0\"/>".to_string())])
        .collect();
    let err = Srdf::parse(path, &srdf(&chain))
        .unwrap()
        .resolve("g0", &tree())
        .unwrap_err()
        .to_string();
    assert!(err.contains("nested more than"), "{err}");

    // Elements nested 100,000 deep: refused before the parser recurses.
    let deep = format!(
        "<robot name=\"r\">{}{}</robot>",
        "<group name=\"g\">".repeat(100_000),
        "</group>".repeat(100_000)
    );
    let err = Srdf::parse(path, &deep).unwrap_err().to_string();
    assert!(err.contains("nest 100001 deep"), "{err}");

    // A group defined twice: which one MoveIt would take is not ours to guess.
    let twice = srdf(&[
        ("arm".into(), "<joint name=\"j0\"/>".into()),
        ("arm".into(), "<joint name=\"j1\"/>".into()),
    ]);
    let err = Srdf::parse(path, &twice).unwrap_err().to_string();
    assert!(err.contains("defined twice"), "{err}");
}

/// A chain whose base is not above its tip (iCub's `chest` -> `l_sole`) resolves as MoveIt
/// (KDL) resolves it, through the two links' common ancestor: the joints from the base up to
/// it, then down to the tip.
#[test]
fn an_srdf_chain_through_a_common_ancestor_is_resolved() {
    let path = Path::new("robot.srdf");
    // waist -> torso (t0) -> chest (t1); waist -> hip (h0) -> knee (h1) -> sole (h2).
    let tree: Vec<(String, String, String)> = [
        ("t0", "waist", "torso"),
        ("t1", "torso", "chest"),
        ("h0", "waist", "hip"),
        ("h1", "hip", "knee"),
        ("h2", "knee", "sole"),
    ]
    .iter()
    .map(|(j, p, c)| (j.to_string(), p.to_string(), c.to_string()))
    .collect();
    let text = srdf(&[(
        "leg".into(),
        "<chain base_link=\"chest\" tip_link=\"sole\"/>".into(),
    )]);
    let members = Srdf::parse(path, &text)
        .unwrap()
        .resolve("leg", &tree)
        .unwrap();
    assert_eq!(members.joints, ["t1", "t0", "h0", "h1", "h2"]);
    assert_eq!(members.tips, ["sole"]);
    // Down from the base as before.
    let text = srdf(&[(
        "leg".into(),
        "<chain base_link=\"waist\" tip_link=\"sole\"/>".into(),
    )]);
    let members = Srdf::parse(path, &text)
        .unwrap()
        .resolve("leg", &tree)
        .unwrap();
    assert_eq!(members.joints, ["h0", "h1", "h2"]);
}

/// A description with collision geometry only is refused for drawing with a hint to draw
/// its collision geometry, which then loads.
#[test]
fn a_collision_only_robot_says_which_geometry_draws_it() {
    use selfmodel::sim::urdf_loader::{GeometryKind, UrdfOptions, load_urdf_with};
    let dir = common::tempdir();
    let urdf = dir.path().join("r.urdf");
    std::fs::write(
        &urdf,
        r#"<robot name="r"><link name="base"><collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
<link name="arm"><collision><geometry><cylinder radius="0.02" length="0.3"/></geometry></collision></link>
<joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"#,
    )
    .unwrap();
    let load = |geometry| {
        load_urdf_with(
            &urdf,
            &UrdfOptions {
                geometry,
                ..UrdfOptions::default()
            },
        )
    };
    let e = load(GeometryKind::Visual).err().unwrap().to_string();
    assert!(
        e.contains("`geometry` collision")
            && selfmodel_lab::cli::in_flags(&e).contains("--geometry collision")
            && !e.contains('\n'),
        "{e}"
    );
    assert!(load(GeometryKind::Collision).unwrap().shape_count() > 0);
    assert_eq!(load(GeometryKind::None).unwrap().dof(), 1);
}

/// `dataset --out` naming one of its inputs (the URDF, the angles) is refused in one line,
/// and the input is left as it was.
#[test]
fn dataset_never_writes_over_its_inputs() {
    let dir = common::tempdir();
    let urdf = dir.path().join("arm.urdf");
    std::fs::write(&urdf, common::arm_urdf(3, false)).unwrap();
    let angles = dir.path().join("angles.csv");
    std::fs::write(&angles, "0,0,0\n10,20,30\n").unwrap();
    let urdf_s = urdf.to_str().unwrap();
    let angles_s = angles.to_str().unwrap();
    for (out, args) in [
        (urdf_s, vec!["--urdf", urdf_s]),
        (angles_s, vec!["--urdf", urdf_s, "--angles", angles_s]),
    ] {
        let before = std::fs::read(out).unwrap();
        let mut all = args.clone();
        all.extend(["--preset", "quick", "--out", out]);
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_dataset"))
            .args(&all)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        eprintln!("dataset {}: {err}", all.join(" "));
        assert!(!run.status.success(), "{all:?}: exit 0");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("is the file it reads"), "{err}");
        assert_eq!(std::fs::read(out).unwrap(), before, "{out} changed");
    }
}

/// Ctrl-C stops every long command within a second or two, in whichever phase it is (drawing,
/// reading a big file, rendering, solving, writing): exit 130, one line, no file left.
#[cfg(unix)]
#[test]
fn ctrl_c_stops_every_long_command_within_seconds_and_leaves_nothing() {
    let dir = common::tempdir();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let ik = env!("CARGO_BIN_EXE_ik");
    let dataset = env!("CARGO_BIN_EXE_dataset");
    let urdf = common::write_arm(dir.path(), "arm", 6, false);
    let run = |args: &[&str]| {
        let out = std::process::Command::new(ik).args(args).output().unwrap();
        common::assert_ok(&out);
    };
    run(&[
        "train",
        "--urdf",
        urdf.to_str().unwrap(),
        "--tip",
        "l6",
        "--preset",
        "quick",
        "--out",
        &d("model"),
    ]);
    run(&[
        "targets",
        "--model",
        &d("model"),
        "--n",
        "400000",
        "--out",
        &d("targets.csv"),
    ]);
    let inputs = ["arm.urdf", "model", "targets.csv"];
    let (model, targets) = (d("model"), d("targets.csv"));
    let solve = vec![
        "solve",
        "--model",
        &model,
        "--targets",
        &targets,
        "--out",
        "a.csv",
    ];
    let cases: Vec<(&str, &str, Vec<&str>, f64)> = vec![
        (
            "dataset, rendering",
            dataset,
            vec!["--samples", "20000", "--out", "big.npz"],
            1.0,
        ),
        // 20,000 images of 100x100 render in about 2 s and compress in about 5 on 2 cores:
        // by 4.5 s most machines are writing.
        (
            "dataset, writing",
            dataset,
            vec!["--samples", "20000", "--out", "big.npz"],
            4.5,
        ),
        (
            "ik targets, ten million rows",
            ik,
            vec![
                "targets", "--model", &model, "--n", "10000000", "--out", "t.csv",
            ],
            1.0,
        ),
        ("ik solve, reading its targets", ik, solve.clone(), 0.2),
        ("ik solve, solving", ik, solve, 3.0),
    ];
    // The outputs named in the dataset's folder.
    let cases = cases
        .into_iter()
        .map(|(name, binary, args, after)| {
            let args: Vec<String> = args
                .iter()
                .map(|a| {
                    if a.ends_with(".npz") || *a == "t.csv" || *a == "a.csv" {
                        d(a)
                    } else {
                        a.to_string()
                    }
                })
                .collect();
            (name, binary, args, after)
        })
        .collect();
    let failures = common::ctrl_c_failures(dir.path(), &inputs, cases, 2.0);
    assert!(failures.is_empty(), "{failures:#?}");
}

/// `--tip` beside `--tips` (or a group's tips) must be one of them: another would train the
/// group's joints for a link they were not chosen for.
#[test]
fn a_tip_outside_the_named_tips_is_refused() {
    use selfmodel::sim::kinematics::JointGroup;
    use selfmodel::sim::robots::RobotSpec;
    let dir = common::tempdir();
    let urdf = dir.path().join("arm.urdf");
    std::fs::write(&urdf, common::arm_urdf(4, true)).unwrap();
    let spec = |tip: &str| RobotSpec::Urdf {
        path: urdf.clone(),
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: Some(tip.into()),
        geometry: selfmodel::sim::urdf_loader::GeometryKind::None,
        joints: JointGroup::Tips(vec!["l2".into(), "finger_a".into()]),
    };
    let err = spec("l3").load_kinematics().unwrap_err().to_string();
    assert!(
        err.contains("is not a tip of `tips` (l2, finger_a)")
            && selfmodel_lab::cli::in_flags(&err).contains("is not a tip of --tips (l2, finger_a)"),
        "{err}"
    );
    // One of them is the tip the poses are read at.
    assert!(spec("finger_a").load_kinematics().is_ok());
}

/// A dataset larger than this machine can hold while it is built and saved (but within the
/// configuration's own 8 GiB limit) is refused in one line before a pixel is rendered, not an
/// abort allocating.
#[cfg(target_os = "linux")]
#[test]
fn a_dataset_beyond_the_machines_memory_is_refused_at_once() {
    let available = selfmodel::core::memory::available_bytes().unwrap();
    // Images of 200x200: 15 bytes a pixel at the peak, 5 counted by the configuration.
    let pixels = 200 * 200;
    let samples = available / (15 * pixels) + 100;
    if samples * pixels * 5 > 8 << 30 {
        eprintln!("this machine holds more than the configuration's limit: nothing to check");
        return;
    }
    let dir = common::tempdir();
    let out = dir.path().join("huge.npz");
    let t0 = std::time::Instant::now();
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_dataset"))
        .args(["--samples", &samples.to_string(), "--size", "200"])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    eprintln!("{samples} samples: {err}");
    assert!(!run.status.success());
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("GiB available") && err.contains("lower --samples"),
        "{err}"
    );
    assert!(t0.elapsed().as_secs_f64() < 5.0);
    assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
}

/// A one-link robot whose link's visual is `geometry`, written as `pkg/urdf/robot.urdf`.
fn one_link(dir: &Path, geometry: &str) -> std::path::PathBuf {
    let urdf = dir.join("pkg").join("urdf").join("robot.urdf");
    std::fs::create_dir_all(urdf.parent().unwrap()).unwrap();
    let text = format!(
        "<robot name=\"r\"><link name=\"base\"/><link name=\"l1\"><visual><geometry>{geometry}</geometry></visual></link>\
         <joint name=\"j1\" type=\"revolute\"><parent link=\"base\"/><child link=\"l1\"/><axis xyz=\"0 0 1\"/>\
         <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint></robot>"
    );
    std::fs::write(&urdf, text).unwrap();
    urdf
}

/// Descriptions that were refused and are valid: a binary STL whose header begins with
/// "solid", a `package:///` reference (three slashes); and one that was accepted and is not: a
/// box of 1e300 m.
#[test]
fn descriptions_are_read_as_ros_reads_them() {
    use selfmodel::sim::urdf_loader::load_urdf;
    let dir = common::tempdir();
    let meshes = dir.path().join("pkg").join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    let mut stl = common::cube_stl_binary(0.1);
    stl[..11].copy_from_slice(b"solid cube ");
    std::fs::write(meshes.join("cube.stl"), &stl).unwrap();
    let urdf = one_link(
        dir.path(),
        "<mesh filename=\"package:///pkg/meshes/cube.stl\"/>",
    );
    let robot = load_urdf(&urdf, nalgebra::Isometry3::identity()).unwrap();
    assert_eq!(robot.dof(), 1);
    let urdf = one_link(dir.path(), "<box size=\"1e300 1 1\"/>");
    let err = load_urdf(&urdf, nalgebra::Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(err.contains("at most"), "{err}");
}

/// A joint vector of one joint is refused by the learned inverse kinematics in words, not by
/// printing its configuration's internals.
#[test]
fn a_one_joint_flow_is_refused_in_words() {
    use selfmodel::ik::flow::{FlowConfig, FlowIk};
    let device = select(DeviceChoice::Cpu).unwrap();
    let Err(err) = FlowIk::conditioned(&FlowConfig::standard(), 1, 7, &device, 0) else {
        panic!("a one-joint flow was built");
    };
    let err = err.to_string();
    assert!(
        err.contains("at least 2 joints") && err.contains("`tip`") && !err.contains("couplings:"),
        "{err}"
    );
}
