//! Collision checking for IK: spheres fitted to each link's collision geometry
//! (`spheres`), the pairs of links checked (`pairs`: an SRDF's `<disable_collisions>` or
//! MoveIt's computed matrix), obstacles in cuRobo's scene format (`scene`) and the check
//! itself (`model`), the contacts an optimiser pushes apart (`contacts`); spheres a user
//! supplies in cuRobo's format (`user_spheres`); the model kept in a file (`cache`).

pub mod cache;
pub mod contacts;
pub mod model;
pub mod pairs;
pub mod scene;
pub mod spheres;
pub mod user_spheres;

use rayon::prelude::*;

use crate::sim::robot::Robot;
use model::CollisionModel;
use pairs::{AllowedPairs, PairSampling};
use spheres::{Sphere, SphereFit};

/// The largest YAML file read (a scene or a spheres file is a few hundred lines).
const MAX_YAML_BYTES: u64 = 16 << 20;

/// The YAML file a user names (`what`: "scene file"), parsed as `T`; `expected` says in the
/// one-line error what it should have been ("a scene as cuRobo writes one").
fn read_yaml<T: serde::de::DeserializeOwned>(
    path: &std::path::Path,
    what: &str,
    expected: &str,
) -> crate::core::error::Result<T> {
    let text = crate::core::input_file::read_user_text(path, what, MAX_YAML_BYTES, "YAML")?;
    parse_yaml(path, expected, &text)
}

/// `text` (of the file at `path`) parsed as `T`, the parser's first line in the error.
fn parse_yaml<T: serde::de::DeserializeOwned>(
    path: &std::path::Path,
    expected: &str,
    text: &str,
) -> crate::core::error::Result<T> {
    serde_saphyr::from_str(text).map_err(|e| {
        let message = e.to_string();
        crate::core::error::Error::Config(format!(
            "{}: not {expected} ({})",
            path.display(),
            message.lines().next().unwrap_or("")
        ))
    })
}

/// Spheres for every link of `robot` (loaded with its collision geometry), in its frame.
pub fn fit_robot(robot: &Robot, fit: &SphereFit) -> Vec<Vec<Sphere>> {
    robot
        .geometry
        .par_iter()
        .map(|g| spheres::fit_link(g.shapes(), fit))
        .collect()
}

/// The allowed pairs MoveIt's setup assistant would compute for `robot` with `spheres`.
pub fn computed_pairs(
    robot: &Robot,
    spheres: &[Vec<Sphere>],
    sampling: &PairSampling,
) -> AllowedPairs {
    // Every pair of links with spheres checked, to find which always or never collide.
    let everything = CollisionModel::new(&robot.chain, spheres.to_vec(), &AllowedPairs::default());
    pairs::compute(&robot.chain, sampling, &|frames| {
        everything.colliding_pairs(frames, 0.0)
    })
}

/// The collision model of `robot` (loaded with its collision geometry): spheres fitted by
/// `fit`; the allowed pairs of the SRDF at `srdf` where it has `<disable_collisions>`, else
/// computed as MoveIt's setup assistant computes them.
pub fn model_for(
    robot: &Robot,
    srdf: Option<&std::path::Path>,
    fit: &SphereFit,
    sampling: &PairSampling,
) -> crate::core::error::Result<CollisionModel> {
    model_with(robot, fit_robot(robot, fit), srdf, sampling)
}

/// [`model_for`] with the spheres given (a user's: [`user_spheres::read`]).
pub fn model_with(
    robot: &Robot,
    spheres: Vec<Vec<Sphere>>,
    srdf: Option<&std::path::Path>,
    sampling: &PairSampling,
) -> crate::core::error::Result<CollisionModel> {
    if spheres.iter().all(Vec::is_empty) {
        return Err(crate::core::error::Error::Config(format!(
            "{} has no collision geometry to check: load it with its <collision> elements (geometry \"collision\")",
            robot.name
        )));
    }
    let from_file = match srdf {
        Some(path) => {
            let file = crate::sim::srdf::Srdf::read(path)?;
            let pairs = AllowedPairs::from_srdf(file.disabled_collisions());
            (!pairs.pairs.is_empty()).then_some(pairs)
        }
        None => None,
    };
    let allowed = match from_file {
        Some(pairs) => pairs,
        None => computed_pairs(robot, &spheres, sampling),
    };
    Ok(CollisionModel::new(&robot.chain, spheres, &allowed))
}
