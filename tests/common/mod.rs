//! Helpers shared by the integration tests (`mod common;`).
#![allow(dead_code)]

use nalgebra::{Isometry3, Point3};
use selfmodel::sim::bvh::Bvh;
use selfmodel::sim::kinematics::KinematicChain;
use selfmodel::sim::robot::Robot;
use selfmodel::sim::shape::Shape;

/// A robot of one fixed link holding `shapes`.
pub fn static_robot(shapes: Vec<Shape>) -> Robot {
    Robot {
        name: "static".into(),
        label: "static".into(),
        chain: KinematicChain::new(vec!["body".into()], vec![], Isometry3::identity(), None)
            .unwrap(),
        geometry: vec![Bvh::new(shapes)],
    }
}

/// The 12 triangles of an axis-aligned cube of half size `h` at the origin.
pub fn cube_triangles(h: f64) -> Vec<[Point3<f64>; 3]> {
    let v = |x: f64, y: f64, z: f64| Point3::new(x * h, y * h, z * h);
    let quads = [
        [
            v(-1., -1., -1.),
            v(1., -1., -1.),
            v(1., 1., -1.),
            v(-1., 1., -1.),
        ],
        [
            v(-1., -1., 1.),
            v(1., -1., 1.),
            v(1., 1., 1.),
            v(-1., 1., 1.),
        ],
        [
            v(-1., -1., -1.),
            v(1., -1., -1.),
            v(1., -1., 1.),
            v(-1., -1., 1.),
        ],
        [
            v(-1., 1., -1.),
            v(1., 1., -1.),
            v(1., 1., 1.),
            v(-1., 1., 1.),
        ],
        [
            v(-1., -1., -1.),
            v(-1., 1., -1.),
            v(-1., 1., 1.),
            v(-1., -1., 1.),
        ],
        [
            v(1., -1., -1.),
            v(1., 1., -1.),
            v(1., 1., 1.),
            v(1., -1., 1.),
        ],
    ];
    quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect()
}

/// An ASCII STL of a cube of half size `h`.
pub fn cube_stl_ascii(h: f64) -> String {
    let mut s = String::from("solid cube\n");
    for t in cube_triangles(h) {
        s += "facet normal 0 0 0\nouter loop\n";
        for p in t {
            s += &format!("vertex {} {} {}\n", p.x, p.y, p.z);
        }
        s += "endloop\nendfacet\n";
    }
    s + "endsolid cube\n"
}

/// A binary STL of a cube of half size `h`.
pub fn cube_stl_binary(h: f64) -> Vec<u8> {
    let tris: Vec<stl_io::Triangle> = cube_triangles(h)
        .iter()
        .map(|t| stl_io::Triangle {
            normal: stl_io::Normal::new([0.0, 0.0, 0.0]),
            vertices: t.map(|p| stl_io::Vertex::new([p.x as f32, p.y as f32, p.z as f32])),
        })
        .collect();
    let mut out = Vec::new();
    stl_io::write_stl(&mut out, tris.iter()).unwrap();
    out
}

/// A fresh folder under the system temp dir, removed when dropped. (Not the `tempfile` crate:
/// a dev-dependency would change shared dependencies' features and make `cargo run` rebuild
/// burn after `cargo test`.)
pub struct TempDir(std::path::PathBuf);

