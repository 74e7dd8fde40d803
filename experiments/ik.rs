//! Learned full-pose inverse kinematics as a tool: `ik train` learns a robot's model and saves
//! it, `ik solve` answers targets of your own from a saved model (exact within 1 mm and
//! 0.572 degrees, every joint inside its limits).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use selfmodel::core::preset::Preset;
use selfmodel::ik::solve::learned::{
    LearnedIk, LearnedIkConfig, SolveStats, joint_columns, read_targets, train,
};
use selfmodel::ik::solve::levenberg_marquardt::PoseTarget;
use selfmodel::ik::solve::solver::IkSolver;
use selfmodel_lab::cli::{RobotArgs, run_main};

#[derive(Parser)]
#[command(
    version,
    about = "Learned full-pose inverse kinematics: train a model of a robot, then solve targets of your own with it"
)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Learn a robot's inverse kinematics (a conditional flow on its poses) and save it;
    /// with --tips A,B, of several tips at once (one pose each in a target).
    Train {
        #[command(flatten)]
        robot: RobotArgs,
        /// paper (200,000 poses, trained to a validation plateau) or quick (seconds).
        #[arg(long, default_value = "paper")]
        preset: String,
        /// Condition on the position only (targets x,y,z).
        #[arg(long)]
        position_only: bool,
        /// Train on collision-free joint samples only (with --scene, --self-collision, --srdf
        /// without --group, --spheres): the flow then proposes answers that keep clear.
        #[command(flatten)]
        collisions: CollisionArgs,
        /// Where the model goes (a folder: model.bpk, model.json).
        #[arg(long)]
        out: PathBuf,
    },
    /// Write random reachable targets of a model's robot: the tip's pose at joints drawn
    /// uniformly within the limits (to try `ik solve` on, or to measure it).
    Targets {
        /// A folder `ik train` wrote.
        #[arg(long)]
        model: PathBuf,
        #[arg(long, default_value_t = 1000)]
        n: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Only poses whose joints are collision-free (with --scene, --self-collision).
        #[command(flatten)]
        collisions: CollisionArgs,
        #[command(flatten)]
        srdf: SrdfArg,
        /// CSV: x,y,z,qw,qx,qy,qz, then the joints that reach it (q1..qN).
        #[arg(long)]
        out: PathBuf,
    },
    /// Answer targets from a saved model: one row per answer.
    Solve {
        /// A folder `ik train` wrote.
        #[arg(long)]
        model: PathBuf,
        /// CSV with a header: x,y,z,qw,qx,qy,qz (metres; x,y,z for a position-only model; a
        /// model of several tips: each tip's columns prefixed, A.x,...,A.qz,B.x,...; other
        /// columns ignored).
        #[arg(long)]
        targets: PathBuf,
        /// Answers per target (k > 1: the flow's k samples, each refined: the family).
        #[arg(long, default_value_t = 1)]
        k: usize,
        /// Iterate each answer until every tip is within MM millimetres and DEG degrees (the
        /// convergence tolerance; an answer is exact within 1 mm and 0.572 degrees, the
        /// success threshold, whatever this is).
        #[arg(
            long,
            value_name = "MM,DEG",
            default_value = "0.0001,0.0001",
            allow_hyphen_values = true
        )]
        tolerance: String,
        #[command(flatten)]
        collisions: CollisionArgs,
        #[command(flatten)]
        srdf: SrdfArg,
        /// Where the answers go (CSV: target,solution, one column per joint named after it,
        /// pos_err_mm,rot_err_deg,exact; beside it OUT.json: how they were made).
        #[arg(long)]
        out: PathBuf,
    },
}

