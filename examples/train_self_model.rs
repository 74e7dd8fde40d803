//! A visual self-model of your own robot from the library: NeuroKin (the paper's decoder)
//! trained on images rendered from the robot's description, framed automatically, then scored
//! on held-out poses.
//!
//! `cargo run --release --example train_self_model -- [URDF [TIP]]` (without a URDF: the
//! built-in UR5). The quick preset's 32x32 images, 1,500 steps: under a minute on 2 cores;
//! `cargo run --release --bin neurokin -- --urdf URDF` runs the paper's.

use selfmodel::core::device::DeviceChoice;
use selfmodel::data::dataset::CameraChoice;
use selfmodel::self_models::harness::run;
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::sim::urdf_loader::GeometryKind;
use selfmodel::{BuiltinRobot, RobotSpec};

fn main() -> selfmodel::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let robot = match args.first() {
        Some(urdf) => RobotSpec::Urdf {
            path: urdf.into(),
            base_xyz: [0.0; 3],
            base_rpy: [0.0; 3],
            tip: args.get(1).cloned(),
            geometry: GeometryKind::Visual,
            joints: Default::default(),
        },
        None => RobotSpec::Builtin(BuiltinRobot::Ur5),
    };
    // The robot's own joints, and a camera that frames it (no placement asked for).
    let mut cfg = neurokin_run("quick")?.on_robot(robot, &CameraChoice::default(), false, None)?;
    // Long enough to see the robot (the quick preset's 200 steps only test the pipeline).
    cfg.train.steps = 1500;
    let out = std::env::temp_dir().join("selfmodel_example_self_model");
    let outcome = run(&cfg, &out, DeviceChoice::Cpu, false)?;
    let r = &outcome.result;
    println!(
        "{} on {}: {} training steps, test PSNR {:.2} dB, IoU {:.3}; wrote {}",
        cfg.name,
        cfg.data.robot.label(),
        outcome.log.step,
        r.psnr_db_test,
        r.iou_test,
        out.display()
    );
    Ok(())
}
