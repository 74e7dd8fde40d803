//! Geometric primitives a robot's links are drawn with, and exact ray intersection.
//!
//! Units are metres. Rays are `origin + t * dir` with `dir` *not* normalised: the camera
//! builds directions whose forward component is 1, so the `t` of a hit is directly the depth
//! along the camera axis, and rigid transforms of the ray keep `t` unchanged.

use nalgebra::{Isometry3, Point3, Vector3};

/// Hits closer than this (in units of `t`) are ignored, so a ray does not hit its own origin.
pub const T_EPSILON: f64 = 1e-9;

/// A ray `origin + t * dir`.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Point3<f64>,
    pub dir: Vector3<f64>,
}

impl Ray {
    /// The same ray expressed in a frame whose pose in the ray's frame is `pose`.
    pub fn to_local(&self, pose: &Isometry3<f64>) -> Ray {
        Ray {
            origin: pose.inverse_transform_point(&self.origin),
            dir: pose.inverse_transform_vector(&self.dir),
        }
    }
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Point3<f64>,
    pub max: Point3<f64>,
}

impl Aabb {
    /// The empty box (the identity of [`Aabb::union`]).
    pub fn empty() -> Self {
        Aabb {
            min: Point3::from([f64::INFINITY; 3]),
            max: Point3::from([f64::NEG_INFINITY; 3]),
        }
    }

    /// The smallest box holding all `points`.
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Point3<f64>>) -> Self {
        points.into_iter().fold(Aabb::empty(), |b, p| b.grow(p))
    }

    pub fn grow(&self, p: &Point3<f64>) -> Self {
        Aabb {
            min: self.min.inf(p),
            max: self.max.sup(p),
        }
    }

    pub fn union(&self, o: &Aabb) -> Self {
        Aabb {
            min: self.min.inf(&o.min),
            max: self.max.sup(&o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }

    pub fn center(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }

    /// The eight corners.
    pub fn corners(&self) -> [Point3<f64>; 8] {
        let (a, b) = (self.min, self.max);
        std::array::from_fn(|i| {
            Point3::new(
                if i & 1 == 0 { a.x } else { b.x },
                if i & 2 == 0 { a.y } else { b.y },
                if i & 4 == 0 { a.z } else { b.z },
            )
        })
    }

    /// The axis-aligned box holding this box after the rigid transform `pose`.
    pub fn transformed(&self, pose: &Isometry3<f64>) -> Aabb {
        Aabb::from_points(self.corners().map(|c| pose * c).iter())
    }

    /// Slab test: the entry `t` of the ray into the box if it enters before `t_max`.
    /// `inv_dir` is the component-wise reciprocal of the ray direction.
    #[inline]
    pub fn hit(&self, ray: &Ray, inv_dir: &Vector3<f64>, t_max: f64) -> Option<f64> {
        let mut t0 = T_EPSILON;
        let mut t1 = t_max;
        for i in 0..3 {
            let ta = (self.min[i] - ray.origin[i]) * inv_dir[i];
            let tb = (self.max[i] - ray.origin[i]) * inv_dir[i];
            let (lo, hi) = if ta < tb { (ta, tb) } else { (tb, ta) };
            // NaN (0 * inf on a slab boundary) keeps the current interval.
            if lo > t0 {
                t0 = lo;
            }
            if hi < t1 {
                t1 = hi;
            }
            if t0 > t1 {
                return None;
            }
        }
        Some(t0)
    }
}

/// One piece of a link's visual geometry, in the link's frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A triangle of a mesh (drawn from both sides).
    Triangle([Point3<f64>; 3]),
    /// A box with half extents `half` around `pose` (URDF `<box size>` is `2 * half`).
    Cuboid {
        pose: Isometry3<f64>,
        half: Vector3<f64>,
    },
    /// A cylinder along the local z axis of `pose`, centred on it (URDF convention).
    Cylinder {
        pose: Isometry3<f64>,
        radius: f64,
        half_length: f64,
    },
    Sphere {
        center: Point3<f64>,
        radius: f64,
    },
}

