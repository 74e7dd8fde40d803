//! Obstacles: a scene in cuRobo's world-configuration YAML, so a cuRobo user's scene loads as
//! it is. Top-level keys `cuboid`, `sphere`, `capsule`, `cylinder` and `mesh`, each a map from
//! an obstacle's name to its entry:
//!
//! ```yaml
//! cuboid:
//!   table: {dims: [2.0, 2.0, 0.2], pose: [0.0, 0.0, -0.1, 1, 0, 0, 0]}  # x y z, qw qx qy qz
//! sphere:
//!   ball: {radius: 0.05, pose: [0.5, 0.0, 0.4, 1, 0, 0, 0]}               # or position: [x, y, z]
//! capsule:
//!   bar: {radius: 0.03, base: [0, 0, 0], tip: [0, 0, 0.5], pose: [0.4, 0.3, 0, 1, 0, 0, 0]}
//! cylinder:
//!   post: {radius: 0.05, height: 0.6, pose: [0.4, -0.3, 0.3, 1, 0, 0, 0]}
//! mesh:
//!   bin: {file_path: bin.stl, pose: [0.6, 0, 0, 1, 0, 0, 0], scale: [1, 1, 1]}
//! ```
//!
//! Lengths in metres, poses in the world (the robot's base frame), quaternions w first as
//! cuRobo writes them; what an obstacle carries for drawing (`color`, `texture`, `material`,
//! ...: [`DRAWING`]) is read and ignored; any other key is refused.
//! A mesh's path is relative to the scene file; it is covered by spheres as a link is
//! ([`crate::sim::collision::spheres`]), so the check stays conservative.

use crate::sim::collision::exact::ExactShapes;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::core::error::{Error, Result};
use crate::sim::collision::spheres::{Sphere, SphereBudget, SphereFit, fit_link};

/// One obstacle in the world frame.
#[derive(Clone, Debug)]
pub enum Obstacle {
    Cuboid {
        pose: Isometry3<f64>,
        half: Vector3<f64>,
    },
    Sphere {
        center: Point3<f64>,
        radius: f64,
    },
    /// The segment `a`-`b` swept by `radius`.
    Capsule {
        a: Point3<f64>,
        b: Point3<f64>,
        radius: f64,
    },
    /// Along the local z axis of `pose`, centred on it.
    Cylinder {
        pose: Isometry3<f64>,
        radius: f64,
        half_height: f64,
    },
    /// A mesh, as spheres covering it.
    Spheres(Vec<Sphere>),
}

impl Obstacle {
    /// Its exact shape, for the narrow phase.
    pub fn exact(&self) -> ExactShapes {
        match self {
            Obstacle::Cuboid { pose, half } => ExactShapes::cuboid(pose, half),
            Obstacle::Sphere { center, radius } => ExactShapes::balls(&[Sphere {
                center: [center.x, center.y, center.z],
                radius: *radius,
            }]),
            Obstacle::Capsule { a, b, radius } => ExactShapes::capsule(a, b, *radius),
            Obstacle::Cylinder {
                pose,
                radius,
                half_height,
            } => ExactShapes::cylinder(pose, *radius, *half_height),
            Obstacle::Spheres(spheres) => ExactShapes::balls(spheres),
        }
    }

    /// The signed distance from `p` to the obstacle's surface (negative inside).
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        match self {
            Obstacle::Cuboid { pose, half } => {
                let q = pose.inverse_transform_point(p);
                let d = q.coords.abs() - half;
                let outside = d.map(|v| v.max(0.0)).norm();
                outside + d.max().min(0.0)
            }
            Obstacle::Sphere { center, radius } => (p - center).norm() - radius,
            Obstacle::Capsule { a, b, radius } => {
                let ab = b - a;
                let t = ((p - a).dot(&ab) / ab.norm_squared().max(1e-300)).clamp(0.0, 1.0);
                (p - (a + ab * t)).norm() - radius
            }
            Obstacle::Cylinder {
                pose,
                radius,
                half_height,
            } => {
                let q = pose.inverse_transform_point(p);
                let radial = (q.x * q.x + q.y * q.y).sqrt() - radius;
                let axial = q.z.abs() - half_height;
                radial.max(axial).min(0.0)
                    + Vector3::new(radial.max(0.0), axial.max(0.0), 0.0).norm()
            }
            Obstacle::Spheres(spheres) => spheres
                .iter()
                .map(|s| (p - s.center()).norm() - s.radius)
                .fold(f64::INFINITY, f64::min),
        }
    }
}

