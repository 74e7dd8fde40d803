//! Spheres that stand at most a distance `p` outside a link, chosen to cover its surface. A
//! sphere centred inside the link at a distance `D` from its surface, of radius `D + p`,
//! holds the ball of radius `D` about its centre, which lies inside the link: no point of the
//! sphere is more than `p` from that ball, so none is more than `p` outside the link, whatever
//! the link's shape. A sphere of radius `p` centred on the surface is one too (`D = 0`).
//! Candidates: the link's inside on a lattice (`D` measured exactly, to its exact shapes) and
//! its surface samples; chosen greedily (set cover), the one covering the most samples not yet
//! covered first, until every sample is covered. The smaller `p`, the more spheres.
//!
//! `p` may differ from sample to sample ([`cover_within`]): a sphere then stands out no more
//! than the least allowance of the samples near it, so a link's spheres can be fine only
//! where another link comes close (each sample's allowance from its clearance) and coarse
//! elsewhere.

use std::collections::{BinaryHeap, HashMap};

use nalgebra::Point3;

use crate::sim::collision::exact::ExactShapes;
use crate::sim::collision::sphere::Sphere;
use crate::sim::collision::spheres::volume::Volume;

/// The most candidate centres of each kind (inside, on the surface) a link is given.
const MAX_CANDIDATES: usize = 8_000;

/// Where a link's spheres may be centred, and how deep inside each centre lies.
pub struct Candidates {
    centres: Vec<Point3<f64>>,
    depth: Vec<f64>,
}

impl Candidates {
    /// The inside voxels of `volume` (thinned to at most [`MAX_CANDIDATES`]) that lie inside
    /// `exact`, each at its exact distance from its surface, and the `samples` themselves
    /// (depth 0).
    pub fn of(volume: &Volume, exact: &ExactShapes, samples: &[Point3<f64>]) -> Self {
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
        Self { centres, depth }
    }

    /// The deepest any centre lies (m).
    pub fn deepest(&self) -> f64 {
        self.depth.iter().copied().fold(0.0, f64::max)
    }
}

/// The points in cubes of a given size, to find those near a point without looking at all.
struct PointGrid {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl PointGrid {
    fn new(points: &[Point3<f64>], cell: f64) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            cells.entry(Self::key(p, cell)).or_default().push(i as u32);
        }
        Self { cell, cells }
    }

    fn key(p: &Point3<f64>, cell: f64) -> [i64; 3] {
        [p.x, p.y, p.z].map(|v| (v / cell).floor() as i64)
    }

    /// The points of `points` within `r` of `c`.
    fn within(&self, points: &[Point3<f64>], c: &Point3<f64>, r: f64) -> Vec<u32> {
        let lo = Self::key(&(c - nalgebra::Vector3::repeat(r)), self.cell);
        let hi = Self::key(&(c + nalgebra::Vector3::repeat(r)), self.cell);
        let mut out = Vec::new();
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    if let Some(ids) = self.cells.get(&[x, y, z]) {
                        let near = ids
                            .iter()
                            .filter(|&&i| (points[i as usize] - c).norm() <= r);
                        out.extend(near);
                    }
                }
            }
        }
        out
    }
}

/// The spheres, each standing at most `p` outside the link, that the greedy cover of
/// `samples` picks from `candidates` (every sample inside one).
pub fn cover(candidates: &Candidates, samples: &[Point3<f64>], p: f64) -> Vec<Sphere> {
    cover_within(candidates, samples, &vec![p; samples.len()])
}

