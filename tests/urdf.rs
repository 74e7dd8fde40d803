//! URDF loading: joints, geometry, package paths, STL formats and every bad input.

mod common;

use std::path::Path;

use common::{cube_stl_ascii, cube_stl_binary};
use nalgebra::Isometry3;
use selfmodel::Error;
use selfmodel::sim::camera::Camera;
use selfmodel::sim::kinematics::JointKind;
use selfmodel::sim::ray_caster::{RayCaster, RenderOptions};
use selfmodel::sim::urdf_loader::{load_urdf, resolve_mesh_path};

fn robot_xml(joint_type: &str, mesh: &str) -> String {
    format!(
        r#"<?xml version="1.0"?>
<robot name="test">
  <link name="base"><visual><geometry><box size="0.1 0.1 0.02"/></geometry></visual></link>
  <link name="arm"><visual><origin xyz="0 0 0.1" rpy="0 0 0"/><geometry><cylinder radius="0.02" length="0.2"/></geometry></visual></link>
  <link name="slider"><visual><geometry><sphere radius="0.03"/></geometry></visual></link>
  <link name="tool"><visual><geometry><mesh filename="{mesh}" scale="0.5 0.5 0.5"/></geometry></visual></link>
  <joint name="j0" type="{joint_type}"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.01"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j1" type="prismatic"><parent link="arm"/><child link="slider"/>
    <origin xyz="0 0 0.2"/><axis xyz="1 0 0"/><limit lower="0" upper="0.1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="fixed"><parent link="slider"/><child link="tool"/><origin xyz="0 0 0.05"/></joint>
</robot>"#
    )
}

/// A package folder `pkg/urdf/r.urdf` with `pkg/meshes/cube.stl`.
fn package(dir: &Path, joint_type: &str, mesh: &str, ascii: bool) -> std::path::PathBuf {
    std::fs::create_dir_all(dir.join("pkg/urdf")).unwrap();
    std::fs::create_dir_all(dir.join("pkg/meshes")).unwrap();
    if ascii {
        std::fs::write(dir.join("pkg/meshes/cube.stl"), cube_stl_ascii(0.04)).unwrap();
    } else {
        std::fs::write(dir.join("pkg/meshes/cube.stl"), cube_stl_binary(0.04)).unwrap();
    }
    let urdf = dir.join("pkg/urdf/r.urdf");
    std::fs::write(&urdf, robot_xml(joint_type, mesh)).unwrap();
    urdf
}

#[test]
fn loads_joints_limits_and_all_geometry_kinds() {
    for ascii in [true, false] {
        let dir = common::tempdir();
        let urdf = package(
            dir.path(),
            "revolute",
            "package://pkg/meshes/cube.stl",
            ascii,
        );
        let robot = load_urdf(&urdf, Isometry3::identity()).unwrap();
        assert_eq!(robot.dof(), 2);
        let kinds: Vec<JointKind> = robot.chain.joints.iter().map(|j| j.kind).collect();
        assert_eq!(
            kinds,
            [JointKind::Revolute, JointKind::Prismatic, JointKind::Fixed]
        );
        assert_eq!(robot.chain.joint_ranges(), vec![[-1.0, 1.0], [0.0, 0.1]]);
        assert_eq!(
            robot
                .geometry
                .iter()
                .map(|g| g.shapes().len())
                .collect::<Vec<_>>(),
            [1, 1, 1, 12]
        );
        // The tip is the deepest link (tool) and follows the prismatic joint.
        let a = robot.end_effector(&[0.0, 0.0]);
        let b = robot.end_effector(&[0.0, 0.1]);
        assert!(((b - a).x - 0.1).abs() < 1e-12 && (a.z - 0.26).abs() < 1e-12);
        // It renders, fast path equal to the reference.
        let caster = RayCaster::new(&robot, Camera::paper(), RenderOptions::default());
        let f = caster.render(&[0.3, 0.05]);
        assert!(f.occupancy() > 0.01);
        assert_eq!(f, caster.render_reference(&[0.3, 0.05]));
    }
}

#[test]
fn mesh_paths_resolve() {
    let dir = Path::new("/robots/pkg/urdf");
    assert_eq!(
        resolve_mesh_path(dir, "package://pkg/meshes/a.stl"),
        Path::new("/robots/pkg/meshes/a.stl")
    );
    // Unknown package name: the conventional layout NAME/urdf/robot.urdf.
    assert_eq!(
        resolve_mesh_path(dir, "package://other/meshes/a.stl"),
        Path::new("/robots/pkg/meshes/a.stl")
    );
    assert_eq!(
        resolve_mesh_path(dir, "../meshes/a.stl"),
        Path::new("/robots/pkg/urdf/../meshes/a.stl")
    );
    assert_eq!(
        resolve_mesh_path(dir, "file:///m/a.stl"),
        Path::new("/m/a.stl")
    );
}

