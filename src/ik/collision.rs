//! Collision-free answers: the check an IK answer must pass, built from a saved model's robot
//! (its collision geometry, the SRDF beside it or named) and a scene. An answer is exact and
//! collision-free only when no checked pair of its spheres, and none of its moving links'
//! spheres and an obstacle, come closer than the margin.

use std::path::Path;

use crate::core::error::{Error, Result};
use crate::sim::collision::model::CollisionModel;
use crate::sim::collision::pairs::PairSampling;
use crate::sim::collision::scene::Scene;
use crate::sim::collision::spheres::SphereFit;
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;
use crate::sim::urdf_loader::GeometryKind;

/// What an answer is checked against.
pub struct CollisionCheck {
    pub model: CollisionModel,
    pub scene: Option<Scene>,
    /// Whether the robot is checked against itself.
    pub self_collision: bool,
    /// The distance kept (m).
    pub margin: f64,
    /// The robot with its collision geometry (what the spheres were fitted to).
    pub robot: Robot,
}

/// The largest margin accepted (m).
const MAX_MARGIN_M: f64 = 1.0;

impl CollisionCheck {
    /// The check for `spec`'s robot: its collision spheres, the allowed pairs of `srdf` (else
    /// of the SRDF beside its URDF, else computed), the obstacles of `scene`.
    pub fn for_robot(
        spec: &RobotSpec,
        srdf: Option<&Path>,
        scene: Option<Scene>,
        self_collision: bool,
        margin: f64,
    ) -> Result<Self> {
        Self::with_spheres(spec, None, srdf, scene, self_collision, margin)
    }

    /// [`Self::for_robot`] with the user's spheres in `spheres` (cuRobo's format) where
    /// given, instead of spheres fitted to the meshes.
    pub fn with_spheres(
        spec: &RobotSpec,
        spheres: Option<&Path>,
        srdf: Option<&Path>,
        scene: Option<Scene>,
        self_collision: bool,
        margin: f64,
    ) -> Result<Self> {
        if !(margin.is_finite() && (0.0..=MAX_MARGIN_M).contains(&margin)) {
            return Err(Error::Config(format!(
                "--margin {}: give a distance from 0 to 1 m",
                crate::core::error::short_number(margin)
            )));
        }
        let robot = spec.with_geometry(GeometryKind::Collision).load()?;
        let beside = match spec {
            RobotSpec::Urdf { path, .. } => crate::sim::srdf::find_beside(path).ok(),
            RobotSpec::Builtin(_) => None,
        };
        let srdf = srdf.map(Path::to_path_buf).or(beside);
        let fitted = match spheres {
            Some(file) => crate::sim::collision::user_spheres::read(file, &robot.chain.links)?,
            None => crate::sim::collision::fit_robot(&robot, &SphereFit::default()),
        };
        let model = crate::sim::collision::model_with(
            &robot,
            fitted,
            srdf.as_deref(),
            &PairSampling::default(),
        )?;
        Ok(Self {
            model,
            scene,
            self_collision,
            margin,
            robot,
        })
    }

    /// The clearance at `q` (m, negative where something overlaps), at most `cap`.
    pub fn clearance(&self, q: &[f64], cap: f64) -> f64 {
        let frames = self.robot.chain.link_frames(q);
        let own = if self.self_collision {
            self.model.self_clearance(&frames, cap)
        } else {
            cap
        };
        match &self.scene {
            Some(s) => self.model.scene_clearance(&frames, s, own),
            None => own,
        }
    }

    /// Whether `q` keeps the margin (the first pair or obstacle closer ends the check).
    pub fn valid(&self, q: &[f64]) -> bool {
        let frames = self.robot.chain.link_frames(q);
        if self.self_collision && self.model.self_collides(&frames, self.margin) {
            return false;
        }
        !(self.scene.as_ref()).is_some_and(|s| self.model.scene_collides(&frames, s, self.margin))
    }
}
