//! Spheres fitted to a link's collision geometry, as cuRobo's robot files give them: the
//! link's surface sampled (every mesh vertex, and points no farther apart than the
//! tolerance allows), the samples clustered, and each cluster enclosed by a near-minimal
//! sphere. Every sample lies inside a sphere of its link, so every vertex does, and every
//! point of the surface lies within `tolerance_m` of one (the samples of a triangle are the
//! corners of sub-triangles whose edges are at most `tolerance_m * sqrt(3)` long).
//!
//! How many spheres: the fewest (up to `max_per_link`) whose largest radius is at most
//! `roundness` times the link's half-width (from the spread of its surface across its
//! second principal axis): a tube gets a row of spheres about as wide as it, a box a few.

use nalgebra::{Matrix3, Point3, Vector3};

use crate::core::error::{Error, Result};
use crate::sim::shape::Shape;

/// A sphere in a link's frame (or the world's, for an obstacle).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sphere {
    pub center: [f64; 3],
    pub radius: f64,
}

impl Sphere {
    pub fn center(&self) -> Point3<f64> {
        Point3::from(self.center)
    }

    /// Whether `p` lies inside, up to `slack`.
    pub fn contains(&self, p: &Point3<f64>, slack: f64) -> bool {
        (p - self.center()).norm() <= self.radius + slack
    }
}

/// How spheres are fitted.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SphereFit {
    /// Every point of the surface lies within this distance of a sphere (m); vertices lie
    /// inside one.
    pub tolerance_m: f64,
    /// At most this many spheres a link.
    pub max_per_link: usize,
    /// A sphere may be this many times the link's half-width.
    pub roundness: f64,
}

impl Default for SphereFit {
    fn default() -> Self {
        Self {
            tolerance_m: 0.004,
            max_per_link: 16,
            roundness: 1.25,
        }
    }
}

/// Points of the surface of `shapes`: every triangle's corners and the corners of its
/// sub-triangles with edges at most `spacing` long; primitives sampled as finely (a sphere
/// gives its own centre and radius instead: see [`fit_link`]).
pub fn surface_points(shapes: &[Shape], spacing: f64) -> Vec<Point3<f64>> {
    let mut points = Vec::new();
    for shape in shapes {
        match shape {
            Shape::Triangle(t) => triangle_points(t, spacing, &mut points),
            Shape::Cuboid { pose, half } => {
                for t in cuboid_triangles(half) {
                    let t = t.map(|p| pose * p);
                    triangle_points(&t, spacing, &mut points);
                }
            }
            Shape::Cylinder {
                pose,
                radius,
                half_length,
            } => {
                let around = ((std::f64::consts::TAU * radius / spacing).ceil() as usize).max(8);
                let along = ((2.0 * half_length / spacing).ceil() as usize).max(1);
                let rings = ((radius / spacing).ceil() as usize).max(1);
                for i in 0..around {
                    let a = std::f64::consts::TAU * i as f64 / around as f64;
                    let (c, s) = (a.cos(), a.sin());
                    for j in 0..=along {
                        let z = -half_length + 2.0 * half_length * j as f64 / along as f64;
                        points.push(pose * Point3::new(radius * c, radius * s, z));
                    }
                    for r in 0..rings {
                        let rr = radius * r as f64 / rings as f64;
                        for z in [-half_length, *half_length] {
                            points.push(pose * Point3::new(rr * c, rr * s, z));
                        }
                    }
                }
            }
            Shape::Sphere { .. } => {}
        }
    }
    points
}

/// The most surface samples one link (or a scene's mesh) is fitted from (about 100 MB of
/// points): a surface that would need more (a mesh scaled 1000x, a cylinder 100 m wide) is
/// refused before a point is made.
pub const MAX_SURFACE_POINTS: f64 = 4e6;

/// How many points [`surface_points`] makes of `shapes` at `spacing`, counted without making
/// them (in floating point: a count beyond any memory does not overflow).
pub fn surface_point_count(shapes: &[Shape], spacing: f64) -> f64 {
    let triangle = |t: &[Point3<f64>; 3]| {
        let longest = (0..3)
            .map(|i| (t[(i + 1) % 3] - t[i]).norm())
            .fold(0.0, f64::max);
        let n = (longest / spacing).ceil().clamp(1.0, 1000.0);
        (n + 1.0) * (n + 2.0) / 2.0
    };
    shapes
        .iter()
        .map(|shape| match shape {
            Shape::Triangle(t) => triangle(t),
            Shape::Cuboid { half, .. } => cuboid_triangles(half).iter().map(triangle).sum(),
            Shape::Cylinder {
                radius,
                half_length,
                ..
            } => {
                let around = (std::f64::consts::TAU * radius / spacing).ceil().max(8.0);
                let along = (2.0 * half_length / spacing).ceil().max(1.0);
                let rings = (radius / spacing).ceil().max(1.0);
                around * (along + 1.0 + 2.0 * rings)
            }
            Shape::Sphere { .. } => 0.0,
        })
        .sum()
}

/// The 12 triangles of a box of half extents `half` about the origin.
fn cuboid_triangles(half: &Vector3<f64>) -> Vec<[Point3<f64>; 3]> {
    let c = |i: usize| {
        Point3::new(
            if i & 1 == 0 { -half.x } else { half.x },
            if i & 2 == 0 { -half.y } else { half.y },
            if i & 4 == 0 { -half.z } else { half.z },
        )
    };
    let faces = [
        [0, 1, 3, 2],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 3, 7, 5],
    ];
    faces
        .iter()
        .flat_map(|f| [[c(f[0]), c(f[1]), c(f[2])], [c(f[0]), c(f[2]), c(f[3])]])
        .collect()
}

