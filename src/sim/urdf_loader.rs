//! Load a [`Robot`] from a URDF file (parsed by the `urdf-rs` crate), as ROS ships them.
//!
//! Supported: revolute, continuous, prismatic and fixed joints with limits, origins and
//! axes (a fixed joint's axis is ignored, as URDF says); `<mimic>` joints, which follow their
//! leader (`multiplier * leader + offset`) and are not inputs; geometry as box, cylinder,
//! sphere and mesh (STL, COLLADA `.dae`, OBJ, with `scale`), visual by default or collision
//! ([`GeometryKind`]), or none for kinematics only. Mesh paths may be relative to the URDF,
//! absolute, `file://` or `package://NAME/...`; the last is resolved against the URDF's
//! package folder: the nearest ancestor folder of the URDF named `NAME`, else the parent of
//! the URDF's folder (the conventional `NAME/urdf/robot.urdf` layout). xacro files (xacro
//! elements, `${...}` or `$(...)` outside comments) are refused with how to expand them; a file
//! that only declares the xacro namespace, as expanded ROS descriptions do, loads. What ROS's
//! urdfdom tolerates and urdf-rs refuses (a `<texture/>` without a filename) loads too.
//!
//! The end effector is the origin of a link named by `tip`, by default the last link of the
//! longest chain; the joint vector is the chain from the root to it (see
//! [`KinematicChain::new`]).

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::core::error::{Error, Result};
use crate::sim::bvh::Bvh;
use crate::sim::kinematics::{Joint, JointGroup, JointKind, KinematicChain, Mimic};
use crate::sim::mesh_file::load_mesh;
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;

/// Which of a link's geometry the robot is drawn with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum GeometryKind {
    /// The `<visual>` elements (what a camera sees).
    #[default]
    Visual,
    /// The `<collision>` elements (usually coarser meshes: faster to render).
    Collision,
    /// None: kinematics only (no mesh is read).
    None,
}

/// How a URDF is loaded.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfOptions {
    /// Where the root link sits in the scene.
    pub base: Isometry3<f64>,
    /// The end-effector link (its origin); `None`: the last link of the longest chain.
    pub tip: Option<String>,
    pub geometry: GeometryKind,
    /// Which movable joints are the joint vector (the chain to the tip by default).
    pub joints: JointGroup,
}

impl Default for UrdfOptions {
    fn default() -> Self {
        UrdfOptions {
            base: Isometry3::identity(),
            tip: None,
            geometry: GeometryKind::Visual,
            joints: JointGroup::Chain,
        }
    }
}

/// Largest mesh scale factor accepted (a `scale` beyond it is a typo, not a robot).
const MAX_SCALE: f64 = 1e3;

/// A URDF `<origin xyz rpy>` as a rigid transform (rpy: fixed-axis roll, pitch, yaw).
pub fn pose_from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// The largest number a joint's origin, limits or mimic may hold (metres, radians): far
/// beyond any robot, small enough that poses stay finite.
pub const MAX_VALUE: f64 = 1e4;

/// The first xacro construct outside comments (`<xacro:...`, `${...}`, `$(...)`), if any: a
/// file that only declares the xacro namespace, as ROS packages ship expanded descriptions,
/// or mentions xacro in a comment, is the URDF it looks like.
fn xacro_construct(text: &str) -> Option<String> {
    let text = crate::core::input_file::without_comments(text);
    ["<xacro:", "${", "$("].iter().find_map(|needle| {
        let at = text.find(needle)?;
        let end = text[at..]
            .find(|c: char| c.is_whitespace() || c == '>' || c == '"')
            .map_or(text.len(), |e| at + e.max(needle.len()));
        Some(text[at..end.min(at + 40)].to_string())
    })
}