impl TempDir {
    pub fn path(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn tempdir() -> TempDir {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    let dir = std::env::temp_dir().join(format!(
        "selfmodel-test-{}-{}-{nanos}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    TempDir(dir)
}

/// Mean PSNR (dB) of an all-black prediction on the first `n` test images of `spec` (all
/// when `None`): the constant predictor a trained self-model must beat.
pub fn black_psnr(spec: &selfmodel::self_models::data_spec::DataSpec, n: Option<usize>) -> f64 {
    let (data, _, test) = spec.load().unwrap();
    let test = test.start..test.start + n.unwrap_or(test.len()).min(test.len());
    let px = data.width * data.height;
    test.clone()
        .map(|i| {
            let truth: Vec<f32> = data.image(i).iter().map(|&v| v as f32 / 255.0).collect();
            selfmodel::eval::evaluation::psnr_db(&vec![0.0; px], &truth)
        })
        .sum::<f64>()
        / test.len() as f64
}

/// A Wavefront OBJ of a cube of half size `h`.
pub fn cube_obj(h: f64) -> String {
    let tris = cube_triangles(h);
    let mut s = String::from("# cube\n");
    for t in &tris {
        for p in t {
            s += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
    }
    for i in 0..tris.len() {
        s += &format!("f {} {} {}\n", 3 * i + 1, 3 * i + 2, 3 * i + 3);
    }
    s
}

/// A COLLADA document of a cube of half size `h`, its vertices written in units of `unit`
/// metres (`<unit meter>`), so a loader that ignores the unit draws another cube.
pub fn cube_collada(h: f64, unit: f64) -> String {
    let tris = cube_triangles(h);
    let floats: Vec<String> = tris
        .iter()
        .flatten()
        .flat_map(|p| [p.x, p.y, p.z].map(|v| (v / unit).to_string()))
        .collect();
    let n = tris.len() * 3;
    let indices: Vec<String> = (0..n).map(|i| i.to_string()).collect();
    format!(
        r##"<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="custom" meter="{unit}"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries>
    <geometry id="cube-mesh" name="cube">
      <mesh>
        <source id="cube-positions">
          <float_array id="cube-positions-array" count="{count}">{floats}</float_array>
          <technique_common>
            <accessor source="#cube-positions-array" count="{n}" stride="3">
              <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
            </accessor>
          </technique_common>
        </source>
        <vertices id="cube-vertices"><input semantic="POSITION" source="#cube-positions"/></vertices>
        <triangles count="{t}">
          <input semantic="VERTEX" source="#cube-vertices" offset="0"/>
          <p>{indices}</p>
        </triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="Scene" name="Scene">
      <node id="cube" name="cube" type="NODE"><instance_geometry url="#cube-mesh" name="cube"/></node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>
"##,
        count = 3 * n,
        floats = floats.join(" "),
        t = tris.len(),
        indices = indices.join(" "),
    )
}

/// A serial arm of `joints` revolute joints as a URDF: a base box, then links of cylinders
/// (0.35 m of arm in all, thick enough to be seen at 32x32 pixels), axes alternating z and y,
/// each joint limited asymmetrically to [-1.2, 1.9] or [-1.9, 0.7] rad. With `gripper`, a
/// hand on a fixed joint with a zero axis (as Franka ships one) and two prismatic fingers in
/// [0, 0.04] m, the second a `<mimic>` of the first: tip `hand` for the arm alone.
pub fn arm_urdf(joints: usize, gripper: bool) -> String {
    let length = 0.35 / joints as f64;
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<robot name=\"test_arm\">\n  <link name=\"base\"><visual><origin xyz=\"0 0 0.02\"/><geometry><box size=\"0.12 0.12 0.04\"/></geometry></visual></link>\n",
    );
    for j in 0..joints {
        let parent = if j == 0 {
            "base".to_string()
        } else {
            format!("l{j}")
        };
        let axis = if j % 2 == 0 { "0 0 1" } else { "0 1 0" };
        let (lo, hi) = if j % 2 == 0 { (-1.2, 1.9) } else { (-1.9, 0.7) };
        let z = if j == 0 { 0.04 } else { length };
        s += &format!(
            "  <link name=\"l{c}\"><visual><origin xyz=\"0 0 {half}\"/><geometry><cylinder radius=\"0.03\" length=\"{length}\"/></geometry></visual></link>\n  <joint name=\"j{c}\" type=\"revolute\"><parent link=\"{parent}\"/><child link=\"l{c}\"/><origin xyz=\"0 0 {z}\"/><axis xyz=\"{axis}\"/><limit lower=\"{lo}\" upper=\"{hi}\" effort=\"1\" velocity=\"1\"/></joint>\n",
            c = j + 1,
            half = length / 2.0,
        );
    }
    if gripper {
        s += &format!(
            "  <link name=\"flange\"/>\n  <joint name=\"flange_joint\" type=\"fixed\"><parent link=\"l{joints}\"/><child link=\"flange\"/><origin xyz=\"0 0 {length}\"/><axis xyz=\"0 0 0\"/></joint>\n  <link name=\"hand\"><visual><origin xyz=\"0 0 0.02\"/><geometry><box size=\"0.04 0.14 0.04\"/></geometry></visual></link>\n  <joint name=\"hand_joint\" type=\"fixed\"><parent link=\"flange\"/><child link=\"hand\"/></joint>\n  <link name=\"finger_a\"><visual><origin xyz=\"0 0 0.03\"/><geometry><box size=\"0.02 0.02 0.06\"/></geometry></visual></link>\n  <link name=\"finger_b\"><visual><origin xyz=\"0 0 0.03\"/><geometry><box size=\"0.02 0.02 0.06\"/></geometry></visual></link>\n  <joint name=\"finger_a_joint\" type=\"prismatic\"><parent link=\"hand\"/><child link=\"finger_a\"/><origin xyz=\"0 0 0.04\"/><axis xyz=\"0 1 0\"/><limit lower=\"0\" upper=\"0.04\" effort=\"1\" velocity=\"1\"/></joint>\n  <joint name=\"finger_b_joint\" type=\"prismatic\"><parent link=\"hand\"/><child link=\"finger_b\"/><origin xyz=\"0 0 0.04\"/><axis xyz=\"0 -1 0\"/><limit lower=\"0\" upper=\"0.04\" effort=\"1\" velocity=\"1\"/><mimic joint=\"finger_a_joint\"/></joint>\n"
        );
    }
    s + "</robot>\n"
}

/// Write [`arm_urdf`] into `dir` as `NAME.urdf` and return its path.
pub fn write_arm(
    dir: &std::path::Path,
    name: &str,
    joints: usize,
    gripper: bool,
) -> std::path::PathBuf {
    let path = dir.join(format!("{name}.urdf"));
    std::fs::write(&path, arm_urdf(joints, gripper)).unwrap();
    path
}

/// Asserts that a finished command succeeded, showing its stderr when it did not.
pub fn assert_ok(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A torso with two arms, the right arm listed first, and a finger on the left hand.
pub fn two_armed_urdf() -> String {
    let mut s = String::from("<robot name=\"two_arms\">");
    for l in [
        "base",
        "torso",
        "r_upper",
        "r_fore",
        "right_hand",
        "l_upper",
        "l_fore",
        "left_hand",
        "finger",
    ] {
        s += &format!(
            "<link name=\"{l}\"><visual><geometry><box size=\"0.05 0.05 0.1\"/></geometry></visual></link>"
        );
    }
    // name, type, parent, child, origin, axis
    for (n, kind, parent, child, xyz, axis) in [
        ("waist", "revolute", "base", "torso", "0 0 0.1", "0 0 1"),
        ("r1", "revolute", "torso", "r_upper", "0 -0.2 0.3", "0 1 0"),
        ("r2", "revolute", "r_upper", "r_fore", "0 0 -0.25", "0 1 0"),
        (
            "r_wrist",
            "fixed",
            "r_fore",
            "right_hand",
            "0 0 -0.2",
            "0 0 1",
        ),
        ("l1", "revolute", "torso", "l_upper", "0 0.2 0.3", "0 1 0"),
        ("l2", "revolute", "l_upper", "l_fore", "0 0 -0.25", "0 1 0"),
        (
            "l_wrist",
            "fixed",
            "l_fore",
            "left_hand",
            "0 0 -0.2",
            "0 0 1",
        ),
        (
            "grip",
            "prismatic",
            "left_hand",
            "finger",
            "0 0 -0.05",
            "0 1 0",
        ),
    ] {
        s += &format!(
            "<joint name=\"{n}\" type=\"{kind}\"><parent link=\"{parent}\"/><child link=\"{child}\"/><origin xyz=\"{xyz}\"/><axis xyz=\"{axis}\"/><limit lower=\"-1.5\" upper=\"1.5\" effort=\"1\" velocity=\"1\"/></joint>"
        );
    }
    s + "</robot>"
}

/// The saved model (`dir/model`), loaded, predicts the run's test poses to the run's own
/// scores; with its weights damaged it is refused.
pub fn the_saved_model_scores_as_its_run<M: selfmodel::self_models::model::SelfModel>(
    cfg: &selfmodel::self_models::run_config::SelfModelRun<M>,
    dir: &std::path::Path,
    run: &selfmodel::eval::evaluation::Quality,
) {
    use selfmodel::self_models::loading;
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let model = loading::load(dir, &device).unwrap();
    let (data, _, test) = cfg.data.load().unwrap();
    let poses: Vec<f32> = test
        .clone()
        .flat_map(|i| data.angles[i].iter().map(|&v| v as f32))
        .collect();
    let (silhouettes, depth) = model.predict(&poses, test.len()).unwrap();
    let (truth, truth_depth): (Vec<f32>, Vec<f32>) = test
        .clone()
        .map(|i| {
            let s: Vec<f32> = data.image(i).iter().map(|&v| v as f32 / 255.0).collect();
            (s, data.depth_map(i).to_vec())
        })
        .fold((Vec::new(), Vec::new()), |(mut a, mut b), (s, d)| {
            a.extend(s);
            b.extend(d);
            (a, b)
        });
    let predictions = selfmodel::eval::evaluation::Predictions {
        silhouettes,
        depth,
        pixels: data.height * data.width,
        depth_pixels: model.renderer.depth_pixels(),
    };
    let q = selfmodel::eval::evaluation::score(
        &predictions,
        &truth,
        Some(&truth_depth),
        cfg.paper_subset,
    );
    assert!(
        (q.psnr_db_test - run.psnr_db_test).abs() < 1e-4
            && (q.iou_test - run.iou_test).abs() < 1e-5,
        "loaded: {:.5} dB, IoU {:.5}; its run: {:.5} dB, IoU {:.5}",
        q.psnr_db_test,
        q.iou_test,
        run.psnr_db_test,
        run.iou_test
    );
    assert!((model.saved.psnr_db_test - run.psnr_db_test).abs() < 1e-9);
    // Wrong shapes and values are refused in one line.
    let dof = model.saved.inputs;
    assert!(model.predict(&vec![0.0; dof + 1], 1).is_err());
    let mut nan = vec![0.0; dof];
    nan[0] = f32::NAN;
    let e = model.predict(&nan, 1).err().unwrap().to_string();
    assert!(e.contains("not a finite number"), "{e}");
    // Damaged weights are refused, naming what to do.
    let bpk = dir.join("model/model.bpk");
    let mut bytes = std::fs::read(&bpk).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(&bpk, bytes).unwrap();
    let e = loading::load(dir, &device).err().unwrap().to_string();
    assert!(e.contains("damaged or replaced"), "{e}");
}

/// A pose IK model of `spec`'s robot trained in seconds (the quick preset on 1,200 poses, two
/// epochs), saved under `dir`.
#[allow(dead_code)]
pub fn quick_pose_model(
    spec: &selfmodel::sim::robots::RobotSpec,
    robot: &selfmodel::sim::robot::Robot,
    dir: &std::path::Path,
) -> selfmodel::ik::solve::learned::LearnedIk {
    use selfmodel::core::preset::Preset;
    let mut cfg = selfmodel::ik::solve::learned::LearnedIkConfig::quick();
    cfg.data.samples = 1200;
    cfg.data.train = 1100;
    cfg.flow.fit.epochs = 2;
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    selfmodel::ik::solve::learned::train(spec, robot, &cfg, &dir.join("model"), &device).unwrap()
}

/// Run `args` of `binary`, send Ctrl-C (SIGINT) after `after` seconds, and return how long it
/// took to stop, its exit code and its last line.
#[cfg(unix)]
#[allow(dead_code)]
pub fn interrupt_after(binary: &str, args: &[&str], after: f64) -> (f64, Option<i32>, String) {
    let mut child = std::process::Command::new(binary)
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs_f64(after));
    let sent = std::time::Instant::now();
    // The shell's own `kill` (a machine without procps has no /bin/kill).
    let kill = std::process::Command::new("sh")
        .args(["-c", &format!("kill -INT {}", child.id())])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            sent.elapsed().as_secs_f64() < 10.0,
            "{args:?}: still running 10 s after Ctrl-C"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    let last = err.lines().last().unwrap_or_default().to_string();
    (sent.elapsed().as_secs_f64(), status.code(), last)
}

/// [`arm_urdf`] (six joints and a hand) with each visual also its collision geometry.
#[allow(dead_code)]
pub fn collision_arm_urdf() -> String {
    let text = arm_urdf(6, true);
    let (mut out, mut rest) = (String::new(), text.as_str());
    while let Some(i) = rest.find("<visual>") {
        let j = i + rest[i..].find("</visual>").unwrap() + "</visual>".len();
        out += &rest[..j];
        out += &rest[i..j].replace("visual", "collision");
        rest = &rest[j..];
    }
    out + rest
}

/// Each case `(what, binary, args, after)` run and sent Ctrl-C after `after` seconds; a line
/// for each that did not stop within `within` seconds with exit 130 and one `interrupted:`
/// line, or that left a file in `dir` beside `inputs`.
#[cfg(unix)]
#[allow(dead_code)]
pub fn ctrl_c_failures(
    dir: &std::path::Path,
    inputs: &[&str],
    cases: Vec<(&str, &str, Vec<String>, f64)>,
    within: f64,
) -> Vec<String> {
    let mut failures = Vec::new();
    for (what, binary, args, after) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (waited, code, last) = interrupt_after(binary, &args, after);
        eprintln!("{what}: stopped {waited:.2} s after Ctrl-C, exit {code:?}: {last}");
        let left: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|f| !inputs.contains(&f.as_str()))
            .collect();
        if code != Some(130)
            || !last.starts_with("interrupted:")
            || waited >= within
            || !left.is_empty()
        {
            failures.push(format!(
                "{what}: exit {code:?} after {waited:.2} s, left {left:?}: {last}"
            ));
        }
    }
    failures
}
