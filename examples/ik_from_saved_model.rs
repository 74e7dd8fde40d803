//! Learned inverse kinematics from the library: train a model of the built-in UR5 in
//! seconds (the quick preset), save it, load it back as `ik solve` does, and answer a target
//! the robot reaches, to 1e-4 mm.
//!
//! `cargo run --release --example ik_from_saved_model -- [FOLDER]` (default: a folder under
//! the system's temporary directory).

use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::ik::solve::learned::{LearnedIk, LearnedIkConfig, train};
use selfmodel::ik::solve::levenberg_marquardt::PoseTarget;
use selfmodel::ik::solve::solver::IkSolver;
use selfmodel::{BuiltinRobot, Preset, RobotSpec};

fn main() -> selfmodel::Result<()> {
    let dir = std::env::args().nth(1).map_or_else(
        || std::env::temp_dir().join("selfmodel_example_ur5_ik"),
        std::path::PathBuf::from,
    );
    let device = select(DeviceChoice::Cpu)?;
    let spec = RobotSpec::Builtin(BuiltinRobot::Ur5);
    let robot = spec.load_kinematics()?;
    let trained = train(&spec, &robot, &LearnedIkConfig::quick(), &dir, &device)?;
    println!(
        "trained and saved {} joints into {}",
        trained.dof(),
        dir.display()
    );

    let (model, robot) = LearnedIk::load_with_robot(&dir, &device)?;
    // A pose the robot reaches: its tip at some joint values.
    let q = [0.3, -1.1, 1.4, -0.5, 1.2, 0.7];
    let target = PoseTarget::of(&robot.chain, &q);
    let answers = model.solve(&robot.chain, &[target], 1, &model.answering())?;
    let a = &answers[0][0];
    println!(
        "answer {:.4?}: {:.2e} mm and {:.2e} degrees from the target, exact: {}",
        a.joints,
        1e3 * a.position_error_m,
        a.rotation_error_rad.to_degrees(),
        a.exact(&model.saved.config.lm)
    );
    Ok(())
}
