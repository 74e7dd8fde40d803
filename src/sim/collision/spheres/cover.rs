//! Spheres that stand at most a distance `p` outside a link, chosen to cover its surface. A
//! sphere centred inside the link at a distance `D` from its surface, of radius `D + p`,
//! holds the ball of radius `D` about its centre, which lies inside the link: no point of the
//! sphere is more than `p` from that ball, so none is more than `p` outside the link, whatever
//! the link's shape. A sphere of radius `p` centred on the surface is one too (`D = 0`).
//! Candidates: the link's inside on a lattice (`D` measured exactly, to its exact shapes) and
//! its surface samples; chosen greedily (set cover), the one holding the most of the surface's
//! triangles not yet held first, until every triangle is held whole by one: the surface is
//! covered exactly. The smaller `p`, the more spheres.
//!
//! `p` may differ from point to point ([`cover_within`]): a sphere then stands out no more
//! than the least allowance of the surface's points near it, so a link's spheres can be fine only
//! where another link comes close (each sample's allowance from its clearance) and coarse
//! elsewhere.

use std::collections::BinaryHeap;

use nalgebra::Point3;

use crate::sim::collision::exact::ExactShapes;
use crate::sim::collision::sphere::Sphere;
use crate::sim::collision::spheres::holding::Holding;
use crate::sim::collision::spheres::surface::{Surface, centroid};
use crate::sim::collision::spheres::volume::Volume;

/// The most candidate centres of each kind (inside, on the surface) a link is given.
const MAX_CANDIDATES: usize = 8_000;

/// Where a link's spheres may be centred, and how deep inside each centre lies; the link's
/// volume and exact shapes, to find more beneath a triangle no candidate holds.
pub struct Candidates<'a> {
    centres: Vec<Point3<f64>>,
    depth: Vec<f64>,
    volume: &'a Volume,
    exact: &'a ExactShapes,
}

impl<'a> Candidates<'a> {
    /// The inside voxels of `volume` (thinned to at most [`MAX_CANDIDATES`]) that lie inside
    /// `exact`, each at its exact distance from its surface, and the `samples` themselves
    /// (depth 0).
    pub fn of(volume: &'a Volume, exact: &'a ExactShapes, samples: &[Point3<f64>]) -> Self {
        let inside = volume.inside_count();
        let stride = ((inside as f64 / MAX_CANDIDATES as f64).cbrt().ceil() as usize).max(1);
        // The grid's inside may hold a narrow gap its shell closed off: each centre confirmed
        // inside the exact shapes.
        let mut centres = volume.inside_centres(stride);
        centres.retain(|c| exact.contains(c));
        let mut depth: Vec<f64> = centres.iter().map(|c| exact.surface_distance(c)).collect();
        let every = samples.len().div_ceil(MAX_CANDIDATES).max(1);
        for s in samples.iter().step_by(every) {
            centres.push(*s);
            depth.push(0.0);
        }
        Self {
            centres,
            depth,
            volume,
            exact,
        }
    }

    /// Centres beneath the triangle with corners `t`: its centroid moved along its normal
    /// into the link, 1 to 64 voxels deep, deepest first, where the grid says inside; each
    /// with its exact depth.
    fn beneath(&self, t: &[Point3<f64>; 3]) -> Vec<(Point3<f64>, f64)> {
        let m = centroid(t);
        let Some(n) = (t[1] - t[0]).cross(&(t[2] - t[0])).try_normalize(1e-18) else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for k in (0..7).rev() {
            let step = self.volume.cell() * f64::from(1u32 << k);
            for c in [m - n * step, m + n * step] {
                if self.volume.place(&c) == super::volume::Place::Inside {
                    out.push((c, self.exact.surface_distance(&c)));
                }
            }
        }
        out
    }

    /// The deepest any centre lies (m).
    pub fn deepest(&self) -> f64 {
        self.depth.iter().copied().fold(0.0, f64::max)
    }
}

