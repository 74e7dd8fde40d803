//! The exact geometry behind the spheres: each link's collision shapes as its description
//! gives them (meshes as triangle meshes, boxes, cylinders, spheres) and each obstacle as it
//! is, for the narrow phase. A pair the broad phase cannot tell apart is decided here by
//! parry's queries (GJK/EPA between convex pieces, bounding-volume trees over meshes): a mesh
//! is its surface, as coal (Pinocchio's checker) takes it, so two meshes collide where their
//! triangles meet and one wholly inside the other does not.

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::math::{Pose, Vector};
use parry3d_f64::query;
use parry3d_f64::shape::SharedShape;

use crate::sim::collision::sphere::Sphere;
use crate::sim::shape::Shape;

mod tree;
mod triangles;

use tree::{Mesh, TriangleTree, near_pairs, near_shape};
use triangles::{
    closest_pair, closest_to_convex, closest_triangles, nearest_triangle, triangles_intersect,
    winding_number,
};

/// One convex piece or mesh of a link (or an obstacle), where it sits in the link's frame.
#[derive(Clone)]
struct Piece {
    pose: Pose,
    shape: SharedShape,
    /// A mesh's tree over its triangles (none for a primitive).
    tree: Option<std::sync::Arc<TriangleTree>>,
}

impl Piece {
    /// A primitive (a convex shape) at `pose`.
    fn convex(pose: Pose, shape: SharedShape) -> Self {
        Self {
            pose,
            shape,
            tree: None,
        }
    }
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
    /// Whether a piece is a primitive (solid: another shape may lie wholly inside it).
    solid: bool,
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

/// How two shapes stand within a distance ([`ExactShapes::near`]).
#[derive(Clone, Copy, Debug)]
pub enum Near {
    /// They overlap (or touch).
    Overlapping,
    /// They keep apart: where they are closest.
    Apart(ExactContact),
}

/// The most vertices a hull may have and still be kept to rule pairs out.
const MAX_HULL_VERTICES: usize = 256;

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
                Shape::Cuboid { pose, half } => pieces.push(Piece::convex(
                    pose_of(pose),
                    SharedShape::cuboid(half.x, half.y, half.z),
                )),
                Shape::Cylinder {
                    pose,
                    radius,
                    half_length,
                } => pieces.push(Piece::convex(
                    cylinder_pose(pose),
                    SharedShape::cylinder(*half_length, *radius),
                )),
                Shape::Sphere { center, radius } => pieces.push(Piece::convex(
                    Pose::from_translation(Vector::new(center.x, center.y, center.z)),
                    SharedShape::ball(*radius),
                )),
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
                let tree = mesh
                    .as_trimesh()
                    .map(|m| std::sync::Arc::new(TriangleTree::of(m)));
                pieces.push(Piece {
                    pose: Pose::IDENTITY,
                    shape: mesh,
                    tree,
                });
            }
        }
        Self::new(pieces)
    }

    /// A box with half extents `half` about `pose`.
    pub fn cuboid(pose: &Isometry3<f64>, half: &Vector3<f64>) -> Self {
        Self::new(vec![Piece::convex(
            pose_of(pose),
            SharedShape::cuboid(half.x, half.y, half.z),
        )])
    }

    /// Balls (a mesh obstacle read as the spheres covering it; one for a sphere).
    pub fn balls(spheres: &[Sphere]) -> Self {
        Self::new(
            spheres
                .iter()
                .map(|s| {
                    Piece::convex(
                        Pose::from_translation(Vector::from(s.center)),
                        SharedShape::ball(s.radius),
                    )
                })
                .collect(),
        )
    }

    /// The segment `a`-`b` swept by `radius`.
    pub fn capsule(a: &Point3<f64>, b: &Point3<f64>, radius: f64) -> Self {
        Self::new(vec![Piece::convex(
            Pose::IDENTITY,
            SharedShape::capsule(
                Vector::new(a.x, a.y, a.z),
                Vector::new(b.x, b.y, b.z),
                radius,
            ),
        )])
    }

    /// A cylinder along the local z axis of `pose`, centred on it.
    pub fn cylinder(pose: &Isometry3<f64>, radius: f64, half_height: f64) -> Self {
        Self::new(vec![Piece::convex(
            cylinder_pose(pose),
            SharedShape::cylinder(half_height, radius),
        )])
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
        // A hull of many vertices costs GJK more than the triangle trees it would spare
        // (measured on the G1's hulls of 418 to 2,167 vertices; the Panda's, of at most 152,
        // pay).
        let hull = hull.filter(|h| {
            h.as_convex_polyhedron()
                .is_some_and(|c| c.points().len() <= MAX_HULL_VERTICES)
        });
        let solid = pieces.iter().any(|p| p.shape.as_trimesh().is_none());
        Self {
            pieces,
            bound,
            hull,
            solid,
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
        let Some((pa, pb)) = self.poses_within(fa, other, fb, margin) else {
            return false;
        };
        self.pieces.iter().any(|a| {
            (other.pieces.iter())
                .any(|b| pieces_closer(a, &(pa * a.pose), b, &(pb * b.pose), margin))
        })
    }

    /// The closest pair of points between these shapes at `fa` and `other`'s at `fb`, where
    /// they come within `within` (m); `None` where they are farther apart. Where they overlap,
    /// the deepest pair the query finds.
    pub fn contact(
        &self,
        fa: &Isometry3<f64>,
        other: &Self,
        fb: &Isometry3<f64>,
        within: f64,
    ) -> Option<ExactContact> {
        let (pa, pb) = self.poses_within(fa, other, fb, within)?;
        let each = |a: &Piece, wa: &Pose, b: &Piece, wb: &Pose, reach| {
            pieces_contact(a, wa, b, wb, reach).map(Found::Closest)
        };
        match self.closest_of_pieces(&pa, other, &pb, within, each)? {
            Found::Closest(c) => Some(exact_contact(&c)),
            Found::Meet => None,
        }
    }

    /// How these shapes at `fa` and `other`'s at `fb` stand within `within` (m): apart, with
    /// their closest points, or overlapping (how deep is not computed: an optimiser pushes an
    /// overlap apart by the spheres, whose distances change smoothly); `None` where they keep
    /// `within` apart. What an optimiser asks at every step, so the cheap question: one
    /// search for the closest pair of triangles, ended by the first pair that meets.
    pub fn near(
        &self,
        fa: &Isometry3<f64>,
        other: &Self,
        fb: &Isometry3<f64>,
        within: f64,
    ) -> Option<Near> {
        let (pa, pb) = self.poses_within(fa, other, fb, within)?;
        Some(
            match self.closest_of_pieces(&pa, other, &pb, within, pieces_closest)? {
                Found::Closest(c) => Near::Apart(exact_contact(&c)),
                Found::Meet => Near::Overlapping,
            },
        )
    }

    /// The poses of these shapes at `fa` and `other`'s at `fb`, where neither their bounding
    /// spheres nor their hulls keep `within` apart.
    fn poses_within(
        &self,
        fa: &Isometry3<f64>,
        other: &Self,
        fb: &Isometry3<f64>,
        within: f64,
    ) -> Option<(Pose, Pose)> {
        if self.bound_gap(fa, other, fb) >= within {
            return None;
        }
        let (pa, pb) = (pose_of(fa), pose_of(fb));
        (!self.hulls_apart(&pa, other, &pb, within)).then_some((pa, pb))
    }

    /// The closest of what `each` finds of every pair of pieces within `within` (each asked
    /// within the closest so far); a pair that meets ends it.
    fn closest_of_pieces(
        &self,
        pa: &Pose,
        other: &Self,
        pb: &Pose,
        within: f64,
        each: impl Fn(&Piece, &Pose, &Piece, &Pose, f64) -> Option<Found>,
    ) -> Option<Found> {
        let mut best: Option<query::Contact> = None;
        for a in &self.pieces {
            for b in &other.pieces {
                let reach = best.map_or(within, |b| b.dist.clamp(0.0, within));
                match each(a, &(pa * a.pose), b, &(pb * b.pose), reach) {
                    None => {}
                    Some(Found::Meet) => return Some(Found::Meet),
                    Some(Found::Closest(c)) => {
                        if c.dist < within && best.is_none_or(|b| c.dist < b.dist) {
                            best = Some(c);
                        }
                    }
                }
            }
        }
        best.map(Found::Closest)
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

    /// Whether a piece of `other` at `fb` lies inside a solid piece of these shapes at `fa`
    /// (a primitive: a mesh is its surface, and nothing lies inside it), by one point of it
    /// (a primitive's centre, a mesh's first vertex). Where the two surfaces keep apart, a
    /// piece is wholly inside a primitive or wholly outside it: this is the collision that
    /// spheres covering the surfaces cannot see.
    pub fn holds_a_piece_of(&self, fa: &Isometry3<f64>, other: &Self, fb: &Isometry3<f64>) -> bool {
        if !self.solid || self.bound_gap(fa, other, fb) > 0.0 {
            return false;
        }
        let (pa, pb) = (pose_of(fa), pose_of(fb));
        let point_of = |t: &Piece| {
            let local = (t.shape.as_trimesh())
                .and_then(|m| m.vertices().first().copied())
                .unwrap_or(Vector::ZERO);
            pb * (t.pose * local)
        };
        (self.pieces.iter())
            .filter(|s| s.shape.as_trimesh().is_none())
            .any(|s| {
                let world = pa * s.pose;
                (other.pieces.iter()).any(|t| s.shape.contains_point(&world, point_of(t)))
            })
    }

    /// The signed distance between these shapes at `fa` and `other`'s at `fb`, `cap` where
    /// it is at least `cap`.
    pub fn gap(&self, fa: &Isometry3<f64>, other: &Self, fb: &Isometry3<f64>, cap: f64) -> f64 {
        self.contact(fa, other, fb, cap)
            .map_or(cap, |c| c.gap.min(cap))
    }
}

/// The piece's triangle mesh with its tree, if it is one.
fn trimesh(piece: &Piece) -> Option<Mesh<'_>> {
    Some(Mesh {
        triangles: piece.shape.as_trimesh()?,
        tree: piece.tree.as_deref()?,
    })
}