fn expect_urdf_error(urdf: &Path, needles: &[&str]) {
    let err = load_urdf(urdf, Isometry3::identity()).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains(&urdf.display().to_string()) || matches!(err, Error::Mesh { .. }),
        "file not named: {msg}"
    );
    for n in needles {
        assert!(msg.contains(n), "expected \"{n}\" in: {msg}");
    }
}

#[test]
fn bad_urdfs_are_clear_errors() {
    let dir = common::tempdir();
    let urdf = package(
        dir.path(),
        "floating",
        "package://pkg/meshes/cube.stl",
        true,
    );
    expect_urdf_error(&urdf, &["joint \"j0\"", "unsupported joint type"]);

    let urdf = package(
        dir.path(),
        "revolute",
        "package://pkg/meshes/missing.stl",
        true,
    );
    expect_urdf_error(&urdf, &["link \"tool\"", "missing.stl", "not found"]);

    let urdf = package(
        dir.path(),
        "revolute",
        "package://pkg/meshes/cube.ply",
        true,
    );
    std::fs::write(dir.path().join("pkg/meshes/cube.ply"), "ply\n").unwrap();
    expect_urdf_error(
        &urdf,
        &["cube.ply", "unsupported mesh format", "STL, COLLADA"],
    );

    std::fs::write(&urdf, "<robot name='x'><link name='a'></robot>").unwrap();
    expect_urdf_error(&urdf, &["not a valid URDF"]);

    std::fs::write(
        &urdf,
        robot_xml("revolute", "package://pkg/meshes/cube.stl")
            .replace("<parent link=\"arm\"/>", "<parent link=\"nope\"/>"),
    )
    .unwrap();
    expect_urdf_error(&urdf, &["joint \"j1\"", "unknown link \"nope\""]);

    let missing = dir.path().join("none.urdf");
    expect_urdf_error(&missing, &["No such file"]);

    // A corrupt STL names the mesh file.
    let urdf = package(
        dir.path(),
        "revolute",
        "package://pkg/meshes/cube.stl",
        true,
    );
    let stl = dir.path().join("pkg/meshes/cube.stl");
    std::fs::write(
        &stl,
        b"solid x\nfacet normal 0 0 0\nouter loop\nvertex 1 2\n",
    )
    .unwrap();
    let msg = load_urdf(&urdf, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("cube.stl") && msg.contains("not a valid STL"),
        "{msg}"
    );
}

