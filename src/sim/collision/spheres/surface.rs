//! A link's surface as points: every triangle's corners and those of its subdivision, boxes
//! and cylinders sampled as finely; counted before they are made.

use nalgebra::{Isometry3, Point3, Vector3};

use crate::sim::shape::Shape;

/// A link's surface as triangles: their corners (`points`, a corner shared by several
/// triangles repeated) and the triangles (`triangles`, indices into `points`). A sphere holds
/// a triangle whole when it holds its three corners (a ball is convex), so spheres that hold
/// every triangle cover the surface exactly: a mesh's or a box's surface is its triangles, and
/// a cylinder's lies at most `curvature` outside its triangles (the sagitta of the arcs
/// between the corners around it).
pub struct Surface {
    pub points: Vec<Point3<f64>>,
    pub triangles: Vec<[u32; 3]>,
    pub curvature: f64,
}

impl Surface {
    /// The surface of `shapes`, every triangle cut into sub-triangles with edges at most
    /// `spacing` long; a cylinder's side and caps as finely (a sphere shape gives its own
    /// centre and radius instead: see [`super::fit_link`]).
    pub fn of(shapes: &[Shape], spacing: f64) -> Self {
        let mut surface = Surface {
            points: Vec::new(),
            triangles: Vec::new(),
            curvature: 0.0,
        };
        for shape in shapes {
            match shape {
                Shape::Triangle(t) => surface.add_triangle(t, spacing),
                Shape::Cuboid { pose, half } => {
                    for t in cuboid_triangles(half) {
                        surface.add_triangle(&t.map(|p| pose * p), spacing);
                    }
                }
                Shape::Cylinder {
                    pose,
                    radius,
                    half_length,
                } => surface.add_cylinder(pose, *radius, *half_length, spacing),
                Shape::Sphere { .. } => {}
            }
        }
        surface
    }

    /// Triangle `t`'s three corners.
    pub fn corners(&self, t: u32) -> [Point3<f64>; 3] {
        self.triangles[t as usize].map(|k| self.points[k as usize])
    }

    /// A triangle's corners and the corners of its subdivision into `n^2` sub-triangles, `n`
    /// the fewest with edges at most `spacing` long; the sub-triangles.
    fn add_triangle(&mut self, t: &[Point3<f64>; 3], spacing: f64) {
        let n = triangle_cuts(t, spacing);
        let (u, v) = ((t[1] - t[0]) / n as f64, (t[2] - t[0]) / n as f64);
        let base = self.points.len() as u32;
        // Row i holds n + 1 - i corners; the corner (i, j) is at row_start(i) + j.
        let row_start = |i: usize| base + (i * (2 * n + 3) - i * i) as u32 / 2;
        for i in 0..=n {
            for j in 0..=(n - i) {
                self.points.push(t[0] + u * i as f64 + v * j as f64);
            }
        }
        for i in 0..n {
            for j in 0..(n - i) {
                let (a, b, c) = (
                    row_start(i) + j as u32,
                    row_start(i + 1) + j as u32,
                    row_start(i) + j as u32 + 1,
                );
                self.triangles.push([a, b, c]);
                if j + 1 < n - i {
                    self.triangles.push([b, row_start(i + 1) + j as u32 + 1, c]);
                }
            }
        }
    }

