//! Our collision checks (the spheres alone, and the exact narrow phase behind them) against
//! Pinocchio and coal on the exact meshes, on random configurations of a robot.
//!
//! `cargo run --release --bin bench_collision_agreement -- --urdf ../shared/robots/ur_description/urdf/ur5.urdf --python target/pyenv/bin/python --out reports/collision_agreement/ur5`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::bench::collision_agreement::{AgreementConfig, run};

/// Decide random configurations of a robot (against itself, zero margin) by our spheres, by
/// the exact narrow phase, and by Pinocchio (scripts/collision_reference.py) on the exact
/// collision meshes: false alarms, misses and time a configuration.
#[derive(Parser)]
#[command(version)]
struct Args {
    /// The robot's description (its <collision> geometry is checked).
    #[arg(
        long,
        default_value = "../shared/robots/franka_description/urdf/panda.urdf"
    )]
    urdf: PathBuf,
    /// The chain's last link [default: the deepest link of the tree].
    #[arg(long)]
    tip: Option<String>,
    /// Which joints move (`--joints all`: the whole body of a humanoid); the others are held.
    #[command(flatten)]
    group: selfmodel_lab::cli::JointGroupArgs,
    /// Random configurations.
    #[arg(long, default_value_t = 10_000)]
    configurations: usize,
    /// The configurations' seed (not 0: the pairs checked are decided on the 10,000 of seed 0).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The Python that runs Pinocchio's check (PyPI pin).
    #[arg(long, default_value = "python3")]
    python: PathBuf,
    /// Spheres of another's to score beside ours (cuRobo's robot file or spheres file, a
    /// collision_spheres block), on the same pairs.
    #[arg(long, value_name = "FILE")]
    spheres: Option<PathBuf>,
    #[command(flatten)]
    fit: selfmodel_lab::cli::SphereFitArgs,
    /// Leave Pinocchio's check out (then no agreement is measured).
    #[arg(long)]
    no_reference: bool,
    /// Output folder.
    #[arg(long, default_value = "runs/bench_collision_agreement")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        let spec = selfmodel::sim::robots::RobotSpec::Urdf {
            path: args.urdf.clone(),
            base_xyz: [0.0; 3],
            base_rpy: [0.0; 3],
            tip: args.tip.clone(),
            geometry: selfmodel::sim::urdf_loader::GeometryKind::None,
            joints: args.group.group(Some(&args.urdf))?,
        };
        let cfg = AgreementConfig {
            configurations: args.configurations,
            seed: args.seed,
            fit: args.fit.fit()?,
            spheres_file: args.spheres.clone(),
        };
        let python = (!args.no_reference).then_some(args.python.as_path());
        let rows = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .map_err(|e| selfmodel::Error::Config(format!("a one-thread pool: {e}")))?
            .install(|| run(&spec, &cfg, python, &args.out))?;
        let (rows, links) = rows;
        println!(
            "{:<16} {:<18} {:>7} {:>12} {:>14} {:>14}",
            "spheres", "link", "spheres", "coverage %", "protrusion max", "mean (mm)"
        );
        for l in &links {
            println!(
                "{:<16} {:<18} {:>7} {:>12.2} {:>14.1} {:>14.2}",
                l.spheres_from,
                l.link,
                l.spheres,
                l.coverage_pct,
                l.protrusion_max_mm,
                l.protrusion_mean_mm
            );
        }
        let cell = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        println!(
            "{:<8} {:<16} {:>6} {:>7} {:>12} {:>14} {:>9} {:>10}",
            "check",
            "spheres from",
            "pairs",
            "spheres",
            "colliding %",
            "false alarm %",
            "missed %",
            "us a conf"
        );
        for r in &rows {
            println!(
                "{:<8} {:<16} {:>6} {:>7} {:>12.2} {:>14} {:>9} {:>10.2}",
                r.check,
                r.spheres_from,
                r.checked_pairs,
                r.spheres,
                r.colliding_pct,
                cell(r.false_alarms_pct),
                cell(r.misses_pct),
                r.us_per_configuration
            );
        }
        println!(
            "bench_collision_agreement: {} configurations of {}, {} colliding on the exact meshes, on {}; wrote {}/results.csv",
            rows[0].configurations,
            rows[0].robot,
            cell(rows[0].mesh_colliding_pct) + "%",
            rows[0].cpu,
            args.out.display()
        );
        Ok(())
    })
}
