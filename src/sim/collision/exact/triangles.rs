//! Triangle-level queries of the exact check: which triangles of two meshes (or of a mesh and
//! a convex shape) come near each other, the closest pair of them, whether two triangles
//! meet, and a mesh's winding number about a point.

use super::tree::{Mesh, near_pairs, near_shape};
use parry3d_f64::math::{Pose, Vector};
use parry3d_f64::query;
use parry3d_f64::shape::{Shape, TriMesh, Triangle};

/// The winding number of `mesh` about `q` (its frame): the solid angle of each triangle seen
/// from `q` (Van Oosterom and Strackee), summed, over 4 pi.
pub(super) fn winding_number(mesh: &TriMesh, q: Vector) -> f64 {
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

/// The closest (or deepest) pair of triangles of `ma` at `wa` and `mb` at `wb` within
/// `within`, as parry's contact: the search narrows to the closest pair found so far.
pub(super) fn closest_triangles(
    ma: Mesh,
    wa: &Pose,
    mb: Mesh,
    wb: &Pose,
    within: f64,
) -> Option<query::Contact> {
    let reach = std::cell::Cell::new(within);
    let mut best: Option<query::Contact> = None;
    for (i, j) in near_pairs(ma.tree, wa, mb.tree, wb, &reach) {
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

/// The closest pair of triangles of `ma` at `wa` and `mb` at `wb` closer than `within`, with
/// their distance (0 where they meet); the search narrows to the closest pair found so far
/// and ends at the first pair closer than `enough` (a test that asks only whether they come
/// that close), or that meets. Each pair the trees bring is first put to [`triangles_apart`]'s
/// cheap bounds, then to Möller's test: GJK is asked only of the few that neither decides.
pub(super) fn closest_pair(
    ma: Mesh,
    wa: &Pose,
    mb: Mesh,
    wb: &Pose,
    within: f64,
    enough: f64,
) -> Option<(u32, u32, f64)> {
    let reach = std::cell::Cell::new(within);
    let ab = wa.inv_mul(wb);
    // The distance of triangles `i` and `j`, where the bounds cannot show it is `reach` or more.
    let distance = |i: u32, j: u32| {
        let (ta, tb) = (ma.triangle(i), mb.triangle(j));
        let tb = Triangle::new(ab * tb.a, ab * tb.b, ab * tb.c);
        if triangles_apart(&ta, &tb, reach.get()) {
            return None;
        }
        let (t, u) = ([ta.a, ta.b, ta.c], [tb.a, tb.b, tb.c]);
        match triangles_intersect(&t, &u) {
            Some(true) => Some(0.0),
            Some(false) => Some(apart_triangles_distance(&t, &u)),
            None => (query::distance(&Pose::IDENTITY, &ta, &Pose::IDENTITY, &tb).ok())
                .map(|d| d.distance),
        }
    };
    let key = (address(ma.triangles), address(mb.triangles));
    let hint = LAST.with(|m| m.borrow().get(&key).copied());
    let triangles = |m: &TriMesh| m.indices().len() as u32;
    let hint = hint.filter(|&(i, j)| i < triangles(ma.triangles) && j < triangles(mb.triangles));
    let mut best = None;
    for (i, j) in hint
        .into_iter()
        .chain(near_pairs(ma.tree, wa, mb.tree, wb, &reach))
    {
        let Some(d) = distance(i, j) else {
            continue;
        };
        if d < reach.get() || (d <= 0.0 && best.is_none()) {
            reach.set(d.max(0.0));
            best = Some((i, j, d));
            if d < enough || d <= 0.0 {
                break;
            }
        }
    }
    if let Some((i, j, _)) = best {
        LAST.with(|m| m.borrow_mut().insert(key, (i, j)));
    }
    best
}

thread_local! {
    /// The pair of triangles (or triangle and shape: `u32::MAX` for the shape) each search
    /// last found closest, by the two shapes' addresses: tried first the next time the same
    /// two are asked about, which is most often at a nearby configuration (an optimiser's next
    /// step), so the search starts with its reach at about the distance it ends with and
    /// looks at few other pairs. A guess only: whatever it names, the search is exact.
    static LAST: std::cell::RefCell<std::collections::HashMap<(usize, usize), (u32, u32)>> =
        Default::default();
}

/// Where a shape lives: its key in [`LAST`].
fn address<T: ?Sized>(shape: &T) -> usize {
    shape as *const T as *const () as usize
}

/// Whether two triangles (in one frame) are shown `limit` or more apart by cheap bounds:
/// their boxes, or either one's plane with the other wholly on one side, `limit` or more
/// from it.
fn triangles_apart(t: &Triangle, u: &Triangle, limit: f64) -> bool {
    let (tl, th) = (t.a.min(t.b).min(t.c), t.a.max(t.b).max(t.c));
    let (ul, uh) = (u.a.min(u.b).min(u.c), u.a.max(u.b).max(u.c));
    let gap = (ul - th).max(tl - uh).max(Vector::ZERO);
    if gap.length_squared() >= limit * limit {
        return true;
    }
    let beside = |p: &Triangle, q: &Triangle| {
        let Some(n) = (p.b - p.a).cross(p.c - p.a).try_normalize() else {
            return false;
        };
        let d = [q.a, q.b, q.c].map(|v| n.dot(v - p.a));
        d.iter().all(|&x| x >= limit) || d.iter().all(|&x| x <= -limit)
    };
    beside(t, u) || beside(u, t)
}

/// The triangle of `mesh` at `wm` nearest the convex `shape` at `ws`, where closer than
/// `within`, with its distance (0 where they meet); the search narrows to the nearest found
/// so far and ends at the first closer than `enough`.
pub(super) fn nearest_triangle(
    mesh: Mesh,
    wm: &Pose,
    shape: &dyn Shape,
    ws: &Pose,
    within: f64,
    enough: f64,
) -> Option<(u32, f64)> {
    let reach = std::cell::Cell::new(within);
    let key = (address(mesh.triangles), address(shape));
    let hint = LAST.with(|m| m.borrow().get(&key).map(|h| h.0));
    let hint = hint.filter(|&i| i < mesh.indices().len() as u32);
    let in_mesh = wm.inv_mul(ws);
    let axis = axis_of(shape).map(|(a, b, r)| (in_mesh * a, in_mesh * b, r));
    let mut best = None;
    for i in hint
        .into_iter()
        .chain(near_shape(mesh.tree, wm, shape, ws, &reach))
    {
        let t = mesh.triangle(i);
        if let Some((a, b, r)) = axis
            && segment_triangle_distance(a, b, &[t.a, t.b, t.c]) - r > reach.get()
        {
            continue;
        }
        let Ok(d) = query::distance(wm, &t, ws, shape) else {
            continue;
        };
        let d = d.distance;
        if d < reach.get() || (d <= 0.0 && best.is_none()) {
            reach.set(d.max(0.0));
            best = Some((i, d));
            if d < enough || d <= 0.0 {
                break;
            }
        }
    }
    if let Some((i, _)) = best {
        LAST.with(|m| m.borrow_mut().insert(key, (i, u32::MAX)));
    }
    best
}

/// A cylinder's or a capsule's axis (in its frame) and radius: the triangles' distance to
/// it, less the radius, bounds their distance to the shape from below, for a fraction of
/// GJK's cost.
fn axis_of(shape: &dyn Shape) -> Option<(Vector, Vector, f64)> {
    if let Some(c) = shape.as_cylinder() {
        let h = Vector::new(0.0, c.half_height, 0.0);
        return Some((-h, h, c.radius));
    }
    shape
        .as_capsule()
        .map(|c| (c.segment.a, c.segment.b, c.radius))
}

/// The distance between the segment `p`-`q` and triangle `tri` (one frame): zero where the
/// segment passes through it; otherwise the nearest of its ends to the triangle and of it to
/// the triangle's edges.
fn segment_triangle_distance(p: Vector, q: Vector, tri: &[Vector; 3]) -> f64 {
    let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
    let (dp, dq) = (n.dot(p - tri[0]), n.dot(q - tri[0]));
    if dp * dq <= 0.0 && dp != dq {
        let x = p + (q - p) * (dp / (dp - dq));
        if (closest_on_triangle(&x, tri) - x).length_squared() <= 1e-24 {
            return 0.0;
        }
    }
    let mut best = (closest_on_triangle(&p, tri) - p).length_squared();
    best = best.min((closest_on_triangle(&q, tri) - q).length_squared());
    for i in 0..3 {
        best = best.min(segments_distance_squared(p, q, tri[i], tri[(i + 1) % 3]));
    }
    best.sqrt()
}

/// The closest (or deepest) pair of points of `mesh` at `wm` and the convex `shape` at `ws`
/// within `within`, as parry's contact (`point1` on the mesh): the search narrows to the
/// closest triangle found so far.
pub(super) fn closest_to_convex(
    mesh: Mesh,
    wm: &Pose,
    shape: &dyn Shape,
    ws: &Pose,
    within: f64,
) -> Option<query::Contact> {
    let reach = std::cell::Cell::new(within);
    let mut best: Option<query::Contact> = None;
    for i in near_shape(mesh.tree, wm, shape, ws, &reach) {
        let found = query::contact(wm, &mesh.triangle(i), ws, shape, reach.get());
        if let Ok(Some(c)) = found
            && best.is_none_or(|b| c.dist < b.dist)
        {
            reach.set(c.dist.max(0.0));
            best = Some(c);
        }
    }
    best
}

/// The distance between two triangles (in one frame) that do not meet: the closest pair of
/// points of two disjoint triangles is a vertex of one and a point of the other, or a point
/// of an edge of each (Ericson, "Real-Time Collision Detection", 5.1.5 and 5.1.9): the
/// smallest of those fifteen, in closed form (several times cheaper than GJK).
fn apart_triangles_distance(t: &[Vector; 3], u: &[Vector; 3]) -> f64 {
    let mut best = f64::INFINITY;
    for (p, tri) in [(t, u), (u, t)] {
        for v in p {
            best = best.min((closest_on_triangle(v, tri) - *v).length_squared());
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            let d = segments_distance_squared(t[i], t[(i + 1) % 3], u[j], u[(j + 1) % 3]);
            best = best.min(d);
        }
    }
    best.sqrt()
}

/// The point of triangle `tri` closest to `p` (Ericson 5.1.5: by `p`'s Voronoi region).
fn closest_on_triangle(p: &Vector, tri: &[Vector; 3]) -> Vector {
    let [a, b, c] = *tri;
    let (ab, ac, ap) = (b - a, c - a, *p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = *p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = *p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        // A degenerate (flat) triangle: its edges answer.
        return [(a, b), (b, c), (c, a)]
            .map(|(s, e)| closest_on_segment(p, s, e))
            .into_iter()
            .min_by(|x, y| {
                (*x - *p)
                    .length_squared()
                    .total_cmp(&(*y - *p).length_squared())
            })
            .unwrap_or(a);
    }
    a + ab * (vb / denom) + ac * (vc / denom)
}

/// The point of the segment `s`-`e` closest to `p`.
fn closest_on_segment(p: &Vector, s: Vector, e: Vector) -> Vector {
    let d = e - s;
    let len = d.length_squared();
    if len <= 0.0 {
        return s;
    }
    s + d * ((*p - s).dot(d) / len).clamp(0.0, 1.0)
}

/// The squared distance between the segments `p1`-`q1` and `p2`-`q2` (Ericson 5.1.9).
fn segments_distance_squared(p1: Vector, q1: Vector, p2: Vector, q2: Vector) -> f64 {
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    const EPS: f64 = 1e-300;
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s = if denom > 0.0 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    ((p1 + d1 * s) - (p2 + d2 * t)).length_squared()
}

/// Whether two triangles (in one frame) meet: Möller's test ("A fast triangle-triangle
/// intersection test", 1997), each triangle against the other's plane, then their spans along
/// the line where the planes meet. `None` where they lie in one plane (the caller asks GJK).
pub(super) fn triangles_intersect(t: &[Vector; 3], u: &[Vector; 3]) -> Option<bool> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A point uniform in the unit square in x and y, and `o` plus up to `spread` in z.
    fn random_point(rng: &mut rand::rngs::StdRng, o: f64, spread: f64) -> Vector {
        Vector::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            o + spread * rng.random_range(-1.0..1.0),
        )
    }

    /// The segment-triangle distance agrees with parry's GJK between the triangle and the
    /// segment (the slow reference) on random pairs, crossing and apart, and a cylinder's
    /// axis bound never exceeds its GJK distance.
    #[test]
    fn the_segment_triangle_distance_agrees_with_gjk() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let mut crossing = 0;
        for k in 0..5_000 {
            let spread = [0.05, 1.0][k % 2];
            let mut point = |o: f64| random_point(&mut rng, o, spread);
            let t = [point(0.0), point(0.0), point(0.0)];
            let (p, q) = (point(0.5), point(-0.5));
            let tri = parry3d_f64::shape::Triangle::new(t[0], t[1], t[2]);
            let segment = parry3d_f64::shape::Segment::new(p, q);
            let reference = query::distance(&Pose::IDENTITY, &tri, &Pose::IDENTITY, &segment)
                .unwrap()
                .distance;
            let fast = segment_triangle_distance(p, q, &t);
            assert!((fast - reference).abs() < 1e-9, "{fast} {reference}");
            crossing += usize::from(reference == 0.0);
            let cylinder = parry3d_f64::shape::Cylinder::new(0.3, 0.1);
            let (a, b, r) = axis_of(&cylinder).unwrap();
            let gjk = query::distance(&Pose::IDENTITY, &tri, &Pose::IDENTITY, &cylinder)
                .unwrap()
                .distance;
            assert!(segment_triangle_distance(a, b, &t) - r <= gjk + 1e-9);
        }
        assert!(crossing > 100, "{crossing} crossing pairs");
    }

    /// The closed-form distance of two triangles that do not meet agrees with parry's GJK (the
    /// slow reference) on random pairs, near, far and nearly parallel.
    #[test]
    fn the_closed_form_triangle_distance_agrees_with_gjk() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let mut checked = 0;
        for k in 0..20_000 {
            let spread = [0.05, 1.0, 3.0][k % 3];
            let mut point = |o: f64| random_point(&mut rng, o, spread);
            let t = [point(0.0), point(0.0), point(0.0)];
            let u = [point(1.0), point(1.0), point(1.0)];
            if triangles_intersect(&t, &u) != Some(false) {
                continue;
            }
            let tri = |v: &[Vector; 3]| parry3d_f64::shape::Triangle::new(v[0], v[1], v[2]);
            let reference =
                query::distance(&Pose::IDENTITY, &tri(&t), &Pose::IDENTITY, &tri(&u)).unwrap();
            let fast = apart_triangles_distance(&t, &u);
            assert!(
                (fast - reference.distance).abs() < 1e-9,
                "{fast} {} {t:?} {u:?}",
                reference.distance
            );
            checked += 1;
        }
        assert!(checked > 10_000, "{checked}");
    }
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
