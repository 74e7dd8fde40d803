//! The contacts an optimiser pushes apart: each pair of spheres (of two checked links, or of
//! a moving link and an obstacle) closer than a distance, with its signed distance and the
//! direction in which that distance grows fastest at each sphere's centre; where the exact
//! shapes decide ([`CollisionModel::with_exact`]), each pair of links (or link and obstacle)
//! closer than it, at their exact closest points.

use nalgebra::{Isometry3, Point3, Vector3};

use crate::sim::collision::exact::Near;
use crate::sim::collision::model::CollisionModel;
use crate::sim::collision::scene::{Obstacle, Scene};

/// Two spheres closer than the distance asked for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Contact {
    /// Sphere `i` of link `a` and sphere `j` of link `b` (a checked pair).
    Spheres {
        a: usize,
        i: usize,
        b: usize,
        j: usize,
    },
    /// Sphere `i` of link `a` (a moving link) and obstacle `k` of the scene.
    Obstacle { a: usize, i: usize, k: usize },
    /// Links `a` and `b` (a checked pair) on their exact shapes.
    Links { a: usize, b: usize },
    /// Link `a` (a moving link) and obstacle `k` of the scene on their exact shapes.
    LinkObstacle { a: usize, k: usize },
}

/// A contact where it is: its signed distance (m, negative where the spheres overlap) and
/// each side's sphere centre (or exact closest point) with the unit direction that moving it
/// along increases the distance (the obstacle's side is fixed: `None`).
#[derive(Clone, Copy, Debug)]
pub struct Placement {
    pub contact: Contact,
    pub gap: f64,
    pub first: (usize, Point3<f64>, Vector3<f64>),
    pub second: Option<(usize, Point3<f64>, Vector3<f64>)>,
}

/// The step of the central differences of an obstacle's distance (m).
const GRADIENT_STEP_M: f64 = 1e-6;

/// The direction in which the distance to `o` grows fastest at `p` (central differences;
/// any unit vector where it is flat).
fn away_from(o: &Obstacle, p: &Point3<f64>) -> Vector3<f64> {
    let h = GRADIENT_STEP_M;
    let grad = Vector3::from_fn(|d, _| {
        let mut e = Vector3::zeros();
        e[d] = h;
        (o.distance(&(p + e)) - o.distance(&(p - e))) / (2.0 * h)
    });
    grad.try_normalize(1e-12).unwrap_or_else(Vector3::z)
}

impl CollisionModel {
    /// Every contact at `frames` closer than `within` (m): the checked pairs' spheres where
    /// `self_collision`, and the moving links' spheres against each obstacle of `scene`.
    pub fn contacts(
        &self,
        frames: &[Isometry3<f64>],
        scene: Option<&Scene>,
        self_collision: bool,
        within: f64,
    ) -> Vec<Placement> {
        if self.exact.is_some() {
            return self.exact_contacts(frames, scene, self_collision, within);
        }
        let mut out = Vec::new();
        if self_collision {
            for &pair in &self.pairs {
                self.sphere_pair_contacts(frames, pair, within, &mut out);
            }
        }
        let Some(scene) = scene else {
            return out;
        };
        let gap = |c: &Point3<f64>, r: f64| scene.gap(c, r);
        for a in 0..frames.len() {
            if !self.moving[a] || !self.trees[a].closer_to(&frames[a], gap, within) {
                continue;
            }
            for k in 0..scene.obstacles.len() {
                self.sphere_obstacle_contacts(frames, (a, k), scene, within, &mut out);
            }
        }
        out
    }

