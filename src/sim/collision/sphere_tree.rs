//! A bounding-sphere tree over one link's spheres, built once: the spheres-alone check of two
//! links (or of a link and the obstacles) walks the trees, and leaves a pair of nodes whose
//! bounding spheres keep the distance asked for without looking at their spheres. Testing
//! every sphere of one link against every sphere of the other costs `n·m` a pair of links,
//! which a fit fine where links come close (thousands of spheres a link) cannot afford.
//!
//! A node's sphere holds every sphere beneath it, so the gap between two nodes' spheres is at
//! most the gap between any two spheres beneath them: the walk prunes on that lower bound, and
//! looks into the nearer of two children first.

use nalgebra::{Isometry3, Point3};

use crate::sim::collision::sphere::Sphere;

/// A node: the sphere bounding its spheres (in the link's frame). A leaf holds one sphere;
/// an inner node's children are the node after it and `right`.
#[derive(Clone, Copy, Debug)]
struct Node {
    center: Point3<f64>,
    radius: f64,
    right: u32,
    sphere: u32,
}

/// `Node::sphere` of an inner node.
const INNER: u32 = u32::MAX;

/// What a bound is widened by (m): its rounding must not prune two spheres that just touch.
const SLACK_M: f64 = 1e-12;

impl Node {
    fn is_leaf(&self) -> bool {
        self.sphere != INNER
    }
}

/// The tree over a link's spheres (empty for a link without any).
#[derive(Clone, Debug, Default)]
pub struct SphereTree {
    nodes: Vec<Node>,
}

impl SphereTree {
    /// Split top-down at the median of the centres along the axis they spread most on.
    pub fn of(spheres: &[Sphere]) -> Self {
        let mut order: Vec<u32> = (0..spheres.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * spheres.len());
        if !order.is_empty() {
            build(spheres, &mut order, &mut nodes);
        }
        Self { nodes }
    }

    /// The smallest signed distance between a sphere of this tree placed by `fa` and one of
    /// `other` placed by `fb` (negative: overlapping), `cap` where none is closer.
    pub fn gap(&self, fa: &Isometry3<f64>, other: &Self, fb: &Isometry3<f64>, cap: f64) -> f64 {
        let mut best = cap;
        self.walk((fa, other, fb), cap, true, &mut |_, _, g| {
            best = g;
            false
        });
        best
    }

    /// Whether a sphere of this tree placed by `fa` comes closer than `margin` to one of
    /// `other` placed by `fb` (stops at the first).
    pub fn closer_than(
        &self,
        fa: &Isometry3<f64>,
        other: &Self,
        fb: &Isometry3<f64>,
        margin: f64,
    ) -> bool {
        let mut found = false;
        self.walk((fa, other, fb), margin, false, &mut |_, _, _| {
            found = true;
            true
        });
        found
    }

