//! A robot: a kinematic chain plus the visual geometry of each link.

use nalgebra::{Isometry3, Point3};

use crate::sim::bvh::Bvh;
use crate::sim::kinematics::KinematicChain;

/// A robot the simulator can move and render.
#[derive(Clone, Debug)]
pub struct Robot {
    /// The description's own name (`<robot name=...>`; `arm4`, `ur5` for the built-in ones).
    pub name: String,
    /// How reports and result rows name it: `arm4`, `ur5`, or the description's path with its
    /// tip or joint group ([`crate::sim::robots::RobotSpec::label`]).
    pub label: String,
    pub chain: KinematicChain,
    /// Visual geometry of each link (index as in `chain.links`), in the link's frame.
    pub geometry: Vec<Bvh>,
}

impl Robot {
    /// Number of joint values.
    pub fn dof(&self) -> usize {
        self.chain.dof()
    }

    /// World pose of every link for joint values `q` (SI units).
    pub fn link_frames(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        self.chain.link_frames(q)
    }

    /// World position of the end effector (SI units).
    pub fn end_effector(&self, q: &[f64]) -> Point3<f64> {
        self.chain.end_effector(q)
    }

    /// Total number of shapes (triangles and primitives) over all links.
    pub fn shape_count(&self) -> usize {
        self.geometry.iter().map(|g| g.shapes().len()).sum()
    }
}
