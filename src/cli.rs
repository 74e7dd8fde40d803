//! Pieces every binary shares: robot selection, the one-line error exit, the git revision.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use nalgebra::Isometry3;

use crate::error::Result;
use crate::robot::Robot;
use crate::urdf_loader::{load_urdf, pose_from_xyz_rpy};

/// Run a binary's body: on error print one line (`error: <file>: <what>`) and exit 1.
pub fn run_main(body: impl FnOnce() -> Result<()>) -> ExitCode {
    match body() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Three numbers on the command line: `x,y,z`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triple(pub [f64; 3]);

impl std::str::FromStr for Triple {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|p| {
                p.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("\"{p}\" is not a number"))
            })
            .collect::<std::result::Result<_, _>>()?;
        match v[..] {
            [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok(Triple([a, b, c])),
            _ => Err(format!("expected three finite numbers x,y,z, got \"{s}\"")),
        }
    }
}

impl std::fmt::Display for Triple {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},{},{}", self.0[0], self.0[1], self.0[2])
    }
}

/// Built-in robots.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BuiltinRobot {
    /// The papers' 4-DOF arm with the project's fitted box geometry.
    Arm4,
}

/// `--robot` / `--urdf` options.
#[derive(Clone, Debug, clap::Args)]
pub struct RobotArgs {
    /// Built-in robot (ignored when --urdf is given).
    #[arg(long, value_enum, default_value = "arm4")]
    pub robot: BuiltinRobot,
    /// Load the robot from a URDF instead (meshes: STL; `package://` resolved next to it).
    #[arg(long, value_name = "PATH")]
    pub urdf: Option<PathBuf>,
    /// Scene position of a URDF's root link, metres.
    #[arg(
        long,
        value_name = "X,Y,Z",
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    pub base_xyz: Triple,
    /// Scene orientation of a URDF's root link, radians (fixed-axis roll, pitch, yaw).
    #[arg(
        long,
        value_name = "R,P,Y",
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    pub base_rpy: Triple,
    /// Place a URDF as the papers' scene places arm4: base at [0,0,-0.108], yaw -pi/2.
    #[arg(long, conflicts_with_all = ["base_xyz", "base_rpy"])]
    pub arm4_scene: bool,
}

impl RobotArgs {
    /// The scene placement of a URDF robot.
    pub fn base(&self) -> Isometry3<f64> {
        if self.arm4_scene {
            return crate::arm4::scene_base();
        }
        pose_from_xyz_rpy(self.base_xyz.0, self.base_rpy.0)
    }

    /// Load the chosen robot.
    pub fn load(&self) -> Result<Robot> {
        match &self.urdf {
            Some(path) => load_urdf(path, self.base()),
            None => Ok(match self.robot {
                BuiltinRobot::Arm4 => crate::arm4::arm4(),
            }),
        }
    }

    /// A short name for reports: `arm4` or the URDF path.
    pub fn label(&self) -> String {
        match &self.urdf {
            Some(p) => p.display().to_string(),
            None => "arm4".into(),
        }
    }
}

/// Where the papers' robot lies in the shared folder beside the repository.
pub fn shared_arm_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/robots/4dof_1st/urdf/4dof_1st.urdf")
}

/// `git describe --always --dirty` of the working tree, or "unknown".
pub fn git_revision() -> String {
    std::process::Command::new("git")
        .args(["describe", "--always", "--dirty", "--abbrev=10"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}