    /// Each pair of spheres (index here, index in `other`) closer than `within`.
    pub fn pairs_within(
        &self,
        fa: &Isometry3<f64>,
        other: &Self,
        fb: &Isometry3<f64>,
        within: f64,
    ) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        self.walk((fa, other, fb), within, false, &mut |i, j, _| {
            out.push((i as usize, j as usize));
            false
        });
        out
    }

    /// The pairs of leaves closer than `reach`, each given to `visit` (with their gap) until it
    /// answers true; where `closest`, the reach shrinks to each pair's gap (so the last pair
    /// given is the closest). This tree is placed by `fa`, `other` by `fb`.
    fn walk(
        &self,
        (fa, other, fb): (&Isometry3<f64>, &Self, &Isometry3<f64>),
        reach: f64,
        closest: bool,
        visit: &mut dyn FnMut(u32, u32, f64) -> bool,
    ) {
        if self.nodes.is_empty() || other.nodes.is_empty() {
            return;
        }
        // Most pairs of links are told apart by their roots: nothing more is set up for them.
        let (ra, rb) = (&self.nodes[0], &other.nodes[0]);
        let root = (fa * ra.center - fb * rb.center).norm() - ra.radius - rb.radius;
        if root >= reach {
            return;
        }
        // The rest in this tree's frame: one placement a node of the other's.
        let rel = fa.inverse() * fb;
        let (a, b) = (&self.nodes, &other.nodes);
        let gap = |(i, j): (u32, u32)| {
            let (a, b) = (&a[i as usize], &b[j as usize]);
            (a.center - rel * b.center).norm() - a.radius - b.radius
        };
        // Open the wider node (a leaf cannot be opened).
        let open = |(i, j): (u32, u32)| {
            let (x, y) = (&a[i as usize], &b[j as usize]);
            match (x.is_leaf(), y.is_leaf()) {
                (true, true) => None,
                (false, _) if y.is_leaf() || x.radius >= y.radius => {
                    Some([(i + 1, j), (x.right, j)])
                }
                _ => Some([(i, j + 1), (i, y.right)]),
            }
        };
        descend(
            ((0, 0), root),
            reach,
            closest,
            gap,
            open,
            &mut |(i, j), g| visit(a[i as usize].sphere, b[j as usize].sphere, g),
        );
    }

    /// The smallest `gap(centre, radius)` over this tree's spheres placed by `f`, `cap` where
    /// none is smaller. `gap` must be a distance less the radius, the distance 1-Lipschitz
    /// (an obstacle's signed distance): a node's sphere then bounds its spheres' gaps below.
    pub fn gap_to(
        &self,
        f: &Isometry3<f64>,
        gap: impl Fn(&Point3<f64>, f64) -> f64,
        cap: f64,
    ) -> f64 {
        let mut best = cap;
        self.walk_to(f, &gap, cap, true, &mut |_, g| {
            best = g;
            false
        });
        best
    }

    /// Whether a sphere placed by `f` has `gap` ([`Self::gap_to`]) below `margin`.
    pub fn closer_to(
        &self,
        f: &Isometry3<f64>,
        gap: impl Fn(&Point3<f64>, f64) -> f64,
        margin: f64,
    ) -> bool {
        let mut found = false;
        self.walk_to(f, &gap, margin, false, &mut |_, _| {
            found = true;
            true
        });
        found
    }

    /// Each sphere placed by `f` whose `gap` ([`Self::gap_to`]) is below `within`.
    pub fn within_of(
        &self,
        f: &Isometry3<f64>,
        gap: impl Fn(&Point3<f64>, f64) -> f64,
        within: f64,
    ) -> Vec<usize> {
        let mut out = Vec::new();
        self.walk_to(f, &gap, within, false, &mut |i, _| {
            out.push(i as usize);
            false
        });
        out
    }

    /// [`Self::walk`] against a distance instead of another tree.
    fn walk_to(
        &self,
        f: &Isometry3<f64>,
        gap: &dyn Fn(&Point3<f64>, f64) -> f64,
        reach: f64,
        closest: bool,
        visit: &mut dyn FnMut(u32, f64) -> bool,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let nodes = &self.nodes;
        let node_gap = |i: u32| {
            let n = &nodes[i as usize];
            gap(&(f * n.center), n.radius)
        };
        let open = |i: u32| {
            let n = &nodes[i as usize];
            (!n.is_leaf()).then_some([i + 1, n.right])
        };
        descend(
            (0, node_gap(0)),
            reach,
            closest,
            node_gap,
            open,
            &mut |i, g| visit(nodes[i as usize].sphere, g),
        );
    }
}

/// The search both walks share: from `root` (a node, or a pair of nodes, with its gap), the
/// leaves closer than `reach` given to `visit` (with their gap) until it answers true; `open`
/// gives an inner one's two children (none: a leaf), `gap` a lower bound of its leaves' gaps;
/// where `closest`, the reach shrinks to each leaf's gap. The nearer child is looked into
/// first.
fn descend<K: Copy>(
    root: (K, f64),
    mut reach: f64,
    closest: bool,
    gap: impl Fn(K) -> f64,
    open: impl Fn(K) -> Option<[K; 2]>,
    visit: &mut dyn FnMut(K, f64) -> bool,
) {
    if root.1 >= reach {
        return;
    }
    let mut stack = Vec::with_capacity(32);
    stack.push(root);
    while let Some((k, g)) = stack.pop() {
        if g >= reach {
            continue;
        }
        let Some([k0, k1]) = open(k) else {
            if visit(k, g) {
                return;
            }
            if closest {
                reach = g;
            }
            continue;
        };
        let (g0, g1) = (gap(k0), gap(k1));
        if g0 <= g1 {
            stack.extend([(k1, g1), (k0, g0)]);
        } else {
            stack.extend([(k0, g0), (k1, g1)]);
        }
    }
}

