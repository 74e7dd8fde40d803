//! The exact geometry behind the spheres: each link's collision shapes as its description
//! gives them (meshes as triangle meshes, boxes, cylinders, spheres) and each obstacle as it
//! is, for the narrow phase. A pair the broad phase cannot tell apart is decided here by
//! parry's queries (GJK/EPA between convex pieces, bounding-volume trees over meshes): a mesh
//! is its surface, as coal (Pinocchio's checker) takes it, so two meshes collide where their
//! triangles meet and one wholly inside the other does not.

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::bounding_volume::BoundingVolume;
use parry3d_f64::math::{Pose, Vector};
use parry3d_f64::query;
use parry3d_f64::shape::{SharedShape, TriMesh};

use crate::sim::collision::sphere::Sphere;
use crate::sim::shape::Shape;

/// One convex piece or mesh of a link (or an obstacle), where it sits in the link's frame.
#[derive(Clone)]
struct Piece {
    pose: Pose,
    shape: SharedShape,
}

/// A link's (or an obstacle's) exact shapes and what bounds them, in its frame.
#[derive(Clone, Default)]
pub struct ExactShapes {
    pieces: Vec<Piece>,
    /// Every piece lies inside it (none: no pieces).
    pub bound: Option<Sphere>,
    /// The convex hull of the pieces (of a mesh's vertices, and of each primitive's bounding
    /// box): two shapes whose hulls keep a distance keep at least that distance, and a hull
    /// does not bulge past a flat face as a sphere does. None: no pieces, or flat.
    hull: Option<SharedShape>,
}

/// Where two shapes are closest, found exactly: the signed distance between them (m, negative
/// where they overlap by that much, as deep as the query can tell), the closest point on each
/// in the world, and the unit direction that moves each away from the other fastest.
#[derive(Clone, Copy, Debug)]
pub struct ExactContact {
    pub gap: f64,
    pub first: (Point3<f64>, Vector3<f64>),
    pub second: (Point3<f64>, Vector3<f64>),
}

