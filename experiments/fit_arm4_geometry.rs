//! Regenerate `src/arm4_geometry.json`: boxes fitted to the papers' STL meshes.
//!
//! `cargo run --release --bin fit_arm4_geometry -- --cell 0.001`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::core::atomic_file::write_bytes;
use selfmodel::sim::primitive_fit::fit_boxes;
use selfmodel::sim::urdf_loader::load_urdf;
use selfmodel_lab::cli::{run_main, shared_arm_urdf};

/// Fit the built-in arm4's box geometry to the mesh robot (needs ../shared/robots).
#[derive(Parser)]
#[command(version, allow_negative_numbers = true)]
struct Args {
    /// The papers' URDF with its STL meshes.
    #[arg(long, default_value_os_t = shared_arm_urdf())]
    urdf: PathBuf,
    /// Voxel size in metres (0.0002 to 0.05).
    #[arg(long, default_value_t = 0.001)]
    cell: f64,
    /// Output JSON.
    #[arg(long, default_value = "src/arm4_geometry.json")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| {
        // A finite cell the meshes can be voxelised with (a 0.2 mm cell is already ~10^8 voxels).
        if !(0.0002..=0.05).contains(&args.cell) {
            return Err(selfmodel::Error::Config(format!(
                "--cell {} is not a voxel size: give metres between 0.0002 and 0.05 (default 0.001)",
                args.cell
            )));
        }
        let robot = load_urdf(&args.urdf, selfmodel::sim::arm4::scene_base())?;
        let mut fitted = std::collections::BTreeMap::new();
        for (name, geometry) in robot.chain.links.iter().zip(&robot.geometry) {
            let boxes = fit_boxes(geometry.shapes(), args.cell);
            println!(
                "{name}: {} triangles -> {} boxes",
                geometry.shapes().len(),
                boxes.boxes.len()
            );
            if boxes.boxes.is_empty() && !geometry.shapes().is_empty() {
                return Err(selfmodel::Error::Config(format!(
                    "link {name}: no boxes fitted to its {} triangles at --cell {}; use a smaller cell",
                    geometry.shapes().len(),
                    args.cell
                )));
            }
            fitted.insert(name.clone(), boxes);
        }
        // One box per line: compact, and diffs stay readable.
        let links: Vec<String> = fitted
            .iter()
            .map(|(name, f)| {
                let boxes: Vec<String> = f
                    .boxes
                    .iter()
                    .map(|b| format!("    {}", serde_json::json!(b)))
                    .collect();
                format!(
                    "  {}: {{\"origin\": {}, \"cell\": {}, \"boxes\": [\n{}\n  ]}}",
                    serde_json::json!(name),
                    serde_json::json!(f.origin),
                    f.cell,
                    boxes.join(",\n")
                )
            })
            .collect();
        write_bytes(
            &args.out,
            format!("{{\n{}\n}}\n", links.join(",\n")).as_bytes(),
        )?;
        println!("wrote {}", args.out.display());
        Ok(())
    })
}