/// A triangle's corners and the corners of its subdivision into `n^2` sub-triangles, `n`
/// the fewest with edges at most `spacing` long.
fn triangle_points(t: &[Point3<f64>; 3], spacing: f64, out: &mut Vec<Point3<f64>>) {
    let longest = (0..3)
        .map(|i| (t[(i + 1) % 3] - t[i]).norm())
        .fold(0.0, f64::max);
    let n = ((longest / spacing).ceil() as usize).clamp(1, 1000);
    let (u, v) = ((t[1] - t[0]) / n as f64, (t[2] - t[0]) / n as f64);
    for i in 0..=n {
        for j in 0..=(n - i) {
            out.push(t[0] + u * i as f64 + v * j as f64);
        }
    }
}

/// The points with duplicates (closer than `cell / 4` on a grid) removed, keeping the first.
fn distinct_points(points: Vec<Point3<f64>>, cell: f64) -> Vec<Point3<f64>> {
    let mut seen = std::collections::HashSet::new();
    let q = cell / 4.0;
    points
        .into_iter()
        .filter(|p| {
            seen.insert([
                (p.x / q).round() as i64,
                (p.y / q).round() as i64,
                (p.z / q).round() as i64,
            ])
        })
        .collect()
}

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

/// Spheres covering one link's collision shapes (none for a link without any). A surface
/// beyond [`MAX_SURFACE_POINTS`] samples is refused (the caller names the link); Ctrl-C
/// ends the fit between two of its clusterings.
pub fn fit_link(shapes: &[Shape], fit: &SphereFit) -> Result<Vec<Sphere>> {
    let mut spheres: Vec<Sphere> = shapes
        .iter()
        .filter_map(|s| match s {
            Shape::Sphere { center, radius } => Some(Sphere {
                center: [center.x, center.y, center.z],
                radius: *radius,
            }),
            _ => None,
        })
        .collect();
    let spacing = fit.tolerance_m * 3f64.sqrt();
    let count = surface_point_count(shapes, spacing);
    if count > MAX_SURFACE_POINTS {
        return Err(Error::Config(format!(
            "its collision geometry would take {count:.1e} samples at {} mm to cover (at most {MAX_SURFACE_POINTS:.0e}): is it tens or hundreds of metres across? check its size and scale",
            1e3 * fit.tolerance_m
        )));
    }
    let all = surface_points(shapes, spacing);
    let points = distinct_points(all.clone(), fit.tolerance_m);
    if points.is_empty() {
        return Ok(spheres);
    }
    let width = half_width(&points).max(fit.tolerance_m);
    let mut best = Vec::new();
    for k in 1..=fit.max_per_link.max(1).min(points.len()) {
        crate::core::interrupt::check(|| "stopped fitting collision spheres".into())?;
        best = clusters(&points, k)
            .iter()
            .map(|c| enclosing_sphere(c))
            .collect::<Vec<_>>();
        let largest = best.iter().map(|s| s.radius).fold(0.0, f64::max);
        if largest <= fit.roundness * width {
            break;
        }
    }
    // The clustering saw the points once each (closer ones merged): every sample, vertices
    // included, is put inside the sphere it sticks out of least.
    for p in &all {
        if best.iter().any(|s| s.contains(p, 0.0)) {
            continue;
        }
        if let Some(s) = best.iter_mut().min_by(|a, b| {
            let out = |s: &Sphere| (p - s.center()).norm() - s.radius;
            out(a).total_cmp(&out(b))
        }) {
            s.radius = (p - s.center()).norm();
        }
    }
    spheres.extend(best);
    Ok(spheres)
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

    #[test]
    fn the_samples_are_counted_before_they_are_made_and_a_huge_surface_refused() {
        let shapes = vec![
            Shape::Cuboid {
                pose: nalgebra::Isometry3::identity(),
                half: Vector3::new(0.3, 0.05, 0.02),
            },
            Shape::Cylinder {
                pose: nalgebra::Isometry3::identity(),
                radius: 0.04,
                half_length: 0.2,
            },
            Shape::Triangle([
                Point3::origin(),
                Point3::new(0.1, 0.0, 0.0),
                Point3::new(0.0, 0.07, 0.0),
            ]),
        ];
        let made = surface_points(&shapes, 0.007).len() as f64;
        assert_eq!(surface_point_count(&shapes, 0.007), made);
        // A cylinder 100 m wide: 2.6e9 samples, refused before one is made.
        let huge = [Shape::Cylinder {
            pose: nalgebra::Isometry3::identity(),
            radius: 100.0,
            half_length: 50.0,
        }];
        let err = fit_link(&huge, &SphereFit::default())
            .unwrap_err()
            .to_string();
        assert!(err.contains("check its size and scale"), "{err}");
    }

    #[test]
    fn a_long_box_gets_a_row_of_spheres_that_cover_its_surface() {
        let shapes = vec![Shape::Cuboid {
            pose: nalgebra::Isometry3::identity(),
            half: Vector3::new(0.3, 0.05, 0.05),
        }];
        let fit = SphereFit::default();
        let spheres = fit_link(&shapes, &fit).unwrap();
        assert!(spheres.len() >= 3, "{} spheres", spheres.len());
        let largest = spheres.iter().map(|s| s.radius).fold(0.0, f64::max);
        assert!(largest < 0.15, "largest radius {largest}");
        for p in surface_points(&shapes, 0.01) {
            assert!(
                spheres.iter().any(|s| s.contains(&p, fit.tolerance_m)),
                "{p}"
            );
        }
    }
}