/// Parry's contact (`normal1` leaving the first shape towards the second) as ours: each side
/// moves away along the opposite of its normal.
fn exact_contact(c: &query::Contact) -> ExactContact {
    ExactContact {
        gap: c.dist,
        first: (point_of(c.point1), -vector_of(c.normal1)),
        second: (point_of(c.point2), -vector_of(c.normal2)),
    }
}

/// Whether piece `a` at `wa` comes closer than `margin` to piece `b` at `wb`: two meshes
/// triangle against triangle (Möller's test at zero margin), a mesh and a convex shape each
/// near triangle against the shape, two convex shapes by GJK; the first pair closer ends it.
fn pieces_closer(a: &Piece, wa: &Pose, b: &Piece, wb: &Pose, margin: f64) -> bool {
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
    let reach = std::cell::Cell::new(margin);
    match (trimesh(a), trimesh(b)) {
        (Some(ma), Some(mb)) if margin <= 0.0 => {
            // Both triangles in the first mesh's frame, tested directly.
            let ab = wa.inv_mul(wb);
            near_pairs(ma.tree, wa, mb.tree, wb, &reach).any(|(i, j)| {
                let (ta, tb) = (ma.triangle(i), mb.triangle(j));
                let tb_in_a = [ab * tb.a, ab * tb.b, ab * tb.c];
                triangles_intersect(&[ta.a, ta.b, ta.c], &tb_in_a)
                    .unwrap_or_else(|| closer(&ta, &Pose::IDENTITY, &tb, &ab))
            })
        }
        (Some(ma), Some(mb)) => closest_pair(ma, wa, mb, wb, margin, margin).is_some(),
        (Some(m), None) if margin > 0.0 => {
            nearest_triangle(m, wa, b.shape.as_ref(), wb, margin, margin).is_some()
        }
        (None, Some(m)) if margin > 0.0 => {
            nearest_triangle(m, wb, a.shape.as_ref(), wa, margin, margin).is_some()
        }
        (Some(m), None) => near_shape(m.tree, wa, b.shape.as_ref(), wb, &reach)
            .any(|i| closer(&m.triangle(i), wa, b.shape.as_ref(), wb)),
        (None, Some(m)) => near_shape(m.tree, wb, a.shape.as_ref(), wa, &reach)
            .any(|i| closer(a.shape.as_ref(), wa, &m.triangle(i), wb)),
        (None, None) => closer(a.shape.as_ref(), wa, b.shape.as_ref(), wb),
    }
}