/// The spheres, each standing at most `p` outside the link, that the greedy cover of
/// `surface` picks from `candidates` (every triangle held whole by one).
pub fn cover(candidates: &Candidates, surface: &Surface, p: f64) -> Vec<Sphere> {
    cover_within(candidates, surface, &vec![p; surface.points.len()])
}

/// [`cover`] with an allowance of its own for each corner of the surface (`allowance[k]` for
/// `surface.points[k]`, m): a candidate stands out at most `p`, the least allowance of the
/// corners within its depth and `2 p` of its centre (where any part of it that stands out lies
/// nearest the link), so spheres are small where the allowance is, and large elsewhere. A triangle no candidate holds gets the deepest centre beneath it that does
/// ([`Candidates::beneath`]), or else the smallest ball about its centroid that holds it.
pub fn cover_within(candidates: &Candidates, surface: &Surface, allowance: &[f64]) -> Vec<Sphere> {
    let most = allowance.iter().copied().fold(0.0, f64::max);
    let cell = (2.0 * most).max(candidates.deepest() / 4.0).max(1e-4);
    let mut holding = Holding::new(surface, cell);
    let points = &surface.points;
    // How far a sphere centred at `c`, `depth` inside, may stand out: the largest `p` at
    // most every allowance within `depth + 2 p` of `c` (a point of the sphere `p` outside the
    // link has a point of the surface within `p`, so within `depth + 2 p` of `c`). A point
    // `d` from `c` allows any `p` up to its allowance, or below `(d - depth) / 2`.
    let uniform = allowance.iter().all(|&a| a == most);
    let allowed = |holding: &Holding, c: &Point3<f64>, depth: f64| match uniform {
        true => most,
        false => (holding.grid.within(points, c, depth + 2.0 * most).iter())
            .map(|&s| {
                let d = (points[s as usize] - c).norm();
                allowance[s as usize].max((d - depth) / 2.0)
            })
            .fold(most, f64::min),
    };
    let radius: Vec<f64> = (candidates.centres.iter().zip(&candidates.depth))
        .map(|(c, &depth)| depth + allowed(&holding, c, depth))
        .collect();
    let mut covered = vec![false; surface.triangles.len()];
    let mut chosen = greedy(candidates, &radius, &mut holding, &mut covered);
    for t in 0..covered.len() {
        if covered[t] {
            continue;
        }
        let corners = surface.corners(t as u32);
        let holds = |c: &Point3<f64>, r: f64| holding.reach_of(c, t as u32) <= r;
        let deep = (candidates.beneath(&corners).into_iter())
            .map(|(c, depth)| (c, depth + allowed(&holding, &c, depth)))
            .find(|(c, r)| holds(c, *r) && candidates.exact.contains(c));
        let (c, r) = deep.unwrap_or_else(|| {
            let c = centroid(&corners);
            (c, holding.reach_of(&c, t as u32))
        });
        for h in holding.held(&c, r) {
            covered[h as usize] = true;
        }
        chosen.push(Sphere {
            center: [c.x, c.y, c.z],
            radius: r,
        });
    }
    chosen
}