/// What ROS's own parser (urdfdom) tolerates and urdf-rs refuses, made readable: `<texture>`
/// elements without a filename (urdfdom ignores them) are dropped.
fn as_urdfdom_reads(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.contains("<texture") {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(start) = rest.find("<texture") {
        out.push_str(&rest[..start]);
        let tail = &rest[start..];
        // The element: self-closing, or up to its closing tag.
        let open_end = tail.find('>').map_or(tail.len(), |e| e + 1);
        let end = if tail[..open_end].ends_with("/>") {
            open_end
        } else {
            tail.find("</texture>")
                .map_or(open_end, |e| e + "</texture>".len())
        };
        if tail[..open_end].contains("filename") {
            out.push_str(&tail[..end]);
        }
        rest = &tail[end..];
    }
    out.push_str(rest);
    std::borrow::Cow::Owned(out)
}

/// Load a URDF with its visual geometry and the default tip; `base` places its root link.
pub fn load_urdf(path: &Path, base: Isometry3<f64>) -> Result<Robot> {
    load_urdf_with(
        path,
        &UrdfOptions {
            base,
            ..UrdfOptions::default()
        },
    )
}

/// Load a URDF as `options` say: parsed and checked, its joints read, the chain built for the
/// tip or group asked for, each link's geometry loaded.
pub fn load_urdf_with(path: &Path, options: &UrdfOptions) -> Result<Robot> {
    let urdf = parse(path)?;
    let link_names: Vec<String> = urdf.links.iter().map(|l| l.name.clone()).collect();
    let joints = urdf
        .joints
        .iter()
        .map(|j| joint_from_urdf(path, j, &urdf, &link_names))
        .collect::<Result<Vec<Joint>>>()?;
    let tip = tip_link(path, options, &link_names)?;
    let group = group_from_urdf(options, &urdf)?;
    let chain = KinematicChain::with_group(link_names.clone(), joints, options.base, tip, &group)
        .map_err(|e| urdf_err(path, "robot".into(), e.to_string()))?;
    // A description drawn by its collision elements only: say which option draws it, rather
    // than load a robot with nothing to see.
    if options.geometry == GeometryKind::Visual
        && urdf.links.iter().all(|l| l.visual.is_empty())
        && urdf.links.iter().any(|l| !l.collision.is_empty())
    {
        return Err(urdf_err(
            path,
            "robot".into(),
            "it has <collision> geometry but no <visual> element: load it with `geometry` collision, or `geometry` none for its kinematics alone".into(),
        ));
    }
    // Geometry, stored in the chain's link order.
    let geometry = chain
        .links
        .iter()
        .map(|name| {
            let link = urdf
                .links
                .iter()
                .find(|l| &l.name == name)
                .expect("link from this URDF");
            link_shapes(path, link, options.geometry).map(Bvh::new)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Robot {
        name: urdf.name.clone(),
        label: path.display().to_string(),
        chain,
        geometry,
    })
}

/// An error in `path`'s `element`.
fn urdf_err(path: &Path, element: String, msg: String) -> Error {
    Error::Urdf {
        path: path.into(),
        element,
        msg,
    }
}

/// The description at `path`, read as a bounded regular file and parsed: not a xacro file, not
/// nested deeper than a robot's XML, at least one link, no link or joint named twice.
fn parse(path: &Path) -> Result<urdf_rs::Robot> {
    let text = crate::core::input_file::read_xml(path, "robot description")?;
    let text = text.as_str();
    if let Some(found) = xacro_construct(text) {
        return Err(urdf_err(
            path,
            "robot".into(),
            format!(
                "is a xacro file (it has `{found}`): expand it into a URDF first (`xacro FILE > robot.urdf`, ROS's xacro package), then pass that"
            ),
        ));
    }
    crate::core::input_file::check_xml_depth(text)
        .map_err(|e| urdf_err(path, "robot".into(), e))?;
    let text = as_urdfdom_reads(text);
    let urdf = urdf_rs::read_from_string(&text)
        .map_err(|e| urdf_err(path, "robot".into(), format!("not a valid URDF: {e}")))?;
    if urdf.links.is_empty() {
        return Err(urdf_err(path, "robot".into(), "no <link> elements".into()));
    }
    let twice = |names: Vec<&String>| {
        (1..names.len())
            .find(|&i| names[..i].contains(&names[i]))
            .map(|i| names[i].clone())
    };
    if let Some(name) = twice(urdf.links.iter().map(|l| &l.name).collect()) {
        return Err(urdf_err(
            path,
            format!("link \"{name}\""),
            "is named twice: every link needs its own name".into(),
        ));
    }
    if let Some(name) = twice(urdf.joints.iter().map(|j| &j.name).collect()) {
        return Err(urdf_err(
            path,
            format!("joint \"{name}\""),
            "is named twice: every joint needs its own name".into(),
        ));
    }
    Ok(urdf)
}

/// One `<joint>` of `urdf`: its kind, axis, limits, origin and mimic checked, its links found
/// among `link_names`.
fn joint_from_urdf(
    path: &Path,
    j: &urdf_rs::Joint,
    urdf: &urdf_rs::Robot,
    link_names: &[String],
) -> Result<Joint> {
    let element = format!("joint \"{}\"", j.name);
    let err = |msg: String| urdf_err(path, element.clone(), msg);
    let kind = match j.joint_type {
        urdf_rs::JointType::Revolute => JointKind::Revolute,
        urdf_rs::JointType::Continuous => JointKind::Continuous,
        urdf_rs::JointType::Prismatic => JointKind::Prismatic,
        urdf_rs::JointType::Fixed => JointKind::Fixed,
        ref other => {
            return Err(err(format!(
                "unsupported joint type {other:?} (supported: revolute, continuous, prismatic, fixed)"
            )));
        }
    };
    // URDF ignores a fixed joint's axis (Franka ships `0 0 0` on one).
    let axis = if kind.is_movable() {
        let axis = Vector3::from(j.axis.xyz.0);
        if !axis.iter().all(|v| v.is_finite()) {
            return Err(err("axis is not finite".into()));
        }
        Unit::try_new(axis, 1e-12).ok_or_else(|| err("axis has zero length".into()))?
    } else {
        Vector3::z_axis()
    };
    let limits = match kind {
        JointKind::Revolute | JointKind::Prismatic => {
            let (lo, hi) = (j.limit.lower, j.limit.upper);
            if !(lo.is_finite() && hi.is_finite() && lo.abs() <= MAX_VALUE && hi.abs() <= MAX_VALUE)
            {
                return Err(err(format!(
                    "<limit lower=\"{lo}\" upper=\"{hi}\">: limits must be finite numbers within +-{MAX_VALUE} (radians or metres)"
                )));
            }
            if lo > hi {
                return Err(err(format!(
                    "<limit lower=\"{lo}\" upper=\"{hi}\">: lower is above upper"
                )));
            }
            // lower = upper (both absent reads as 0, 0): no range stated.
            (lo < hi).then_some([lo, hi])
        }
        _ => None,
    };
    let values = j.origin.xyz.0.iter().chain(&j.origin.rpy.0);
    if values
        .clone()
        .any(|v| !(v.is_finite() && v.abs() <= MAX_VALUE))
    {
        return Err(err(format!(
            "<origin xyz=\"{:?}\" rpy=\"{:?}\">: values must be finite and within +-{MAX_VALUE} (metres, radians)",
            j.origin.xyz.0, j.origin.rpy.0
        )));
    }
    let mimic = match &j.mimic {
        Some(m) if kind.is_movable() => {
            let leader = urdf
                .joints
                .iter()
                .position(|l| l.name == m.joint)
                .ok_or_else(|| err(format!("<mimic> names unknown joint \"{}\"", m.joint)))?;
            let (multiplier, offset) = (m.multiplier.unwrap_or(1.0), m.offset.unwrap_or(0.0));
            if !(multiplier.is_finite()
                && offset.is_finite()
                && multiplier.abs() <= MAX_VALUE
                && offset.abs() <= MAX_VALUE)
            {
                return Err(err("<mimic> multiplier and offset must be finite".into()));
            }
            Some(Mimic {
                leader,
                multiplier,
                offset,
            })
        }
        _ => None,
    };
    let find_link = |name: &str| {
        link_names
            .iter()
            .position(|l| l == name)
            .ok_or_else(|| err(format!("refers to unknown link \"{name}\"")))
    };
    Ok(Joint {
        name: j.name.clone(),
        kind,
        parent: find_link(&j.parent.link)?,
        child: find_link(&j.child.link)?,
        origin: pose_from_xyz_rpy(j.origin.xyz.0, j.origin.rpy.0),
        axis,
        limits,
        mimic,
    })
}

/// The link `tip` names (its origin), if it names one.
fn tip_link(
    path: &Path,
    options: &UrdfOptions,
    link_names: &[String],
) -> Result<Option<(usize, Point3<f64>)>> {
    let Some(tip) = &options.tip else {
        return Ok(None);
    };
    match link_names.iter().position(|l| l == tip) {
        Some(l) => Ok(Some((l, Point3::origin()))),
        None => Err(urdf_err(
            path,
            "robot".into(),
            format!(
                "`tip` \"{tip}\" is not a link of this robot; its links: {}",
                link_names.join(", ")
            ),
        )),
    }
}

/// The joints `options` ask for, an SRDF group resolved against `urdf`'s tree.
fn group_from_urdf(options: &UrdfOptions, urdf: &urdf_rs::Robot) -> Result<JointGroup> {
    match &options.joints {
        JointGroup::Srdf { file, group } => {
            let tree: Vec<crate::sim::srdf::TreeJoint> = urdf
                .joints
                .iter()
                .map(|j| (j.name.clone(), j.parent.link.clone(), j.child.link.clone()))
                .collect();
            let members = crate::sim::srdf::Srdf::read(file)?.resolve(group, &tree)?;
            Ok(JointGroup::Members {
                joints: members.joints,
                tips: members.tips,
            })
        }
        other => Ok(other.clone()),
    }
}

/// The shapes of `link`'s visual or collision elements (none for [`GeometryKind::None`]),
/// meshes read relative to the description's folder.
fn link_shapes(path: &Path, link: &urdf_rs::Link, kind: GeometryKind) -> Result<Vec<Shape>> {
    let parts: Vec<(&urdf_rs::Pose, &urdf_rs::Geometry)> = match kind {
        GeometryKind::Visual => link
            .visual
            .iter()
            .map(|v| (&v.origin, &v.geometry))
            .collect(),
        GeometryKind::Collision => link
            .collision
            .iter()
            .map(|c| (&c.origin, &c.geometry))
            .collect(),
        GeometryKind::None => Vec::new(),
    };
    let mut shapes = Vec::new();
    for (origin, geometry) in parts {
        shapes.extend(shapes_from_urdf(path, &link.name, origin, geometry)?);
    }
    Ok(shapes)
}

/// One `<geometry>` of link `link` at `origin`: a box, cylinder or sphere checked for size, or
/// a mesh's triangles.
fn shapes_from_urdf(
    path: &Path,
    link: &str,
    origin: &urdf_rs::Pose,
    geometry: &urdf_rs::Geometry,
) -> Result<Vec<Shape>> {
    let element = format!("link \"{link}\"");
    let err = |msg: String| urdf_err(path, element.clone(), msg);
    if origin
        .xyz
        .0
        .iter()
        .chain(&origin.rpy.0)
        .any(|v| !v.is_finite())
    {
        return Err(err("a geometry origin is not finite".into()));
    }
    let pose = pose_from_xyz_rpy(origin.xyz.0, origin.rpy.0);
    let size = |v: f64, what: &str| {
        if v.is_finite() && v > 0.0 && v <= MAX_VALUE {
            Ok(v)
        } else {
            Err(err(format!(
                "{what} must be a positive number of at most {MAX_VALUE} m, got {}",
                crate::core::error::short_number(v)
            )))
        }
    };
    Ok(match geometry {
        urdf_rs::Geometry::Box { size: s } => vec![Shape::Cuboid {
            pose,
            half: Vector3::new(
                size(s.0[0], "box size")?,
                size(s.0[1], "box size")?,
                size(s.0[2], "box size")?,
            ) / 2.0,
        }],
        urdf_rs::Geometry::Cylinder { radius, length } => vec![Shape::Cylinder {
            pose,
            radius: size(*radius, "cylinder radius")?,
            half_length: size(*length, "cylinder length")? / 2.0,
        }],
        urdf_rs::Geometry::Sphere { radius } => vec![Shape::Sphere {
            center: pose * Point3::origin(),
            radius: size(*radius, "sphere radius")?,
        }],
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let dir = path.parent().unwrap_or(Path::new("."));
            let file = resolve_mesh_path(dir, filename);
            // Missing here; a folder, FIFO or device is refused where it is read.
            if std::fs::metadata(&file).is_err() {
                return Err(err(format!(
                    "mesh \"{filename}\" not found (looked for {})",
                    file.display()
                )));
            }
            let scale = scale
                .as_ref()
                .map_or(Vector3::repeat(1.0), |s| Vector3::from(s.0));
            if scale
                .iter()
                .any(|s| !s.is_finite() || *s == 0.0 || s.abs() > MAX_SCALE)
            {
                return Err(err(format!(
                    "mesh \"{filename}\": scale {} {} {} must be non-zero and at most {MAX_SCALE} in size",
                    scale.x, scale.y, scale.z
                )));
            }
            load_mesh(&file, scale, &pose)?
        }
        urdf_rs::Geometry::Capsule { .. } => {
            return Err(err(
                "capsule geometry is not supported (use box, cylinder, sphere or a mesh)".into(),
            ));
        }
    })
}

/// Every mesh file the description at `path` names, visual and collision (what an `out`
/// must not be); none where it does not parse (its loading then says why).
pub fn mesh_files(path: &Path) -> Vec<PathBuf> {
    let Ok(urdf) = parse(path) else {
        return Vec::new();
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    let geometries = (urdf.links.iter()).flat_map(|l| {
        (l.visual.iter().map(|v| &v.geometry)).chain(l.collision.iter().map(|c| &c.geometry))
    });
    let mut files: Vec<PathBuf> = geometries
        .filter_map(|g| match g {
            urdf_rs::Geometry::Mesh { filename, .. } => Some(resolve_mesh_path(dir, filename)),
            _ => None,
        })
        .collect();
    files.sort();
    files.dedup();
    files
}

/// Where a URDF mesh reference points, relative to the URDF's folder `dir`.
pub fn resolve_mesh_path(dir: &Path, filename: &str) -> PathBuf {
    if let Some(rest) = filename.strip_prefix("package://") {
        // `package:///NAME/...` (three slashes, as some packages write it) is the same place.
        let rest = rest.trim_start_matches('/');
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
