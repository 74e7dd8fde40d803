//! Bad input, round 5 (issue 72): what the collision work reads (scenes, sphere files, SRDF
//! pairs, the collision model kept beside a saved IK model) and what it writes. Each bullet of
//! the round's findings is a row here: the input, and what must happen (a one-line refusal, an
//! untouched input, a prompt stop on Ctrl-C, a valid input read).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use selfmodel::ik::solve::collision::{CollisionCheck, Spheres};
use selfmodel::sim::collision::cache;
use selfmodel::sim::collision::pairs::PairSampling;
use selfmodel::sim::collision::spheres::SphereFit;
use selfmodel::sim::robots::RobotSpec;
use selfmodel::sim::urdf_loader::GeometryKind;

const IK: &str = env!("CARGO_BIN_EXE_ik");

/// The arm with its collision geometry, as `dir/arm.urdf`.
fn collision_arm(dir: &Path) -> PathBuf {
    let path = dir.join("arm.urdf");
    std::fs::write(&path, common::collision_arm_urdf()).unwrap();
    path
}

fn spec(urdf: &Path) -> RobotSpec {
    RobotSpec::Urdf {
        path: urdf.to_path_buf(),
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: Some("hand".into()),
        geometry: GeometryKind::None,
        joints: Default::default(),
    }
}

/// `base` then `extra`, as the owned arguments of a command.
fn with(base: &[&str], extra: &[&str]) -> Vec<String> {
    base.iter().chain(extra).map(|s| s.to_string()).collect()
}

fn ik(args: &[&str]) -> Output {
    Command::new(IK).args(args).output().unwrap()
}

/// The one line a refused command printed (asserted: exit 1, one line, no panic).
fn refused(what: &str, out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).trim().to_string();
    eprintln!("{what}: {err}");
    assert_eq!(out.status.code(), Some(1), "{what}: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: {err}");
    assert!(
        err.starts_with("error: ") && !err.contains("panicked"),
        "{what}: {err}"
    );
    err
}

/// A model of the arm trained in a second, with its collision model kept (`dir/model`).
fn trained(dir: &Path) -> (PathBuf, String) {
    let urdf = collision_arm(dir);
    let model = dir.join("model");
    let out = ik(&[
        "train",
        "--urdf",
        urdf.to_str().unwrap(),
        "--tip",
        "hand",
        "--preset",
        "quick",
        "--out",
        model.to_str().unwrap(),
    ]);
    common::assert_ok(&out);
    assert!(model.join(cache::FILE).is_file());
    (urdf, model.to_str().unwrap().to_string())
}

