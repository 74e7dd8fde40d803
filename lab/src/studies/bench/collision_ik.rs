//! Collision-free IK, benchmarked: a saved model's answers to targets made from random
//! configurations that keep the margin from the robot itself and a scene (by our spheres,
//! then checked on the exact meshes), with the collision check and without it (what the check
//! costs, and how many answers would have collided), their share exact and collision-free by
//! our spheres and, for the same answers, by Pinocchio and coal on the exact collision meshes
//! at zero margin (`scripts/collision_reference.py`, run as a child process; skipped, with the
//! reason printed, when Python or `pin` is absent); cuRobo's published figures beside them as
//! labelled reference rows, never measured here.

use std::path::{Path, PathBuf};

use selfmodel::core::error::{Error, Result};
use selfmodel::core::timing::{Repeats, median_seconds};
use selfmodel::ik::solve::collision::{CollisionCheck, Spheres};
use selfmodel::ik::solve::learned::LearnedIk;
use selfmodel::ik::solve::levenberg_marquardt::Answering;
use selfmodel::ik::solve::levenberg_marquardt::{Avoid, PoseSolution, PoseTarget};
use selfmodel::ik::solve::solver::IkSolver;
use selfmodel::sim::collision::scene::Scene;
use selfmodel::sim::robot::Robot;
use selfmodel::sim::robots::RobotSpec;

use super::pinocchio::{Reference, agreement_pct, pct, write_reference_inputs};

/// What the benchmark runs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CollisionIkConfig {
    pub preset: String,
    /// Targets, each the tips' poses at a random collision-free configuration.
    pub targets: usize,
    pub seed: u64,
    /// The distance kept from the robot itself and the obstacles (m).
    pub margin: f64,
    /// Timed passes over every target (the median is reported), after one warm-up pass: at
    /// least `repeats`, and as many more as `min_seconds` takes (a pass of the Panda's
    /// thousand targets is a few hundredths of a second: three alone varied by 1.7x between
    /// sittings).
    pub repeats: usize,
    #[serde(default)]
    pub min_seconds: f64,
}

impl CollisionIkConfig {
    pub fn named(preset: &str) -> Result<Self> {
        let (targets, repeats, min_seconds) = match preset {
            "paper" => (1000, 3, 3.0),
            "quick" => (40, 1, 0.0),
            other => {
                return Err(Error::Config(format!(
                    "unknown preset \"{other}\" (paper or quick)"
                )));
            }
        };
        Ok(CollisionIkConfig {
            preset: preset.into(),
            targets,
            seed: 11,
            margin: 0.005,
            repeats,
            min_seconds,
        })
    }
}

/// One row: ours measured, or a published figure (`source` names where it is from).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CollisionIkRow {
    pub robot: String,
    pub solver: String,
    /// What the answers are checked against.
    pub checked: String,
    /// Targets (a published figure's where it says).
    pub targets: Option<usize>,
    /// Answers exact (1 mm, 0.572 degrees) and collision-free by the solver's own check.
    pub exact_free_pct: f64,
    pub exact_free_per_s: f64,
    pub ms_per_target: Option<f64>,
    /// Ours: of those answers, the share Pinocchio finds collision-free on the exact meshes
    /// at zero margin.
    pub exact_mesh_free_pct: Option<f64>,
    /// Ours: of the exact answers, the share our check finds in collision (without the
    /// check, what would have been returned).
    pub exact_but_colliding_pct: Option<f64>,
    /// Ours, our check against the exact meshes at zero margin on as many random
    /// configurations (free or not) as targets: of those the meshes find free, the share it
    /// calls colliding (its conservativeness), and of those the meshes find colliding, the
    /// share it calls free (missed: should be none). Named for the spheres, which decided
    /// alone before the exact check (rows before 302bbeb).
    pub spheres_conservative_pct: Option<f64>,
    pub spheres_missed_pct: Option<f64>,
    pub iterations_mean: Option<f64>,
    pub starts_mean: Option<f64>,
    /// Where it ran: "2 cores of ...", or the publication's GPU.
    pub hardware: String,
    /// "measured" or the publication.
    pub source: String,
    pub preset: String,
    pub git_revision: String,
}

/// A published figure: robot (as our rows name it, `"Franka Panda"` or `"Unitree G1"`),
/// solver, targets, share exact and collision-free, solutions a second, hardware, source.
type Published = (
    &'static str,
    &'static str,
    Option<usize>,
    f64,
    f64,
    &'static str,
    &'static str,
);