    /// A cylinder's side as a prism of `around` faces, `along` rows high, and each cap as
    /// `rings` rings about its centre, all corners on the cylinder.
    fn add_cylinder(&mut self, pose: &Isometry3<f64>, radius: f64, half_length: f64, spacing: f64) {
        let around = around_cylinder(radius, spacing) as usize;
        let along = ((2.0 * half_length / spacing).ceil() as usize).max(1);
        let rings = ((radius / spacing).ceil() as usize).max(1);
        let base = self.points.len() as u32;
        let column = along + 1 + 2 * rings;
        for i in 0..around {
            let a = std::f64::consts::TAU * i as f64 / around as f64;
            let (c, s) = (a.cos(), a.sin());
            for j in 0..=along {
                let z = -half_length + 2.0 * half_length * j as f64 / along as f64;
                self.points
                    .push(pose * Point3::new(radius * c, radius * s, z));
            }
            for r in 0..rings {
                let rr = radius * r as f64 / rings as f64;
                for z in [-half_length, half_length] {
                    self.points.push(pose * Point3::new(rr * c, rr * s, z));
                }
            }
        }
        // Corner `k` of column `i`: the side's row `k` (0..=along), then the caps' rings.
        let at = |i: usize, k: usize| base + ((i % around) * column + k) as u32;
        // Ring `r` of a cap (`end` 0 below, 1 above); ring `rings` is the side's edge.
        let ring = |i: usize, r: usize, end: usize| match r == rings {
            true => at(i, end * along),
            false => at(i, along + 1 + 2 * r + end),
        };
        let mut quad = |a: u32, b: u32, c: u32, d: u32| {
            self.triangles.push([a, b, c]);
            self.triangles.push([a, c, d]);
        };
        for i in 0..around {
            for j in 0..along {
                quad(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            }
            for end in 0..2 {
                for r in 0..rings {
                    quad(
                        ring(i, r, end),
                        ring(i + 1, r, end),
                        ring(i + 1, r + 1, end),
                        ring(i, r + 1, end),
                    );
                }
            }
        }
        let sagitta = radius * (1.0 - (std::f64::consts::PI / around as f64).cos());
        self.curvature = self.curvature.max(sagitta);
    }
}

/// A triangle's centroid.
pub fn centroid(t: &[Point3<f64>; 3]) -> Point3<f64> {
    Point3::from((t[0].coords + t[1].coords + t[2].coords) / 3.0)
}

/// Points of the surface of `shapes`: the corners of [`Surface::of`]'s triangles.
pub fn surface_points(shapes: &[Shape], spacing: f64) -> Vec<Point3<f64>> {
    Surface::of(shapes, spacing).points
}

/// How many pieces each edge of triangle `t` is cut into: the fewest at most `spacing` long.
fn triangle_cuts(t: &[Point3<f64>; 3], spacing: f64) -> usize {
    let longest = (0..3)
        .map(|i| (t[(i + 1) % 3] - t[i]).norm())
        .fold(0.0, f64::max);
    ((longest / spacing).ceil() as usize).clamp(1, 1000)
}

/// The most surface samples one link (or a scene's mesh) is fitted from (about 100 MB of
/// points): a surface that would need more (a mesh scaled 1000x, a cylinder 100 m wide) is
/// refused before a point is made.
pub const MAX_SURFACE_POINTS: f64 = 4e6;

/// How many points [`surface_points`] makes of `shapes` at `spacing`, counted without making
/// them (in floating point: a count beyond any memory does not overflow).
pub fn surface_point_count(shapes: &[Shape], spacing: f64) -> f64 {
    let triangle = |t: &[Point3<f64>; 3]| {
        let n = triangle_cuts(t, spacing) as f64;
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

    /// Every point of a coarsely cut cylinder (its points at a fine spacing) lies within the
    /// surface's curvature of its triangles, and the side's bulge reaches nearly that far.
    #[test]
    fn a_cylinder_lies_within_its_curvature_of_its_triangles() {
        let shapes = [Shape::Cylinder {
            pose: nalgebra::Isometry3::rotation(Vector3::new(0.2, -0.4, 0.0)),
            radius: 0.04,
            half_length: 0.05,
        }];
        let surface = Surface::of(&shapes, 0.03);
        let triangles: Vec<Shape> = (surface.triangles.iter())
            .map(|t| t.map(|k| surface.points[k as usize]))
            .filter(|t| (t[1] - t[0]).cross(&(t[2] - t[0])).norm() > 1e-12)
            .map(Shape::Triangle)
            .collect();
        let exact = crate::sim::collision::exact::ExactShapes::of_link(&triangles);
        let farthest = (surface_points(&shapes, 0.002).iter())
            .map(|p| exact.surface_distance(p))
            .fold(0.0, f64::max);
        let c = surface.curvature;
        assert!(farthest <= c + 1e-9 && farthest > 0.9 * c, "{farthest} {c}");
    }
}
