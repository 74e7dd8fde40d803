//! How well a link's spheres fit it, on the exact geometry: coverage (the share of its
//! surface inside some sphere: 100% is conservative, a pair of links whose surfaces meet has
//! spheres that meet) and protrusion (how far the outer surface of its spheres stands outside
//! the link: what makes a false alarm).

use rayon::prelude::*;

use crate::sim::collision::exact::ExactShapes;
use crate::sim::collision::spheres::volume::{Place, Volume};
use crate::sim::collision::spheres::{Sphere, surface_point_count, surface_points};
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;

/// One link's spheres scored.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LinkFitScore {
    /// Whose spheres (`fitted`, or the file they were read from): as the caller names them.
    pub spheres_from: String,
    pub link: String,
    pub spheres: usize,
    /// Surface samples (and sphere shapes) inside some sphere, % (samples `spacing_mm` apart).
    pub coverage_pct: f64,
    /// The farthest a point of the spheres' outer surface lies outside the link (mm).
    pub protrusion_max_mm: f64,
    /// The mean over the spheres' outer surface of how far it lies outside the link (mm; 0
    /// where it lies inside).
    pub protrusion_mean_mm: f64,
    pub spacing_mm: f64,
}

/// Points read on each sphere's surface for its protrusion.
const SURFACE_POINTS_PER_SPHERE: usize = 256;
/// The most surface samples coverage is read on (the spacing grows past the one asked for).
const COVERAGE_SAMPLES: f64 = 1e6;

/// `n` unit vectors spread evenly over the sphere (a Fibonacci lattice).
fn directions(n: usize) -> Vec<nalgebra::Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            nalgebra::Vector3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// `spheres` of the link `shapes` scored, its surface sampled `spacing` apart (more coarsely
/// on a surface that would take more than a million samples); None without shapes.
pub fn score_link(
    link: &str,
    shapes: &[Shape],
    spheres: &[Sphere],
    spacing: f64,
) -> Option<LinkFitScore> {
    if shapes.is_empty() {
        return None;
    }
    let mut spacing = spacing;
    while surface_point_count(shapes, spacing) > COVERAGE_SAMPLES {
        spacing *= 1.25;
    }
    let samples = surface_points(shapes, spacing);
    let given: Vec<(nalgebra::Point3<f64>, f64)> = (shapes.iter())
        .filter_map(|s| match s {
            Shape::Sphere { center, radius } => Some((*center, *radius)),
            _ => None,
        })
        .collect();
    let inside = |c: &nalgebra::Point3<f64>, r: f64| {
        (spheres.iter()).any(|s| (c - s.center()).norm() + r <= s.radius + 1e-9)
    };
    let covered = samples.iter().filter(|p| inside(p, 0.0)).count()
        + given.iter().filter(|(c, r)| inside(c, *r)).count();
    let total = samples.len() + given.len();
    let exact = ExactShapes::of_link(shapes);
    let reach = crate::sim::collision::spheres::surface::sample_reach(shapes, spacing);
    let volume = Volume::of(&samples, spacing, reach, 0.05);
    let dirs = directions(SURFACE_POINTS_PER_SPHERE);
    let (mut worst, mut sum, mut outer) = (0.0f64, 0.0, 0usize);
    for (i, s) in spheres.iter().enumerate() {
        for u in &dirs {
            let q = s.center() + u * s.radius;
            let hidden = (spheres.iter().enumerate())
                .any(|(j, o)| j != i && (q - o.center()).norm() < o.radius);
            if hidden {
                continue;
            }
            outer += 1;
            // The grid answers away from the surface; the exact shapes near it.
            let outside = match volume.as_ref().map(|v| v.place(&q)) {
                Some(Place::Outside) => true,
                Some(Place::Inside) => false,
                _ => !exact.contains(&q),
            };
            if outside {
                let d = exact.surface_distance(&q);
                worst = worst.max(d);
                sum += d;
            }
        }
    }
    Some(LinkFitScore {
        spheres_from: String::new(),
        link: link.to_string(),
        spheres: spheres.len(),
        coverage_pct: 100.0 * covered as f64 / total.max(1) as f64,
        protrusion_max_mm: 1e3 * worst,
        protrusion_mean_mm: 1e3 * sum / outer.max(1) as f64,
        spacing_mm: 1e3 * spacing,
    })
}

/// Every link of `robot` with collision geometry scored with its `spheres` (one list a link),
/// each row saying they are `from` there.
pub fn score_robot(
    robot: &Robot,
    spheres: &[Vec<Sphere>],
    spacing: f64,
    from: &str,
) -> Vec<LinkFitScore> {
    (robot
        .geometry
        .par_iter()
        .zip(&robot.chain.links)
        .zip(spheres))
    .filter_map(|((g, name), s)| score_link(name, g.shapes(), s, spacing))
    .map(|score| LinkFitScore {
        spheres_from: from.to_string(),
        ..score
    })
    .collect()
}
