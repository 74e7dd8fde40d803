//! Which of a surface's triangles a sphere holds whole: those whose three corners it holds
//! (a ball is convex). The corners are kept in cubes (`PointGrid`) to find those near a
//! sphere without looking at all, and each triangle is found from its first corner.

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

use crate::sim::collision::sphere::Sphere;
use crate::sim::collision::spheres::surface::Surface;

/// The points in cubes of a given size, to find those near a point without looking at all.
pub struct PointGrid {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl PointGrid {
    pub fn new(points: &[Point3<f64>], cell: f64) -> Self {
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
    pub fn within(&self, points: &[Point3<f64>], c: &Point3<f64>, r: f64) -> Vec<u32> {
        let lo = Self::key(&(c - Vector3::repeat(r)), self.cell);
        let hi = Self::key(&(c + Vector3::repeat(r)), self.cell);
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

/// A surface's triangles, ready to be asked which a sphere holds.
pub struct Holding<'a> {
    pub surface: &'a Surface,
    pub grid: PointGrid,
    /// The triangles whose first corner is point `k`: `first_ids[first_start[k]..first_start[k + 1]]`.
    first_start: Vec<u32>,
    first_ids: Vec<u32>,
    /// Points marked with the current `stamp` are inside the sphere asked about.
    mark: Vec<u32>,
    stamp: u32,
}

impl<'a> Holding<'a> {
    /// `surface`'s corners kept in cubes of side `cell`.
    pub fn new(surface: &'a Surface, cell: f64) -> Self {
        let n = surface.points.len();
        let mut first_start = vec![0u32; n + 1];
        for t in &surface.triangles {
            first_start[t[0] as usize + 1] += 1;
        }
        for k in 0..n {
            first_start[k + 1] += first_start[k];
        }
        let mut next = first_start.clone();
        let mut first_ids = vec![0u32; surface.triangles.len()];
        for (i, t) in surface.triangles.iter().enumerate() {
            first_ids[next[t[0] as usize] as usize] = i as u32;
            next[t[0] as usize] += 1;
        }
        Self {
            surface,
            grid: PointGrid::new(&surface.points, cell),
            first_start,
            first_ids,
            mark: vec![0; n],
            stamp: 0,
        }
    }

    /// The triangles the ball of radius `r` about `c` holds whole.
    pub fn held(&mut self, c: &Point3<f64>, r: f64) -> Vec<u32> {
        let near = self.grid.within(&self.surface.points, c, r);
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.mark.fill(0);
            self.stamp = 1;
        }
        for &k in &near {
            self.mark[k as usize] = self.stamp;
        }
        let mut out = Vec::new();
        for &k in &near {
            let (a, b) = (
                self.first_start[k as usize],
                self.first_start[k as usize + 1],
            );
            for &t in &self.first_ids[a as usize..b as usize] {
                let [_, p, q] = self.surface.triangles[t as usize];
                if self.mark[p as usize] == self.stamp && self.mark[q as usize] == self.stamp {
                    out.push(t);
                }
            }
        }
        out
    }

    /// The triangles `sphere` holds whole.
    pub fn held_by(&mut self, sphere: &Sphere) -> Vec<u32> {
        self.held(&sphere.center(), sphere.radius)
    }

    /// How many of `spheres` hold each triangle whole.
    pub fn holders(&mut self, spheres: &[Sphere]) -> Vec<u32> {
        let mut holders = vec![0u32; self.surface.triangles.len()];
        for s in spheres {
            for t in self.held_by(s) {
                holders[t as usize] += 1;
            }
        }
        holders
    }

    /// The smallest ball about `c` that holds triangle `t` whole (its farthest corner's
    /// distance).
    pub fn reach_of(&self, c: &Point3<f64>, t: u32) -> f64 {
        (self.surface.triangles[t as usize].iter())
            .map(|&k| (self.surface.points[k as usize] - c).norm())
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::shape::Shape;

    /// On a subdivided box, the triangles a ball is said to hold are exactly those whose
    /// three corners lie inside it (checked against every triangle, for balls of several
    /// sizes and places).
    #[test]
    fn a_ball_holds_the_triangles_whose_corners_it_holds() {
        let shapes = [Shape::Cuboid {
            pose: nalgebra::Isometry3::identity(),
            half: Vector3::new(0.05, 0.03, 0.02),
        }];
        let surface = Surface::of(&shapes, 0.01);
        let mut holding = Holding::new(&surface, 0.013);
        for (c, r) in [
            (Point3::new(0.05, 0.0, 0.0), 0.025),
            (Point3::new(0.0, 0.03, 0.02), 0.04),
            (Point3::new(0.01, -0.01, 0.0), 0.005),
            (Point3::origin(), 1.0),
        ] {
            let mut held = holding.held(&c, r);
            held.sort();
            let expected: Vec<u32> = (0..surface.triangles.len() as u32)
                .filter(|&t| holding.reach_of(&c, t) <= r)
                .collect();
            assert_eq!(held, expected, "ball at {c} of radius {r}");
        }
    }
}