/// The nodes of `order`'s spheres appended to `nodes` depth first; the index of the first.
fn build(spheres: &[Sphere], order: &mut [u32], nodes: &mut Vec<Node>) -> u32 {
    let at = nodes.len() as u32;
    if let [only] = order {
        let s = &spheres[*only as usize];
        nodes.push(Node {
            center: s.center(),
            radius: s.radius + SLACK_M,
            right: 0,
            sphere: *only,
        });
        return at;
    }
    let center = |k: &u32| spheres[*k as usize].center();
    let (lo, hi) = order.iter().fold(
        (
            Point3::from([f64::INFINITY; 3]),
            Point3::from([f64::NEG_INFINITY; 3]),
        ),
        |(lo, hi), k| (lo.inf(&center(k)), hi.sup(&center(k))),
    );
    let axis = (hi - lo).imax();
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |x, y| center(x)[axis].total_cmp(&center(y)[axis]));
    nodes.push(Node {
        center: Point3::origin(),
        radius: 0.0,
        right: 0,
        sphere: INNER,
    });
    let (left, right) = order.split_at_mut(mid);
    build(spheres, left, nodes);
    let r = build(spheres, right, nodes);
    let bound = tighter(
        enclosing(&nodes[at as usize + 1], &nodes[r as usize]),
        direct(spheres, order),
    );
    nodes[at as usize] = Node {
        center: bound.0,
        radius: bound.1 + SLACK_M,
        right: r,
        sphere: INNER,
    };
    at
}

/// The smallest sphere holding two nodes' spheres.
fn enclosing(a: &Node, b: &Node) -> (Point3<f64>, f64) {
    let d = b.center - a.center;
    let dist = d.norm();
    if dist + b.radius <= a.radius {
        return (a.center, a.radius);
    }
    if dist + a.radius <= b.radius {
        return (b.center, b.radius);
    }
    let radius = 0.5 * (dist + a.radius + b.radius);
    (a.center + d * ((radius - a.radius) / dist), radius)
}

/// A sphere holding `order`'s spheres about the middle of their box.
fn direct(spheres: &[Sphere], order: &[u32]) -> (Point3<f64>, f64) {
    let (lo, hi) = order.iter().fold(
        (
            Point3::from([f64::INFINITY; 3]),
            Point3::from([f64::NEG_INFINITY; 3]),
        ),
        |(lo, hi), &k| {
            let s = &spheres[k as usize];
            let r = nalgebra::Vector3::repeat(s.radius);
            (lo.inf(&(s.center() - r)), hi.sup(&(s.center() + r)))
        },
    );
    let c = nalgebra::center(&lo, &hi);
    let r = order.iter().fold(0.0f64, |m, &k| {
        let s = &spheres[k as usize];
        m.max((s.center() - c).norm() + s.radius)
    });
    (c, r)
}

