//! Collision checking for IK: spheres fitted to each link's collision geometry
//! (`spheres`) as the broad phase, the exact geometry behind them (`exact`) as the narrow
//! phase, the pairs of links checked (`pairs`: an SRDF's `<disable_collisions>` or
//! MoveIt's computed matrix), obstacles in cuRobo's scene format (`scene`) and the check
//! itself (`model`), the contacts an optimiser pushes apart (`contacts`); spheres a user
//! supplies in cuRobo's format (`user_spheres`); spheres fine only where links come close
//! (`where_close`); the model kept in a file (`cache`).

pub mod cache;
pub mod contacts;
pub mod exact;
pub mod model;
pub mod pairs;
pub mod scene;
pub mod sphere;
pub mod sphere_score;
pub mod sphere_tree;
pub mod spheres;
pub mod user_spheres;
pub mod where_close;

use rayon::prelude::*;

use crate::core::error::{Error, Result};
use crate::sim::robot::Robot;
use crate::sim::srdf::Srdf;
use model::CollisionModel;
use pairs::{AllowedPairs, PairSampling};
use spheres::{Sphere, SphereFit};

/// The largest YAML file read (a scene or a spheres file is a few hundred lines).
pub const MAX_YAML_BYTES: u64 = 16 << 20;

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
    // `.nan` and `.inf` read as numbers (cuRobo's files carry them in colours): a length or
    // pose that is not finite is refused where it is read.
    let options = serde_saphyr::options! {
        non_finite_float_policy: serde_saphyr::NonFiniteFloatPolicy::PassThrough,
    };
    serde_saphyr::from_str_with_options(text, options).map_err(|e| {
        let message = e.to_string();
        crate::core::error::Error::Config(format!(
            "{}: not {expected} ({})",
            path.display(),
            message.lines().next().unwrap_or("")
        ))
    })
}

/// Spheres for every link of `robot` (loaded with its collision geometry), in its frame; a
/// link whose surface is too large to sample is refused by name.
pub fn fit_robot(robot: &Robot, fit: &SphereFit) -> Result<Vec<Vec<Sphere>>> {
    robot
        .geometry
        .par_iter()
        .zip(&robot.chain.links)
        .map(|(g, name)| spheres::fit_link(g.shapes(), fit).map_err(in_link(robot, name)))
        .collect()
}

/// A link's fit's error, naming the robot and the link.
pub(crate) fn in_link<'a>(robot: &'a Robot, name: &'a str) -> impl Fn(Error) -> Error + 'a {
    move |e| match e {
        Error::Config(why) => Error::Config(format!("{}: link \"{name}\": {why}", robot.name)),
        other => other,
    }
}

/// The allowed pairs MoveIt's setup assistant would compute for `robot`, decided as it
/// decides them, on the links' exact shapes (`spheres` their broad phase, which may fall short
/// of the shapes by `sphere_slack`: [`model::ExactLinks::sphere_slack`]): a pair is never
/// switched off because its spheres bulge into each other where its meshes do not.
pub fn computed_pairs(
    robot: &Robot,
    spheres: &[Vec<Sphere>],
    sphere_slack: Option<f64>,
    sampling: &PairSampling,
) -> Result<AllowedPairs> {
    // Every pair of links with spheres checked, to find which always or never collide.
    let everything = CollisionModel::new(&robot.chain, spheres.to_vec(), &AllowedPairs::default())
        .with_exact(exact_links(robot), sphere_slack);
    pairs::compute(&robot.chain, sampling, &|frames| {
        everything.colliding_pairs(frames, 0.0)
    })
}

/// Each link's exact shapes (`robot` loaded with its collision geometry).
pub fn exact_links(robot: &Robot) -> Vec<exact::ExactShapes> {
    (robot.geometry.iter())
        .map(|g| exact::ExactShapes::of_link(g.shapes()))
        .collect()
}

/// The collision model of `robot` (loaded with its collision geometry): spheres fitted by
/// `fit`; the pairs `allowed` (an SRDF's: [`allowed_by_srdf`]), else those MoveIt's setup
/// assistant would compute.
pub fn model_for(
    robot: &Robot,
    allowed: Option<AllowedPairs>,
    fit: &SphereFit,
    sampling: &PairSampling,
) -> Result<CollisionModel> {
    if let spheres::SphereBudget::WhereClose { .. } = fit.budget {
        // Fine where the links checked come close: which those are, from the default fit.
        let default = fit_robot(robot, &SphereFit::default())?;
        let base = model_with(robot, default, Some(0.0), allowed, sampling)?;
        let fitted = where_close::fit_robot(robot, &base, fit)?;
        return Ok(CollisionModel {
            allowed: base.allowed.clone(),
            ..CollisionModel::with_pairs(&robot.chain, fitted, base.pairs)
        });
    }
    model_with(robot, fit_robot(robot, fit)?, Some(0.0), allowed, sampling)
}

/// [`model_for`] with the spheres given (a user's: [`user_spheres::read`]), which may fall
/// short of the links' shapes by `sphere_slack` (`None`: by any distance).
pub fn model_with(
    robot: &Robot,
    spheres: Vec<Vec<Sphere>>,
    sphere_slack: Option<f64>,
    allowed: Option<AllowedPairs>,
    sampling: &PairSampling,
) -> Result<CollisionModel> {
    if spheres.iter().all(Vec::is_empty) {
        return Err(Error::Config(format!(
            "{} has no collision geometry to check: load it with its <collision> elements (geometry \"collision\")",
            robot.name
        )));
    }
    let allowed = match allowed {
        Some(pairs) => pairs,
        None => computed_pairs(robot, &spheres, sphere_slack, sampling)?,
    };
    Ok(CollisionModel::new(&robot.chain, spheres, &allowed))
}

/// The pairs `srdf`'s `<disable_collisions>` allow (None: it has none). An SRDF whose
/// entries name no pair of `robot`'s links is another robot's, and is refused: its pairs
/// would allow nothing and every pair would be checked.
pub fn allowed_by_srdf(robot: &Robot, srdf: &Srdf) -> Result<Option<AllowedPairs>> {
    let entries = srdf.disabled_collisions();
    if entries.is_empty() {
        return Ok(None);
    }
    let links = &robot.chain.links;
    let known = |l: &String| links.contains(l);
    if !entries.iter().any(|(a, b, _)| known(a) && known(b)) {
        let (a, b, _) = &entries[0];
        return Err(Error::Config(format!(
            "{}: its <disable_collisions> name no pair of {}'s links (the first: {a} and {b}): is it this robot's SRDF?",
            srdf.path().display(),
            robot.name
        )));
    }
    Ok(Some(AllowedPairs::from_srdf(entries)))
}
