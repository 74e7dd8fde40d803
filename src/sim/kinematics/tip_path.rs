//! The path from the root to a tip with its constant parts folded together: the tip's pose
//! and pose Jacobian in one pass over the movable joints on it (the fast path).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// One movable joint on the path to the tip: `origin` (everything constant since the previous
/// movable joint folded in), then the motion about (or along) `axis` by
/// `scale * q[index] + offset`.
#[derive(Clone, Debug)]
pub(super) struct PathStep {
    pub origin: Isometry3<f64>,
    pub axis: Vector3<f64>,
    pub rotational: bool,
    pub index: usize,
    pub scale: f64,
    pub offset: f64,
}

/// The chain from the root to the tip with its constant parts folded together: the tip's
/// pose and pose Jacobian in one pass over the movable joints on the path (the fast path of
/// [`KinematicChain::tip_pose`] and [`KinematicChain::pose_jacobian`], which it matches; a
/// test compares them).
#[derive(Clone, Debug)]
pub struct TipPath {
    pub(super) steps: Vec<PathStep>,
    /// From the last movable joint's frame to the tip (its link's orientation).
    pub(super) tip: Isometry3<f64>,
    pub(super) dof: usize,
}

impl TipPath {
    /// The motion of `step`'s joint at `q`.
    fn motion(step: &PathStep, q: &[f64]) -> Isometry3<f64> {
        let v = step.scale * q[step.index] + step.offset;
        if step.rotational {
            Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_scaled_axis(step.axis * v),
            )
        } else {
            Isometry3::from_parts(
                Translation3::from(step.axis * v),
                UnitQuaternion::identity(),
            )
        }
    }

    /// The tip's world pose at `q`.
    pub fn pose(&self, q: &[f64]) -> Isometry3<f64> {
        let mut f = Isometry3::identity();
        for s in &self.steps {
            f = f * s.origin * Self::motion(s, q);
        }
        f * self.tip
    }

    /// The tip's world pose at `q` and its pose Jacobian written into `jac` (`[6, dof]`:
    /// linear rows, then angular).
    pub fn pose_and_jacobian(
        &self,
        q: &[f64],
        jac: &mut nalgebra::Matrix6xX<f64>,
    ) -> Isometry3<f64> {
        if jac.ncols() != self.dof {
            *jac = nalgebra::Matrix6xX::zeros(self.dof);
        } else {
            jac.fill(0.0);
        }
        // Each movable joint's world origin and axis, then the tip.
        let mut axes = Vec::with_capacity(self.steps.len());
        let mut f = Isometry3::identity();
        for s in &self.steps {
            let at = f * s.origin;
            axes.push((at * Point3::origin(), at * s.axis));
            f = at * Self::motion(s, q);
        }
        let pose = f * self.tip;
        let tip = Point3::from(pose.translation.vector);
        for (s, (o, axis)) in self.steps.iter().zip(axes) {
            let (linear, angular) = if s.rotational {
                (axis.cross(&(tip - o)), axis)
            } else {
                (axis, Vector3::zeros())
            };
            let mut col = jac.column_mut(s.index);
            col.fixed_rows_mut::<3>(0).axpy(s.scale, &linear, 1.0);
            col.fixed_rows_mut::<3>(3).axpy(s.scale, &angular, 1.0);
        }
        pose
    }
}