/// Two pieces within a distance: meeting, or where they are closest (apart; or, as
/// [`pieces_contact`] finds it, the deepest pair of an overlap).
enum Found {
    Meet,
    Closest(query::Contact),
}

/// Whether piece `a` at `wa` and piece `b` at `wb` meet, else their closest points, where
/// within `within`. Of meshes, the closest pair of triangles is found by distance alone and
/// its contact computed once.
fn pieces_closest(a: &Piece, wa: &Pose, b: &Piece, wb: &Pose, within: f64) -> Option<Found> {
    let apart = |ta: &parry3d_f64::shape::Triangle, sb: &dyn parry3d_f64::shape::Shape, wb| {
        let c = query::contact(wa, ta, wb, sb, within).ok().flatten()?;
        Some(Found::Closest(c))
    };
    match (trimesh(a), trimesh(b)) {
        (Some(ma), Some(mb)) => match closest_pair(ma, wa, mb, wb, within, f64::NEG_INFINITY)? {
            (i, j, d) if d > 0.0 => apart(&ma.triangle(i), &mb.triangle(j), wb),
            _ => Some(Found::Meet),
        },
        (Some(m), None) => {
            let shape = b.shape.as_ref();
            match nearest_triangle(m, wa, shape, wb, within, f64::NEG_INFINITY)? {
                (i, d) if d > 0.0 => apart(&m.triangle(i), shape, wb),
                _ => Some(Found::Meet),
            }
        }
        (None, Some(_)) => match pieces_closest(b, wb, a, wa, within)? {
            Found::Closest(c) => Some(Found::Closest(c.flipped())),
            Found::Meet => Some(Found::Meet),
        },
        (None, None) => {
            let c = query::contact(wa, a.shape.as_ref(), wb, b.shape.as_ref(), within).ok()??;
            Some(if c.dist > 0.0 {
                Found::Closest(c)
            } else {
                Found::Meet
            })
        }
    }
}

