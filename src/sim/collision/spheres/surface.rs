//! A link's surface as points: every triangle's corners and those of its subdivision, boxes
//! and cylinders sampled as finely; counted before they are made.

use nalgebra::{Point3, Vector3};

use crate::sim::shape::Shape;

/// Points of the surface of `shapes`: every triangle's corners and the corners of its
/// sub-triangles with edges at most `spacing` long; primitives sampled as finely (a sphere
/// gives its own centre and radius instead: see [`super::fit_link`]).
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
                let around = around_cylinder(*radius, spacing) as usize;
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
                let around = around_cylinder(*radius, spacing);
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
pub fn distinct_points(points: Vec<Point3<f64>>, cell: f64) -> Vec<Point3<f64>> {
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

/// How many samples go around a cylinder of `radius` at `spacing` (at least 8).
fn around_cylinder(radius: f64, spacing: f64) -> f64 {
    (std::f64::consts::TAU * radius / spacing).ceil().max(8.0)
}

/// The smallest box around `points` (its lowest and highest corners).
pub fn bounds(points: &[Point3<f64>]) -> (Point3<f64>, Point3<f64>) {
    let mut lo = Point3::from(Vector3::repeat(f64::INFINITY));
    let mut hi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (lo, hi)
}

/// The farthest a point of the surface of `shapes` lies from its nearest sample at `spacing`:
/// a triangle's sub-triangles have edges at most `spacing` long (no point of one is farther
/// than `spacing / sqrt(3)` from a corner); a cylinder's cells are at most `spacing` square,
/// and its side bulges past their corners by the sagitta of an arc between two.
pub fn sample_reach(shapes: &[Shape], spacing: f64) -> f64 {
    shapes
        .iter()
        .map(|shape| match shape {
            Shape::Cylinder { radius, .. } => {
                let around = around_cylinder(*radius, spacing);
                let sagitta = radius * (1.0 - (std::f64::consts::PI / around).cos());
                spacing / 2f64.sqrt() + sagitta
            }
            Shape::Sphere { .. } => 0.0,
            _ => spacing / 3f64.sqrt(),
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::collision::spheres::{SphereFit, fit_link};

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
}
