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
use crate::sim::collision::spheres::Sphere;
use crate::sim::kinematics::KinematicChain;

/// A sphere placed in the world: its centre and radius.
#[derive(Clone, Copy, Debug)]
pub struct Placed {
    pub center: Point3<f64>,
    pub radius: f64,
}

/// What may touch what.
#[derive(Clone, Debug)]
pub struct CollisionModel {
    /// Each link's spheres in its frame (index as in the chain's links).
    pub spheres: Vec<Vec<Sphere>>,
    /// The checked pairs of link indices (`a < b`), both with spheres.
    pub pairs: Vec<(usize, usize)>,
    /// Each link's spheres' bounding sphere in its frame (none without spheres): a pair
    /// whose bounds are apart needs no closer look.
    pub(super) bounds: Vec<Option<Sphere>>,
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

/// Where two spheres are closest: the signed distance between their surfaces.
#[inline]
fn gap(a: &Placed, b: &Placed) -> f64 {
    (a.center - b.center).norm() - a.radius - b.radius
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
        let bounds = spheres.iter().map(|s| bounding(s)).collect();
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
            bounds,
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
    fn pair_closer(
        &self,
        placed: &[Vec<Placed>],
        frames: &[Isometry3<f64>],
        (a, b): (usize, usize),
        margin: f64,
    ) -> bool {
        let Some(x) = &self.exact else {
            return self.pair_gap(placed, frames, a, b, margin) < margin;
        };
        !self.spheres_keep_pair_apart(x, placed, frames, (a, b), margin)
            && x.links[a].closer_than(&frames[a], &x.links[b], &frames[b], margin)
    }

    /// Whether the spheres of links `a` and `b` show their exact shapes keep `margin` apart:
    /// they keep the margin plus how far each link's shapes may stand outside its spheres.
    pub(super) fn spheres_keep_pair_apart(
        &self,
        x: &ExactLinks,
        placed: &[Vec<Placed>],
        frames: &[Isometry3<f64>],
        (a, b): (usize, usize),
        margin: f64,
    ) -> bool {
        x.sphere_slack.is_some_and(|slack| {
            let wide = margin + 2.0 * slack;
            self.pair_gap(placed, frames, a, b, wide) >= wide
        })
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
            let f = &frames[link];
            let wide = margin + slack;
            let apart = |s: &Sphere| o.distance(&(f * s.center())) - s.radius >= wide;
            self.bounds[link].as_ref().is_some_and(apart) || self.spheres[link].iter().all(apart)
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
    /// `scene`, at most `cap`. A link whose bounding sphere is farther than the best so far is
    /// not looked into (its spheres lie inside it).
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
        let mut best = cap;
        for (link, (spheres, f)) in self.spheres.iter().zip(frames).enumerate() {
            if !self.moving[link] {
                continue;
            }
            if let Some(b) = &self.bounds[link]
                && scene.gap(&(f * b.center()), b.radius) >= best
            {
                continue;
            }
            for s in spheres {
                best = best.min(scene.gap(&(f * s.center()), s.radius));
            }
        }
        best
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
        for (link, (spheres, f)) in self.spheres.iter().zip(frames).enumerate() {
            if !self.moving[link] {
                continue;
            }
            if let Some(b) = &self.bounds[link]
                && scene.gap(&(f * b.center()), b.radius) >= margin
            {
                continue;
            }
            if spheres
                .iter()
                .any(|s| scene.gap(&(f * s.center()), s.radius) < margin)
            {
                return true;
            }
        }
        false
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

    /// Every link's spheres placed by the link frames.
    pub fn place(&self, frames: &[Isometry3<f64>]) -> Vec<Vec<Placed>> {
        self.spheres
            .iter()
            .zip(frames)
            .map(|(s, f)| {
                s.iter()
                    .map(|s| Placed {
                        center: f * s.center(),
                        radius: s.radius,
                    })
                    .collect()
            })
            .collect()
    }

    /// The smallest signed distance between the spheres of two links, `cap` where it is
    /// larger (a link pair whose bounds are farther than `cap` apart is not looked into).
    fn pair_gap(
        &self,
        placed: &[Vec<Placed>],
        frames: &[Isometry3<f64>],
        a: usize,
        b: usize,
        cap: f64,
    ) -> f64 {
        if let (Some(ba), Some(bb)) = (&self.bounds[a], &self.bounds[b]) {
            let (pa, pb) = (frames[a] * ba.center(), frames[b] * bb.center());
            if (pa - pb).norm() - ba.radius - bb.radius > cap {
                return cap;
            }
        }
        let mut best = cap;
        for sa in &placed[a] {
            for sb in &placed[b] {
                best = best.min(gap(sa, sb));
            }
        }
        best
    }

    /// The checked pairs in collision at `frames` (closer than `margin`).
    pub fn colliding_pairs(&self, frames: &[Isometry3<f64>], margin: f64) -> Vec<(usize, usize)> {
        let placed = self.place(frames);
        self.pairs
            .iter()
            .copied()
            .filter(|&pair| self.pair_closer(&placed, frames, pair, margin))
            .collect()
    }

    /// The smallest signed distance over the checked pairs, at most `cap` (the clearance
    /// further than `cap` is not needed).
    pub fn self_clearance(&self, frames: &[Isometry3<f64>], cap: f64) -> f64 {
        let placed = self.place(frames);
        let Some(x) = &self.exact else {
            return self.pairs.iter().fold(cap, |m, &(a, b)| {
                m.min(self.pair_gap(&placed, frames, a, b, m))
            });
        };
        self.pairs.iter().fold(cap, |m, &(a, b)| {
            if let Some(slack) = x.sphere_slack {
                let wide = m + 2.0 * slack;
                if self.pair_gap(&placed, frames, a, b, wide) >= wide {
                    return m;
                }
            }
            m.min(x.links[a].gap(&frames[a], &x.links[b], &frames[b], m))
        })
    }

    /// Whether a checked pair is closer than `margin` at `frames`.
    pub fn self_collides(&self, frames: &[Isometry3<f64>], margin: f64) -> bool {
        if self.exact.is_none() {
            return self.self_clearance(frames, margin) < margin;
        }
        let placed = self.place(frames);
        self.pairs
            .iter()
            .any(|&pair| self.pair_closer(&placed, frames, pair, margin))
    }
}

/// The bounding sphere of some spheres (centred at their centres' mean).
fn bounding(spheres: &[Sphere]) -> Option<Sphere> {
    if spheres.is_empty() {
        return None;
    }
    let n = spheres.len() as f64;
    let c = spheres
        .iter()
        .fold(nalgebra::Vector3::zeros(), |a, s| a + s.center().coords)
        / n;
    let r = spheres
        .iter()
        .map(|s| (s.center().coords - c).norm() + s.radius)
        .fold(0.0, f64::max);
    Some(Sphere {
        center: [c.x, c.y, c.z],
        radius: r,
    })
}