    /// [`Self::contacts`] on the exact shapes: each checked pair (and moving link and
    /// obstacle) closer than `within` that the spheres cannot rule out, at its exact closest
    /// points while they keep apart; a pair already overlapping is pushed apart by its
    /// spheres' contacts instead (a mesh's deepest triangle changes as it moves, the spheres'
    /// distances change smoothly), or where its spheres do not reach each other, by its
    /// deepest exact contact.
    fn exact_contacts(
        &self,
        frames: &[Isometry3<f64>],
        scene: Option<&Scene>,
        self_collision: bool,
        within: f64,
    ) -> Vec<Placement> {
        let Some(x) = &self.exact else {
            return Vec::new();
        };
        let mut out = Vec::new();
        if self_collision {
            for &(a, b) in &self.pairs {
                if self.spheres_keep_pair_apart(x, frames, (a, b), within) {
                    continue;
                }
                let (la, lb) = (&x.links[a], &x.links[b]);
                let (fa, fb) = (&frames[a], &frames[b]);
                let c = match la.near(fa, lb, fb, within) {
                    None => continue,
                    Some(Near::Apart(c)) => c,
                    Some(Near::Overlapping) => {
                        let before = out.len();
                        self.sphere_pair_contacts(frames, (a, b), within, &mut out);
                        if out.len() > before {
                            continue;
                        }
                        let Some(c) = la.contact(fa, lb, fb, within) else {
                            continue;
                        };
                        c
                    }
                };
                out.push(Placement {
                    contact: Contact::Links { a, b },
                    gap: c.gap,
                    first: (a, c.first.0, c.first.1),
                    second: Some((b, c.second.0, c.second.1)),
                });
            }
        }
        let Some(scene) = scene else {
            return out;
        };
        let world = Isometry3::identity();
        for (a, f) in frames.iter().enumerate() {
            if !self.moving[a] {
                continue;
            }
            for (k, o) in scene.exact().iter().enumerate() {
                let obstacle = &scene.obstacles[k].1;
                if self.spheres_keep_obstacle_apart(x, frames, a, obstacle, within) {
                    continue;
                }
                let c = match x.links[a].near(f, o, &world, within) {
                    None => continue,
                    Some(Near::Apart(c)) => c,
                    Some(Near::Overlapping) => {
                        let before = out.len();
                        self.sphere_obstacle_contacts(frames, (a, k), scene, within, &mut out);
                        if out.len() > before {
                            continue;
                        }
                        let Some(c) = x.links[a].contact(f, o, &world, within) else {
                            continue;
                        };
                        c
                    }
                };
                out.push(Placement {
                    contact: Contact::LinkObstacle { a, k },
                    gap: c.gap,
                    first: (a, c.first.0, c.first.1),
                    second: None,
                });
            }
        }
        out
    }
}

impl CollisionModel {
    /// The contacts of link `a`'s and link `b`'s spheres closer than `within` (in the order
    /// of their spheres), each placed as it is found.
    fn sphere_pair_contacts(
        &self,
        frames: &[Isometry3<f64>],
        (a, b): (usize, usize),
        within: f64,
        out: &mut Vec<Placement>,
    ) {
        let (ta, tb) = (&self.trees[a], &self.trees[b]);
        let mut pairs = ta.pairs_within(&frames[a], tb, &frames[b], within);
        pairs.sort_unstable();
        for (i, j) in pairs {
            let (sa, sb) = (&self.spheres[a][i], &self.spheres[b][j]);
            let (ca, cb) = (frames[a] * sa.center(), frames[b] * sb.center());
            let d = ca - cb;
            let n = d.try_normalize(1e-12).unwrap_or_else(Vector3::z);
            out.push(Placement {
                contact: Contact::Spheres { a, i, b, j },
                gap: d.norm() - sa.radius - sb.radius,
                first: (a, ca, n),
                second: Some((b, cb, -n)),
            });
        }
    }

    /// The contacts of link `a`'s spheres with obstacle `k` of `scene` closer than `within`
    /// (in the order of the spheres), each placed as it is found.
    fn sphere_obstacle_contacts(
        &self,
        frames: &[Isometry3<f64>],
        (a, k): (usize, usize),
        scene: &Scene,
        within: f64,
        out: &mut Vec<Placement>,
    ) {
        let o = &scene.obstacles[k].1;
        let gap = |c: &Point3<f64>, r: f64| o.distance(c) - r;
        let mut near = self.trees[a].within_of(&frames[a], gap, within);
        near.sort_unstable();
        for i in near {
            let s = &self.spheres[a][i];
            let c = frames[a] * s.center();
            out.push(Placement {
                contact: Contact::Obstacle { a, i, k },
                gap: o.distance(&c) - s.radius,
                first: (a, c, away_from(o, &c)),
                second: None,
            });
        }
    }
}