/// Bad input, round 3: descriptions and meshes that panicked, overflowed the stack, blocked
/// or were accepted wrongly are refused with one line naming the file.
#[test]
fn damaged_deep_duplicate_and_unreadable_descriptions_are_refused() {
    let dir = common::tempdir();
    let d = dir.path();
    let good = robot_xml("revolute", "package://pkg/meshes/cube.stl");
    let urdf = package(d, "revolute", "package://pkg/meshes/cube.stl", true);
    // Two joints, or two links, of one name.
    std::fs::write(&urdf, good.replace("name=\"j1\"", "name=\"j0\"")).unwrap();
    expect_urdf_error(&urdf, &["joint \"j0\"", "named twice"]);
    std::fs::write(
        &urdf,
        good.replace("link name=\"slider\"", "link name=\"arm\""),
    )
    .unwrap();
    expect_urdf_error(&urdf, &["link \"arm\"", "named twice"]);
    // Values no robot has (poses came out infinite).
    std::fs::write(
        &urdf,
        good.replace("xyz=\"0 0 0.2\"", "xyz=\"1e300 0 0.2\""),
    )
    .unwrap();
    expect_urdf_error(&urdf, &["joint \"j1\"", "origin", "within"]);
    std::fs::write(&urdf, good.replace("upper=\"0.1\"", "upper=\"1e300\"")).unwrap();
    expect_urdf_error(
        &urdf,
        &["joint \"j1\"", "limits must be finite numbers within"],
    );
    // 200,000 nested elements (a stack overflow after 21 s).
    let deep = format!(
        "<robot name='x'><link name='a'/>{}{}</robot>",
        "<g>".repeat(200_000),
        "</g>".repeat(200_000)
    );
    std::fs::write(&urdf, deep).unwrap();
    expect_urdf_error(&urdf, &["nest 200001 deep"]);
    // A folder, and (on Unix) a FIFO or a device as the description or as a mesh.
    let err = load_urdf(d, Isometry3::identity()).unwrap_err().to_string();
    assert!(err.contains("a folder"), "{err}");
    #[cfg(unix)]
    {
        let fifo = d.join("fifo.urdf");
        assert!(
            std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .unwrap()
                .success()
        );
        let err = load_urdf(&fifo, Isometry3::identity())
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a regular file"), "{err}");
        std::fs::write(&urdf, &good).unwrap();
        let mesh = d.join("pkg/meshes/cube.stl");
        std::fs::remove_file(&mesh).unwrap();
        std::os::unix::fs::symlink("/dev/zero", &mesh).unwrap();
        let err = load_urdf(&urdf, Isometry3::identity())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cube.stl") && err.contains("not a regular file"),
            "{err}"
        );
        // An OBJ whose materials file is a FIFO (it blocked forever) or /dev/zero (3.7 GB
        // read): the materials are not read (a silhouette needs none), the mesh loads.
        let obj = d.join("pkg/meshes/cube.obj");
        std::fs::write(&urdf, good.replace("cube.stl", "cube.obj")).unwrap();
        assert!(
            std::process::Command::new("mkfifo")
                .arg(d.join("pkg/meshes/mat.mtl"))
                .status()
                .unwrap()
                .success()
        );
        for mtl in ["mat.mtl", "/dev/zero"] {
            std::fs::write(&obj, format!("mtllib {mtl}\n{}", common::cube_obj(0.04))).unwrap();
            let robot = load_urdf(&urdf, Isometry3::identity()).unwrap();
            assert_eq!(robot.geometry[3].shapes().len(), 12);
        }
    }
    // A COLLADA unit of no length, and a COLLADA face pointing past its vertices (the mesh
    // loader panicked).
    let dae = d.join("pkg/meshes/cube.dae");
    std::fs::write(&urdf, good.replace("cube.stl", "cube.dae")).unwrap();
    for unit in ["0", "-1"] {
        std::fs::write(
            &dae,
            common::cube_collada(0.04, 1.0).replace("meter=\"1\"", &format!("meter=\"{unit}\"")),
        )
        .unwrap();
        let err = load_urdf(&urdf, Isometry3::identity())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cube.dae") && err.contains("not a positive length"),
            "{err}"
        );
    }
    // A 2 GB sparse mesh is refused by its size before it is read.
    let huge = d.join("pkg/meshes/huge.stl");
    std::fs::File::create(&huge)
        .unwrap()
        .set_len(2 << 30)
        .unwrap();
    std::fs::write(&urdf, good.replace("cube.stl", "huge.stl")).unwrap();
    let err = load_urdf(&urdf, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("huge.stl") && err.contains("2048 MiB, more than"),
        "{err}"
    );
    std::fs::remove_file(&huge).unwrap();
    // A COLLADA accessor claiming more data than it holds (an assertion inside the loader).
    std::fs::write(&urdf, good.replace("cube.stl", "cube.dae")).unwrap();
    let text = common::cube_collada(0.04, 1.0);
    let claimed = text.replacen("count=\"", "count=\"9999", 1);
    assert_ne!(claimed, text);
    std::fs::write(&dae, claimed).unwrap();
    let err = load_urdf(&urdf, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(err.contains("cube.dae") && !err.contains('\n'), "{err}");
    // An OBJ face of vertex 0 ("face index out of bounds (4294967295)").
    let obj = d.join("pkg/meshes/zero.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n").unwrap();
    std::fs::write(&urdf, good.replace("cube.stl", "zero.obj")).unwrap();
    let err = load_urdf(&urdf, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("line 4") && err.contains("numbers vertices from 1"),
        "{err}"
    );
    std::fs::write(&urdf, good.replace("cube.stl", "cube.dae")).unwrap();
    let text = common::cube_collada(0.04, 1.0);
    let at = text.find("<p>").unwrap() + 3;
    std::fs::write(&dae, format!("{}999999 {}", &text[..at], &text[at..])).unwrap();
    let err = load_urdf(&urdf, Isometry3::identity())
        .unwrap_err()
        .to_string();
    assert!(err.contains("cube.dae") && !err.contains('\n'), "{err}");
}

#[test]
fn a_description_is_read_once_per_version_of_its_file() {
    use selfmodel::sim::robots::{RobotSpec, description_reads};
    let dir = common::tempdir();
    let urdf = package(
        dir.path(),
        "revolute",
        "package://pkg/meshes/cube.stl",
        false,
    );
    let spec = RobotSpec::urdf_in_arm4_scene(urdf.clone());
    let first = spec.load().unwrap();
    let again = spec.load().unwrap();
    assert_eq!(
        description_reads(&urdf),
        1,
        "the second load read the file again"
    );
    assert_eq!(first.chain.joint_names(), again.chain.joint_names());
    assert_eq!(first.geometry.len(), again.geometry.len());
    // The robot carries the name reports give it: its path (and group), as its spec's label.
    assert_eq!(first.label, spec.label());
    assert!(first.label.ends_with("r.urdf"), "{}", first.label);
    // Kinematics only is another robot (no meshes), read once too.
    assert_eq!(spec.load_kinematics().unwrap().dof(), first.dof());
    assert_eq!(description_reads(&urdf), 2);
    // The file edited (a prismatic joint now): read again, and the edit shows.
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(
        &urdf,
        robot_xml("prismatic", "package://pkg/meshes/cube.stl"),
    )
    .unwrap();
    let edited = spec.load().unwrap();
    assert_eq!(description_reads(&urdf), 3);
    assert_eq!(edited.chain.joints[0].kind, JointKind::Prismatic);
}
