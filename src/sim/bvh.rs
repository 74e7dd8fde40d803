//! A bounding-volume hierarchy over a link's shapes: the acceleration structure of the
//! ray caster. Built once per link in the link's frame (median split on the longest axis of
//! the centroids, at most [`LEAF_SIZE`] shapes a leaf); the link's pose moves the ray, not
//! the tree. [`Bvh::closest_hit_brute_force`] is the slow reference it is tested against.

use nalgebra::Vector3;

use crate::sim::shape::{Aabb, Ray, Shape};

/// Most shapes in one leaf.
pub const LEAF_SIZE: usize = 4;

#[derive(Clone, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: index of the first shape. Inner: index of the left child (right is `left + 1`).
    first: u32,
    /// Number of shapes in a leaf; 0 for an inner node.
    count: u32,
}

/// Shapes of one link and the tree over them (the shapes are stored in tree order).
#[derive(Clone, Debug)]
pub struct Bvh {
    shapes: Vec<Shape>,
    nodes: Vec<Node>,
}

impl Bvh {
    /// Build the tree. An empty list gives an empty tree that nothing hits.
    pub fn new(shapes: Vec<Shape>) -> Self {
        let mut items: Vec<(Aabb, Shape)> = shapes.into_iter().map(|s| (s.aabb(), s)).collect();
        let mut nodes = Vec::with_capacity(2 * items.len() / LEAF_SIZE + 1);
        if !items.is_empty() {
            nodes.push(Node {
                bounds: Aabb::empty(),
                first: 0,
                count: 0,
            });
            build(&mut nodes, 0, &mut items, 0);
        }
        Bvh {
            shapes: items.into_iter().map(|(_, s)| s).collect(),
            nodes,
        }
    }

    pub fn shapes(&self) -> &[Shape] {
        &self.shapes
    }

    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty()
    }

    /// The corners of the tree's boxes `depth` levels below the root (or of leaves above
    /// that), in the link frame: a hull of the link's shapes that is tighter than one box
    /// (every shape lies inside the boxes these corners span).
    pub fn outline(&self, depth: usize) -> Vec<nalgebra::Point3<f64>> {
        let mut out = Vec::new();
        let mut stack = match self.nodes.is_empty() {
            true => vec![],
            false => vec![(0usize, 0usize)],
        };
        while let Some((i, d)) = stack.pop() {
            let node = &self.nodes[i];
            if node.count > 0 || d == depth {
                out.extend(node.bounds.corners());
            } else {
                let left = node.first as usize;
                stack.push((left, d + 1));
                stack.push((left + 1, d + 1));
            }
        }
        out
    }

    /// Bounds of everything in the link frame (empty box for no shapes).
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::empty(), |n| n.bounds)
    }

    /// The nearest hit before `t_max`, walking the tree front to back.
    pub fn closest_hit(&self, ray: &Ray, t_max: f64) -> Option<f64> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv: Vector3<f64> = ray.dir.map(|d| 1.0 / d);
        let mut best = t_max;
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        if self.nodes[0].bounds.hit(ray, &inv, best).is_none() {
            return None;
        }
        stack[sp] = 0;
        sp += 1;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if node.count > 0 {
                let start = node.first as usize;
                for s in &self.shapes[start..start + node.count as usize] {
                    if let Some(t) = s.intersect(ray, best) {
                        best = t;
                    }
                }
                continue;
            }
            let (l, r) = (node.first as usize, node.first as usize + 1);
            let tl = self.nodes[l].bounds.hit(ray, &inv, best);
            let tr = self.nodes[r].bounds.hit(ray, &inv, best);
            // Push the far child first so the near one is visited first.
            match (tl, tr) {
                (Some(a), Some(b)) => {
                    let (near, far) = if a <= b { (l, r) } else { (r, l) };
                    stack[sp] = far as u32;
                    stack[sp + 1] = near as u32;
                    sp += 2;
                }
                (Some(_), None) => {
                    stack[sp] = l as u32;
                    sp += 1;
                }
                (None, Some(_)) => {
                    stack[sp] = r as u32;
                    sp += 1;
                }
                (None, None) => {}
            }
        }
        (best < t_max).then_some(best)
    }

    /// The same answer as [`Bvh::closest_hit`] by testing every shape: the slow reference.
    pub fn closest_hit_brute_force(&self, ray: &Ray, t_max: f64) -> Option<f64> {
        let mut best = t_max;
        for s in &self.shapes {
            if let Some(t) = s.intersect(ray, best) {
                best = t;
            }
        }
        (best < t_max).then_some(best)
    }
}

fn build(nodes: &mut Vec<Node>, index: usize, items: &mut [(Aabb, Shape)], first: usize) {
    let bounds = items.iter().fold(Aabb::empty(), |b, (a, _)| b.union(a));
    if items.len() <= LEAF_SIZE {
        nodes[index] = Node {
            bounds,
            first: first as u32,
            count: items.len() as u32,
        };
        return;
    }
    let centroids = items
        .iter()
        .fold(Aabb::empty(), |b, (a, _)| b.grow(&a.center()));
    let extent = centroids.max - centroids.min;
    let axis = extent.imax();
    let mid = items.len() / 2;
    items.select_nth_unstable_by(mid, |a, b| {
        a.0.center()[axis].total_cmp(&b.0.center()[axis])
    });
    let left = nodes.len();
    let placeholder = Node {
        bounds: Aabb::empty(),
        first: 0,
        count: 0,
    };
    nodes.push(placeholder.clone());
    nodes.push(placeholder);
    nodes[index] = Node {
        bounds,
        first: left as u32,
        count: 0,
    };
    let (lo, hi) = items.split_at_mut(mid);
    build(nodes, left, lo, first);
    build(nodes, left + 1, hi, first + mid);
}