impl Shape {
    /// Bounding box in the link frame.
    pub fn aabb(&self) -> Aabb {
        match self {
            Shape::Triangle(v) => Aabb::from_points(v.iter()),
            Shape::Cuboid { pose, half } => Aabb {
                min: Point3::from(-half),
                max: Point3::from(*half),
            }
            .transformed(pose),
            Shape::Cylinder {
                pose,
                radius,
                half_length,
            } => {
                let h = Vector3::new(*radius, *radius, *half_length);
                Aabb {
                    min: Point3::from(-h),
                    max: Point3::from(h),
                }
                .transformed(pose)
            }
            Shape::Sphere { center, radius } => Aabb {
                min: center - Vector3::repeat(*radius),
                max: center + Vector3::repeat(*radius),
            },
        }
    }

    /// The smallest `t` in `(T_EPSILON, t_max)` where the ray meets the surface.
    pub fn intersect(&self, ray: &Ray, t_max: f64) -> Option<f64> {
        let t = match self {
            Shape::Triangle(v) => intersect_triangle(ray, v),
            Shape::Cuboid { pose, half } => {
                let r = ray.to_local(pose);
                let inv = r.dir.map(|d| 1.0 / d);
                let b = Aabb {
                    min: Point3::from(-half),
                    max: Point3::from(*half),
                };
                // Entry point; if the origin is inside, the exit point.
                match b.hit(&r, &inv, f64::INFINITY) {
                    Some(t) if t > T_EPSILON => Some(t),
                    _ => None,
                }
            }
            Shape::Cylinder {
                pose,
                radius,
                half_length,
            } => intersect_cylinder(&ray.to_local(pose), *radius, *half_length),
            Shape::Sphere { center, radius } => intersect_sphere(ray, center, *radius),
        }?;
        (t > T_EPSILON && t < t_max).then_some(t)
    }
}

/// Möller–Trumbore, two-sided.
fn intersect_triangle(ray: &Ray, v: &[Point3<f64>; 3]) -> Option<f64> {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let p = ray.dir.cross(&e2);
    let det = e1.dot(&p);
    if det.abs() < 1e-18 {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - v[0];
    let u = s.dot(&p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(&e1);
    let w = ray.dir.dot(&q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    Some(e2.dot(&q) * inv)
}

/// Smallest positive root of `a t^2 + 2 b t + c = 0`.
fn smallest_positive_root(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - a * c;
    if disc < 0.0 || a == 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some(((-b - s) / a, (-b + s) / a))
}

fn intersect_sphere(ray: &Ray, center: &Point3<f64>, radius: f64) -> Option<f64> {
    let oc = ray.origin - center;
    let (t0, t1) = smallest_positive_root(
        ray.dir.norm_squared(),
        oc.dot(&ray.dir),
        oc.norm_squared() - radius * radius,
    )?;
    [t0, t1].into_iter().find(|&t| t > T_EPSILON)
}

/// Capped cylinder along z in its own frame.
fn intersect_cylinder(r: &Ray, radius: f64, half_length: f64) -> Option<f64> {
    let mut best = f64::INFINITY;
    // Side.
    let (o, d) = (r.origin, r.dir);
    if let Some((t0, t1)) = smallest_positive_root(
        d.x * d.x + d.y * d.y,
        o.x * d.x + o.y * d.y,
        o.x * o.x + o.y * o.y - radius * radius,
    ) {
        for t in [t0, t1] {
            let z = o.z + t * d.z;
            if t > T_EPSILON && z.abs() <= half_length && t < best {
                best = t;
            }
        }
    }
    // Caps.
    if d.z != 0.0 {
        for zc in [-half_length, half_length] {
            let t = (zc - o.z) / d.z;
            let (x, y) = (o.x + t * d.x, o.y + t * d.y);
            if t > T_EPSILON && x * x + y * y <= radius * radius && t < best {
                best = t;
            }
        }
    }
    best.is_finite().then_some(best)
}