/// cuRobo's collision-free IK as published (on a GPU, their own targets and scenes): the
/// reference rows beside ours, matched to ours by robot.
const PUBLISHED: [Published; 3] = [
    (
        "Franka Panda",
        "cuRoboV2 collision-free IK",
        Some(100),
        100.0,
        100.0 / 2.73e-3,
        "NVIDIA GPU",
        "cuRoboV2 (Sundaralingam et al., 2026): 100 poses in 2.73 ms",
    ),
    (
        "Franka Panda",
        "cuRobo 0.7 collision-free IK",
        None,
        99.7,
        9100.0,
        "NVIDIA GPU",
        "cuRobo 0.7 IK benchmark (curobo.org): 99.7% at ~9,100 solutions/s",
    ),
    (
        "Unitree G1",
        "cuRoboV2 collision-free IK",
        Some(100),
        98.4,
        100.0 / 0.527,
        "NVIDIA GPU",
        "cuRoboV2 (Sundaralingam et al., 2026): 100 poses in 527 ms",
    ),
];

/// The robot's name as the rows give it (the published rows' terms), from its description's
/// file name; other robots go by their description's path.
fn published_name(spec: &RobotSpec) -> Option<&'static str> {
    let RobotSpec::Urdf { path, .. } = spec else {
        return None;
    };
    let file = path.file_name()?.to_string_lossy().to_lowercase();
    if file.starts_with("panda") {
        Some("Franka Panda")
    } else if file.starts_with("g1") {
        Some("Unitree G1")
    } else if file.starts_with("ur5") {
        Some("Universal Robots UR5")
    } else {
        None
    }
}

/// Targets (each tip's pose) and the configurations that reach them.
type Drawn = (Vec<Vec<PoseTarget>>, Vec<Vec<f64>>);

/// `n` targets from random configurations within the model's ranges that `check` accepts
/// (at most a thousand draws a target), and those configurations.
fn free_targets(
    robot: &Robot,
    ranges: &[[f64; 2]],
    check: &CollisionCheck,
    n: usize,
    seed: u64,
) -> Result<Drawn> {
    let qs: Vec<Vec<f64>> =
        selfmodel::ik::solve::targets::kept_draws(ranges, seed, n, Some(check)).collect();
    selfmodel::core::interrupt::check(|| {
        "stopped drawing collision-free targets; nothing was kept".into()
    })?;
    if qs.len() < n {
        return Err(Error::Config(format!(
            "only {} of {n} random configurations were collision-free: the scene leaves the robot little room",
            qs.len()
        )));
    }
    let targets = qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    Ok((targets, qs))
}

/// Everything about one solve of every target: the answers (one a target) and the time of
/// one pass (median of the repeats).
struct Solved {
    answers: Vec<PoseSolution>,
    seconds: f64,
}

fn solve_all(
    model: &LearnedIk,
    robot: &Robot,
    targets: &[Vec<PoseTarget>],
    avoid: Option<&dyn Avoid>,
    cfg: &CollisionIkConfig,
) -> Result<Solved> {
    let lm = model.saved.config.lm.clone();
    let how = Answering {
        lm: &lm,
        stop: &selfmodel::core::interrupt::requested,
        avoid,
    };
    let solve = || model.solve(&robot.chain, targets, 1, &how);
    let answers: Vec<PoseSolution> = solve()?.into_iter().flatten().collect();
    let repeats = Repeats {
        warmup: 0,
        min_repeats: cfg.repeats,
        min_seconds: cfg.min_seconds,
    };
    let seconds = median_seconds(repeats, || {
        std::hint::black_box(solve().ok());
    });
    selfmodel::core::interrupt::check(|| "stopped timing the answers; nothing was kept".into())?;
    Ok(Solved { answers, seconds })
}

/// What the answers are checked against, as the rows say it.
fn checked_label(obstacles: usize, margin: f64) -> String {
    let mm = 1e3 * margin;
    match obstacles {
        0 => format!("itself, {mm} mm margin"),
        n => format!("itself and {n} obstacles, {mm} mm margin"),
    }
}