/// The obstacles of a scene, with their names.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub obstacles: Vec<(String, Obstacle)>,
    /// The obstacles' exact shapes, built the first time the exact check asks.
    exact: std::sync::OnceLock<Vec<ExactShapes>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    #[serde(default)]
    cuboid: BTreeMap<String, Drawn<CuboidEntry>>,
    #[serde(default)]
    sphere: BTreeMap<String, Drawn<SphereEntry>>,
    #[serde(default)]
    capsule: BTreeMap<String, Drawn<CapsuleEntry>>,
    #[serde(default)]
    cylinder: BTreeMap<String, Drawn<CylinderEntry>>,
    #[serde(default)]
    mesh: BTreeMap<String, Drawn<MeshEntry>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CuboidEntry {
    dims: [f64; 3],
    pose: [f64; 7],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SphereEntry {
    radius: f64,
    #[serde(default)]
    pose: Option<[f64; 7]>,
    #[serde(default)]
    position: Option<[f64; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CapsuleEntry {
    radius: f64,
    base: [f64; 3],
    tip: [f64; 3],
    pose: [f64; 7],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CylinderEntry {
    radius: f64,
    height: f64,
    pose: [f64; 7],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshEntry {
    file_path: PathBuf,
    pose: [f64; 7],
    #[serde(default)]
    scale: Option<[f64; 3]>,
}

/// A scene entry's geometry `S`, read past what it carries for drawing ([`DRAWING`];
/// any value): `S` refuses every other key it does not know.
struct Drawn<S>(S);

impl<'de, S: Deserialize<'de>> Deserialize<'de> for Drawn<S> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct Entry<S>(std::marker::PhantomData<S>);
        impl<'de, S: Deserialize<'de>> serde::de::Visitor<'de> for Entry<S> {
            type Value = S;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a mapping of the entry's fields")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                map: A,
            ) -> std::result::Result<S, A::Error> {
                S::deserialize(SkipDrawing(map))
            }
        }
        d.deserialize_map(Entry(std::marker::PhantomData))
            .map(Drawn)
    }
}

/// What cuRobo's obstacles carry for drawing or bookkeeping (any value): read and ignored.
const DRAWING: &[&str] = &[
    "color",
    "texture",
    "texture_id",
    "material",
    "name",
    "vertex_colors",
    "vertex_normals",
    "face_colors",
    "voxel_size",
    "tensor_args",
];

/// A mapping without the keys of [`DRAWING`].
struct SkipDrawing<A>(A);

impl<'de, A: serde::de::MapAccess<'de>> serde::Deserializer<'de> for SkipDrawing<A> {
    type Error = A::Error;
    fn deserialize_any<V: serde::de::Visitor<'de>>(
        self,
        visitor: V,
    ) -> std::result::Result<V::Value, A::Error> {
        visitor.visit_map(self)
    }
    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map struct enum identifier
        ignored_any
    }
}

impl<'de, A: serde::de::MapAccess<'de>> serde::de::MapAccess<'de> for SkipDrawing<A> {
    type Error = A::Error;
    fn next_key_seed<K: serde::de::DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> std::result::Result<Option<K::Value>, A::Error> {
        use serde::de::IntoDeserializer;
        while let Some(key) = self.0.next_key::<String>()? {
            if !DRAWING.contains(&key.as_str()) {
                return seed.deserialize(key.into_deserializer()).map(Some);
            }
            self.0.next_value::<serde::de::IgnoredAny>()?;
        }
        Ok(None)
    }
    fn next_value_seed<V: serde::de::DeserializeSeed<'de>>(
        &mut self,
        seed: V,
    ) -> std::result::Result<V::Value, A::Error> {
        self.0.next_value_seed(seed)
    }
}

/// What a scene file should be, for the parser's error.
const SCENE: &str = "a scene as cuRobo writes one";
/// The largest length a scene may give (m): beyond it, a typo.
const MAX_LENGTH_M: f64 = 1e4;

/// Where a scene at `scene` finds a mesh it names.
fn mesh_path(scene: &Path, file: &Path) -> PathBuf {
    scene.parent().unwrap_or(Path::new(".")).join(file)
}

impl Scene {
    /// The files a scene at `path` reads: itself and the meshes it names (what an `out`
    /// must not be), from its text alone.
    pub fn files(path: &Path) -> Result<Vec<PathBuf>> {
        let file: SceneFile = crate::sim::collision::read_yaml(path, "scene file", SCENE)?;
        let meshes = file
            .mesh
            .values()
            .map(|Drawn(m)| mesh_path(path, &m.file_path));
        Ok(std::iter::once(path.to_path_buf()).chain(meshes).collect())
    }

    /// Read a cuRobo world-configuration YAML file.
    pub fn read(path: &Path) -> Result<Self> {
        let file = crate::sim::collision::read_yaml(path, "scene file", SCENE)?;
        Self::from_file(path, file)
    }

