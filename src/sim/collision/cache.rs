//! A collision model kept in a file (`collision.json` beside a saved IK model, written by
//! `ik train`): each link's spheres and the checked pairs, with a key of everything they were
//! computed from (the links' collision shapes, the joints, the SRDF's text, the fit's and the
//! pair sampling's settings) and a hash of what it holds. A file whose key differs is
//! ignored and the model computed again: a changed mesh or SRDF never gives stale spheres.
//! A file that is not a bounded regular file of JSON, whose content no longer matches its
//! hash, or whose spheres do not cover the links' geometry as a fit does (a radius of 0 or
//! less, not finite, a link's spheres removed, moved or given to another link, a pair
//! naming a link the robot lacks) is refused in one line and never used.

use std::path::Path;

use crate::core::error::{Error, Result};
use crate::sim::collision::model::CollisionModel;
use crate::sim::collision::pairs::PairSampling;
use crate::sim::collision::spheres::{Sphere, SphereFit, surface_points};
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;

/// The file's name in a model's folder.
pub const FILE: &str = "collision.json";

/// What the file holds.
#[derive(serde::Serialize, serde::Deserialize)]
struct Cached {
    key: String,
    /// [`content_hash`] of the spheres and pairs (absent in files written before it was
    /// kept: such a file is computed again).
    #[serde(default)]
    content: Option<String>,
    /// Each link's spheres, by the link's name.
    spheres: Vec<(String, Vec<Sphere>)>,
    /// The checked pairs, by the links' names.
    pairs: Vec<[String; 2]>,
}

/// The hash of what a file holds (its spheres and pairs as JSON).
fn content_hash(spheres: &[(String, Vec<Sphere>)], pairs: &[[String; 2]]) -> String {
    let text = serde_json::to_vec(&(spheres, pairs)).expect("spheres serialise");
    crate::core::input_file::fnv(&text)
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
        // The pairs are decided on the links' exact shapes (before: on their spheres).
        "pairs_decided_on": "exact shapes",
        // Spheres hold every triangle of the surface whole (before: every sample, grown by
        // how far the surface lies from its samples).
        "spheres_hold": "triangles",
    });
    bytes.extend_from_slice(settings.to_string().as_bytes());
    crate::core::input_file::fnv(&bytes)
}

/// The model in `dir`'s file where its key is `key` (None: no file, or one computed from
/// something else); a file that cannot be trusted is an error (see the module's text).
pub fn read(
    dir: &Path,
    key: &str,
    robot: &Robot,
    fit: &SphereFit,
) -> Result<Option<CollisionModel>> {
    let path = dir.join(FILE);
    if std::fs::symlink_metadata(&path).is_err() {
        return Ok(None);
    }
    let damaged = |why: String| {
        Error::Config(format!(
            "{}: the collision model kept beside the IK model cannot be used ({why}); delete it and it is computed again",
            path.display()
        ))
    };
    let bytes = crate::core::input_file::read_regular(
        &path,
        "kept collision model",
        crate::core::input_file::MAX_JSON_BYTES,
    )
    .map_err(|e| damaged(e.to_string()))?;
    let cached: Cached =
        serde_json::from_slice(&bytes).map_err(|e| damaged(format!("not its JSON: {e}")))?;
    let Some(content) = &cached.content else {
        return Ok(None);
    };
    if cached.key != key {
        return Ok(None);
    }
    if *content != content_hash(&cached.spheres, &cached.pairs) {
        return Err(damaged(
            "what it holds no longer matches its hash: it was edited".into(),
        ));
    }
    let links = &robot.chain.links;
    let index = |name: &str| {
        links.iter().position(|l| l == name).ok_or_else(|| {
            damaged(format!(
                "it names a link \"{name}\" the robot does not have"
            ))
        })
    };
    let mut spheres: Vec<Option<Vec<Sphere>>> = vec![None; links.len()];
    for (name, s) in cached.spheres {
        let i = index(&name)?;
        if spheres[i].replace(s).is_some() {
            return Err(damaged(format!("it gives \"{name}\" spheres twice")));
        }
    }
    let spheres: Vec<Vec<Sphere>> = spheres.into_iter().map(Option::unwrap_or_default).collect();
    for (l, s) in spheres.iter().enumerate() {
        covers(robot.geometry[l].shapes(), s, fit)
            .map_err(|why| damaged(format!("link \"{}\": {why}", links[l])))?;
    }
    let mut pairs = Vec::with_capacity(cached.pairs.len());
    for [a, b] in &cached.pairs {
        let (a, b) = (index(a)?, index(b)?);
        if a == b || spheres[a].is_empty() || spheres[b].is_empty() {
            return Err(damaged(format!(
                "it checks {} against {}, which cannot be a pair",
                links[a], links[b]
            )));
        }
        pairs.push((a.min(b), a.max(b)));
    }
    Ok(Some(CollisionModel::with_pairs(
        &robot.chain,
        spheres,
        pairs,
    )))
}

