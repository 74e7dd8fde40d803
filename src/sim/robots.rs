//! The robots the project knows by name (`--robot`), and where the papers' real arm lies.
//! A new built-in robot is one file in `sim/` and one variant here.

use std::path::{Path, PathBuf};

use crate::sim::robot::Robot;

/// Built-in robots.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BuiltinRobot {
    /// The papers' 4-DOF arm with the project's fitted box geometry.
    Arm4,
    /// The UR5 from its standard DH parameters, joints in +-90 degrees (kinematics only, no
    /// geometry: the arm of the inverse-kinematics experiments).
    Ur5,
}

impl BuiltinRobot {
    pub fn load(self) -> Robot {
        match self {
            BuiltinRobot::Arm4 => crate::sim::arm4::arm4(),
            BuiltinRobot::Ur5 => {
                crate::sim::dh_robot::ur5(crate::sim::kinematics::DEFAULT_ROTATIONAL_RANGE)
            }
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            BuiltinRobot::Arm4 => "arm4",
            BuiltinRobot::Ur5 => "ur5",
        }
    }
}

/// Where the papers' robot lies in the shared folder beside the repository.
pub fn shared_arm_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/robots/4dof_1st/urdf/4dof_1st.urdf")
}
