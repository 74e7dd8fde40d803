//! Regenerate `src/arm4_geometry.json`: boxes fitted to the papers' STL meshes.
//!
//! `cargo run --release --bin fit_arm4_geometry -- --cell 0.001`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::cli::{run_main, shared_arm_urdf};
use selfmodel::core::atomic_file::write_bytes;
use selfmodel::sim::primitive_fit::fit_boxes;
use selfmodel::sim::urdf_loader::load_urdf;

/// Fit the built-in arm4's box geometry to the mesh robot (needs ../shared/robots).
#[derive(Parser)]
#[command(version)]
struct Args {
    /// The papers' URDF with its STL meshes.
    #[arg(long, default_value_os_t = shared_arm_urdf())]
    urdf: PathBuf,
    /// Voxel size in metres.
    #[arg(long, default_value_t = 0.001)]
    cell: f64,
    /// Output JSON.
    #[arg(long, default_value = "src/arm4_geometry.json")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| {
        let robot = load_urdf(&args.urdf, selfmodel::sim::arm4::scene_base())?;
        let mut fitted = std::collections::BTreeMap::new();
        for (name, geometry) in robot.chain.links.iter().zip(&robot.geometry) {
            let boxes = fit_boxes(geometry.shapes(), args.cell);
            println!(
                "{name}: {} triangles -> {} boxes",
                geometry.shapes().len(),
                boxes.boxes.len()
            );
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
