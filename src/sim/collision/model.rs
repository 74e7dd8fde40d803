//! A robot's collision model: each link's spheres and the pairs of links checked. A
//! configuration collides where two spheres of a checked pair overlap, or a sphere overlaps
//! an obstacle, by more than `-margin` (a margin keeps them that far apart). The clearance is
//! the smallest signed distance between them (negative: overlapping).
//!
//! With the exact shapes behind them ([`CollisionModel::with_exact`]) the spheres are only
//! the broad phase: a pair they cannot tell apart is decided on the links' own shapes
//! ([`crate::sim::collision::exact`]), so a configuration collides only where the geometry
//! itself comes closer than the margin.

use std::sync::Arc;

use nalgebra::{Isometry3, Point3};

use crate::sim::collision::exact::ExactShapes;
use crate::sim::collision::pairs::AllowedPairs;
use crate::sim::collision::scene::{Obstacle, Scene};
use crate::sim::collision::sphere_tree::SphereTree;
use crate::sim::collision::spheres::Sphere;
use crate::sim::kinematics::KinematicChain;

/// What may touch what.
#[derive(Clone, Debug)]
pub struct CollisionModel {
    /// Each link's spheres in its frame (index as in the chain's links).
    pub spheres: Vec<Vec<Sphere>>,
    /// The checked pairs of link indices (`a < b`), both with spheres.
    pub pairs: Vec<(usize, usize)>,
    /// Each link's spheres' bounding-sphere tree in its frame: a pair of links is checked
    /// by walking their trees, not by testing every sphere against every other.
    pub(super) trees: Vec<SphereTree>,
    /// Whether a link moves with the joints: links fixed to the root (the base resting on a
    /// table) are not checked against obstacles.
    pub moving: Vec<bool>,
    /// The links' exact shapes, where the check decides on them (none: the spheres decide).
    pub exact: Option<Arc<ExactLinks>>,
    /// The pairs not checked, each with its reason, where the model was made from them (none:
    /// read back from a file, which keeps the checked pairs only).
    pub allowed: Option<AllowedPairs>,
}

/// Each link's exact shapes (in its frame), and how far the spheres may fall short of them.
#[derive(Debug)]
pub struct ExactLinks {
    pub links: Vec<ExactShapes>,
    /// How far a point of a link's shapes may lie outside its spheres (m; fitted spheres: 0,
    /// they cover every point). Known, the spheres rule out what is farther apart than the
    /// margin plus this on each side before the exact shapes are looked at; `None` (a user's
    /// spheres, which need not cover the shapes): only the shapes' own bounds do.
    pub sphere_slack: Option<f64>,
}

/// How a check decides: on the spheres alone, or on the exact shapes behind them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum CollisionMode {
    /// The spheres alone (fast, conservative: they bulge past flat faces).
    Spheres,
    /// The spheres as the broad phase, the links' own shapes as the narrow one.
    #[default]
    Exact,
}

impl std::fmt::Display for CollisionMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CollisionMode::Spheres => "spheres",
            CollisionMode::Exact => "exact",
        })
    }
}

impl CollisionModel {
    /// The model of `chain`'s links with spheres `spheres`, every pair checked that
    /// `allowed` does not allow.
    pub fn new(chain: &KinematicChain, spheres: Vec<Vec<Sphere>>, allowed: &AllowedPairs) -> Self {
        let names = &chain.links;
        let mut pairs = Vec::new();
        for a in 0..names.len() {
            for b in a + 1..names.len() {
                if !spheres[a].is_empty()
                    && !spheres[b].is_empty()
                    && !allowed.allows(&names[a], &names[b])
                {
                    pairs.push((a, b));
                }
            }
        }
        Self {
            allowed: Some(allowed.clone()),
            ..Self::with_pairs(chain, spheres, pairs)
        }
    }