/// `Err` saying why, unless `spheres` cover `shapes` as [`crate::sim::collision::spheres::fit_link`]
/// leaves them: finite, positive radii, no larger than the geometry, centres on it, every
/// sample of its surface (vertices included) inside one; none on a link without geometry.
fn covers(
    shapes: &[Shape],
    spheres: &[Sphere],
    fit: &SphereFit,
) -> std::result::Result<(), String> {
    if shapes.is_empty() {
        return match spheres.is_empty() {
            true => Ok(()),
            false => Err("spheres on a link without collision geometry".into()),
        };
    }
    let points = surface_points(shapes, fit.spacing_m);
    let given: Vec<(nalgebra::Point3<f64>, f64)> = shapes
        .iter()
        .filter_map(|s| match s {
            Shape::Sphere { center, radius } => Some((*center, *radius)),
            _ => None,
        })
        .collect();
    // The geometry's box (every sample, every sphere shape), for where a sphere may be.
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let corners = (points.iter().map(|p| (*p, 0.0)))
        .chain(given.iter().copied())
        .flat_map(|(c, r)| [c.coords.add_scalar(-r), c.coords.add_scalar(r)]);
    for c in corners {
        for k in 0..3 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
    }
    let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let slack = 1e-9 + 1e-12 * diagonal;
    for s in spheres {
        let inside = (0..3).all(|k| (lo[k] - slack..=hi[k] + slack).contains(&s.center[k]));
        if !(s.radius.is_finite() && s.radius > 0.0 && s.radius <= diagonal + slack && inside) {
            return Err(format!(
                "a sphere of radius {} at {:?} is not one a fit gives its geometry",
                crate::core::error::short_number(s.radius),
                s.center.map(crate::core::error::short_number)
            ));
        }
    }
    let inside = |c: &nalgebra::Point3<f64>, r: f64| {
        spheres
            .iter()
            .any(|s| (c - s.center()).norm() + r <= s.radius + slack)
    };
    if !points.iter().all(|p| inside(p, 0.0)) || !given.iter().all(|(c, r)| inside(c, *r)) {
        return Err("its spheres leave part of its geometry uncovered".into());
    }
    Ok(())
}

/// Write `model` (of `robot`) with its `key` into `dir`'s file.
pub fn write(dir: &Path, key: &str, robot: &Robot, model: &CollisionModel) -> Result<()> {
    let links = &robot.chain.links;
    let spheres: Vec<(String, Vec<Sphere>)> = (links.iter().cloned())
        .zip(model.spheres.iter().cloned())
        .collect();
    let pairs: Vec<[String; 2]> = (model.pairs.iter())
        .map(|&(a, b)| [links[a].clone(), links[b].clone()])
        .collect();
    let cached = Cached {
        key: key.into(),
        content: Some(content_hash(&spheres, &pairs)),
        spheres,
        pairs,
    };
    crate::core::atomic_file::write_json(&dir.join(FILE), &cached)
}