/// The published figures for `robot` (as the rows name it), labelled.
fn published_rows(robot: &str, preset: &str, revision: &str) -> Vec<CollisionIkRow> {
    (PUBLISHED.iter())
        .filter(|p| p.0 == robot)
        .map(
            |&(robot, solver, targets, exact, per_s, hardware, source)| CollisionIkRow {
                robot: robot.into(),
                solver: format!("{solver} (published)"),
                checked: "itself and the benchmark's scene".into(),
                targets,
                exact_free_pct: exact,
                exact_free_per_s: per_s,
                ms_per_target: None,
                exact_mesh_free_pct: None,
                exact_but_colliding_pct: None,
                spheres_conservative_pct: None,
                spheres_missed_pct: None,
                iterations_mean: None,
                starts_mean: None,
                hardware: hardware.into(),
                source: source.into(),
                preset: preset.into(),
                git_revision: revision.into(),
            },
        )
        .collect()
}

/// Run the benchmark on the model `ik train` saved in `model_dir`, against `scene` (and
/// the robot itself), with Pinocchio's check through `python` where given; rows to
/// `out/results.csv`.
pub fn run(
    model_dir: &Path,
    scene: Option<&Path>,
    cfg: &CollisionIkConfig,
    python: Option<&Path>,
    out: &Path,
) -> Result<Vec<CollisionIkRow>> {
    use selfmodel::core::atomic_file::{OutKind, check_out, refuse_overwrite, refuse_writing_over};
    check_out(out, OutKind::Folder)?;
    let device = selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu)?;
    let (model, robot) = LearnedIk::load_with_robot(model_dir, &device)?;
    let spec = &model.saved.robot;
    if model.position_only() {
        return Err(Error::Config(format!(
            "{}: a position-only model (ik train --position-only) answers positions, and this benchmark asks for full poses: train one without --position-only",
            model_dir.display()
        )));
    }
    let mut inputs = spec.files();
    if let Some(scene) = scene {
        inputs.extend(Scene::files(scene)?);
    }
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    refuse_overwrite(out, &inputs, Some(model_dir))?;
    refuse_writing_over(out, WRITTEN, &inputs)?;
    selfmodel::core::atomic_file::nothing_left_on_failure(out, WRITTEN, || {
        measure(&model, &robot, model_dir, scene, cfg, python, out)
    })
}

/// What [`run`] writes into its folder.
const WRITTEN: &[&str] = &[
    "config.json",
    "results.csv",
    "results.md",
    "pairs.json",
    "target_joints.csv",
    "answer_joints.csv",
    "random_joints.csv",
    "target_joints_exact_meshes.csv",
    "answer_joints_exact_meshes.csv",
    "random_joints_exact_meshes.csv",
];