    /// The model of `chain`'s links with spheres `spheres` checking the pairs `pairs` (link
    /// indices, `a < b`).
    pub fn with_pairs(
        chain: &KinematicChain,
        spheres: Vec<Vec<Sphere>>,
        pairs: Vec<(usize, usize)>,
    ) -> Self {
        let trees = spheres.iter().map(|s| SphereTree::of(s)).collect();
        // A link moves when its frame differs between the joints' lower and upper ends.
        let ranges = chain.joint_ranges();
        let lo: Vec<f64> = ranges.iter().map(|r| r[0]).collect();
        let hi: Vec<f64> = ranges.iter().map(|r| r[1]).collect();
        let (a, b) = (chain.link_frames(&lo), chain.link_frames(&hi));
        let moving = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x.inverse() * y).to_homogeneous() != nalgebra::Matrix4::identity())
            .collect();
        Self {
            spheres,
            pairs,
            trees,
            moving,
            exact: None,
            allowed: None,
        }
    }

    /// This model deciding on `links`' exact shapes (one a link, in its frame) behind its
    /// spheres, which may fall short of them by `sphere_slack` ([`ExactLinks::sphere_slack`]).
    pub fn with_exact(mut self, links: Vec<ExactShapes>, sphere_slack: Option<f64>) -> Self {
        self.exact = Some(Arc::new(ExactLinks {
            links,
            sphere_slack,
        }));
        self
    }

    /// This model deciding on its spheres alone.
    pub fn spheres_only(mut self) -> Self {
        self.exact = None;
        self
    }

    /// How it decides.
    pub fn mode(&self) -> CollisionMode {
        if self.exact.is_some() {
            CollisionMode::Exact
        } else {
            CollisionMode::Spheres
        }
    }

    /// Whether the checked pair `(a, b)` comes closer than `margin`: on the spheres, or where
    /// they cannot rule it out, on the exact shapes.
    fn pair_closer(&self, frames: &[Isometry3<f64>], (a, b): (usize, usize), margin: f64) -> bool {
        let Some(x) = &self.exact else {
            return self.spheres_closer(frames, (a, b), margin);
        };
        !self.spheres_keep_pair_apart(x, frames, (a, b), margin)
            && x.links[a].closer_than(&frames[a], &x.links[b], &frames[b], margin)
    }

    /// Whether the spheres of links `a` and `b` show their exact shapes keep `margin` apart:
    /// they keep the margin plus how far each link's shapes may stand outside its spheres,
    /// and neither link lies wholly inside a solid piece of the other (spheres fitted to
    /// the surfaces need not fill a box or a cylinder).
    pub(super) fn spheres_keep_pair_apart(
        &self,
        x: &ExactLinks,
        frames: &[Isometry3<f64>],
        (a, b): (usize, usize),
        margin: f64,
    ) -> bool {
        let (la, lb, fa, fb) = (&x.links[a], &x.links[b], &frames[a], &frames[b]);
        x.sphere_slack
            .is_some_and(|slack| !self.spheres_closer(frames, (a, b), margin + 2.0 * slack))
            && !la.holds_a_piece_of(fa, lb, fb)
            && !lb.holds_a_piece_of(fb, la, fa)
    }

    /// Whether a sphere of link `a` comes closer than `margin` to one of link `b`.
    fn spheres_closer(
        &self,
        frames: &[Isometry3<f64>],
        (a, b): (usize, usize),
        margin: f64,
    ) -> bool {
        self.trees[a].closer_than(&frames[a], &self.trees[b], &frames[b], margin)
    }

    /// Whether moving link `link`'s spheres show its exact shapes keep `margin` from obstacle
    /// `o`.
    pub(super) fn spheres_keep_obstacle_apart(
        &self,
        x: &ExactLinks,
        frames: &[Isometry3<f64>],
        link: usize,
        o: &Obstacle,
        margin: f64,
    ) -> bool {
        x.sphere_slack.is_some_and(|slack| {
            let gap = |c: &Point3<f64>, r: f64| o.distance(c) - r;
            !self.trees[link].closer_to(&frames[link], gap, margin + slack)
        })
    }

    /// Whether moving link `link` comes closer than `margin` to obstacle `k` of `scene`, the
    /// exact shapes deciding what its spheres cannot rule out.
    fn obstacle_closer(
        &self,
        x: &ExactLinks,
        frames: &[Isometry3<f64>],
        link: usize,
        (scene, k): (&Scene, usize),
        margin: f64,
    ) -> bool {
        if self.spheres_keep_obstacle_apart(x, frames, link, &scene.obstacles[k].1, margin) {
            return false;
        }
        let world = Isometry3::identity();
        x.links[link].closer_than(&frames[link], &scene.exact()[k], &world, margin)
    }

    /// The smallest signed distance between a moving link's spheres and the obstacles of
    /// `scene`, at most `cap`.
    pub fn scene_clearance(&self, frames: &[Isometry3<f64>], scene: &Scene, cap: f64) -> f64 {
        if let Some(x) = &self.exact {
            let world = Isometry3::identity();
            let mut best = cap;
            for (link, f) in frames.iter().enumerate() {
                if !self.moving[link] {
                    continue;
                }
                for o in scene.exact() {
                    best = best.min(x.links[link].gap(f, o, &world, best));
                }
            }
            return best;
        }
        let gap = |c: &Point3<f64>, r: f64| scene.gap(c, r);
        (self.trees.iter().zip(frames).enumerate())
            .filter(|(link, _)| self.moving[*link])
            .fold(cap, |best, (_, (tree, f))| tree.gap_to(f, gap, best))
    }

    /// Whether a moving link's sphere comes closer than `margin` to an obstacle of `scene`
    /// (stops at the first).
    pub fn scene_collides(&self, frames: &[Isometry3<f64>], scene: &Scene, margin: f64) -> bool {
        if let Some(x) = &self.exact {
            return (0..frames.len()).filter(|&l| self.moving[l]).any(|link| {
                (0..scene.obstacles.len())
                    .any(|k| self.obstacle_closer(x, frames, link, (scene, k), margin))
            });
        }
        let gap = |c: &Point3<f64>, r: f64| scene.gap(c, r);
        (self.trees.iter().zip(frames).enumerate())
            .any(|(link, (tree, f))| self.moving[link] && tree.closer_to(f, gap, margin))
    }

    /// The clearance against itself and, where given, the scene: at most `cap`.
    pub fn clearance(&self, frames: &[Isometry3<f64>], scene: Option<&Scene>, cap: f64) -> f64 {
        let own = self.self_clearance(frames, cap);
        match scene {
            Some(s) => self.scene_clearance(frames, s, own),
            None => own,
        }
    }

    /// Whether the robot at `frames` comes closer than `margin` to itself or the scene.
    pub fn collides(&self, frames: &[Isometry3<f64>], scene: Option<&Scene>, margin: f64) -> bool {
        self.self_collides(frames, margin)
            || scene.is_some_and(|s| self.scene_collides(frames, s, margin))
    }

    /// The checked pairs in collision at `frames` (closer than `margin`).
    pub fn colliding_pairs(&self, frames: &[Isometry3<f64>], margin: f64) -> Vec<(usize, usize)> {
        self.pairs
            .iter()
            .copied()
            .filter(|&pair| self.pair_closer(frames, pair, margin))
            .collect()
    }

    /// The smallest signed distance over the checked pairs, at most `cap` (the clearance
    /// further than `cap` is not needed).
    pub fn self_clearance(&self, frames: &[Isometry3<f64>], cap: f64) -> f64 {
        let t = &self.trees;
        let Some(x) = &self.exact else {
            return (self.pairs.iter())
                .fold(cap, |m, &(a, b)| t[a].gap(&frames[a], &t[b], &frames[b], m));
        };
        self.pairs.iter().fold(cap, |m, &(a, b)| {
            if self.spheres_keep_pair_apart(x, frames, (a, b), m) {
                return m;
            }
            m.min(x.links[a].gap(&frames[a], &x.links[b], &frames[b], m))
        })
    }

    /// Whether a checked pair is closer than `margin` at `frames`.
    pub fn self_collides(&self, frames: &[Isometry3<f64>], margin: f64) -> bool {
        self.pairs
            .iter()
            .any(|&pair| self.pair_closer(frames, pair, margin))
    }
}
