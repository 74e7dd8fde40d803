//! Silhouette IoU of the built-in arm4 against the mesh robot, and of our renderer against PyBullet.
//!
//! `cargo run --release --bin mesh_fidelity [-- --pybullet data/pybullet.npz]`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::core::preset::Preset;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::mesh_fidelity::{FidelityConfig, run};

/// Compare silhouettes: arm4 (fitted boxes) vs the mesh robot, and both vs PyBullet renders.
#[derive(Parser)]
#[command(version, allow_negative_numbers = true)]
struct Args {
    /// paper (100 poses) or quick (5 poses).
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Number of random poses (overrides the preset).
    #[arg(long)]
    poses: Option<usize>,
    /// The papers' URDF with its meshes (default: ../shared/robots/4dof_1st/urdf/4dof_1st.urdf).
    #[arg(long)]
    urdf: Option<PathBuf>,
    /// PyBullet renders (made by scripts/pybullet_render.py from `angles.csv` in the output
    /// folder), compared with our renders of the same angles [paper preset: data/pybullet.npz
    /// when it exists].
    #[arg(long, value_name = "NPZ")]
    pybullet: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "runs/mesh_fidelity")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| {
        let mut cfg = FidelityConfig::preset(&args.preset)?;
        cfg.poses = args.poses.unwrap_or(cfg.poses);
        if let Some(u) = &args.urdf {
            cfg.urdf = u.clone();
        }
        if cfg.poses == 0 {
            return Err(selfmodel::Error::Config(
                "--poses must be at least 1".into(),
            ));
        }
        if let Some(p) = &args.pybullet {
            if !p.is_file() {
                return Err(selfmodel::Error::Config(format!(
                    "{}: no PyBullet renders there; make them with scripts/pybullet_render.py",
                    p.display()
                )));
            }
            cfg.pybullet = Some(p.clone());
        }
        let rows = run(&cfg, &args.out)?;
        for r in &rows {
            println!(
                "{:<28} vs {:<28} shift {:>1} px: mean IoU {:.4} (median {:.4}, min {:.4}) over {} poses",
                r.ours, r.reference, r.row_shift_px, r.mean_iou, r.median_iou, r.min_iou, r.poses
            );
        }
        println!(
            "wrote {}/results.csv, results.md, angles.csv",
            args.out.display()
        );
        Ok(())
    })
}