fn pose_of(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Pose::from_parts(
        Vector::new(t.x, t.y, t.z),
        parry3d_f64::math::Rotation::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

fn point_of(v: Vector) -> Point3<f64> {
    Point3::new(v.x, v.y, v.z)
}

fn vector_of(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

/// A cylinder along z (URDF's and cuRobo's axis) is parry's along y turned a quarter turn
/// about x.
fn cylinder_pose(pose: &Isometry3<f64>) -> Pose {
    let quarter =
        nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
    pose_of(&(pose * quarter))
}

impl ExactShapes {
    /// A link's collision shapes (in its frame): its triangles as one mesh, each primitive as
    /// itself.
    pub fn of_link(shapes: &[Shape]) -> Self {
        let mut pieces = Vec::new();
        let mut vertices = Vec::new();
        for shape in shapes {
            match shape {
                Shape::Triangle(t) => {
                    vertices.extend(t.iter().map(|p| Vector::new(p.x, p.y, p.z)));
                }
                Shape::Cuboid { pose, half } => pieces.push(Piece {
                    pose: pose_of(pose),
                    shape: SharedShape::cuboid(half.x, half.y, half.z),
                }),
                Shape::Cylinder {
                    pose,
                    radius,
                    half_length,
                } => pieces.push(Piece {
                    pose: cylinder_pose(pose),
                    shape: SharedShape::cylinder(*half_length, *radius),
                }),
                Shape::Sphere { center, radius } => pieces.push(Piece {
                    pose: Pose::from_translation(Vector::new(center.x, center.y, center.z)),
                    shape: SharedShape::ball(*radius),
                }),
            }
        }
        let triangles = vertices.len() / 3;
        if triangles > 0 {
            let indices = (0..triangles as u32)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect();
            // A triangle soup parry cannot index (none: it takes any finite one) is left out
            // rather than failing the link.
            if let Ok(mesh) = SharedShape::trimesh(vertices, indices) {
                pieces.push(Piece {
                    pose: Pose::IDENTITY,
                    shape: mesh,
                });
            }
        }
        Self::new(pieces)
    }

    /// A box with half extents `half` about `pose`.
    pub fn cuboid(pose: &Isometry3<f64>, half: &Vector3<f64>) -> Self {
        Self::new(vec![Piece {
            pose: pose_of(pose),
            shape: SharedShape::cuboid(half.x, half.y, half.z),
        }])
    }

    /// Balls (a mesh obstacle read as the spheres covering it; one for a sphere).
    pub fn balls(spheres: &[Sphere]) -> Self {
        Self::new(
            spheres
                .iter()
                .map(|s| Piece {
                    pose: Pose::from_translation(Vector::from(s.center)),
                    shape: SharedShape::ball(s.radius),
                })
                .collect(),
        )
    }

    /// The segment `a`-`b` swept by `radius`.
    pub fn capsule(a: &Point3<f64>, b: &Point3<f64>, radius: f64) -> Self {
        Self::new(vec![Piece {
            pose: Pose::IDENTITY,
            shape: SharedShape::capsule(
                Vector::new(a.x, a.y, a.z),
                Vector::new(b.x, b.y, b.z),
                radius,
            ),
        }])
    }

    /// A cylinder along the local z axis of `pose`, centred on it.
    pub fn cylinder(pose: &Isometry3<f64>, radius: f64, half_height: f64) -> Self {
        Self::new(vec![Piece {
            pose: cylinder_pose(pose),
            shape: SharedShape::cylinder(half_height, radius),
        }])
    }

    fn new(pieces: Vec<Piece>) -> Self {
        let bound = (!pieces.is_empty()).then(|| {
            let (mut lo, mut hi) = (
                Vector::splat(f64::INFINITY),
                Vector::splat(f64::NEG_INFINITY),
            );
            for p in &pieces {
                let aabb = p.shape.compute_aabb(&p.pose);
                lo = lo.min(aabb.mins);
                hi = hi.max(aabb.maxs);
            }
            let c = (lo + hi) / 2.0;
            Sphere {
                center: [c.x, c.y, c.z],
                radius: (hi - lo).length() / 2.0,
            }
        });
        let mut points = Vec::new();
        for p in &pieces {
            match p.shape.as_trimesh() {
                Some(mesh) => points.extend(mesh.vertices().iter().map(|v| p.pose * *v)),
                None => points.extend(p.shape.compute_aabb(&p.pose).vertices()),
            }
        }
        let hull = (points.len() >= 4)
            .then(|| SharedShape::convex_hull(&points))
            .flatten();
        Self {
            pieces,
            bound,
            hull,
        }
    }

    /// Whether the convex hulls at `pa` and `pb` keep at least `margin` apart (then so do
    /// the shapes inside them); false where either has none.
    fn hulls_apart(&self, pa: &Pose, other: &Self, pb: &Pose, margin: f64) -> bool {
        let (Some(ha), Some(hb)) = (&self.hull, &other.hull) else {
            return false;
        };
        if margin <= 0.0 {
            query::intersection_test(pa, ha.as_ref(), pb, hb.as_ref())
                .is_ok_and(|i| !i.intersecting)
        } else {
            query::distance(pa, ha.as_ref(), pb, hb.as_ref()).is_ok_and(|d| d.distance >= margin)
        }
    }

    /// The distance between the two bounding spheres at `fa` and `fb` (negative: they
    /// overlap); infinite where either has no pieces.
    fn bound_gap(&self, fa: &Isometry3<f64>, other: &Self, fb: &Isometry3<f64>) -> f64 {
        match (&self.bound, &other.bound) {
            (Some(a), Some(b)) => (fa * a.center() - fb * b.center()).norm() - a.radius - b.radius,
            _ => f64::INFINITY,
        }
    }

    /// Whether these shapes at `fa` come closer than `margin` to `other`'s at `fb`
    /// (touching counts at zero margin).
    pub fn closer_than(
        &self,
        fa: &Isometry3<f64>,
        other: &Self,
        fb: &Isometry3<f64>,
        margin: f64,
    ) -> bool {
        if self.bound_gap(fa, other, fb) >= margin {
            return false;
        }
        let (pa, pb) = (pose_of(fa), pose_of(fb));
        if self.hulls_apart(&pa, other, &pb, margin) {
            return false;
        }
        self.pieces.iter().any(|a| {
            other.pieces.iter().any(|b| {
                let (wa, wb) = (pa * a.pose, pb * b.pose);
                let closer = |sa: &dyn parry3d_f64::shape::Shape,
                              wa: &Pose,
                              sb: &dyn parry3d_f64::shape::Shape,
                              wb: &Pose| {
                    if margin <= 0.0 {
                        query::intersection_test(wa, sa, wb, sb).is_ok_and(|i| i.intersecting)
                    } else {
                        query::distance(wa, sa, wb, sb).is_ok_and(|d| d.distance < margin)
                    }
                };
                match (trimesh(a), trimesh(b)) {
                    (Some(ma), Some(mb)) if margin <= 0.0 => {
                        // Both triangles in the first mesh's frame, tested directly.
                        let ab = wa.inv_mul(&wb);
                        let reach = std::cell::Cell::new(margin);
                        near_triangles(ma, &wa, mb, &wb, &reach).any(|(i, j)| {
                            let (ta, tb) = (ma.triangle(i), mb.triangle(j));
                            let tb_in_a = [ab * tb.a, ab * tb.b, ab * tb.c];
                            triangles_intersect(&[ta.a, ta.b, ta.c], &tb_in_a)
                                .unwrap_or_else(|| closer(&ta, &Pose::IDENTITY, &tb, &ab))
                        })
                    }
                    (Some(ma), Some(mb)) => {
                        let reach = std::cell::Cell::new(margin);
                        near_triangles(ma, &wa, mb, &wb, &reach)
                            .any(|(i, j)| closer(&ma.triangle(i), &wa, &mb.triangle(j), &wb))
                    }
                    _ => closer(a.shape.as_ref(), &wa, b.shape.as_ref(), &wb),
                }
            })
        })
    }

    /// The closest pair of points between these shapes at `fa` and `other`'s at `fb`, where
    /// they come within `within` (m); `None` where they are farther apart.
    pub fn contact(
        &self,
        fa: &Isometry3<f64>,
        other: &Self,
        fb: &Isometry3<f64>,
        within: f64,
    ) -> Option<ExactContact> {
        if self.bound_gap(fa, other, fb) >= within {
            return None;
        }
        let (pa, pb) = (pose_of(fa), pose_of(fb));
        if self.hulls_apart(&pa, other, &pb, within) {
            return None;
        }
        let mut best: Option<ExactContact> = None;
        for a in &self.pieces {
            for b in &other.pieces {
                let (wa, wb) = (pa * a.pose, pb * b.pose);
                let contact = match (trimesh(a), trimesh(b)) {
                    (Some(ma), Some(mb)) => closest_triangles(ma, &wa, mb, &wb, within),
                    _ => query::contact(&wa, a.shape.as_ref(), &wb, b.shape.as_ref(), within)
                        .ok()
                        .flatten(),
                };
                let Some(c) = contact else {
                    continue;
                };
                if c.dist < within && best.is_none_or(|b| c.dist < b.gap) {
                    // `normal1` leaves the first shape towards the second: the first moves
                    // away along its opposite, and the second along the opposite of
                    // `normal2`.
                    best = Some(ExactContact {
                        gap: c.dist,
                        first: (point_of(c.point1), -vector_of(c.normal1)),
                        second: (point_of(c.point2), -vector_of(c.normal2)),
                    });
                }
            }
        }
        best
    }

    /// The distance from `p` (in these shapes' frame) to the nearest of their surfaces.
    pub fn surface_distance(&self, p: &Point3<f64>) -> f64 {
        let q = Vector::new(p.x, p.y, p.z);
        (self.pieces.iter())
            .map(|piece| piece.shape.distance_to_point(&piece.pose, q, false))
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether `p` (in these shapes' frame) lies inside them: inside a primitive, or inside a
    /// mesh by its winding number (the solid angle its triangles subtend, over 4 pi: 1 inside
    /// a closed mesh, 0 outside, whichever way its triangles turn).
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        let q = Vector::new(p.x, p.y, p.z);
        self.pieces
            .iter()
            .any(|piece| match piece.shape.as_trimesh() {
                Some(mesh) => winding_number(mesh, piece.pose.inverse() * q).abs() > 0.5,
                None => piece.shape.contains_point(&piece.pose, q),
            })
    }

    /// The signed distance between these shapes at `fa` and `other`'s at `fb`, `cap` where
    /// it is at least `cap`.
    pub fn gap(&self, fa: &Isometry3<f64>, other: &Self, fb: &Isometry3<f64>, cap: f64) -> f64 {
        self.contact(fa, other, fb, cap)
            .map_or(cap, |c| c.gap.min(cap))
    }
}

/// The winding number of `mesh` about `q` (its frame): the solid angle of each triangle seen
/// from `q` (Van Oosterom and Strackee), summed, over 4 pi.
fn winding_number(mesh: &TriMesh, q: Vector) -> f64 {
    let total: f64 = mesh
        .triangles()
        .map(|t| {
            let (a, b, c) = (t.a - q, t.b - q, t.c - q);
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let num = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
            2.0 * num.atan2(den)
        })
        .sum();
    total / (4.0 * std::f64::consts::PI)
}

/// The piece's triangle mesh, if it is one.
fn trimesh(piece: &Piece) -> Option<&TriMesh> {
    piece.shape.as_trimesh()
}

/// The pairs of triangles of `ma` at `wa` and `mb` at `wb` whose bounding boxes come within
/// `reach` of each other: both meshes' trees traversed together, so only the triangles near
/// the other mesh are ever looked at. `reach` is read as the traversal goes: a caller that
/// lowers it (the closest pair so far) prunes what is left.
fn near_triangles<'a>(
    ma: &'a TriMesh,
    wa: &Pose,
    mb: &'a TriMesh,
    wb: &Pose,
    reach: &'a std::cell::Cell<f64>,
) -> impl Iterator<Item = (u32, u32)> + 'a {
    let ab = wa.inv_mul(wb);
    ma.bvh().leaf_pairs(mb.bvh(), move |n1, n2| {
        n1.aabb()
            .loosened(reach.get().max(0.0))
            .intersects(&n2.aabb().transform_by(&ab))
    })
}

/// The closest (or deepest) pair of triangles of `ma` at `wa` and `mb` at `wb` within
/// `within`, as parry's contact: the search narrows to the closest pair found so far.
fn closest_triangles(
    ma: &TriMesh,
    wa: &Pose,
    mb: &TriMesh,
    wb: &Pose,
    within: f64,
) -> Option<query::Contact> {
    let reach = std::cell::Cell::new(within);
    let mut best: Option<query::Contact> = None;
    for (i, j) in near_triangles(ma, wa, mb, wb, &reach) {
        let found = query::contact(wa, &ma.triangle(i), wb, &mb.triangle(j), reach.get());
        if let Ok(Some(c)) = found
            && best.is_none_or(|b| c.dist < b.dist)
        {
            reach.set(c.dist.max(0.0));
            best = Some(c);
        }
    }
    best
}

/// Whether two triangles (in one frame) meet: Möller's test ("A fast triangle-triangle
/// intersection test", 1997), each triangle against the other's plane, then their spans along
/// the line where the planes meet. `None` where they lie in one plane (the caller asks GJK).
fn triangles_intersect(t: &[Vector; 3], u: &[Vector; 3]) -> Option<bool> {
    // Distances this close to a plane count as on it (metres; far below any mesh's detail).
    const ON_PLANE: f64 = 1e-12;
    let side = |tri: &[Vector; 3], of: &[Vector; 3]| {
        let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
        let d = of.map(|p| {
            let v = n.dot(p - tri[0]);
            if v.abs() < ON_PLANE * n.length().max(1.0) {
                0.0
            } else {
                v
            }
        });
        (n, d)
    };
    let (nt, du) = side(t, u);
    if du.iter().all(|&d| d > 0.0) || du.iter().all(|&d| d < 0.0) {
        return Some(false);
    }
    let (nu, dt) = side(u, t);
    if dt.iter().all(|&d| d > 0.0) || dt.iter().all(|&d| d < 0.0) {
        return Some(false);
    }
    let line = nt.cross(nu);
    if du.iter().all(|&d| d == 0.0) || line.length_squared() == 0.0 {
        return None;
    }
    // Project onto the line's largest axis (the spans' order is all that matters).
    let axis = line.abs().max_position();
    let span = |tri: &[Vector; 3], d: [f64; 3]| -> Option<(f64, f64)> {
        let p = tri.map(|v| v[axis]);
        // The vertex alone on its side of the other plane, and the other two.
        let (a, b, c) = if d[0] * d[1] > 0.0 {
            (2, 0, 1)
        } else if d[0] * d[2] > 0.0 {
            (1, 0, 2)
        } else if d[1] * d[2] > 0.0 || d[0] != 0.0 {
            (0, 1, 2)
        } else if d[1] != 0.0 {
            (1, 0, 2)
        } else if d[2] != 0.0 {
            (2, 0, 1)
        } else {
            return None;
        };
        let at = |o: usize| p[a] + (p[o] - p[a]) * d[a] / (d[a] - d[o]);
        let (x, y) = (at(b), at(c));
        Some((x.min(y), x.max(y)))
    };
    let (t0, t1) = span(t, dt)?;
    let (u0, u1) = span(u, du)?;
    Some(t0 <= u1 && u0 <= t1)
}

impl std::fmt::Debug for ExactShapes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExactShapes")
            .field("pieces", &self.pieces.len())
            .field("bound", &self.bound)
            .field("hull", &self.hull.is_some())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// Möller's test against parry's GJK (the slow reference) on random pairs of small
    /// triangles near each other, touching and crossing ones among them.
    #[test]
    fn the_triangle_test_agrees_with_gjk() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let point = |rng: &mut rand::rngs::StdRng| {
            Vector::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let (mut meeting, mut apart) = (0, 0);
        for _ in 0..20_000 {
            let t = [point(&mut rng), point(&mut rng), point(&mut rng)];
            let u = [point(&mut rng), point(&mut rng), point(&mut rng)];
            let reference = query::intersection_test(
                &Pose::IDENTITY,
                &parry3d_f64::shape::Triangle::new(t[0], t[1], t[2]),
                &Pose::IDENTITY,
                &parry3d_f64::shape::Triangle::new(u[0], u[1], u[2]),
            )
            .unwrap()
            .intersecting;
            let fast = triangles_intersect(&t, &u).expect("not coplanar");
            assert_eq!(fast, reference, "{t:?} {u:?}");
            if fast {
                meeting += 1;
            } else {
                apart += 1;
            }
        }
        assert!(
            meeting > 1000 && apart > 1000,
            "{meeting} meeting, {apart} apart"
        );
        // Coplanar triangles are left to GJK.
        let flat = [Vector::ZERO, Vector::X, Vector::Y];
        assert_eq!(triangles_intersect(&flat, &flat.map(|v| v * 0.5)), None);
    }
}
