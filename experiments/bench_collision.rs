//! How long a collision check of one configuration takes (the robot against itself and a
//! scene), beside its forward kinematics alone.
//!
//! `cargo run --release --bin bench_collision`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel_lab::cli::run_main;

/// Time the sphere check of random configurations of the Panda (or `--urdf`) against itself
/// and a scene of ten obstacles, on one thread.
#[derive(Parser)]
#[command(version, allow_negative_numbers = true)]
struct Args {
    #[arg(
        long,
        default_value = "../shared/robots/franka_description/urdf/panda.urdf"
    )]
    urdf: PathBuf,
    #[arg(long, default_value = "panda_hand")]
    tip: String,
    /// The obstacles (cuRobo's world-configuration YAML).
    #[arg(long, default_value = "examples/scenes/panda_ten_obstacles.yml")]
    scene: PathBuf,
    /// Random configurations timed.
    #[arg(long, default_value_t = 20_000)]
    n: usize,
    /// Output folder (results.csv, results.md).
    #[arg(long, default_value = "runs/bench_collision")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| {
        if args.n == 0 {
            return Err(selfmodel::Error::Config("--n must be at least 1".into()));
        }
        let spec = selfmodel::sim::robots::RobotSpec::Urdf {
            path: args.urdf.clone(),
            base_xyz: [0.0; 3],
            base_rpy: [0.0; 3],
            tip: Some(args.tip.clone()),
            geometry: selfmodel::sim::urdf_loader::GeometryKind::None,
            joints: Default::default(),
        };
        let rows = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| selfmodel::Error::Config(format!("a one-thread pool: {e}")))?
            .install(|| {
                selfmodel_lab::studies::bench::collision::run(&spec, &args.scene, args.n, &args.out)
            })?;
        for r in &rows {
            println!(
                "{:<70} {:>7.2} us  ({} spheres, {} checked pairs, {} obstacles, {:.1}% colliding)",
                r.what,
                r.us_per_configuration,
                r.spheres,
                r.checked_pairs,
                r.obstacles,
                r.colliding_pct
            );
        }
        println!(
            "bench_collision: on {}; wrote {}/results.csv",
            rows[0].cpu,
            args.out.display()
        );
        Ok(())
    })
}