/// What answers (and targets) are checked against.
#[derive(clap::Args)]
struct CollisionArgs {
    /// Obstacles (cuRobo's world-configuration YAML: cuboid, sphere, capsule, cylinder,
    /// mesh): an answer is exact only if it keeps --margin from them and from itself.
    #[arg(long, value_name = "FILE")]
    scene: Option<PathBuf>,
    /// Check each answer against the robot itself (on with --scene, --srdf and --spheres).
    #[arg(long)]
    self_collision: bool,
    /// The distance an answer keeps from obstacles and from itself (metres, 0 to 1) [default:
    /// 0.005, with a collision option].
    #[arg(long, value_name = "M", allow_hyphen_values = true)]
    margin: Option<f64>,
    /// Your own collision spheres (cuRobo's robot YAML or spheres file: a collision_spheres
    /// block) instead of spheres fitted to the description's collision meshes.
    #[arg(long, value_name = "FILE")]
    spheres: Option<PathBuf>,
    /// On what a collision is decided: exact (the spheres as the broad phase, the collision
    /// meshes and primitives themselves deciding what they cannot rule out) or spheres (the
    /// spheres alone: faster, and they bulge past flat faces).
    #[arg(long, value_enum, default_value_t = selfmodel::sim::collision::model::CollisionMode::Exact)]
    collision: selfmodel::sim::collision::model::CollisionMode,
    #[command(flatten)]
    fit: selfmodel_lab::cli::SphereFitArgs,
}

/// `--srdf` where it names collisions only (`ik targets`, `ik solve`; `ik train` shares the
/// one `--group` reads).
#[derive(clap::Args)]
struct SrdfArg {
    /// The SRDF whose <disable_collisions> say which links may touch [default: the one
    /// beside the URDF; without one, the pairs MoveIt's setup assistant would disable].
    #[arg(long, value_name = "FILE")]
    srdf: Option<PathBuf>,
}

/// The margin kept where `--margin` is not given (m).
const DEFAULT_MARGIN_M: f64 = 0.005;

/// A command's collision options with `srdf`; `--margin` without a collision option is
/// refused (it would change nothing; the check refuses a margin out of range).
fn collision_options(
    args: CollisionArgs,
    srdf: Option<PathBuf>,
) -> selfmodel::Result<selfmodel::ik::solve::collision::CollisionOptions> {
    let options = selfmodel::ik::solve::collision::CollisionOptions {
        scene: args.scene,
        self_collision: args.self_collision,
        srdf,
        spheres: args.spheres,
        margin: args.margin.unwrap_or(DEFAULT_MARGIN_M),
        mode: args.collision,
        fit: args.fit.fit()?,
    };
    let fitting = args.fit.spheres_per_link.is_some() || args.fit.protrusion_mm.is_some();
    if fitting && options.spheres.is_some() {
        return Err(selfmodel::Error::Config(
            "--spheres-per-link and --protrusion-mm say how spheres are fitted, and --spheres gives your own: give one".into(),
        ));
    }
    if fitting && !options.any() {
        return Err(selfmodel::Error::Config(
            "--spheres-per-link and --protrusion-mm fit the collision spheres, so they need --scene, --self-collision or --srdf".into(),
        ));
    }
    if let Some(m) = args.margin.filter(|_| !options.any()) {
        return Err(selfmodel::Error::Config(format!(
            "--margin {}: it is the distance kept from obstacles and from the robot itself, so it needs --scene, --self-collision, --srdf or --spheres",
            selfmodel::core::error::short_number(m)
        )));
    }
    Ok(options)
}

/// The most answers per target `ik solve` gives, and targets `ik targets` writes.
const MAX_K: usize = 1000;
const MAX_TARGETS: usize = 10_000_000;

/// What `ik targets` and `ik solve` start with: `out` checked (a file it can write, neither an
/// input, nor inside the model's folder, nor the robot description it names), then the model
/// in `dir` and the robot it names.
fn answering(
    dir: &std::path::Path,
    outs: &[&std::path::Path],
    inputs: &[PathBuf],
    device: &burn::tensor::Device,
) -> selfmodel::Result<(LearnedIk, selfmodel::Robot)> {
    use selfmodel::core::atomic_file::{OutKind, check_out, refuse_overwrite};
    let model_folder = Some(dir).filter(|d| d.join("model.json").is_file());
    let inputs: Vec<&std::path::Path> = inputs.iter().map(PathBuf::as_path).collect();
    for out in outs {
        check_out(out, OutKind::File)?;
        refuse_overwrite(out, &inputs, model_folder)?;
    }
    let (model, robot) = LearnedIk::load_with_robot(dir, device)?;
    // Nor the robot description the model names.
    let robot_files = model.saved.robot.files();
    let robot_files: Vec<&std::path::Path> = robot_files.iter().map(|p| p.as_path()).collect();
    for out in outs {
        refuse_overwrite(out, &robot_files, None)?;
    }
    Ok((model, robot))
}

