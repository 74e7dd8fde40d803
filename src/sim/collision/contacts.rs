//! The contacts an optimiser pushes apart: each pair of spheres (of two checked links, or of
//! a moving link and an obstacle) closer than a distance, with its signed distance and the
//! direction in which that distance grows fastest at each sphere's centre.

use nalgebra::{Isometry3, Point3, Vector3};

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
}

/// A contact where it is: its signed distance (m, negative where the spheres overlap) and
/// each side's sphere centre with the unit direction that moving it along increases the
/// distance (the obstacle's side is fixed: `None`).
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
        let placed = self.place(frames);
        let mut out = Vec::new();
        if self_collision {
            for &(a, b) in &self.pairs {
                if let (Some(ba), Some(bb)) = (&self.bounds[a], &self.bounds[b]) {
                    let (pa, pb) = (frames[a] * ba.center(), frames[b] * bb.center());
                    if (pa - pb).norm() - ba.radius - bb.radius >= within {
                        continue;
                    }
                }
                for (i, sa) in placed[a].iter().enumerate() {
                    for (j, sb) in placed[b].iter().enumerate() {
                        let d = sa.center - sb.center;
                        let gap = d.norm() - sa.radius - sb.radius;
                        if gap < within {
                            let n = d.try_normalize(1e-12).unwrap_or_else(Vector3::z);
                            out.push(Placement {
                                contact: Contact::Spheres { a, i, b, j },
                                gap,
                                first: (a, sa.center, n),
                                second: Some((b, sb.center, -n)),
                            });
                        }
                    }
                }
            }
        }
        let Some(scene) = scene else {
            return out;
        };
        for (a, spheres) in placed.iter().enumerate() {
            if !self.moving[a] {
                continue;
            }
            if let Some(b) = &self.bounds[a]
                && scene.gap(&(frames[a] * b.center()), b.radius) >= within
            {
                continue;
            }
            for (i, s) in spheres.iter().enumerate() {
                for (k, (_, o)) in scene.obstacles.iter().enumerate() {
                    let gap = o.distance(&s.center) - s.radius;
                    if gap < within {
                        out.push(Placement {
                            contact: Contact::Obstacle { a, i, k },
                            gap,
                            first: (a, s.center, away_from(o, &s.center)),
                            second: None,
                        });
                    }
                }
            }
        }
        out
    }
}