/// The closest (or deepest) pair of points of piece `a` at `wa` and piece `b` at `wb` within
/// `within`, as parry's contact (`point1` and `normal1` on `a`): where they meet, every pair
/// of triangles that meets is asked for its contact and the deepest kept.
fn pieces_contact(
    a: &Piece,
    wa: &Pose,
    b: &Piece,
    wb: &Pose,
    within: f64,
) -> Option<query::Contact> {
    match pieces_closest(a, wa, b, wb, within)? {
        Found::Closest(c) => Some(c),
        Found::Meet => match (trimesh(a), trimesh(b)) {
            (Some(ma), Some(mb)) => closest_triangles(ma, wa, mb, wb, within),
            (Some(m), None) => closest_to_convex(m, wa, b.shape.as_ref(), wb, within),
            (None, Some(m)) => {
                closest_to_convex(m, wb, a.shape.as_ref(), wa, within).map(|c| c.flipped())
            }
            (None, None) => query::contact(wa, a.shape.as_ref(), wb, b.shape.as_ref(), within)
                .ok()
                .flatten(),
        },
    }
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

    /// A closed, lumpy mesh of `n` by `2n` quads about the origin: a ball of radius about 0.1
    /// whose radius varies with direction.
    fn lumpy(n: usize, seed: u64) -> Vec<Shape> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let bumps: Vec<f64> = (0..(n + 1) * 2 * n)
            .map(|_| rng.random_range(0.08..0.12))
            .collect();
        let at = |i: usize, j: usize| {
            let (th, ph) = (
                std::f64::consts::PI * i as f64 / n as f64,
                std::f64::consts::PI * j as f64 / n as f64,
            );
            let r = bumps[i * 2 * n + j % (2 * n)];
            Point3::new(
                r * th.sin() * ph.cos(),
                r * th.sin() * ph.sin(),
                r * th.cos(),
            )
        };
        let mut shapes = Vec::new();
        for i in 0..n {
            for j in 0..2 * n {
                let q = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                shapes.push(Shape::Triangle([q[0], q[1], q[2]]));
                shapes.push(Shape::Triangle([q[0], q[2], q[3]]));
            }
        }
        shapes
    }

    /// The distance between two meshes over every pair of triangles (GJK): the slow reference.
    fn brute(a: &[Shape], fa: &Isometry3<f64>, b: &[Shape], fb: &Isometry3<f64>) -> f64 {
        let tri = |s: &Shape, f: &Isometry3<f64>| match s {
            Shape::Triangle(t) => {
                let p = t.map(|p| f * p);
                parry3d_f64::shape::Triangle::new(
                    Vector::new(p[0].x, p[0].y, p[0].z),
                    Vector::new(p[1].x, p[1].y, p[1].z),
                    Vector::new(p[2].x, p[2].y, p[2].z),
                )
            }
            _ => unreachable!("triangles only"),
        };
        let mut best = f64::INFINITY;
        for s in a {
            for t in b {
                let d = query::distance(&Pose::IDENTITY, &tri(s, fa), &Pose::IDENTITY, &tri(t, fb));
                best = best.min(d.expect("triangles").distance);
            }
        }
        best
    }

    /// The fast questions an optimiser asks agree with the slow ones: `near` (the cheap bounds,
    /// Möller's test, the closed-form distance, the warm start) and `closer_than` give what
    /// every pair of triangles gives, for two meshes and a mesh and a box, apart, close and
    /// overlapping, asked twice at nearby poses (the second time from the first's guess).
    #[test]
    fn near_and_closer_than_agree_with_every_pair_of_triangles() {
        let (ma, mb) = (lumpy(6, 1), lumpy(5, 2));
        let (a, b) = (ExactShapes::of_link(&ma), ExactShapes::of_link(&mb));
        let half = Vector3::new(0.05, 0.2, 0.1);
        let cuboid = ExactShapes::cuboid(&Isometry3::identity(), &half);
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let within = 0.03;
        let (mut apart, mut overlapping) = (0, 0);
        for _ in 0..80 {
            let fa = Isometry3::new(
                Vector3::from_fn(|_, _| rng.random_range(-0.02..0.02)),
                Vector3::from_fn(|_, _| rng.random_range(-3.0..3.0)),
            );
            let fb = Isometry3::new(
                Vector3::new(
                    rng.random_range(0.1..0.25),
                    0.0,
                    rng.random_range(-0.05..0.05),
                ),
                Vector3::from_fn(|_, _| rng.random_range(-3.0..3.0)),
            );
            for nudge in [0.0, 1e-3] {
                let fb = Isometry3::translation(nudge, 0.0, 0.0) * fb;
                let reference = brute(&ma, &fa, &mb, &fb);
                match a.near(&fa, &b, &fb, within) {
                    None => assert!(reference >= within, "{reference}"),
                    Some(Near::Overlapping) => {
                        assert!(reference <= 1e-12, "{reference}");
                        overlapping += 1;
                    }
                    Some(Near::Apart(c)) => {
                        assert!((c.gap - reference).abs() < 1e-7, "{} {reference}", c.gap);
                        apart += 1;
                    }
                }
                for margin in [0.0, 0.01, within] {
                    let closer = a.closer_than(&fa, &b, &fb, margin);
                    assert_eq!(
                        closer,
                        reference < margin || reference <= 0.0,
                        "{reference} {margin}"
                    );
                }
                // A mesh and a box (at the origin): against each triangle's distance to it.
                let shape = parry3d_f64::shape::Cuboid::new(Vector::new(half.x, half.y, half.z));
                let to_box = (ma.iter())
                    .map(|s| {
                        let Shape::Triangle(t) = s else {
                            unreachable!()
                        };
                        let p = t.map(|p| fa * p).map(|p| Vector::new(p.x, p.y, p.z));
                        let t = parry3d_f64::shape::Triangle::new(p[0], p[1], p[2]);
                        query::distance(&Pose::IDENTITY, &t, &Pose::IDENTITY, &shape)
                            .expect("a triangle and a box")
                            .distance
                    })
                    .fold(f64::INFINITY, f64::min);
                match a.near(&fa, &cuboid, &Isometry3::identity(), within) {
                    None => assert!(to_box >= within, "{to_box}"),
                    Some(Near::Overlapping) => assert!(to_box <= 1e-12, "{to_box}"),
                    Some(Near::Apart(c)) => assert!((c.gap - to_box).abs() < 1e-7),
                }
            }
        }
        assert!(
            apart > 10 && overlapping > 10,
            "{apart} apart, {overlapping} overlapping"
        );
    }
}
