//! A robot's forward kinematics and Jacobian from the library: the tip's pose and its `6 x n`
//! pose Jacobian at the middle of every joint's range.
//!
//! `cargo run --release --example forward_kinematics -- [URDF [TIP]]` (without a URDF: the
//! built-in UR5).

use nalgebra::Matrix6xX;
use selfmodel::sim::urdf_loader::GeometryKind;
use selfmodel::{BuiltinRobot, RobotSpec};

fn main() -> selfmodel::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let spec = match args.first() {
        Some(urdf) => RobotSpec::Urdf {
            path: urdf.into(),
            base_xyz: [0.0; 3],
            base_rpy: [0.0; 3],
            tip: args.get(1).cloned(),
            geometry: GeometryKind::None,
            joints: Default::default(),
        },
        None => RobotSpec::Builtin(BuiltinRobot::Ur5),
    };
    let robot = spec.load_kinematics()?;
    let chain = &robot.chain;
    let q: Vec<f64> = (chain.joint_ranges().iter())
        .map(|r| 0.5 * (r[0] + r[1]))
        .collect();
    println!(
        "{}: {} joints ({})",
        spec.label(),
        q.len(),
        chain.joint_names().join(", ")
    );
    println!("q (mid-range) = {q:.3?}");
    for (tip, pose) in chain.tip_names().iter().zip(chain.tip_poses(&q)) {
        let t = pose.translation.vector;
        let (r, p, y) = pose.rotation.euler_angles();
        println!(
            "{tip}: position [{:.4}, {:.4}, {:.4}] m, roll-pitch-yaw [{r:.4}, {p:.4}, {y:.4}] rad",
            t.x, t.y, t.z
        );
    }
    let mut jacobian = Matrix6xX::zeros(q.len());
    chain.tip_paths()[0].pose_and_jacobian(&q, &mut jacobian);
    println!("pose Jacobian (linear rows, then angular):{jacobian:.3}");
    Ok(())
}
