//! A self-model run on one's own robot ([`SelfModelRun::on_robot`]): its joints, its camera, or
//! a dataset file of its own.

use std::path::Path;

use crate::core::error::Result;
use crate::data::dataset::{CameraChoice, Dataset};
use crate::self_models::model::SelfModel;
use crate::self_models::run_config::SelfModelRun;
use crate::sim::robots::RobotSpec;

impl<M: SelfModel> SelfModelRun<M> {
    /// This run on `robot`, its images rendered by `camera`, or read from the dataset `file`:
    /// the model's joint count (and joint tree) become the robot's, or the file's. The papers'
    /// arm keeps the papers' camera, as does any robot given `papers_camera` (a URDF placed in
    /// the papers' scene); any other is framed automatically unless `camera` places it.
    pub fn on_robot(
        mut self,
        robot: RobotSpec,
        camera: &CameraChoice,
        papers_camera: bool,
        file: Option<&Path>,
    ) -> Result<Self> {
        self.data.robot = robot;
        if let Some(file) = file {
            self.data.file = Some(file.to_path_buf());
            // The joint count is the file's (a lab's own data needs no robot description).
            self.model.set_dof(Dataset::load(file)?.dof());
        } else if !self.data.robot.is_papers_arm() {
            let robot = self.data.robot.load_kinematics()?;
            self.model.set_dof(robot.dof());
            self.model.set_joint_tree(&robot.chain.input_parents());
        }
        let papers_camera = self.data.robot.is_papers_arm() || papers_camera;
        camera.apply(&mut self.data.dataset, !papers_camera);
        Ok(self)
    }
}
