//! Generate a self-modeling dataset: silhouettes, depth maps and joint angles.
//!
//! `cargo run --release --bin dataset` writes the paper's 2,000-sample dataset of the built-in
//! arm to `data/dataset.npz`, with `.stats.json`, `.config.json` and `.preview.png` beside it.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::core::preset::Preset;
use selfmodel::data::dataset::{DatasetConfig, build_and_save, read_angles};
use selfmodel::sim::trajectory::SamplerKind;
use selfmodel_lab::cli::{CameraArgs, RobotArgs, run_main};

/// Render a robot from a fixed camera into a dataset (.npz with images, angles, focal, poses, depth).
#[derive(Parser)]
#[command(version, allow_negative_numbers = true)]
struct Args {
    /// Named preset: paper (2,000 Lorenz samples, 1,600 train) or quick (40, 32 train).
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Number of samples (overrides the preset).
    #[arg(long)]
    samples: Option<usize>,
    /// Training samples, the first ones (overrides the preset; with --angles: 80% by default).
    #[arg(long)]
    train: Option<usize>,
    /// How joint angles are drawn.
    #[arg(long, value_enum)]
    sampler: Option<SamplerKind>,
    /// Step of the grid sampler, degrees.
    #[arg(long)]
    grid_step: Option<f64>,
    /// Seed of the random samplers.
    #[arg(long)]
    seed: Option<u64>,
    /// Render these poses instead of sampling: CSV (one row per pose, degrees) or .npz with `angles`.
    #[arg(long, value_name = "FILE")]
    angles: Option<PathBuf>,
    #[command(flatten)]
    robot: RobotArgs,
    #[command(flatten)]
    camera: CameraArgs,
    /// Reproduce the paper's dataset artefact: the ground plane below the horizon is foreground.
    #[arg(long)]
    ground_artifact: bool,
    /// Output .npz (stats, config and preview are written beside it).
    #[arg(long, default_value = "data/dataset.npz")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    // The revision the run starts from, before it writes anything.
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        selfmodel::core::atomic_file::check_out(
            &args.out,
            selfmodel::core::atomic_file::OutKind::File,
        )?;
        // Never one of the run's inputs: the robot's description, its SRDF, the angles.
        let mut inputs = args.robot.spec()?.files();
        inputs.extend(args.angles.clone());
        let inputs: Vec<&std::path::Path> = inputs.iter().map(|p| p.as_path()).collect();
        selfmodel::core::atomic_file::refuse_overwrite(&args.out, &inputs, None)?;
        let robot = args.robot.load()?;
        args.robot
            .spec()?
            .require_movable(&robot, "a dataset (of more than one pose)")?;
        let mut cfg = DatasetConfig::preset(&args.preset)?;
        let given = match &args.angles {
            Some(path) => Some(read_angles(path, robot.dof())?),
            None => None,
        };
        if let Some(rows) = &given {
            cfg.samples = rows.len();
            cfg.train = rows.len() * 4 / 5;
        }
        cfg.samples = args.samples.unwrap_or(cfg.samples);
        cfg.train = args.train.unwrap_or(cfg.train.min(cfg.samples));
        if let Some(s) = &args.sampler {
            cfg.sampler = s.clone();
        }
        cfg.grid_step_deg = args.grid_step.unwrap_or(cfg.grid_step_deg);
        cfg.seed = args.seed.unwrap_or(cfg.seed);
        // The papers' arm keeps the papers' camera; any other robot is framed automatically.
        args.camera
            .choice()
            .apply(&mut cfg, !args.robot.papers_scene());
        cfg.render.ground_artifact = args.ground_artifact;
        if given.as_ref().is_some_and(|rows| rows.len() != cfg.samples) {
            return Err(selfmodel::Error::Config(
                "--samples cannot be combined with --angles".into(),
            ));
        }

        let (data, report) =
            build_and_save(&robot, &args.robot.label(), &cfg, given, &args.out, true)?;
        selfmodel::report::dataset_preview::dataset_preview(&data, &report, &args.out)?;
        let stats = &report.stats;
        let (render_s, write_s) = (report.render_seconds, report.write_seconds);
        println!(
            "dataset: {} samples ({} train, {} test) of {} ({} joints, {} shapes), {}x{} px, focal {:.4} px",
            data.len(),
            data.n_train,
            data.len() - data.n_train,
            args.robot.label(),
            robot.dof(),
            robot.shape_count(),
            data.width,
            data.height,
            data.focal
        );
        let camera = data.camera();
        let f = |v: [f64; 3]| format!("{:.3},{:.3},{:.3}", v[0], v[1], v[2]);
        let (forward, _, _) = camera.basis();
        println!(
            "camera: eye {} looking along {} ({}; fov {} deg)",
            f(camera.eye),
            f(forward.into()),
            if cfg.framing.is_some() {
                "framed automatically"
            } else {
                "as given"
            },
            cfg.camera.fov_deg
        );
        println!(
            "render: {:.3} s ({:.0} images/s on {} threads); write: {:.3} s",
            render_s,
            data.len() as f64 / render_s,
            rayon::current_num_threads(),
            write_s
        );
        println!(
            "occupancy: mean {:.2}% min {:.2}% max {:.2}%; robot on the image border in {} of {} images, out of view in {}",
            100.0 * stats.occupancy.mean,
            100.0 * stats.occupancy.min,
            100.0 * stats.occupancy.max,
            stats.border_images,
            data.len(),
            stats.empty_images
        );
        let width = stats
            .joints
            .iter()
            .map(|j| j.name.len())
            .max()
            .unwrap_or(5)
            .max(10);
        for (j, joint) in stats.joints.iter().zip(robot.chain.movable_joints()) {
            let unit = if joint.kind.is_rotational() {
                "deg"
            } else {
                "m"
            };
            println!(
                "  {:<width$} {:>8.2} .. {:>7.2} {unit}, mean {:>7.2}, std {:>6.2}",
                j.name, j.degrees.min, j.degrees.max, j.degrees.mean, j.degrees.std
            );
        }
        println!(
            "wrote {} (+ .stats.json, .config.json, .preview.png)",
            args.out.display()
        );
        Ok(())
    })
}