/// [`cover`] with an allowance of its own for each sample (`allowance[k]` for `samples[k]`,
/// m): a candidate stands out at most the least allowance of the samples within its depth
/// and twice the largest allowance of its centre (where any part of it that stands out
/// lies nearest the link), so spheres are small where the allowance is, and large elsewhere.
pub fn cover_within(
    candidates: &Candidates,
    samples: &[Point3<f64>],
    allowance: &[f64],
) -> Vec<Sphere> {
    let most = allowance.iter().copied().fold(0.0, f64::max);
    let grid = PointGrid::new(
        samples,
        (2.0 * most).max(candidates.deepest() / 4.0).max(1e-4),
    );
    // How far a sphere centred at `c`, `depth` inside, may stand out; each candidate's, then
    // the samples it covers.
    let uniform = allowance.iter().all(|&a| a == most);
    let allowed = |c: &Point3<f64>, depth: f64| {
        if uniform {
            return most;
        }
        let near = grid.within(samples, c, depth + 2.0 * most);
        (near.iter().map(|&s| allowance[s as usize])).fold(most, f64::min)
    };
    let protrusion: Vec<f64> = (0..candidates.centres.len())
        .map(|i| allowed(&candidates.centres[i], candidates.depth[i]))
        .collect();
    let covers = |i: usize| {
        let r = candidates.depth[i] + protrusion[i];
        grid.within(samples, &candidates.centres[i], r)
    };
    let mut covered = vec![false; samples.len()];
    let mut left = samples.len();
    // Lazy greedy: a candidate's count only falls, so one still above the next best is best.
    // What each covers is found again when it is looked at, not kept (a large allowance
    // would keep every sample for every candidate).
    let mut heap: BinaryHeap<(usize, usize)> = (0..candidates.centres.len())
        .map(|i| (covers(i).len(), i))
        .collect();
    let mut chosen = Vec::new();
    while left > 0 {
        let Some((count, i)) = heap.pop() else {
            break;
        };
        let mine = covers(i);
        let now = mine.iter().filter(|&&s| !covered[s as usize]).count();
        if now == 0 {
            continue;
        }
        if now < count && heap.peek().is_some_and(|&(next, _)| next > now) {
            heap.push((now, i));
            continue;
        }
        for &s in &mine {
            if !covered[s as usize] {
                covered[s as usize] = true;
                left -= 1;
            }
        }
        let c = candidates.centres[i];
        chosen.push(Sphere {
            center: [c.x, c.y, c.z],
            radius: candidates.depth[i] + protrusion[i],
        });
    }
    // A sample no candidate reaches (the surface's candidates are thinned) is a centre itself.
    for i in 0..samples.len() {
        if !covered[i] {
            let p = allowed(&samples[i], 0.0);
            for s in grid.within(samples, &samples[i], p) {
                covered[s as usize] = true;
            }
            let c = samples[i];
            chosen.push(Sphere {
                center: [c.x, c.y, c.z],
                radius: p,
            });
        }
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::collision::spheres::{surface, surface_points};
    use crate::sim::shape::Shape;

    /// The test box (half extents 100, 40 and 20 mm): its surface samples 3 mm apart and the
    /// cover's candidates.
    fn box_samples_and_candidates() -> (Vec<Point3<f64>>, Candidates) {
        let shapes = [Shape::Cuboid {
            pose: nalgebra::Isometry3::identity(),
            half: nalgebra::Vector3::new(0.1, 0.04, 0.02),
        }];
        let spacing = 0.003;
        let samples = surface_points(&shapes, spacing);
        let reach = surface::sample_reach(&shapes, spacing);
        let volume = Volume::of(&samples, spacing, reach, 0.01).unwrap();
        let candidates = Candidates::of(&volume, &ExactShapes::of_link(&shapes), &samples);
        (samples, candidates)
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

    #[test]
    fn every_sample_is_covered_and_no_sphere_stands_out_further_than_asked() {
        let (samples, candidates) = box_samples_and_candidates();
        let mut counts = Vec::new();
        for p in [0.002, 0.005, 0.02] {
            let spheres = cover(&candidates, &samples, p);
            for s in &samples {
                assert!(spheres.iter().any(|x| x.contains(s, 1e-12)), "{s}");
            }
            for x in &spheres {
                let worst = past_the_box(x);
                assert!(worst <= p + 1e-9, "p {p}: stands {worst} out");
            }
            counts.push(spheres.len());
        }
        assert!(counts[0] > counts[1] && counts[1] > counts[2], "{counts:?}");
    }

    /// Where one face's samples allow 2 mm and the rest 20 mm, no sphere that reaches within
    /// 1 cm of that face's plane stands more than 2 mm past any face, none stands more than
    /// 20 mm out, and the cover takes fewer spheres than 2 mm everywhere does.
    #[test]
    fn a_small_allowance_keeps_the_spheres_near_it_small() {
        let (samples, candidates) = box_samples_and_candidates();
        let tight = |p: &Point3<f64>| p.x > 0.1 - 1e-9;
        let allowance: Vec<f64> = (samples.iter())
            .map(|p| if tight(p) { 0.002 } else { 0.02 })
            .collect();
        let spheres = cover_within(&candidates, &samples, &allowance);
        for s in &samples {
            assert!(spheres.iter().any(|x| x.contains(s, 1e-12)), "{s}");
        }
        for x in &spheres {
            let (c, worst) = (x.center(), past_the_box(x));
            assert!(worst <= 0.02 + 1e-9, "stands {worst} out");
            if c.x + x.radius > 0.1 - 0.01 {
                assert!(
                    worst <= 0.002 + 1e-9,
                    "near the tight face, stands {worst} out"
                );
            }
        }
        let uniform = cover(&candidates, &samples, 0.002);
        assert!(
            spheres.len() < uniform.len(),
            "{} {}",
            spheres.len(),
            uniform.len()
        );
    }
}
