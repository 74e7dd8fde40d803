//! A collision model kept in a file (`collision.json` beside a saved IK model, written by
//! `ik train`): each link's spheres and the checked pairs, with a key of everything they were
//! computed from (the links' collision shapes, the joints, the SRDF's text, the fit's and the
//! pair sampling's settings). A file whose key differs is ignored and the model computed
//! again: a changed mesh or SRDF never gives stale spheres.

use std::path::Path;

use crate::core::error::Result;
use crate::sim::collision::model::CollisionModel;
use crate::sim::collision::pairs::PairSampling;
use crate::sim::collision::spheres::{Sphere, SphereFit};
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;

/// The file's name in a model's folder.
pub const FILE: &str = "collision.json";

/// What the file holds.
#[derive(serde::Serialize, serde::Deserialize)]
struct Cached {
    key: String,
    /// Each link's spheres, by the link's name.
    spheres: Vec<(String, Vec<Sphere>)>,
    /// The checked pairs, by the links' names.
    pairs: Vec<[String; 2]>,
}

/// The key of a model of `robot` (loaded with its collision geometry) computed with `fit`,
/// `sampling` and the SRDF text `srdf`.
pub fn key(robot: &Robot, srdf: Option<&str>, fit: &SphereFit, sampling: &PairSampling) -> String {
    let mut bytes = Vec::new();
    let mut put = |v: f64| bytes.extend_from_slice(&v.to_le_bytes());
    for (g, link) in robot.geometry.iter().zip(&robot.chain.links) {
        put(link.len() as f64);
        for s in g.shapes() {
            match s {
                Shape::Triangle(t) => t.iter().flat_map(|p| p.coords.iter()).for_each(|&v| put(v)),
                Shape::Cuboid { pose, half } => pose
                    .to_homogeneous()
                    .iter()
                    .chain(half.iter())
                    .for_each(|&v| put(v)),
                Shape::Cylinder {
                    pose,
                    radius,
                    half_length,
                } => (pose.to_homogeneous().iter())
                    .chain([radius, half_length])
                    .for_each(|&v| put(v)),
                Shape::Sphere { center, radius } => {
                    center.coords.iter().chain([radius]).for_each(|&v| put(v))
                }
            }
        }
    }
    let settings = serde_json::json!({
        "links": robot.chain.links,
        "joints": robot.chain.fingerprint(),
        "srdf": srdf,
        "fit": fit,
        "sampling": sampling,
    });
    bytes.extend_from_slice(settings.to_string().as_bytes());
    crate::core::input_file::fnv(&bytes)
}

/// The model in `dir`'s file where its key is `key` (None: no file, another key, or a file
/// that does not read).
pub fn read(dir: &Path, key: &str, robot: &Robot) -> Option<CollisionModel> {
    let text = std::fs::read_to_string(dir.join(FILE)).ok()?;
    let cached: Cached = serde_json::from_str(&text).ok()?;
    if cached.key != key {
        return None;
    }
    let links = &robot.chain.links;
    let index = |name: &str| links.iter().position(|l| l == name);
    let mut spheres = vec![Vec::new(); links.len()];
    for (name, s) in cached.spheres {
        spheres[index(&name)?] = s;
    }
    let pairs = (cached.pairs.iter())
        .map(|[a, b]| Some((index(a)?, index(b)?)))
        .collect::<Option<Vec<_>>>()?;
    Some(CollisionModel::with_pairs(&robot.chain, spheres, pairs))
}

/// Write `model` (of `robot`) with its `key` into `dir`'s file.
pub fn write(dir: &Path, key: &str, robot: &Robot, model: &CollisionModel) -> Result<()> {
    let links = &robot.chain.links;
    let cached = Cached {
        key: key.into(),
        spheres: (links.iter().cloned())
            .zip(model.spheres.iter().cloned())
            .collect(),
        pairs: (model.pairs.iter())
            .map(|&(a, b)| [links[a].clone(), links[b].clone()])
            .collect(),
    };
    crate::core::atomic_file::write_json(&dir.join(FILE), &cached)
}
