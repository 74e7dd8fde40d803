//! Spheres shaped after the link: its surface samples clustered (Lloyd's iterations from
//! farthest-point seeds) and each cluster enclosed by a near-minimal sphere; how many, the
//! fewest no wider than a multiple of the link's half-width (a tube gets a row of spheres
//! about as wide as it, a box a few), or a number given.

use nalgebra::{Matrix3, Point3, Vector3};

use crate::sim::collision::sphere::Sphere;

/// A near-minimal sphere around `points` (Badoiu and Clarkson's iteration from the centroid),
/// its radius the exact largest distance from its centre.
pub fn enclosing_sphere(points: &[Point3<f64>]) -> Sphere {
    let n = points.len().max(1) as f64;
    let mut c = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let farthest = |c: &Vector3<f64>| {
        points
            .iter()
            .map(|p| (p.coords - c).norm_squared())
            .enumerate()
            .fold(
                (0, -1.0),
                |best, (i, d)| if d > best.1 { (i, d) } else { best },
            )
    };
    for k in 1..=200 {
        let (i, _) = farthest(&c);
        c += (points[i].coords - c) / (k as f64 + 1.0);
    }
    let r = farthest(&c).1.max(0.0).sqrt();
    Sphere {
        center: [c.x, c.y, c.z],
        radius: r,
    }
}

/// The link's half-width: the spread of its points across their second principal axis.
fn half_width(points: &[Point3<f64>]) -> f64 {
    let n = points.len().max(1) as f64;
    let mean = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cov = points.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p.coords - mean;
        a + d * d.transpose()
    }) / n;
    let mut eig: Vec<f64> = cov.symmetric_eigenvalues().iter().copied().collect();
    eig.sort_by(f64::total_cmp);
    (2.0 * eig[1].max(0.0)).sqrt()
}

/// `k` clusters of `points` (Lloyd's iterations from farthest-point seeds: deterministic).
fn clusters(points: &[Point3<f64>], k: usize) -> Vec<Vec<Point3<f64>>> {
    let mut centers = vec![points[0]];
    let mut nearest = vec![f64::INFINITY; points.len()];
    while centers.len() < k {
        let last = *centers.last().expect("one centre");
        for (d, p) in nearest.iter_mut().zip(points) {
            *d = d.min((p - last).norm_squared());
        }
        let (i, _) = nearest
            .iter()
            .enumerate()
            .fold((0, -1.0), |b, (i, &d)| if d > b.1 { (i, d) } else { b });
        centers.push(points[i]);
    }
    let mut owner = vec![0usize; points.len()];
    for _ in 0..30 {
        let mut moved = false;
        for (o, p) in owner.iter_mut().zip(points) {
            let best = (0..k)
                .min_by(|&a, &b| {
                    (p - centers[a])
                        .norm_squared()
                        .total_cmp(&(p - centers[b]).norm_squared())
                })
                .expect("k > 0");
            moved |= *o != best;
            *o = best;
        }
        let mut sums = vec![(Vector3::zeros(), 0usize); k];
        for (o, p) in owner.iter().zip(points) {
            sums[*o].0 += p.coords;
            sums[*o].1 += 1;
        }
        for (c, (s, m)) in centers.iter_mut().zip(sums) {
            if m > 0 {
                *c = Point3::from(s / m as f64);
            }
        }
        if !moved {
            break;
        }
    }
    let mut out = vec![Vec::new(); k];
    for (o, p) in owner.iter().zip(points) {
        out[*o].push(*p);
    }
    out.retain(|c| !c.is_empty());
    out
}

/// How wide a sphere may be against the link's half-width (the clustered fit's rule).
pub const ROUNDNESS: f64 = 1.25;

/// `k` clusters of `points` (fewer where there are fewer points), each enclosed.
pub fn enclosed(points: &[Point3<f64>], k: usize) -> Vec<Sphere> {
    clusters(points, k.clamp(1, points.len().max(1)))
        .iter()
        .map(|c| enclosing_sphere(c))
        .collect()
}

/// The fewest enclosed clusters of `points` (up to `most`) whose largest radius is at most
/// [`ROUNDNESS`] times the link's half-width (at least `floor`). Ctrl-C ends it between two
/// clusterings.
pub fn shaped(
    points: &[Point3<f64>],
    most: usize,
    floor: f64,
) -> crate::core::error::Result<Vec<Sphere>> {
    let width = half_width(points).max(floor);
    let mut best = Vec::new();
    for k in 1..=most.max(1).min(points.len()) {
        crate::core::interrupt::check(|| "stopped fitting collision spheres".into())?;
        best = enclosed(points, k);
        let largest = best.iter().map(|s| s.radius).fold(0.0, f64::max);
        if largest <= ROUNDNESS * width {
            break;
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_enclosing_sphere_of_a_cube_s_corners_is_the_circumscribed_one() {
        let corners: Vec<Point3<f64>> = (0..8)
            .map(|i| {
                Point3::new(
                    (i & 1) as f64 * 2.0 - 1.0,
                    ((i >> 1) & 1) as f64 * 2.0 - 1.0,
                    ((i >> 2) & 1) as f64 * 2.0 - 1.0,
                )
            })
            .collect();
        let s = enclosing_sphere(&corners);
        assert!((s.radius - 3f64.sqrt()).abs() < 1e-2, "{s:?}");
        assert!(corners.iter().all(|p| s.contains(p, 1e-12)));
    }
}