/// [`run`] once its output is checked.
#[allow(clippy::too_many_arguments)]
fn measure(
    model: &LearnedIk,
    robot: &Robot,
    model_dir: &Path,
    scene: Option<&Path>,
    cfg: &CollisionIkConfig,
    python: Option<&Path>,
    out: &Path,
) -> Result<Vec<CollisionIkRow>> {
    let robot = robot.clone();
    let spec = &model.saved.robot;
    let obstacles = scene.map(Scene::read).transpose()?;
    let n_obstacles = obstacles.as_ref().map_or(0, |s| s.obstacles.len());
    let kept = Spheres::KeptIn(model_dir, Default::default());
    let check = CollisionCheck::with_spheres(spec, kept, None, obstacles, true, cfg.margin)?;
    let (targets, qs) = free_targets(&robot, &model.saved.ranges, &check, cfg.targets, cfg.seed)?;
    let lm = &model.saved.config.lm;
    let checked = solve_all(model, &robot, &targets, Some(&check), cfg)?;
    let unchecked = solve_all(model, &robot, &targets, None, cfg)?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    selfmodel::core::atomic_file::write_json(&out.join("config.json"), cfg)?;
    let exact_free: Vec<&PoseSolution> = checked.answers.iter().filter(|a| a.exact(lm)).collect();
    let exact_unchecked: Vec<&PoseSolution> =
        unchecked.answers.iter().filter(|a| a.exact(lm)).collect();
    let colliding = exact_unchecked
        .iter()
        .filter(|a| !check.valid(&a.joints))
        .count();

    // Pinocchio on the exact meshes: the targets' configurations, our answers, and random
    // configurations colliding or not (the spheres' agreement with the meshes).
    let random: Vec<Vec<f64>> =
        selfmodel::sim::trajectory::babbling_rows(&model.saved.ranges, cfg.seed ^ 0xA9)
            .take(cfg.targets)
            .collect();
    let answers: Vec<&[f64]> = exact_free.iter().map(|a| a.joints.as_slice()).collect();
    let pairs_file = write_reference_inputs(
        out,
        &check,
        &model.saved.joint_names,
        &[
            ("target_joints.csv", qs.iter().map(Vec::as_slice).collect()),
            ("answer_joints.csv", answers),
            (
                "random_joints.csv",
                random.iter().map(Vec::as_slice).collect(),
            ),
        ],
    )?;
    let spheres_collide: Vec<bool> = random
        .iter()
        .map(|q| {
            let frames = check.robot.chain.link_frames(q);
            check.model.collides(&frames, check.scene.as_ref(), 0.0)
        })
        .collect();
    let (mut mesh_free_answers, mut mesh_free_targets, mut agreement) = (None, None, None);
    if let (Some(python), RobotSpec::Urdf { path, .. }) = (python, spec) {
        let reference = Reference {
            python,
            urdf: path,
            pairs: pairs_file,
            scene,
        };
        let on_meshes = |file: &str, out_file: &str| {
            reference
                .collides(&out.join(file), &out.join(out_file))
                .map(|f| f.map(|f| pct(f.iter().filter(|c| !**c).count(), f.len())))
        };
        mesh_free_targets = on_meshes("target_joints.csv", "target_joints_exact_meshes.csv")?;
        mesh_free_answers = on_meshes("answer_joints.csv", "answer_joints_exact_meshes.csv")?;
        let meshes = reference.collides(
            &out.join("random_joints.csv"),
            &out.join("random_joints_exact_meshes.csv"),
        )?;
        agreement = meshes.map(|meshes| agreement_pct(&meshes, &spheres_collide));
    } else {
        eprintln!(
            "bench_collision_ik: Pinocchio's check skipped (no --python, or a built-in robot)"
        );
    }

    let n = targets.len();
    let cpu = selfmodel::eval::compute_peak::machine_label(false);
    let revision = selfmodel::core::provenance::git_revision();
    let what = checked_label(n_obstacles, cfg.margin);
    let robot_name = published_name(spec).map_or_else(|| spec.label(), String::from);
    let mean = |a: &[PoseSolution], f: fn(&PoseSolution) -> usize| {
        a.iter().map(|s| f(s) as f64).sum::<f64>() / a.len().max(1) as f64
    };
    let ours = |solver: &str,
                s: &Solved,
                exact: usize,
                extra: (Option<f64>, Option<f64>),
                agree: Option<(f64, f64)>| {
        CollisionIkRow {
            robot: robot_name.clone(),
            solver: solver.into(),
            checked: what.clone(),
            targets: Some(n),
            exact_free_pct: pct(exact, n),
            exact_free_per_s: exact as f64 / s.seconds,
            ms_per_target: Some(1e3 * s.seconds / n.max(1) as f64),
            exact_mesh_free_pct: extra.0,
            exact_but_colliding_pct: extra.1,
            spheres_conservative_pct: agree.map(|a| a.0),
            spheres_missed_pct: agree.map(|a| a.1),
            iterations_mean: Some(mean(&s.answers, |a| a.iterations)),
            starts_mean: Some(mean(&s.answers, |a| a.starts)),
            hardware: cpu.clone(),
            source: "measured".into(),
            preset: cfg.preset.clone(),
            git_revision: revision.clone(),
        }
    };
    let mut rows = vec![
        ours(
            "selfmodel flow + LM (contacts pushed apart)",
            &checked,
            exact_free.len(),
            (mesh_free_answers, Some(0.0)),
            agreement,
        ),
        ours(
            "selfmodel flow + LM (no collision check)",
            &unchecked,
            exact_unchecked.len() - colliding,
            (None, Some(pct(colliding, exact_unchecked.len()))),
            None,
        ),
    ];
    rows.extend(published_rows(&robot_name, &cfg.preset, &revision));
    let targets_note = mesh_free_targets.map_or(String::new(), |p| {
        format!(" Pinocchio finds {p:.1}% of the targets' configurations collision-free on the exact meshes.")
    });
    selfmodel::report::table::write_table(
        &out.join("results.csv"),
        &rows,
        "Collision-free IK",
        &format!(
            "{n} targets, each the tips' poses at a random configuration our spheres find collision-free; one answer a target; the median of at least {} passes over {} s after a warm-up pass, every thread of the machine. Exact: within 1 mm and 0.572 degrees and no checked pair of spheres, nor a sphere and an obstacle, closer than the margin.{targets_note} Published rows: cuRobo's own targets, scenes and GPU, not measured here.",
            cfg.repeats, cfg.min_seconds
        ),
    )?;
    Ok(rows)
}
