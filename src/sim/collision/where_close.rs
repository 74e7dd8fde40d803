//! Spheres fine only where links come close ([`SphereBudget::WhereClose`]): a sphere standing
//! out past a link meets another link's spheres (a false alarm) only where that link comes
//! closer than the two protrusions together. So each point of a link's surface is given as
//! much as a share of the least distance the links checked against it come to it, over
//! random configurations free on the exact shapes (and no more than the budget's `mm`), and
//! the link is covered within that ([`spheres::fit_link_within`]). Where nothing comes close,
//! a few large spheres; where a link passes near, many small ones.
//!
//! The distances are read on the checked pairs of a model with the default spheres (the
//! pairs do not depend on the spheres: they are decided on the exact shapes), against the
//! robot itself: obstacles are not looked at.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rayon::prelude::*;

use crate::core::error::Result;
use crate::sim::collision::model::CollisionModel;
use crate::sim::collision::spheres::{self, Sphere, SphereBudget, SphereFit, Surface};
use crate::sim::robot::Robot;

/// Random configurations the distances are read over (those not free are left out).
pub const CONFIGURATIONS: usize = 2_000;
/// Their seed (the allowed pairs are sampled from seed 0; the benchmarks' from seed 1).
pub const SEED: u64 = 7;
/// The least a sphere is allowed to stand out (m): below, covers take thousands of spheres.
pub const FLOOR_M: f64 = 0.5e-3;

/// Spheres for every link of `robot` (loaded with its collision geometry) fitted by `fit`
/// (budget [`SphereBudget::WhereClose`]), the distances read on `base`'s checked pairs, with
/// the links' exact shapes deciding which configurations are free.
pub fn fit_robot(
    robot: &Robot,
    base: &CollisionModel,
    fit: &SphereFit,
) -> Result<Vec<Vec<Sphere>>> {
    let SphereBudget::WhereClose { mm, share, most } = fit.budget else {
        return crate::sim::collision::fit_robot(robot, fit);
    };
    let links = crate::sim::collision::exact_links(robot);
    let check = base.clone().with_exact(links.clone(), Some(0.0));
    let chain = &robot.chain;
    let mut rng = StdRng::seed_from_u64(SEED);
    let ranges = chain.joint_ranges();
    let configurations: Vec<Vec<f64>> = (0..CONFIGURATIONS)
        .map(|_| crate::sim::trajectory::uniform_in(&mut rng, &ranges))
        .collect();
    let frames = |k: usize| {
        let f = chain.link_frames(&configurations[k]);
        (!crate::core::interrupt::requested() && !check.self_collides(&f, 0.0)).then_some(f)
    };
    let surfaces: Vec<Surface> = (robot.geometry.iter())
        .map(|g| Surface::of(g.shapes(), fit.spacing_m))
        .collect();
    let points: Vec<_> = surfaces.into_iter().map(|s| s.points).collect();
    let most_m = 1e-3 * mm;
    let cap = most_m / share;
    let clearance = spheres::clearance::clearances(
        &points,
        &links,
        &base.pairs,
        (CONFIGURATIONS, &frames),
        cap,
    );
    crate::core::interrupt::check(|| "stopped fitting collision spheres".into())?;
    (robot.geometry.par_iter())
        .zip(&clearance)
        .zip(&chain.links)
        .map(|((g, c), name)| {
            let allowance: Vec<f64> = (c.iter())
                .map(|&d| (share * d).clamp(FLOOR_M.min(most_m), most_m))
                .collect();
            spheres::fit_link_within(g.shapes(), fit.spacing_m, &allowance, most)
                .map_err(crate::sim::collision::in_link(robot, name))
        })
        .collect()
}
