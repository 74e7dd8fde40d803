//! Collision-free IK benchmarked: a saved model's answers with and without the collision
//! check, checked again by Pinocchio on the exact meshes, beside cuRobo's published figures.
//!
//! `cargo run --release --bin bench_collision_ik -- --model runs/ik_models/panda --scene examples/scenes/panda_table.yml --out reports/collision_ik/panda`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::bench::collision_ik::{CollisionIkConfig, run};

/// Benchmark collision-free IK on a model `ik train` saved: targets from random
/// collision-free configurations, the share answered exactly and collision-free and the
/// answers a second, with the check and without, and the share of those answers Pinocchio
/// (scripts/collision_reference.py) finds collision-free on the exact meshes.
#[derive(Parser)]
#[command(version)]
struct Args {
    /// A folder `ik train` wrote (full pose).
    #[arg(long)]
    model: PathBuf,
    /// The obstacles (cuRobo's world-configuration YAML) [default: none: the robot against
    /// itself only].
    #[arg(long, value_name = "FILE")]
    scene: Option<PathBuf>,
    /// paper (1,000 targets, timed over at least three passes and 3 s) or quick (40, one pass).
    #[arg(long, default_value = "paper")]
    preset: String,
    /// The distance kept from the robot itself and the obstacles (m).
    #[arg(long, default_value_t = 0.005, allow_hyphen_values = true)]
    margin: f64,
    /// The Python that runs Pinocchio's check (PyPI pin and pyyaml).
    #[arg(long, default_value = "python3")]
    python: PathBuf,
    /// Leave Pinocchio's check out.
    #[arg(long)]
    no_reference: bool,
    /// Output folder [default: runs/bench_collision_ik/<model folder>; the committed results
    /// were written with --out reports/collision_ik/<robot>].
    #[arg(long)]
    out: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        let cfg = CollisionIkConfig {
            margin: args.margin,
            ..CollisionIkConfig::named(&args.preset)?
        };
        let out = args.out.clone().unwrap_or_else(|| {
            let name = args.model.file_name().unwrap_or_default();
            PathBuf::from("runs/bench_collision_ik").join(name)
        });
        let python = (!args.no_reference).then_some(args.python.as_path());
        let rows = run(&args.model, args.scene.as_deref(), &cfg, python, &out)?;
        println!(
            "{:<44} {:>9} {:>8} {:>9} {:>11} {:>11} {:>10}  {}",
            "solver",
            "collision",
            "exact %",
            "exact/s",
            "ms a target",
            "mesh-free %",
            "unchecked",
            "hardware"
        );
        for r in &rows {
            let cell = |v: Option<f64>, digits: usize| {
                v.map_or("-".to_string(), |v| format!("{v:.digits$}"))
            };
            println!(
                "{:<44} {:>9} {:>8.2} {:>9.0} {:>11} {:>11} {:>10}  {}",
                r.solver,
                r.collision,
                r.exact_free_pct,
                r.exact_free_per_s,
                cell(r.ms_per_target, 4),
                cell(r.exact_mesh_free_pct, 2),
                r.colliding_in_unchecked_pairs
                    .map_or("-".to_string(), |c| c.to_string()),
                r.hardware
            );
        }
        if let Some(r) = rows.iter().find(|r| r.collision == "none") {
            println!(
                "without the check, {:.1}% of the exact answers collide (by the exact check)",
                r.exact_but_colliding_pct.unwrap_or(0.0)
            );
        }
        for r in rows.iter().filter(|r| r.source == "measured") {
            if let (Some(c), Some(m)) = (r.spheres_conservative_pct, r.spheres_missed_pct) {
                println!(
                    "the {} check against the exact meshes (zero margin) on {} random configurations: {c:.1}% of the free ones called colliding, {m:.1}% of the colliding ones missed",
                    r.collision, cfg.targets
                );
            }
        }
        println!(
            "unchecked: answers colliding on the exact meshes in a pair of links the check leaves out (Pinocchio, every pair no joint joins)"
        );
        println!(
            "bench_collision_ik ({} preset, {} targets, {}): wrote {}/results.csv",
            cfg.preset,
            cfg.targets,
            rows[0].hardware,
            out.display()
        );
        Ok(())
    })
}
