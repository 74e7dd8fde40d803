//! A sphere: what collision checks are made of (a link's, an obstacle's, a bound).

use nalgebra::Point3;

/// A sphere in a link's frame (or the world's, for an obstacle).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sphere {
    pub center: [f64; 3],
    pub radius: f64,
}

impl Sphere {
    pub fn center(&self) -> Point3<f64> {
        Point3::from(self.center)
    }

    /// Whether `p` lies inside, up to `slack`.
    pub fn contains(&self, p: &Point3<f64>, slack: f64) -> bool {
        (p - self.center()).norm() <= self.radius + slack
    }
}