fn tighter(a: (Point3<f64>, f64), b: (Point3<f64>, f64)) -> (Point3<f64>, f64) {
    if a.1 <= b.1 { a } else { b }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    fn cloud(rng: &mut StdRng, n: usize, size: f64) -> Vec<Sphere> {
        (0..n)
            .map(|_| Sphere {
                center: [0; 3].map(|_| rng.random_range(-size..size)),
                radius: rng.random_range(0.002..0.03),
            })
            .collect()
    }

    fn pose(rng: &mut StdRng, reach: f64) -> Isometry3<f64> {
        let t = Vector3::from_fn(|_, _| rng.random_range(-reach..reach));
        let axis = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
        Isometry3::from_parts(
            Translation3::from(t),
            UnitQuaternion::from_scaled_axis(axis * 3.0),
        )
    }

    fn brute(a: &[Sphere], fa: &Isometry3<f64>, b: &[Sphere], fb: &Isometry3<f64>) -> Vec<f64> {
        let mut out = Vec::new();
        for sa in a {
            for sb in b {
                out.push((fa * sa.center() - fb * sb.center()).norm() - sa.radius - sb.radius);
            }
        }
        out
    }

    #[test]
    fn the_walk_finds_what_every_pair_finds() {
        let mut rng = StdRng::seed_from_u64(3);
        for case in 0..200 {
            let (n, m) = (1 + case % 37, 1 + (case * 7) % 53);
            let (a, b) = (cloud(&mut rng, n, 0.1), cloud(&mut rng, m, 0.15));
            let (fa, fb) = (pose(&mut rng, 0.2), pose(&mut rng, 0.2));
            let (ta, tb) = (SphereTree::of(&a), SphereTree::of(&b));
            let all = brute(&a, &fa, &b, &fb);
            let least = all.iter().copied().fold(f64::INFINITY, f64::min);
            for cap in [-0.05, 0.0, 0.01, 0.1, 1.0] {
                let want = least.min(cap);
                assert!(
                    (ta.gap(&fa, &tb, &fb, cap) - want).abs() < 1e-9,
                    "case {case} cap {cap}"
                );
                assert_eq!(
                    ta.closer_than(&fa, &tb, &fb, cap),
                    least < cap,
                    "case {case}"
                );
                let mut pairs = ta.pairs_within(&fa, &tb, &fb, cap);
                pairs.sort();
                let want: Vec<(usize, usize)> = (0..n * m)
                    .filter(|&k| all[k] < cap)
                    .map(|k| (k / m, k % m))
                    .collect();
                assert_eq!(pairs, want, "case {case} cap {cap}");
            }
        }
    }

    #[test]
    fn the_walk_to_an_obstacle_finds_what_every_sphere_finds() {
        let mut rng = StdRng::seed_from_u64(5);
        let plane = |p: &Point3<f64>, r: f64| p.z - 0.05 - r;
        let ball = |p: &Point3<f64>, r: f64| (p - Point3::new(0.1, 0.0, 0.0)).norm() - 0.04 - r;
        for case in 0..100 {
            let a = cloud(&mut rng, 1 + case % 61, 0.1);
            let f = pose(&mut rng, 0.1);
            let tree = SphereTree::of(&a);
            for gap in [&plane as &dyn Fn(&Point3<f64>, f64) -> f64, &ball] {
                let each: Vec<f64> = a.iter().map(|s| gap(&(f * s.center()), s.radius)).collect();
                let least = each.iter().copied().fold(f64::INFINITY, f64::min);
                for cap in [-0.02, 0.0, 0.03, 1.0] {
                    assert!((tree.gap_to(&f, gap, cap) - least.min(cap)).abs() < 1e-9);
                    assert_eq!(tree.closer_to(&f, gap, cap), least < cap);
                    let mut within = tree.within_of(&f, gap, cap);
                    within.sort();
                    let want: Vec<usize> = (0..a.len()).filter(|&k| each[k] < cap).collect();
                    assert_eq!(within, want, "case {case}");
                }
            }
        }
    }

    #[test]
    fn every_node_holds_the_spheres_beneath_it() {
        let mut rng = StdRng::seed_from_u64(9);
        let spheres = cloud(&mut rng, 300, 0.2);
        let tree = SphereTree::of(&spheres);
        assert_eq!(tree.nodes.len(), 2 * spheres.len() - 1);
        fn leaves(t: &SphereTree, i: usize, out: &mut Vec<usize>) {
            let n = &t.nodes[i];
            if n.is_leaf() {
                out.push(n.sphere as usize);
            } else {
                leaves(t, i + 1, out);
                leaves(t, n.right as usize, out);
            }
        }
        for (i, n) in tree.nodes.iter().enumerate() {
            let mut under = Vec::new();
            leaves(&tree, i, &mut under);
            for k in under {
                let s = &spheres[k];
                assert!((s.center() - n.center).norm() + s.radius <= n.radius + 1e-15);
            }
        }
    }
}