/// The candidates (each of radius `radius[i]`) the greedy set cover picks, the one holding
/// the most triangles not yet `covered` first, until none holds any more; `covered` marked.
fn greedy(
    candidates: &Candidates,
    radius: &[f64],
    holding: &mut Holding,
    covered: &mut [bool],
) -> Vec<Sphere> {
    let mut left = covered.iter().filter(|c| !**c).count();
    // Lazy greedy: a candidate's count only falls, so one still above the next best is best.
    // What each holds is found again when it is looked at, not kept (a large allowance
    // would keep every triangle for every candidate).
    let mut heap: BinaryHeap<(usize, usize)> = (0..candidates.centres.len())
        .map(|i| (holding.held(&candidates.centres[i], radius[i]).len(), i))
        .collect();
    let mut chosen = Vec::new();
    while left > 0 {
        let Some((count, i)) = heap.pop() else {
            break;
        };
        let mine = holding.held(&candidates.centres[i], radius[i]);
        let now = mine.iter().filter(|&&t| !covered[t as usize]).count();
        if now == 0 {
            continue;
        }
        if now < count && heap.peek().is_some_and(|&(next, _)| next > now) {
            heap.push((now, i));
            continue;
        }
        for &t in &mine {
            if !covered[t as usize] {
                covered[t as usize] = true;
                left -= 1;
            }
        }
        let c = candidates.centres[i];
        chosen.push(Sphere {
            center: [c.x, c.y, c.z],
            radius: radius[i],
        });
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::collision::spheres::surface;
    use crate::sim::shape::Shape;

    /// `check` given the test box's surface (half extents 100, 40 and 20 mm, cut 3 mm fine)
    /// and the cover's candidates.
    fn with_box(check: impl FnOnce(&Surface, &Candidates)) {
        let shapes = [Shape::Cuboid {
            pose: nalgebra::Isometry3::identity(),
            half: nalgebra::Vector3::new(0.1, 0.04, 0.02),
        }];
        let spacing = 0.003;
        let surface = Surface::of(&shapes, spacing);
        let reach = surface::sample_reach(&shapes, spacing);
        let volume = Volume::of(&surface.points, spacing, reach, 0.01).unwrap();
        let exact = ExactShapes::of_link(&shapes);
        check(&surface, &Candidates::of(&volume, &exact, &surface.points));
    }

    /// How far sphere `x` stands past the test box (a box's outside distance is exact: its
    /// farthest reach past each face).
    fn past_the_box(x: &Sphere) -> f64 {
        let c = x.center();
        let out = [
            c.x.abs() + x.radius - 0.1,
            c.y.abs() + x.radius - 0.04,
            c.z.abs() + x.radius - 0.02,
        ];
        out.iter().copied().fold(f64::NEG_INFINITY, f64::max)
    }

    /// Every triangle of `surface` held whole by one of `spheres`.
    fn all_held(surface: &Surface, spheres: &[Sphere]) {
        let holds = |x: &Sphere, t: &[u32; 3]| {
            (t.iter()).all(|&k| x.contains(&surface.points[k as usize], 1e-12))
        };
        for t in &surface.triangles {
            assert!(spheres.iter().any(|x| holds(x, t)), "{t:?}");
        }
    }

    #[test]
    fn every_triangle_is_held_and_no_sphere_stands_out_further_than_asked() {
        with_box(|surface, candidates| {
            let mut counts = Vec::new();
            for p in [0.002, 0.005, 0.02] {
                let spheres = cover(candidates, surface, p);
                all_held(surface, &spheres);
                for x in &spheres {
                    let worst = past_the_box(x);
                    assert!(worst <= p + 1e-9, "p {p}: stands {worst} out");
                }
                counts.push(spheres.len());
            }
            assert!(counts[0] > counts[1] && counts[1] > counts[2], "{counts:?}");
        });
    }

    /// Where one face's points allow 2 mm and the rest 20 mm, no sphere stands more than 2 mm
    /// past that face, none more than 20 mm out, and the cover takes fewer spheres than 2 mm
    /// everywhere does.
    #[test]
    fn a_small_allowance_keeps_the_spheres_near_it_small() {
        with_box(|surface, candidates| {
            let tight = |p: &Point3<f64>| p.x > 0.1 - 1e-9;
            let allowance: Vec<f64> = (surface.points.iter())
                .map(|p| if tight(p) { 0.002 } else { 0.02 })
                .collect();
            let spheres = cover_within(candidates, surface, &allowance);
            all_held(surface, &spheres);
            for x in &spheres {
                let worst = past_the_box(x);
                assert!(worst <= 0.02 + 1e-9, "stands {worst} out");
                // A point of a sphere past the tight face lies nearest that face's points.
                let past_tight = x.center().x + x.radius - 0.1;
                assert!(
                    past_tight <= 0.002 + 1e-9,
                    "stands {past_tight} past the tight face"
                );
            }
            let uniform = cover(candidates, surface, 0.002);
            assert!(
                spheres.len() < uniform.len(),
                "{} {}",
                spheres.len(),
                uniform.len()
            );
        });
    }
}
