//! Collision checking for IK: spheres fitted to each link's collision geometry
//! (`spheres`), the pairs of links checked (`pairs`: an SRDF's `<disable_collisions>` or
//! MoveIt's computed matrix) and the check itself (`model`).

pub mod model;
pub mod pairs;
pub mod spheres;

use rayon::prelude::*;

use crate::sim::robot::Robot;
use model::CollisionModel;
use pairs::{AllowedPairs, PairSampling};
use spheres::{Sphere, SphereFit};

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
    let everything = CollisionModel::new(
        &robot.chain.links,
        spheres.to_vec(),
        &AllowedPairs::default(),
    );
    pairs::compute(&robot.chain, sampling, &|frames| {
        everything.colliding_pairs(frames, 0.0)
    })
}