    /// Parse a scene's text (`path` names it in errors and places its meshes).
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        Self::from_file(path, crate::sim::collision::parse_yaml(path, SCENE, text)?)
    }

    fn from_file(path: &Path, file: SceneFile) -> Result<Self> {
        let bad = |msg: String| Error::Config(format!("{}: {msg}", path.display()));
        let length = |what: &str, name: &str, v: f64| {
            if v.is_finite() && v > 0.0 && v <= MAX_LENGTH_M {
                Ok(v)
            } else {
                Err(bad(format!(
                    "{what} of \"{name}\" is {}: give a positive length in metres",
                    crate::core::error::short_number(v)
                )))
            }
        };
        let mut obstacles = Vec::new();
        for (name, Drawn(c)) in &file.cuboid {
            let pose = pose_of(&bad, name, &c.pose)?;
            let mut half = Vector3::zeros();
            for k in 0..3 {
                half[k] = length("a side (dims)", name, c.dims[k])? / 2.0;
            }
            obstacles.push((name.clone(), Obstacle::Cuboid { pose, half }));
        }
        for (name, Drawn(s)) in &file.sphere {
            let radius = length("the radius", name, s.radius)?;
            let center = match (&s.pose, &s.position) {
                (Some(p), _) => Point3::from(pose_of(&bad, name, p)?.translation.vector),
                (None, Some(p)) => Point3::from(finite3(&bad, name, p)?),
                (None, None) => {
                    return Err(bad(format!("sphere \"{name}\" has no pose or position")));
                }
            };
            obstacles.push((name.clone(), Obstacle::Sphere { center, radius }));
        }
        for (name, Drawn(c)) in &file.capsule {
            let pose = pose_of(&bad, name, &c.pose)?;
            let radius = length("the radius", name, c.radius)?;
            let (a, b) = (finite3(&bad, name, &c.base)?, finite3(&bad, name, &c.tip)?);
            obstacles.push((
                name.clone(),
                Obstacle::Capsule {
                    a: pose * Point3::from(a),
                    b: pose * Point3::from(b),
                    radius,
                },
            ));
        }
        for (name, Drawn(c)) in &file.cylinder {
            let pose = pose_of(&bad, name, &c.pose)?;
            let radius = length("the radius", name, c.radius)?;
            let half_height = length("the height", name, c.height)? / 2.0;
            obstacles.push((
                name.clone(),
                Obstacle::Cylinder {
                    pose,
                    radius,
                    half_height,
                },
            ));
        }
        for (name, Drawn(m)) in &file.mesh {
            let pose = pose_of(&bad, name, &m.pose)?;
            let scale = match &m.scale {
                Some(s) => {
                    let mut v = Vector3::zeros();
                    for k in 0..3 {
                        v[k] = length("a scale", name, s[k])?;
                    }
                    v
                }
                None => Vector3::new(1.0, 1.0, 1.0),
            };
            let file = mesh_path(path, &m.file_path);
            if !file.is_file() {
                return Err(bad(format!(
                    "the mesh of \"{name}\", {}, is not a file: give its path relative to the scene file",
                    file.display()
                )));
            }
            let shapes = crate::sim::mesh_file::load_mesh(&file, scale, &pose)?;
            let fit = SphereFit {
                budget: SphereBudget::Shaped { most: 64 },
                ..SphereFit::default()
            };
            let spheres = fit_link(&shapes, &fit).map_err(|e| match e {
                Error::Config(why) => bad(format!("the mesh of \"{name}\": {why}")),
                other => other,
            })?;
            obstacles.push((name.clone(), Obstacle::Spheres(spheres)));
        }
        Ok(Scene {
            obstacles,
            exact: Default::default(),
        })
    }

    /// Each obstacle's exact shapes (in the world), in order.
    pub fn exact(&self) -> &[ExactShapes] {
        self.exact
            .get_or_init(|| (self.obstacles.iter()).map(|(_, o)| o.exact()).collect())
    }

    /// The smallest signed distance from a sphere at `center` of `radius` to any obstacle.
    pub fn gap(&self, center: &Point3<f64>, radius: f64) -> f64 {
        self.obstacles
            .iter()
            .map(|(_, o)| o.distance(center) - radius)
            .fold(f64::INFINITY, f64::min)
    }
}

fn finite3(bad: &dyn Fn(String) -> Error, name: &str, v: &[f64; 3]) -> Result<Vector3<f64>> {
    if v.iter().all(|x| x.is_finite() && x.abs() <= MAX_LENGTH_M) {
        Ok(Vector3::from(*v))
    } else {
        Err(bad(format!(
            "\"{name}\" has a coordinate that is not a finite number of metres (at most 1e4)"
        )))
    }
}

/// A cuRobo pose `[x, y, z, qw, qx, qy, qz]` (the quaternion normalised).
fn pose_of(bad: &dyn Fn(String) -> Error, name: &str, p: &[f64; 7]) -> Result<Isometry3<f64>> {
    let t = finite3(bad, name, &[p[0], p[1], p[2]])?;
    // Scaled by its largest part before it is normalised: the norm of (1e200, 0, 0, 0)
    // overflows, and a quaternion is a rotation at any scale.
    let largest = p[3..].iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let q = Quaternion::new(p[3], p[4], p[5], p[6]) / largest;
    if !p[3..].iter().all(|x| x.is_finite()) || largest == 0.0 {
        return Err(bad(format!(
            "the pose of \"{name}\" has no rotation: its quaternion (qw, qx, qy, qz: the last four numbers) must be finite and not zero"
        )));
    }
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_quaternion(q),
    ))
}
