//! Load a [`Robot`] from a URDF file (parsed by the `urdf-rs` crate).
//!
//! Supported: revolute, continuous, prismatic and fixed joints with limits, origins and
//! axes; visual geometry as box, cylinder, sphere and STL mesh (binary or ASCII, with
//! `scale`). Mesh paths may be relative to the URDF, absolute, `file://` or
//! `package://NAME/...`; the last is resolved against the URDF's package folder: the nearest
//! ancestor folder of the URDF named `NAME`, else the parent of the URDF's folder (the
//! conventional `NAME/urdf/robot.urdf` layout). Collision geometry is ignored.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::core::error::{Error, Result};
use crate::sim::bvh::Bvh;
use crate::sim::kinematics::{Joint, JointKind, KinematicChain};
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;
use crate::sim::stl_mesh::load_stl;

/// A URDF `<origin xyz rpy>` as a rigid transform (rpy: fixed-axis roll, pitch, yaw).
pub fn pose_from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// Load a URDF; `base` places its root link in the scene.
pub fn load_urdf(path: &Path, base: Isometry3<f64>) -> Result<Robot> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let urdf_err = |element: String, msg: String| Error::Urdf {
        path: path.into(),
        element,
        msg,
    };
    let urdf = urdf_rs::read_from_string(&text)
        .map_err(|e| urdf_err("robot".into(), format!("not a valid URDF: {e}")))?;
    if urdf.links.is_empty() {
        return Err(urdf_err("robot".into(), "no <link> elements".into()));
    }
    let link_names: Vec<String> = urdf.links.iter().map(|l| l.name.clone()).collect();
    let find_link = |joint: &str, name: &str| {
        link_names.iter().position(|l| l == name).ok_or_else(|| {
            urdf_err(
                format!("joint \"{joint}\""),
                format!("refers to unknown link \"{name}\""),
            )
        })
    };

    let mut joints = Vec::with_capacity(urdf.joints.len());
    for j in &urdf.joints {
        let element = format!("joint \"{}\"", j.name);
        let kind = match j.joint_type {
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Continuous => JointKind::Continuous,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Fixed => JointKind::Fixed,
            ref other => {
                return Err(urdf_err(
                    element,
                    format!(
                        "unsupported joint type {other:?} (supported: revolute, continuous, prismatic, fixed)"
                    ),
                ));
            }
        };
        let axis = Vector3::from(j.axis.xyz.0);
        let axis = Unit::try_new(axis, 1e-12)
            .ok_or_else(|| urdf_err(element.clone(), "axis has zero length".into()))?;
        let limits = match kind {
            JointKind::Revolute | JointKind::Prismatic => {
                let (lo, hi) = (j.limit.lower, j.limit.upper);
                (lo.is_finite() && hi.is_finite() && lo < hi).then_some([lo, hi])
            }
            _ => None,
        };
        let values = j.origin.xyz.0.iter().chain(&j.origin.rpy.0);
        if values.clone().any(|v| !v.is_finite()) {
            return Err(urdf_err(element, "origin is not finite".into()));
        }
        joints.push(Joint {
            name: j.name.clone(),
            kind,
            parent: find_link(&j.name, &j.parent.link)?,
            child: find_link(&j.name, &j.child.link)?,
            origin: pose_from_xyz_rpy(j.origin.xyz.0, j.origin.rpy.0),
            axis,
            limits,
        });
    }

    let chain = KinematicChain::new(link_names.clone(), joints, base, None)
        .map_err(|e| urdf_err("robot".into(), e.to_string()))?;

    // Geometry, stored in the chain's link order.
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut geometry = Vec::with_capacity(chain.links.len());
    for name in &chain.links {
        let link = urdf
            .links
            .iter()
            .find(|l| &l.name == name)
            .expect("link from this URDF");
        let mut shapes = Vec::new();
        for v in &link.visual {
            let pose = pose_from_xyz_rpy(v.origin.xyz.0, v.origin.rpy.0);
            let element = format!("link \"{}\"", link.name);
            match &v.geometry {
                urdf_rs::Geometry::Box { size } => shapes.push(Shape::Cuboid {
                    pose,
                    half: Vector3::from(size.0) / 2.0,
                }),
                urdf_rs::Geometry::Cylinder { radius, length } => shapes.push(Shape::Cylinder {
                    pose,
                    radius: *radius,
                    half_length: length / 2.0,
                }),
                urdf_rs::Geometry::Sphere { radius } => shapes.push(Shape::Sphere {
                    center: pose * Point3::origin(),
                    radius: *radius,
                }),
                urdf_rs::Geometry::Mesh { filename, scale } => {
                    let file = resolve_mesh_path(dir, filename);
                    let ext = file.extension().map(|e| e.to_string_lossy().to_lowercase());
                    if ext.as_deref() != Some("stl") {
                        return Err(urdf_err(
                            element,
                            format!("mesh \"{filename}\": only STL meshes are supported"),
                        ));
                    }
                    if !file.is_file() {
                        return Err(urdf_err(
                            element,
                            format!(
                                "mesh \"{filename}\" not found (looked for {})",
                                file.display()
                            ),
                        ));
                    }
                    let scale = scale
                        .as_ref()
                        .map_or(Vector3::repeat(1.0), |s| Vector3::from(s.0));
                    shapes.extend(load_stl(&file, scale, &pose)?);
                }
                urdf_rs::Geometry::Capsule { .. } => {
                    return Err(urdf_err(element, "capsule geometry is not supported (use box, cylinder, sphere or an STL mesh)".into()));
                }
            }
        }
        geometry.push(Bvh::new(shapes));
    }
    Ok(Robot {
        name: urdf.name.clone(),
        chain,
        geometry,
    })
}

/// Where a URDF mesh reference points, relative to the URDF's folder `dir`.
pub fn resolve_mesh_path(dir: &Path, filename: &str) -> PathBuf {
    if let Some(rest) = filename.strip_prefix("package://") {
        let (package, inner) = rest.split_once('/').unwrap_or((rest, ""));
        let dir = std::path::absolute(dir).unwrap_or_else(|_| dir.to_path_buf());
        let root = dir
            .ancestors()
            .find(|a| a.file_name().is_some_and(|n| n == package))
            .map(Path::to_path_buf)
            .unwrap_or_else(|| dir.parent().unwrap_or(&dir).to_path_buf());
        return root.join(inner);
    }
    let plain = filename.strip_prefix("file://").unwrap_or(filename);
    let p = Path::new(plain);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        dir.join(p)
    }
}