fn main() -> ExitCode {
    let args = Args::parse();
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        let device = selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu)?;
        match args.command {
            Command::Train {
                mut robot,
                preset,
                position_only,
                collisions,
                out,
            } => {
                // One --srdf: --group's file where a group is named (the collision check then
                // reads it too), else the collision check's alone.
                let srdf = match robot.parts.group.group {
                    Some(_) => None,
                    None => robot.parts.group.srdf.take(),
                };
                let collisions = collision_options(collisions, srdf)?;
                let mut cfg = LearnedIkConfig::preset(&preset)?;
                cfg.position_only = position_only;
                cfg.collisions = collisions.any().then(|| collisions.clone());
                selfmodel::core::atomic_file::check_out(
                    &out,
                    selfmodel::core::atomic_file::OutKind::Folder,
                )?;
                let spec = robot.spec()?;
                let mut inputs = spec.files();
                if collisions.any() {
                    inputs.extend(collisions.inputs()?);
                }
                let inputs: Vec<&std::path::Path> = inputs.iter().map(PathBuf::as_path).collect();
                selfmodel::core::atomic_file::refuse_writing_over(
                    &out,
                    selfmodel::ik::solve::learned::WRITTEN,
                    &inputs,
                )?;
                let loaded = spec.load_kinematics()?;
                let start = std::time::Instant::now();
                let model = train(&spec, &loaded, &cfg, &out, &device)?;
                let tips = if model.tips().is_empty() {
                    String::new()
                } else {
                    format!(", the poses of {}", model.tips().join(" and "))
                };
                let free = if cfg.collisions.is_some() {
                    " collision-free"
                } else {
                    ""
                };
                println!(
                    "ik train ({preset} preset): {} joints ({}){tips}, {}{free} poses, {:.0} s; wrote {}/model.json (+ model.bpk)",
                    model.dof(),
                    model.saved.joint_names.join(", "),
                    cfg.data.train,
                    start.elapsed().as_secs_f64(),
                    out.display()
                );
                Ok(())
            }
            Command::Targets {
                model,
                n,
                seed,
                collisions,
                srdf,
                out,
            } => {
                let collisions = collision_options(collisions, srdf.srdf)?;
                if !(1..=MAX_TARGETS).contains(&n) {
                    return Err(selfmodel::Error::Config(format!(
                        "--n must be 1 to {MAX_TARGETS} targets"
                    )));
                }
                let inputs = collisions.inputs()?;
                let model_dir = model;
                let (model, robot) = answering(&model_dir, &[&out], &inputs, &device)?;
                let check = collisions.check(&model.saved.robot, Some(&model_dir))?;
                // Streamed: each row's pose is made as it is written (ten million rows of a
                // humanoid would not fit in memory as text and targets at once).
                // Ctrl-C ends the rows; the file is then dropped whole.
                // With a collision check, draws that collide are skipped: at most a thousand
                // draws a row (a scene that leaves no room ends with a message).
                let written = std::cell::Cell::new(0usize);
                let rows = selfmodel::ik::solve::targets::kept_draws(
                    &model.saved.ranges,
                    seed,
                    n,
                    check.as_ref(),
                )
                .inspect(|_| written.set(written.get() + 1))
                .map(|q| (PoseTarget::of(&robot.chain, &q), q));
                selfmodel::core::atomic_file::write_atomic(&out, |w| {
                    selfmodel::ik::solve::targets::write_targets_csv(
                        w,
                        rows,
                        &model.saved.joint_names,
                        model.tips(),
                    )
                    .map_err(|e| selfmodel::Error::io(&out, e))?;
                    selfmodel::core::interrupt::check(|| {
                        format!("stopped writing {}; nothing was written", out.display())
                    })?;
                    if written.get() < n {
                        return Err(selfmodel::Error::Config(format!(
                            "only {} of {n} draws ({} tried) were collision-free: the scene leaves the robot little room; nothing was written",
                            written.get(),
                            n.saturating_mul(selfmodel::ik::solve::targets::MAX_DRAWS_PER_KEPT)
                        )));
                    }
                    Ok(())
                })?;
                let free = if check.is_some() {
                    " collision-free"
                } else {
                    ""
                };
                println!(
                    "ik targets: {n}{free} reachable poses of {}; wrote {}",
                    model.saved.robot.label(),
                    out.display()
                );
                Ok(())
            }
            Command::Solve {
                model: model_dir,
                targets: targets_file,
                k,
                tolerance,
                collisions,
                srdf,
                out,
            } => {
                let collisions = collision_options(collisions, srdf.srdf)?;
                if !(1..=MAX_K).contains(&k) {
                    return Err(selfmodel::Error::Config(format!(
                        "--k must be 1 to {MAX_K} (answers per target)"
                    )));
                }
                let provenance = PathBuf::from(format!("{}.json", out.display()));
                let mut inputs = vec![targets_file.clone()];
                inputs.extend(collisions.inputs()?);
                let (model, robot) = answering(&model_dir, &[&out, &provenance], &inputs, &device)?;
                let check = collisions.check(&model.saved.robot, Some(&model_dir))?;
                let checking = check.is_some();
                let cfg = model
                    .saved
                    .config
                    .lm
                    .clone()
                    .converging_to_text(&tolerance)
                    .map_err(|e| selfmodel::Error::Config(format!("--tolerance: {e}")))?;
                let targets = read_targets(&targets_file, model.position_only(), model.tips())?;
                let start = std::time::Instant::now();
                let stop = selfmodel::core::interrupt::requested;
                let how = selfmodel::ik::solve::levenberg_marquardt::Answering {
                    lm: &cfg,
                    stop: &stop,
                    avoid: check
                        .as_ref()
                        .map(|c| c as &dyn selfmodel::ik::solve::levenberg_marquardt::Avoid),
                };
                let answers = model.solve(&robot.chain, &targets, k, &how)?;
                let seconds = start.elapsed().as_secs_f64();
                let mut header = String::from("target,solution");
                let taken = ["target", "solution", "pos_err_mm", "rot_err_deg", "exact"];
                for c in joint_columns(&model.saved.joint_names, &taken) {
                    header += &format!(",{c}");
                }
                // Streamed, a row an answer.
                selfmodel::core::atomic_file::write_atomic(&out, |w| {
                    use std::io::Write;
                    let io = |e| selfmodel::Error::io(&out, e);
                    writeln!(w, "{header},pos_err_mm,rot_err_deg,exact").map_err(io)?;
                    for (t, sols) in answers.iter().enumerate() {
                        for (s, a) in sols.iter().enumerate() {
                            write!(w, "{t},{s}").map_err(io)?;
                            for q in &a.joints {
                                write!(w, ",{q}").map_err(io)?;
                            }
                            let (p, r) = (1000.0 * a.position_error_m, a.rotation_error_rad);
                            writeln!(w, ",{p},{},{}", r.to_degrees(), a.exact(&cfg)).map_err(io)?;
                        }
                    }
                    Ok(())
                })?;
                let stats = SolveStats::of(&answers, &cfg, &model.saved.ranges);
                let threads = rayon::current_num_threads();
                selfmodel::core::atomic_file::write_json(
                    &provenance,
                    &serde_json::json!({
                        "model": model_dir,
                        "targets": targets_file,
                        "k": k,
                        "exact_within_mm": 1e3 * cfg.tolerance_m,
                        "exact_within_deg": cfg.tolerance_rad.to_degrees(),
                        "tolerance_mm": 1e3 * cfg.convergence_m,
                        "tolerance_deg": cfg.convergence_rad.to_degrees(),
                        "solver": &cfg,
                        "scene": collisions.scene,
                        "collisions_checked": checking,
                        "margin_m": checking.then_some(collisions.margin),
                        "stats": stats,
                        "seconds": seconds,
                        "threads": threads,
                        "device": "cpu",
                        "revision": selfmodel::core::provenance::git_revision(),
                    }),
                )?;
                let exact = if checking {
                    "exactly and collision-free"
                } else {
                    "exactly"
                };
                println!(
                    "ik solve: {} targets, {} solved {exact} ({:.2}%), {} exact answers ({:.1} distinct per target), {}, {:.1} iterations and {:.2} starts an answer, {:.0} exact solutions/s on {threads} threads; wrote {}",
                    stats.targets,
                    stats.exact_targets,
                    stats.exact_pct(),
                    stats.exact_answers,
                    stats.distinct_mean,
                    stats.precision(),
                    stats.iterations_mean,
                    stats.starts_mean,
                    stats.exact_answers as f64 / seconds,
                    out.display()
                );
                Ok(())
            }
        }
    })
}
