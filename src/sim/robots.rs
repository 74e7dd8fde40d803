//! The robots the project knows by name (`robot`), and where the papers' real arm lies.
//! A new built-in robot is one file in `sim/` and one variant here.

use std::path::{Path, PathBuf};

use crate::core::error::Result;
use crate::sim::kinematics::JointGroup;
use crate::sim::robot::Robot;
use crate::sim::urdf_loader::{GeometryKind, UrdfOptions};

/// Built-in robots.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum BuiltinRobot {
    /// The papers' 4-DOF arm with the project's fitted box geometry.
    Arm4,
    /// The UR5 from its standard DH parameters, joints limited to +-180 degrees (the
    /// inverse-kinematics experiments narrow them to their +-90 or +-180), drawn as cylinders
    /// along its links: the arm of the inverse-kinematics experiments.
    Ur5,
}

impl BuiltinRobot {
    pub fn load(self) -> Robot {
        match self {
            BuiltinRobot::Arm4 => crate::sim::arm4::arm4(),
            BuiltinRobot::Ur5 => {
                crate::sim::dh_robot::ur5([-std::f64::consts::PI, std::f64::consts::PI])
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

/// The robot a run uses, as its config records it: a built-in one, or a URDF placed in the
/// scene (its root link at `base_xyz`, metres, turned by `base_rpy`, radians).
///
/// # Examples
///
/// A robot's tip pose at some joint values (`examples/forward_kinematics.rs` adds its
/// Jacobian):
///
/// ```
/// use selfmodel::{BuiltinRobot, RobotSpec};
///
/// let robot = RobotSpec::Builtin(BuiltinRobot::Ur5).load_kinematics()?;
/// assert_eq!(robot.dof(), 6);
/// let tip = robot.chain.tip_poses(&[0.0; 6])[0];
/// assert!((tip.translation.vector.norm() - 0.84).abs() < 0.01);
/// # Ok::<(), selfmodel::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobotSpec {
    Builtin(BuiltinRobot),
    Urdf {
        path: PathBuf,
        base_xyz: [f64; 3],
        base_rpy: [f64; 3],
        /// The end-effector link (`tip`); none: the last link of the longest chain.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tip: Option<String>,
        /// Visual or collision geometry (`geometry`).
        #[serde(default, skip_serializing_if = "is_visual")]
        geometry: GeometryKind,
        /// Which movable joints are the joint vector (`joints`, `tips`; the chain to the
        /// tip by default).
        #[serde(default, skip_serializing_if = "JointGroup::is_chain")]
        joints: JointGroup,
    },
}

fn is_visual(g: &GeometryKind) -> bool {
    *g == GeometryKind::Visual
}

impl Default for RobotSpec {
    /// The papers' arm.
    fn default() -> Self {
        RobotSpec::Builtin(BuiltinRobot::Arm4)
    }
}

/// A loaded description: its spec, geometry override and file version.
type LoadedKey = (
    String,
    Option<GeometryKind>,
    Option<(u64, Option<std::time::SystemTime>)>,
);

/// The descriptions this process has read ([`RobotSpec::load`]).
static LOADED: std::sync::OnceLock<std::sync::Mutex<Vec<(LoadedKey, std::sync::Arc<Robot>)>>> =
    std::sync::OnceLock::new();

/// How many times this process has read each robot description from disk.
static READS: std::sync::Mutex<Vec<(PathBuf, usize)>> = std::sync::Mutex::new(Vec::new());

/// How many times this process has read the description at `path` from disk (a run reads it
/// once).
pub fn description_reads(path: &Path) -> usize {
    let reads = READS.lock().unwrap_or_else(|e| e.into_inner());
    reads.iter().find(|(p, _)| p == path).map_or(0, |(_, n)| *n)
}

impl RobotSpec {
    /// The same description with `geometry` (a built-in robot as it is).
    pub fn with_geometry(&self, geometry: GeometryKind) -> Self {
        let mut spec = self.clone();
        if let RobotSpec::Urdf { geometry: g, .. } = &mut spec {
            *g = geometry;
        }
        spec
    }

    /// A URDF placed where the papers' scene places arm4 (base at [0, 0, -0.108], yaw -pi/2),
    /// so the papers' camera sees it as it sees arm4.
    pub fn urdf_in_arm4_scene(path: PathBuf) -> Self {
        let base = crate::sim::arm4::scene_base();
        let (r, p, y) = base.rotation.euler_angles();
        let t = base.translation.vector;
        RobotSpec::Urdf {
            path,
            base_xyz: [t.x, t.y, t.z],
            base_rpy: [r, p, y],
            tip: None,
            geometry: GeometryKind::Visual,
            joints: JointGroup::Chain,
        }
    }

    pub fn load(&self) -> Result<Robot> {
        self.load_as(None)
    }

    /// Load its kinematics only (no mesh is read): for the inverse-kinematics experiments.
    pub fn load_kinematics(&self) -> Result<Robot> {
        self.load_as(Some(GeometryKind::None))
    }

    /// A description is read from disk once per process and version of its file: every layer
    /// of a run that asks for the robot (dataset, self-model, renderer, damage, IK, reports)
    /// gets the same robot, and a file edited between runs of a long-lived process (Python) is
    /// read again.
    fn load_as(&self, geometry_override: Option<GeometryKind>) -> Result<Robot> {
        let RobotSpec::Urdf { path, .. } = self else {
            return self.read(geometry_override);
        };
        let version = std::fs::metadata(path)
            .ok()
            .map(|m| (m.len(), m.modified().ok()));
        let key = (
            serde_json::to_string(self).expect("a robot spec serialises"),
            geometry_override,
            version,
        );
        let cache = LOADED.get_or_init(Default::default);
        if let Some(robot) = cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, r)| r.clone())
        {
            return Ok((*robot).clone());
        }
        let robot = std::sync::Arc::new(self.read(geometry_override)?);
        let mut reads = READS.lock().unwrap_or_else(|e| e.into_inner());
        match reads.iter_mut().find(|(p, _)| p == path) {
            Some((_, n)) => *n += 1,
            None => reads.push((path.clone(), 1)),
        }
        drop(reads);
        let mut cache = cache.lock().unwrap_or_else(|e| e.into_inner());
        // A few descriptions a process: the oldest goes first.
        if cache.len() >= 8 {
            cache.remove(0);
        }
        cache.push((key, robot.clone()));
        Ok((*robot).clone())
    }

    /// Read the description from disk.
    fn read(&self, geometry_override: Option<GeometryKind>) -> Result<Robot> {
        match self {
            RobotSpec::Builtin(b) => Ok(b.load()),
            RobotSpec::Urdf {
                path,
                base_xyz,
                base_rpy,
                tip,
                geometry,
                joints,
            } => {
                let mut robot = crate::sim::urdf_loader::load_urdf_with(
                    path,
                    &UrdfOptions {
                        base: crate::sim::urdf_loader::pose_from_xyz_rpy(*base_xyz, *base_rpy),
                        tip: tip.clone(),
                        geometry: geometry_override.unwrap_or(*geometry),
                        joints: joints.clone(),
                    },
                )?;
                robot.label = self.label();
                Ok(robot)
            }
        }
    }

    /// Whether it is the papers' arm (built in, or its URDF placed in the papers' scene), which
    /// keeps the papers' camera and reference figures.
    pub fn is_papers_arm(&self) -> bool {
        *self == RobotSpec::Builtin(BuiltinRobot::Arm4)
    }

    /// The files this robot is read from (its URDF, the SRDF naming its group or beside it,
    /// the meshes it names): what a run's `out` must never name.
    pub fn files(&self) -> Vec<PathBuf> {
        match self {
            RobotSpec::Builtin(_) => Vec::new(),
            RobotSpec::Urdf { path, joints, .. } => {
                let mut files = vec![path.clone()];
                if let JointGroup::Srdf { file, .. } = joints {
                    files.push(file.clone());
                }
                files.extend(crate::sim::urdf_loader::mesh_files(path));
                // Read for collisions where none is named.
                files.extend(crate::sim::srdf::find_beside(path).ok());
                files
            }
        }
    }

    /// `Ok` where `robot` (this spec, loaded) has a joint to move; otherwise the one line
    /// every edge gives (`needs`: what needs one, "inverse kinematics").
    pub fn require_movable(&self, robot: &Robot, needs: &str) -> Result<()> {
        if robot.dof() > 0 {
            return Ok(());
        }
        Err(crate::core::error::Error::Config(format!(
            "{}: this robot has no movable joints (every joint is fixed, or its tip or group has none); {needs} needs at least one: choose a tip below a joint (`tip`), a group with joints, or a robot that moves",
            self.label()
        )))
    }

    /// `arm4`, `ur5` or the URDF's path.
    pub fn label(&self) -> String {
        match self {
            RobotSpec::Builtin(b) => b.name().into(),
            RobotSpec::Urdf {
                path, tip, joints, ..
            } => {
                let mut label = path.display().to_string();
                if let Some(t) = tip {
                    label += &format!(" (tip {t})");
                }
                match joints {
                    JointGroup::Chain => {}
                    JointGroup::All => label += " (all joints)",
                    JointGroup::Tips(t) => label += &format!(" (tips {})", t.join(",")),
                    JointGroup::Named(n) => label += &format!(" (joints {})", n.join(",")),
                    JointGroup::Srdf { group, .. } => label += &format!(" (group {group})"),
                    JointGroup::Members { joints, .. } => {
                        label += &format!(" (joints {})", joints.join(","))
                    }
                }
                label
            }
        }
    }
}
