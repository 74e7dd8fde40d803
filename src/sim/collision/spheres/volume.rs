//! What is inside a link, on a grid: the voxels near its surface samples are its shell
//! (every voxel whose centre lies within half a voxel and the samples' reach of one, on each
//! axis: no step between two neighbouring voxel centres crosses the surface without one of
//! them in the shell), the voxels reached from the grid's border without crossing the shell
//! are outside, the rest inside. A mesh need not be oriented, or closed to the last triangle:
//! a gap narrower than the shell does not let the outside in. Where a fit may centre its
//! spheres, and a first answer to whether a point is outside a link.

use nalgebra::{Point3, Vector3};

/// The most voxels a link's grid has (its cell grows past the one asked for to stay below).
const MAX_VOXELS: f64 = 4e6;

/// Where a point lies, as the grid tells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    Outside,
    /// Near the surface: either side.
    Shell,
    Inside,
}

/// A link's inside and outside on a grid.
pub struct Volume {
    origin: Point3<f64>,
    cell: f64,
    dims: [usize; 3],
    place: Vec<Place>,
}

impl Volume {
    /// The grid around `points` (a link's surface samples; no point of the surface farther
    /// than `reach` from one), voxels `cell` wide (or wider, for a large link), `pad` beyond
    /// the samples on every side; None without points.
    pub fn of(points: &[Point3<f64>], cell: f64, reach: f64, pad: f64) -> Option<Self> {
        let first = points.first()?;
        let (mut lo, mut hi) = (first.coords, first.coords);
        for p in points {
            lo = lo.inf(&p.coords);
            hi = hi.sup(&p.coords);
        }
        let (lo, hi) = (lo.add_scalar(-pad), hi.add_scalar(pad));
        let extent = hi - lo;
        let cell = cell.max((extent.x * extent.y * extent.z / MAX_VOXELS).cbrt());
        let dims = [0, 1, 2].map(|k| ((extent[k] / cell).ceil() as usize).max(1) + 1);
        let mut grid = Self {
            origin: Point3::from(lo),
            cell,
            dims,
            place: vec![Place::Outside; dims[0] * dims[1] * dims[2]],
        };
        let half = 0.5 + reach / cell;
        let mut shell = vec![false; grid.place.len()];
        for p in points {
            let u = (p - grid.origin) / cell;
            let (a, b) = (u.add_scalar(-half), u.add_scalar(half));
            for z in grid.span(a.z, b.z, 2) {
                for y in grid.span(a.y, b.y, 1) {
                    for x in grid.span(a.x, b.x, 0) {
                        shell[grid.index(x, y, z)] = true;
                    }
                }
            }
        }
        let outside = grid.flood_outside(&shell);
        for (i, place) in grid.place.iter_mut().enumerate() {
            *place = match (shell[i], outside[i]) {
                (true, _) => Place::Shell,
                (false, true) => Place::Outside,
                (false, false) => Place::Inside,
            };
        }
        Some(grid)
    }

    /// The voxel indices along axis `k` whose centres lie in `[a, b]` (grid units, a voxel's
    /// centre at its index), clamped to the grid.
    fn span(&self, a: f64, b: f64, k: usize) -> std::ops::RangeInclusive<usize> {
        let last = self.dims[k] - 1;
        let lo = (a.ceil().max(0.0) as usize).min(last);
        let hi = (b.floor().max(0.0) as usize).min(last);
        lo..=hi.max(lo)
    }

    fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// The voxels reached from the border (outside the padding) without crossing the shell.
    fn flood_outside(&self, shell: &[bool]) -> Vec<bool> {
        let [nx, ny, nz] = self.dims;
        let mut outside = vec![false; shell.len()];
        let mut stack = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let border =
                        x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1;
                    let i = self.index(x, y, z);
                    if border && !shell[i] {
                        outside[i] = true;
                        stack.push((x, y, z));
                    }
                }
            }
        }
        while let Some((x, y, z)) = stack.pop() {
            let steps = [
                (x.wrapping_sub(1), y, z),
                (x + 1, y, z),
                (x, y.wrapping_sub(1), z),
                (x, y + 1, z),
                (x, y, z.wrapping_sub(1)),
                (x, y, z + 1),
            ];
            for (a, b, c) in steps {
                if a < nx && b < ny && c < nz {
                    let i = self.index(a, b, c);
                    if !outside[i] && !shell[i] {
                        outside[i] = true;
                        stack.push((a, b, c));
                    }
                }
            }
        }
        outside
    }

    /// A voxel's side (m).
    pub fn cell(&self) -> f64 {
        self.cell
    }

    /// Where `p` lies: in the voxel whose centre is nearest; outside beyond the grid.
    pub fn place(&self, p: &Point3<f64>) -> Place {
        let u = (p - self.origin) / self.cell;
        let mut at = [0usize; 3];
        for k in 0..3 {
            let i = u[k].round();
            if i < 0.0 || i > (self.dims[k] - 1) as f64 {
                return Place::Outside;
            }
            at[k] = i as usize;
        }
        self.place[self.index(at[0], at[1], at[2])]
    }

    /// The centres of the inside voxels, every `stride`-th on each axis.
    pub fn inside_centres(&self, stride: usize) -> Vec<Point3<f64>> {
        let stride = stride.max(1);
        let mut out = Vec::new();
        for z in (0..self.dims[2]).step_by(stride) {
            for y in (0..self.dims[1]).step_by(stride) {
                for x in (0..self.dims[0]).step_by(stride) {
                    if self.place[self.index(x, y, z)] == Place::Inside {
                        let u = Vector3::new(x as f64, y as f64, z as f64) * self.cell;
                        out.push(self.origin + u);
                    }
                }
            }
        }
        out
    }

    /// How many voxels are inside.
    pub fn inside_count(&self) -> usize {
        self.place.iter().filter(|p| **p == Place::Inside).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_box_s_surface_has_an_inside_and_an_outside() {
        let shapes = [crate::sim::shape::Shape::Cuboid {
            pose: nalgebra::Isometry3::identity(),
            half: Vector3::new(0.1, 0.05, 0.03),
        }];
        let spacing = 0.003;
        let points = crate::sim::collision::spheres::surface_points(&shapes, spacing);
        let reach = crate::sim::collision::spheres::surface::sample_reach(&shapes, spacing);
        let volume = Volume::of(&points, spacing, reach, 0.02).unwrap();
        assert_eq!(volume.place(&Point3::origin()), Place::Inside);
        assert_eq!(volume.place(&Point3::new(0.09, 0.04, 0.02)), Place::Inside);
        assert_eq!(volume.place(&Point3::new(0.0, 0.0, 0.03)), Place::Shell);
        assert_eq!(volume.place(&Point3::new(0.0, 0.0, 0.045)), Place::Outside);
        assert_eq!(volume.place(&Point3::new(0.0, 0.0, 1.0)), Place::Outside);
        // Every inside centre is inside the box.
        let centres = volume.inside_centres(1);
        assert!(centres.len() > 1000, "{}", centres.len());
        for c in centres {
            assert!(
                c.x.abs() < 0.1 && c.y.abs() < 0.05 && c.z.abs() < 0.03,
                "{c}"
            );
        }
    }
}