/// A kept collision model edited in every way round 5 tried, by hand (its hash no longer
/// matches) or forged (rewritten with a matching hash: its spheres then no longer cover the
/// links): each refused in one line, never used.
#[test]
fn a_tampered_collision_cache_is_refused_never_used() {
    let dir = common::tempdir();
    let (urdf, model_dir) = trained(dir.path());
    let model_dir = Path::new(&model_dir);
    let spec = spec(&urdf);
    let use_kept = || {
        CollisionCheck::with_spheres(
            &spec,
            Spheres::KeptIn(model_dir, Default::default()),
            None,
            None,
            true,
            0.005,
        )
        .map(|_| "used".to_string())
    };
    assert!(use_kept().is_ok(), "the file as written is used");
    let file = model_dir.join(cache::FILE);
    let original = std::fs::read_to_string(&file).unwrap();
    let json: serde_json::Value = serde_json::from_str(&original).unwrap();
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut v = json.clone();
        f(&mut v);
        v
    };
    let each_sphere = |v: &mut serde_json::Value, f: &dyn Fn(&mut serde_json::Value)| {
        for link in v["spheres"].as_array_mut().unwrap() {
            for s in link[1].as_array_mut().unwrap() {
                f(s);
            }
        }
    };
    let with_spheres: Vec<usize> = (json["spheres"].as_array().unwrap().iter())
        .enumerate()
        .filter(|(_, l)| !l[1].as_array().unwrap().is_empty())
        .map(|(i, _)| i)
        .collect();
    let cases: Vec<(&str, serde_json::Value)> = vec![
        (
            "every radius -1",
            edit(&|v| each_sphere(v, &|s| s["radius"] = (-1.0).into())),
        ),
        (
            "every radius 0",
            edit(&|v| each_sphere(v, &|s| s["radius"] = 0.0.into())),
        ),
        (
            "two links' spheres swapped",
            edit(&|v| {
                let (a, b) = (with_spheres[1], with_spheres[with_spheres.len() - 3]);
                let spheres = v["spheres"].as_array_mut().unwrap();
                let t = spheres[a][1].take();
                spheres[a][1] = spheres[b][1].take();
                spheres[b][1] = t;
            }),
        ),
        (
            "the hand's spheres removed",
            edit(&|v| {
                for link in v["spheres"].as_array_mut().unwrap() {
                    if link[0] == "hand" {
                        link[1] = serde_json::json!([]);
                    }
                }
            }),
        ),
        (
            "every pair removed",
            edit(&|v| v["pairs"] = serde_json::json!([])),
        ),
        (
            "every centre moved 100 m",
            edit(&|v| each_sphere(v, &|s| s["center"][0] = 100.0.into())),
        ),
        (
            "every centre at 1e300",
            edit(&|v| each_sphere(v, &|s| s["center"][0] = 1e300.into())),
        ),
    ];
    let mut failures = Vec::new();
    for (what, value) in &cases {
        std::fs::write(&file, serde_json::to_string(value).unwrap()).unwrap();
        match use_kept() {
            Err(e) if e.to_string().contains("cannot be used") => eprintln!("{what}: {e}"),
            other => failures.push(format!("{what}: {other:?}")),
        }
    }
    // Forged: the same edits of the spheres written with a matching hash.
    let robot = spec.with_geometry(GeometryKind::Collision).load().unwrap();
    let (fit, sampling) = (SphereFit::default(), PairSampling::default());
    let key = cache::key(&robot, None, &fit, &sampling);
    std::fs::write(&file, &original).unwrap();
    let kept = CollisionCheck::with_spheres(
        &spec,
        Spheres::KeptIn(model_dir, Default::default()),
        None,
        None,
        true,
        0.0,
    )
    .unwrap()
    .model;
    let hand = robot.chain.links.iter().position(|l| l == "hand").unwrap();
    let forgeries: Vec<(
        &str,
        Box<dyn Fn(&mut Vec<Vec<selfmodel::sim::collision::spheres::Sphere>>)>,
    )> = vec![
        (
            "radii -1",
            Box::new(|s| s.iter_mut().flatten().for_each(|s| s.radius = -1.0)),
        ),
        (
            "radii halved",
            Box::new(|s| s.iter_mut().flatten().for_each(|s| s.radius *= 0.5)),
        ),
        ("the hand's removed", Box::new(move |s| s[hand].clear())),
        ("swapped", Box::new(move |s| s.swap(1, hand))),
        (
            "moved 100 m",
            Box::new(|s| s.iter_mut().flatten().for_each(|s| s.center[0] += 100.0)),
        ),
    ];
    for (what, forge) in forgeries {
        let mut spheres = kept.spheres.clone();
        forge(&mut spheres);
        let pairs = kept.pairs.clone();
        let model = selfmodel::sim::collision::model::CollisionModel::with_pairs(
            &robot.chain,
            spheres,
            pairs,
        );
        cache::write(model_dir, &key, &robot, &model).unwrap();
        match use_kept() {
            Err(e) if e.to_string().contains("cannot be used") => eprintln!("forged, {what}: {e}"),
            other => failures.push(format!("forged, {what}: {other:?}")),
        }
    }
    // A FIFO in its place: refused at once, not waited on.
    #[cfg(unix)]
    {
        std::fs::remove_file(&file).unwrap();
        assert!(
            Command::new("mkfifo")
                .arg(&file)
                .status()
                .unwrap()
                .success()
        );
        match use_kept() {
            Err(e) if e.to_string().contains("not a regular file") => eprintln!("a FIFO: {e}"),
            other => failures.push(format!("a FIFO: {other:?}")),
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// No `--out` is a file the command reads: the spheres, a scene's mesh, a collision mesh of
/// the robot, a scene through a link, a file `ik train` would write over; nor a FIFO.
#[cfg(unix)]
#[test]
fn no_output_is_a_file_the_collision_work_reads() {
    let dir = common::tempdir();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (urdf, model) = trained(dir.path());
    // A collision mesh of the robot's own: the hand as an STL.
    let meshes = dir.path().join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    std::fs::write(meshes.join("cube.stl"), common::cube_stl_binary(0.02)).unwrap();
    let text = std::fs::read_to_string(&urdf).unwrap().replace(
        "<collision><origin xyz=\"0 0 0.02\"/><geometry><box size=\"0.04 0.14 0.04\"/></geometry></collision>",
        "<collision><geometry><mesh filename=\"meshes/cube.stl\"/></geometry></collision>",
    );
    let meshed = dir.path().join("meshed.urdf");
    std::fs::write(&meshed, text).unwrap();
    let meshed_model = d("meshed_model");
    common::assert_ok(&ik(&[
        "train",
        "--urdf",
        meshed.to_str().unwrap(),
        "--tip",
        "hand",
        "--preset",
        "quick",
        "--out",
        &meshed_model,
    ]));
    std::fs::write(
        d("spheres.yml"),
        "collision_spheres:\n  l1:\n    - {center: [0, 0, 0.02], radius: 0.03}\n",
    )
    .unwrap();
    std::fs::write(meshes.join("bin.stl"), common::cube_stl_binary(0.05)).unwrap();
    std::fs::write(
        d("scene.yml"),
        "mesh:\n  bin: {file_path: meshes/bin.stl, pose: [0.5, 0, 0, 1, 0, 0, 0]}\n",
    )
    .unwrap();
    std::os::unix::fs::symlink("scene.yml", dir.path().join("link.yml")).unwrap();
    std::fs::create_dir_all(d("trained")).unwrap();
    std::fs::write(
        d("trained/collision.json"),
        "sphere:\n  ball: {radius: 0.05, position: [0.5, 0, 0.4]}\n",
    )
    .unwrap();
    std::fs::write(
        d("trained/model.json"),
        "collision_spheres:\n  l1:\n    - {center: [0, 0, 0.02], radius: 0.03}\n",
    )
    .unwrap();
    common::assert_ok(&ik(&[
        "targets",
        "--model",
        &model,
        "--n",
        "20",
        "--out",
        &d("t.csv"),
    ]));
    assert!(
        Command::new("mkfifo")
            .arg(d("fifo"))
            .status()
            .unwrap()
            .success()
    );
    let train = |extra: &[&str]| {
        let urdf = urdf.to_str().unwrap();
        with(
            &[
                "train", "--urdf", urdf, "--tip", "hand", "--preset", "quick",
            ],
            extra,
        )
    };
    let s = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<String>>();
    let (mesh, bin, cube) = (
        meshes.join("cube.stl").to_str().unwrap().to_string(),
        meshes.join("bin.stl").to_str().unwrap().to_string(),
        d("spheres.yml"),
    );
    let cases: Vec<(&str, Vec<String>, String)> = vec![
        (
            "ik targets --out the --spheres file",
            s(&[
                "targets",
                "--model",
                &model,
                "--spheres",
                &cube,
                "--out",
                &cube,
            ]),
            cube.clone(),
        ),
        (
            "ik solve --out the --spheres file",
            s(&[
                "solve",
                "--model",
                &model,
                "--targets",
                &d("t.csv"),
                "--spheres",
                &cube,
                "--out",
                &cube,
            ]),
            cube.clone(),
        ),
        (
            "ik solve --out a mesh the scene loads",
            s(&[
                "solve",
                "--model",
                &model,
                "--targets",
                &d("t.csv"),
                "--scene",
                &d("scene.yml"),
                "--out",
                &bin,
            ]),
            bin.clone(),
        ),
        (
            "ik solve --self-collision --out the robot's collision mesh",
            s(&[
                "solve",
                "--model",
                &meshed_model,
                "--targets",
                &d("t.csv"),
                "--self-collision",
                "--out",
                &mesh,
            ]),
            mesh.clone(),
        ),
        (
            "ik solve --out the scene through a link",
            s(&[
                "solve",
                "--model",
                &model,
                "--targets",
                &d("t.csv"),
                "--scene",
                &d("link.yml"),
                "--out",
                &d("scene.yml"),
            ]),
            d("scene.yml"),
        ),
        (
            "ik solve --out a link to the scene",
            s(&[
                "solve",
                "--model",
                &model,
                "--targets",
                &d("t.csv"),
                "--scene",
                &d("scene.yml"),
                "--out",
                &d("link.yml"),
            ]),
            d("scene.yml"),
        ),
        (
            "ik train --out the folder of a scene called collision.json",
            train(&[
                "--scene",
                &d("trained/collision.json"),
                "--out",
                &d("trained"),
            ]),
            d("trained/collision.json"),
        ),
        (
            "ik train --out the folder of spheres called model.json",
            train(&[
                "--spheres",
                &d("trained/model.json"),
                "--out",
                &d("trained"),
            ]),
            d("trained/model.json"),
        ),
    ];
    let mut failures = Vec::new();
    for (what, args, input) in &cases {
        let before = std::fs::read(input).unwrap();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let err = refused(what, &ik(&args));
        if !err.contains("reads") || std::fs::read(input).unwrap() != before {
            failures.push(format!("{what}: {err}"));
        }
    }
    // A FIFO (a device likewise) as --out is refused, and stays what it was.
    let err = refused(
        "--out a FIFO",
        &ik(&[
            "targets",
            "--model",
            &model,
            "--n",
            "5",
            "--out",
            &d("fifo"),
        ]),
    );
    assert!(err.contains("not a file"), "{err}");
    assert!(!std::fs::metadata(d("fifo")).unwrap().is_file());
    assert!(failures.is_empty(), "{failures:#?}");
}

/// What would have blocked for ever or taken the machine's memory is refused at once: a FIFO
/// named as the spheres, the SRDF or the scene; a 2 GB sparse SRDF; a scene mesh scaled
/// 1000x; and a plain `ik train` of a robot with a 100 m collision cylinder trains (its
/// collision model, beyond any sampling, is not kept) instead of being killed.
#[cfg(unix)]
#[test]
fn collision_inputs_that_would_hang_or_abort_are_refused_at_once() {
    let dir = common::tempdir();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (_, model) = trained(dir.path());
    common::assert_ok(&ik(&[
        "targets",
        "--model",
        &model,
        "--n",
        "5",
        "--out",
        &d("t.csv"),
    ]));
    assert!(
        Command::new("mkfifo")
            .arg(d("fifo"))
            .status()
            .unwrap()
            .success()
    );
    let sparse = std::fs::File::create(d("sparse.srdf")).unwrap();
    sparse.set_len(2 << 30).unwrap();
    std::fs::write(d("cube.stl"), common::cube_stl_binary(0.05)).unwrap();
    std::fs::write(d("big.yml"), "mesh:\n  bin: {file_path: cube.stl, pose: [1, 0, 0, 1, 0, 0, 0], scale: [1000, 1000, 1000]}\n").unwrap();
    let solve = |extra: &[&str]| {
        with(
            &[
                "solve",
                "--model",
                &model,
                "--targets",
                &d("t.csv"),
                "--out",
                &d("a.csv"),
            ],
            extra,
        )
    };
    let cases = [
        (
            "a FIFO as --spheres",
            solve(&["--spheres", &d("fifo")]),
            "not a regular file",
        ),
        (
            "a FIFO as --srdf",
            solve(&["--self-collision", "--srdf", &d("fifo")]),
            "not a regular file",
        ),
        (
            "a FIFO as --scene",
            solve(&["--scene", &d("fifo")]),
            "not a regular file",
        ),
        (
            "a 2 GB sparse SRDF",
            solve(&["--self-collision", "--srdf", &d("sparse.srdf")]),
            "more than the 64 MiB",
        ),
        (
            "a scene mesh scaled 1000x",
            solve(&["--scene", &d("big.yml")]),
            "check its size and scale",
        ),
    ];
    for (what, args, expected) in cases {
        let start = std::time::Instant::now();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let err = refused(what, &ik(&args));
        assert!(err.contains(expected), "{what}: {err}");
        assert!(
            start.elapsed().as_secs_f64() < 10.0,
            "{what}: {:?}",
            start.elapsed()
        );
        assert!(
            !Path::new(&d("a.csv")).exists(),
            "{what}: a result was left"
        );
    }
    // The last link a cylinder 100 m wide: the kinematics train, the collision model is not kept.
    let text = common::arm_urdf(4, false).replace(
        "</visual></link>\n  <joint name=\"j4\"",
        "</visual><collision><geometry><cylinder radius=\"100\" length=\"100\"/></geometry></collision></link>\n  <joint name=\"j4\"",
    );
    let text = text.replacen(
        "<link name=\"l4\"><visual>",
        "<link name=\"l4\"><collision><geometry><cylinder radius=\"100\" length=\"100\"/></geometry></collision><visual>",
        1,
    );
    assert!(text.contains("radius=\"100\""));
    std::fs::create_dir_all(d("huge")).unwrap();
    std::fs::write(d("huge/huge.urdf"), text).unwrap();
    let start = std::time::Instant::now();
    let out = ik(&[
        "train",
        "--urdf",
        &d("huge/huge.urdf"),
        "--preset",
        "quick",
        "--out",
        &d("huge_model"),
    ]);
    common::assert_ok(&out);
    assert!(
        start.elapsed().as_secs_f64() < 30.0,
        "{:?}",
        start.elapsed()
    );
    assert!(!Path::new(&d("huge_model")).join(cache::FILE).exists());
    let err = refused(
        "ik solve --self-collision on the 100 m cylinder",
        &ik(&[
            "solve",
            "--model",
            &d("huge_model"),
            "--targets",
            &d("t.csv"),
            "--self-collision",
            "--out",
            &d("a.csv"),
        ]),
    );
    assert!(
        err.contains("link \"l4\"") && err.contains("check its size and scale"),
        "{err}"
    );
}

/// Options that would do nothing or be taken wrongly are refused in one line: an SRDF that
/// is missing, a folder, a device, the URDF itself, another robot's, or one naming links the
/// robot lacks; a sphere of 1e9 m; --margin alone or NaN; --self-collision on a robot with
/// no collision geometry; a position-only model given to the full-pose benchmark.
#[test]
fn collision_options_that_would_do_nothing_are_refused() {
    let dir = common::tempdir();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (urdf, model) = trained(dir.path());
    common::assert_ok(&ik(&[
        "targets",
        "--model",
        &model,
        "--n",
        "5",
        "--out",
        &d("t.csv"),
    ]));
    // Another robot's SRDF, named only (in a folder of its own: one beside the URDF would be
    // read for every row).
    std::fs::create_dir_all(d("panda")).unwrap();
    std::fs::write(d("panda/other.srdf"), "<robot name=\"panda\"><disable_collisions link1=\"panda_link0\" link2=\"panda_link1\" reason=\"Adjacent\"/></robot>").unwrap();
    std::fs::write(
        d("big.yml"),
        "collision_spheres:\n  l1:\n    - {center: [0, 0, 0], radius: 1e9}\n",
    )
    .unwrap();
    let ur5 = d("ur5");
    common::assert_ok(&ik(&[
        "train", "--robot", "ur5", "--preset", "quick", "--out", &ur5,
    ]));
    let solve = |extra: &[&str]| {
        with(
            &[
                "solve",
                "--model",
                &model,
                "--targets",
                &d("t.csv"),
                "--out",
                &d("a.csv"),
            ],
            extra,
        )
    };
    let urdf = urdf.to_str().unwrap();
    let cases = [
        (
            "an SRDF that does not exist",
            solve(&["--self-collision", "--srdf", &d("none.srdf")]),
            "No such file",
        ),
        (
            "an SRDF that is a folder",
            solve(&["--self-collision", "--srdf", dir.path().to_str().unwrap()]),
            "a folder",
        ),
        (
            "/dev/zero as the SRDF",
            solve(&["--self-collision", "--srdf", "/dev/zero"]),
            "not a regular file",
        ),
        (
            "the URDF as the SRDF",
            solve(&["--self-collision", "--srdf", urdf]),
            "no <disable_collisions>",
        ),
        (
            "another robot's SRDF",
            solve(&["--self-collision", "--srdf", &d("panda/other.srdf")]),
            "is it this robot's SRDF",
        ),
        (
            "a sphere of 1e9 m",
            solve(&["--spheres", &d("big.yml")]),
            "a radius of at most",
        ),
        (
            "--margin without a collision option",
            solve(&["--margin", "0.01"]),
            "needs --scene",
        ),
        (
            "--spheres-per-link 0",
            solve(&["--self-collision", "--spheres-per-link", "0"]),
            "give 1 to 256",
        ),
        (
            "--protrusion-mm NaN",
            solve(&["--self-collision", "--protrusion-mm", "NaN"]),
            "above 0 and at most 1000 mm",
        ),
        (
            "--protrusion-mm with --spheres-per-link",
            solve(&[
                "--self-collision",
                "--protrusion-mm",
                "5",
                "--spheres-per-link",
                "4",
            ]),
            "not both",
        ),
        (
            "--spheres-per-link with --spheres",
            solve(&["--spheres", &d("big.yml"), "--spheres-per-link", "4"]),
            "give one",
        ),
        (
            "--protrusion-mm without a collision option",
            solve(&["--protrusion-mm", "5"]),
            "need --scene",
        ),
        (
            "--margin NaN",
            solve(&["--self-collision", "--margin", "NaN"]),
            "from 0 to 1 m",
        ),
        (
            "--margin -1",
            solve(&["--self-collision", "--margin", "-1"]),
            "from 0 to 1 m",
        ),
        (
            "--tolerance -1e-4,1e-4",
            solve(&["--tolerance", "-1e-4,1e-4"]),
            "is not between",
        ),
        (
            "--self-collision on the built-in UR5",
            vec![
                "solve".into(),
                "--model".into(),
                ur5.clone(),
                "--targets".into(),
                d("t.csv"),
                "--self-collision".into(),
                "--out".into(),
                d("a.csv"),
            ],
            "has no collision geometry",
        ),
    ];
    for (what, args, expected) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let err = refused(what, &ik(&args));
        assert!(err.contains(expected), "{what}: {err}");
        assert!(
            !Path::new(&d("a.csv")).exists(),
            "{what}: a result was left"
        );
    }
    let position_only = d("position_only");
    common::assert_ok(&ik(&[
        "train",
        "--urdf",
        urdf,
        "--tip",
        "hand",
        "--preset",
        "quick",
        "--position-only",
        "--out",
        &position_only,
    ]));
    let bench = Command::new(env!("CARGO_BIN_EXE_bench_collision_ik"))
        .args([
            "--model",
            &position_only,
            "--preset",
            "quick",
            "--no-reference",
            "--out",
            &d("bench"),
        ])
        .output()
        .unwrap();
    let err = refused("a position-only model benchmarked", &bench);
    assert!(err.contains("position-only"), "{err}");
    assert!(!Path::new(&d("bench")).exists());
    // Onto the model's own files: said in words, not as an OS error.
    for file in [cache::FILE, "model.json"] {
        let target = Path::new(&model).join(file);
        let before = std::fs::read(&target).unwrap();
        let bench = Command::new(env!("CARGO_BIN_EXE_bench_collision_ik"))
            .args([
                "--model",
                &model,
                "--preset",
                "quick",
                "--no-reference",
                "--out",
            ])
            .arg(&target)
            .output()
            .unwrap();
        let err = refused("bench_collision_ik --out onto the model's own file", &bench);
        assert!(err.contains("--out") && !err.contains("os error"), "{err}");
        assert_eq!(std::fs::read(&target).unwrap(), before);
    }
}

/// What was refused and is valid: `ik train --srdf FILE` for collisions (no --group), cuRobo's
/// drawing fields on obstacles (`color: [.nan, ...]`, `material`, `texture`), a quaternion
/// whose norm overflows (1e200: a rotation all the same).
#[test]
fn valid_collision_inputs_once_refused_are_read() {
    let dir = common::tempdir();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let urdf = collision_arm(dir.path());
    // The pairs MoveIt's setup assistant would write for it.
    let robot = spec(&urdf)
        .with_geometry(GeometryKind::Collision)
        .load()
        .unwrap();
    let spheres = selfmodel::sim::collision::fit_robot(&robot, &SphereFit::default()).unwrap();
    let allowed = selfmodel::sim::collision::computed_pairs(
        &robot,
        &spheres,
        Some(0.0),
        &PairSampling::default(),
    )
    .unwrap();
    let mut srdf = String::from("<robot name=\"test_arm\">\n");
    for (a, b) in allowed.pairs.keys() {
        srdf += &format!("  <disable_collisions link1=\"{a}\" link2=\"{b}\" reason=\"Never\"/>\n");
    }
    std::fs::write(d("arm.srdf"), srdf + "</robot>\n").unwrap();
    let out = ik(&[
        "train",
        "--urdf",
        urdf.to_str().unwrap(),
        "--tip",
        "hand",
        "--preset",
        "quick",
        "--srdf",
        &d("arm.srdf"),
        "--out",
        &d("model"),
    ]);
    common::assert_ok(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("collision-free"), "{said}");
    let scene = "cuboid:\n  wall: {dims: [0.1, 2, 2], pose: [0.5, 0, 0, 1e200, 0, 1e200, 0], color: [.nan, 0.5, 0.5, 1], material: steel, texture: wood}\n";
    let parsed =
        selfmodel::sim::collision::scene::Scene::parse(Path::new("scene.yml"), scene).unwrap();
    let selfmodel::sim::collision::scene::Obstacle::Cuboid { pose, .. } = &parsed.obstacles[0].1
    else {
        panic!("not a cuboid");
    };
    // (1, 0, 1, 0) normalised: a quarter turn about y, the wall's thin side now along z.
    let turned = pose.rotation * nalgebra::Vector3::x();
    assert!(
        (turned - nalgebra::Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12,
        "{turned}"
    );
    let err = selfmodel::sim::collision::scene::Scene::parse(
        Path::new("scene.yml"),
        "sphere:\n  ball: {radius: .nan, position: [0, 0, 0]}\n",
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("NaN"), "{err}");
}

/// Ctrl-C ends every collision phase within a second, with exit 130 and nothing written:
/// drawing collision-free samples among 10,000 obstacles (`ik train --scene`), solving
/// against 22,000 user spheres decided on the spheres alone (`ik solve --spheres --collision
/// spheres`) and on the exact shapes (`ik solve --self-collision`), the benchmark, and the
/// benchmark's reference child (a `--python` that never ends). (Which pairs are checked is
/// decided on the links' exact shapes, whatever the spheres: no longer a phase that 22,000
/// spheres make long.)
#[cfg(unix)]
#[test]
fn ctrl_c_stops_every_collision_phase_within_a_second() {
    let dir = common::tempdir();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (urdf, model) = trained(dir.path());
    common::assert_ok(&ik(&[
        "targets",
        "--model",
        &model,
        "--n",
        "20000",
        "--out",
        &d("t.csv"),
    ]));
    let mut scene = String::from("sphere:\n");
    for i in 0..10_000 {
        let (x, y) = (2.0 + (i % 100) as f64 * 0.05, (i / 100) as f64 * 0.05);
        scene += &format!("  s{i}: {{radius: 0.01, position: [{x}, {y}, 0]}}\n");
    }
    std::fs::write(d("crowd.yml"), scene).unwrap();
    let mut spheres = String::from("collision_spheres:\n");
    for l in 1..=6 {
        spheres += &format!("  l{l}:\n");
        for i in 0..3_700 {
            spheres += &format!(
                "    - {{center: [0, 0, {}], radius: 0.02}}\n",
                i as f64 * 1e-5
            );
        }
    }
    std::fs::write(d("many.yml"), spheres).unwrap();
    std::fs::write(d("forever.sh"), "#!/bin/sh\nexec sleep 1000\n").unwrap();
    std::fs::set_permissions(
        d("forever.sh"),
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    let urdf = urdf.to_str().unwrap();
    let train = |preset: &str, extra: &[&str]| {
        let base = ["train", "--urdf", urdf, "--tip", "hand", "--preset", preset];
        with(&base, &[&["--out", &d("new")][..], extra].concat())
    };
    let solve = |extra: &[&str]| {
        with(
            &[
                "solve",
                "--model",
                &model,
                "--targets",
                &d("t.csv"),
                "--out",
                &d("a.csv"),
            ],
            extra,
        )
    };
    let bench = env!("CARGO_BIN_EXE_bench_collision_ik");
    let bench_args = |python: &str| -> Vec<String> {
        [
            "--model",
            &model,
            "--preset",
            "quick",
            "--python",
            python,
            "--out",
            &d("bench"),
        ]
        .map(String::from)
        .to_vec()
    };
    let cases: Vec<(&str, &str, Vec<String>, f64)> = vec![
        (
            "ik train --scene, drawing among 10,000 obstacles",
            IK,
            // The paper preset's 210,000 draws: a minute among 10,000 obstacles.
            train("paper", &["--scene", &d("crowd.yml")]),
            2.0,
        ),
        (
            "ik solve --spheres, solving against 22,000 spheres",
            IK,
            // Ten answers a target: the spheres' trees answer the 20,000 targets once in
            // under two seconds.
            solve(&[
                "--spheres",
                &d("many.yml"),
                "--collision",
                "spheres",
                "--k",
                "10",
            ]),
            2.0,
        ),
        (
            "ik solve --self-collision, solving",
            IK,
            solve(&["--self-collision"]),
            2.0,
        ),
        (
            "bench_collision_ik, its reference that never ends",
            bench,
            bench_args(&d("forever.sh")),
            5.0,
        ),
    ];
    let inputs = [
        "arm.urdf",
        "model",
        "t.csv",
        "crowd.yml",
        "many.yml",
        "forever.sh",
    ];
    let failures = common::ctrl_c_failures(dir.path(), &inputs, cases, 1.0);
    assert!(failures.is_empty(), "{failures:#?}");
}

/// `--precision bf16` or `f16` where the models trained are f32 only (damage, multiview,
/// NeuroKin's tree encoder): refused in one line before anything is written, not a panic in
/// burn's CPU backend.
#[test]
fn a_precision_the_models_cannot_train_in_is_refused() {
    let dir = common::tempdir();
    let cases = [
        ("damage", env!("CARGO_BIN_EXE_damage")),
        ("multiview", env!("CARGO_BIN_EXE_multiview")),
        ("neurokin_tree", env!("CARGO_BIN_EXE_neurokin_tree")),
    ];
    for (name, binary) in cases {
        for precision in ["bf16", "f16"] {
            let out = dir.path().join(format!("{name}_{precision}"));
            let run = Command::new(binary)
                .args(["--preset", "quick", "--precision", precision, "--out"])
                .arg(&out)
                .output()
                .unwrap();
            let err = refused(&format!("{name} --precision {precision}"), &run);
            assert!(err.contains("--precision") && err.contains("f32"), "{err}");
            assert!(!out.exists(), "{name}: {} was written", out.display());
        }
    }
}
