//! Collision-free IK, benchmarked: a saved model's answers to targets made from random
//! configurations that keep the margin from the robot itself and a scene by the exact check
//! (the links' own meshes and primitives, as Pinocchio and coal decide, the spheres only their
//! broad phase), answered three ways: with the exact check, with the spheres alone deciding,
//! and without a check (what the check costs, and how many answers would have collided). For
//! each, the share exact and collision-free by its own check and, for the same answers, by
//! Pinocchio and coal on the exact collision meshes at zero margin
//! (`scripts/collision_reference.py`, run as a child process; skipped, with the reason
//! printed, when Python or `pin` is absent), on the pairs checked and on every other pair of
//! links no joint joins (a pair left unchecked that the answers hit). cuRobo's published
//! figures beside them as labelled reference rows, never measured here.

use std::path::{Path, PathBuf};

use selfmodel::core::error::{Error, Result};
use selfmodel::core::timing::{Repeats, median_seconds};
use selfmodel::ik::solve::collision::{CollisionCheck, Spheres};
use selfmodel::ik::solve::learned::LearnedIk;
use selfmodel::ik::solve::levenberg_marquardt::Answering;
use selfmodel::ik::solve::levenberg_marquardt::{Avoid, PoseSolution, PoseTarget};
use selfmodel::ik::solve::solver::IkSolver;
use selfmodel::sim::collision::model::CollisionMode;
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
    /// What decides a collision: `exact` (the links' meshes and primitives, spheres their
    /// broad phase), `spheres` (the spheres alone) or `none` (no check); a published row's
    /// as its source says.
    #[serde(default)]
    pub collision: String,
    /// What the answers are checked against.
    pub checked: String,
    /// Targets (a published figure's where it says).
    pub targets: Option<usize>,
    /// Answers exact (1 mm, 0.572 degrees) and collision-free by the solver's own check.
    pub exact_free_pct: f64,
    pub exact_free_per_s: f64,
    pub ms_per_target: Option<f64>,
    /// Ours: of those answers, the share Pinocchio finds collision-free on the exact meshes
    /// at zero margin, on the pairs checked (and the scene).
    pub exact_mesh_free_pct: Option<f64>,
    /// Ours: of those answers, how many Pinocchio finds colliding on the exact meshes in a
    /// pair of links the check leaves out although they may collide (neither adjacent nor
    /// touching at the home pose: [`unchecked_pairs`]).
    #[serde(default)]
    pub colliding_in_unchecked_pairs: Option<usize>,
    /// Ours: of the exact answers, the share our check finds in collision (without the
    /// check, what would have been returned).
    pub exact_but_colliding_pct: Option<f64>,
    /// Ours, the row's check against the exact meshes at zero margin on as many random
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
                collision: "spheres".into(),
                checked: "itself and the benchmark's scene".into(),
                targets,
                exact_free_pct: exact,
                exact_free_per_s: per_s,
                ms_per_target: None,
                exact_mesh_free_pct: None,
                colliding_in_unchecked_pairs: None,
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
    "unchecked_pairs.json",
    "target_joints.csv",
    "target_joints_exact_meshes.csv",
    "random_joints.csv",
    "random_joints_exact_meshes.csv",
    "answer_joints_exact.csv",
    "answer_joints_exact_exact_meshes.csv",
    "answer_joints_exact_unchecked_pairs.csv",
    "answer_joints_spheres.csv",
    "answer_joints_spheres_exact_meshes.csv",
    "answer_joints_spheres_unchecked_pairs.csv",
];

/// The rows of `v` as slices.
fn rows_of(v: &[Vec<f64>]) -> Vec<&[f64]> {
    v.iter().map(Vec::as_slice).collect()
}

/// What Pinocchio says of one row's answers and check, where it ran.
#[derive(Clone, Copy, Default)]
struct Verdict {
    /// Of the answers, the share free on the exact meshes on the pairs checked (%).
    mesh_free_pct: Option<f64>,
    /// Of the answers, how many collide on the exact meshes in a pair left unchecked.
    in_unchecked_pairs: Option<usize>,
    /// The check against the meshes on random configurations: false alarms and misses (%).
    agreement: Option<(f64, f64)>,
}

/// The pairs of `check`'s links with collision geometry that it does not check although
/// they may collide: not adjacent as MoveIt's setup assistant counts adjacency (a joint's
/// parent and child, a link without geometry between them passed through: the Panda's
/// `panda_link7` and `panda_hand`), and apart at the home pose on their exact shapes (a pair
/// touching there is allowed by design, as MoveIt allows it), by name; and how many pairs
/// touch at home.
fn unchecked_pairs(check: &CollisionCheck) -> (Vec<[String; 2]>, usize) {
    let chain = &check.robot.chain;
    let has = |l: usize| !check.robot.geometry[l].is_empty();
    let mut parent = vec![None; chain.links.len()];
    for j in &chain.joints {
        parent[j.child] = Some(j.parent);
    }
    // The nearest link above `l` that has geometry.
    let above = |l: usize| {
        let mut p = parent[l];
        while let Some(x) = p.filter(|&x| !has(x)) {
            p = parent[x];
        }
        p
    };
    let adjacent = |a: usize, b: usize| above(a) == Some(b) || above(b) == Some(a);
    let home: Vec<f64> = (chain.joint_ranges().iter())
        .map(|r| 0f64.clamp(r[0], r[1]))
        .collect();
    let frames = chain.link_frames(&home);
    let x = selfmodel::sim::collision::exact_links(&check.robot);
    let (mut pairs, mut at_home) = (Vec::new(), 0);
    for a in (0..chain.links.len()).filter(|&l| has(l)) {
        for b in (a + 1..chain.links.len()).filter(|&l| has(l)) {
            if check.model.pairs.contains(&(a, b)) || adjacent(a, b) {
                continue;
            }
            if x[a].closer_than(&frames[a], &x[b], &frames[b], 0.0) {
                at_home += 1;
                continue;
            }
            pairs.push([chain.links[a].clone(), chain.links[b].clone()]);
        }
    }
    (pairs, at_home)
}

/// What Pinocchio says of the answers of the two checks (exact, spheres), where it ran: the
/// targets' share free on the meshes, each check's [`Verdict`], and how many pairs may
/// collide unchecked and how many touch at home.
struct Judged {
    verdicts: [Verdict; 2],
    mesh_free_targets: Option<f64>,
    unchecked_pairs: usize,
    touching_at_home: usize,
}

/// Pinocchio on the exact meshes (`python` and the URDF, where given): the targets'
/// configurations, each check's answers (on the pairs checked, and on those left unchecked
/// that may collide), and random configurations colliding or not (each check's agreement
/// with the meshes). `sets`: the targets', the random, and the two checks' answers' joints,
/// written to `out` for the script.
fn on_the_meshes(
    out: &Path,
    checks: [&CollisionCheck; 2],
    joint_names: &[String],
    sets: [&[Vec<f64>]; 4],
    python: Option<(&Path, &Path)>,
    scene: Option<&Path>,
) -> Result<Judged> {
    let [targets, random, exact_answers, sphere_answers] = sets;
    let pairs_file = write_reference_inputs(
        out,
        checks[0],
        joint_names,
        &[
            ("target_joints.csv", rows_of(targets)),
            ("random_joints.csv", rows_of(random)),
            ("answer_joints_exact.csv", rows_of(exact_answers)),
            ("answer_joints_spheres.csv", rows_of(sphere_answers)),
        ],
    )?;
    let unchecked_file = out.join("unchecked_pairs.json");
    let (unchecked_list, touching_at_home) = unchecked_pairs(checks[0]);
    selfmodel::core::atomic_file::write_json(&unchecked_file, &unchecked_list)?;
    let mut judged = Judged {
        verdicts: [Verdict::default(); 2],
        mesh_free_targets: None,
        unchecked_pairs: unchecked_list.len(),
        touching_at_home,
    };
    let Some((python, urdf)) = python else {
        eprintln!(
            "bench_collision_ik: Pinocchio's check skipped (no --python, or a built-in robot)"
        );
        return Ok(judged);
    };
    let reference = Reference {
        python,
        urdf,
        pairs: pairs_file,
        scene,
    };
    let every_other = Reference {
        python,
        urdf,
        pairs: unchecked_file,
        scene: None,
    };
    let ours_at_zero = |check: &CollisionCheck| -> Vec<bool> {
        (random.iter())
            .map(|q| {
                let frames = check.robot.chain.link_frames(q);
                check.model.collides(&frames, check.scene.as_ref(), 0.0)
            })
            .collect()
    };
    // No answers: no share of them.
    let free_pct =
        |f: Vec<bool>| (!f.is_empty()).then(|| pct(f.iter().filter(|c| !**c).count(), f.len()));
    let on = |r: &Reference, stem: &str, suffix: &str| {
        let (input, output) = (format!("{stem}.csv"), format!("{stem}_{suffix}.csv"));
        r.collides(&out.join(input), &out.join(output))
    };
    judged.mesh_free_targets = on(&reference, "target_joints", "exact_meshes")?.and_then(free_pct);
    let meshes = on(&reference, "random_joints", "exact_meshes")?;
    for (v, (stem, check)) in judged.verdicts.iter_mut().zip([
        ("answer_joints_exact", checks[0]),
        ("answer_joints_spheres", checks[1]),
    ]) {
        v.mesh_free_pct = on(&reference, stem, "exact_meshes")?.and_then(free_pct);
        v.in_unchecked_pairs =
            on(&every_other, stem, "unchecked_pairs")?.map(|f| f.iter().filter(|c| **c).count());
        v.agreement = (meshes.as_ref()).map(|m| agreement_pct(m, &ours_at_zero(check)));
    }
    Ok(judged)
}

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
    let exact = CollisionCheck::with_spheres(spec, kept, None, obstacles, true, cfg.margin)?
        .deciding(CollisionMode::Exact);
    let spheres = exact.clone().deciding(CollisionMode::Spheres);
    let (targets, qs) = free_targets(&robot, &model.saved.ranges, &exact, cfg.targets, cfg.seed)?;
    let lm = &model.saved.config.lm;
    let by_exact = solve_all(model, &robot, &targets, Some(&exact), cfg)?;
    let by_spheres = solve_all(model, &robot, &targets, Some(&spheres), cfg)?;
    let unchecked = solve_all(model, &robot, &targets, None, cfg)?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    selfmodel::core::atomic_file::write_json(&out.join("config.json"), cfg)?;
    let exact_of = |s: &Solved| -> Vec<Vec<f64>> {
        (s.answers.iter())
            .filter(|a| a.exact(lm))
            .map(|a| a.joints.clone())
            .collect()
    };
    let (exact_answers, sphere_answers) = (exact_of(&by_exact), exact_of(&by_spheres));
    let exact_unchecked = exact_of(&unchecked);
    let colliding = exact_unchecked.iter().filter(|q| !exact.valid(q)).count();

    let python = python.zip(match spec {
        RobotSpec::Urdf { path, .. } => Some(path.as_path()),
        RobotSpec::Builtin(_) => None,
    });
    let random: Vec<Vec<f64>> =
        selfmodel::sim::trajectory::babbling_rows(&model.saved.ranges, cfg.seed ^ 0xA9)
            .take(cfg.targets)
            .collect();
    let judged = on_the_meshes(
        out,
        [&exact, &spheres],
        &model.saved.joint_names,
        [&qs, &random, &exact_answers, &sphere_answers],
        python,
        scene,
    )?;
    let (verdicts, mesh_free_targets) = (judged.verdicts, judged.mesh_free_targets);

    let n = targets.len();
    let cpu = selfmodel::eval::compute_peak::machine_label(false);
    let revision = selfmodel::core::provenance::git_revision();
    let what = checked_label(n_obstacles, cfg.margin);
    let robot_name = published_name(spec).map_or_else(|| spec.label(), String::from);
    let mean = |a: &[PoseSolution], f: fn(&PoseSolution) -> usize| {
        a.iter().map(|s| f(s) as f64).sum::<f64>() / a.len().max(1) as f64
    };
    let ours =
        |solver: &str, collision: &str, s: &Solved, exact: usize, v: Verdict| CollisionIkRow {
            robot: robot_name.clone(),
            solver: solver.into(),
            collision: collision.into(),
            checked: what.clone(),
            targets: Some(n),
            exact_free_pct: pct(exact, n),
            exact_free_per_s: exact as f64 / s.seconds,
            ms_per_target: Some(1e3 * s.seconds / n.max(1) as f64),
            exact_mesh_free_pct: v.mesh_free_pct,
            colliding_in_unchecked_pairs: v.in_unchecked_pairs,
            exact_but_colliding_pct: Some(0.0),
            spheres_conservative_pct: v.agreement.map(|a| a.0),
            spheres_missed_pct: v.agreement.map(|a| a.1),
            iterations_mean: Some(mean(&s.answers, |a| a.iterations)),
            starts_mean: Some(mean(&s.answers, |a| a.starts)),
            hardware: cpu.clone(),
            source: "measured".into(),
            preset: cfg.preset.clone(),
            git_revision: revision.clone(),
        };
    let pushed = "selfmodel flow + LM (contacts pushed apart)";
    let mut rows = vec![
        ours(pushed, "exact", &by_exact, exact_answers.len(), verdicts[0]),
        ours(
            pushed,
            "spheres",
            &by_spheres,
            sphere_answers.len(),
            verdicts[1],
        ),
        CollisionIkRow {
            exact_but_colliding_pct: Some(pct(colliding, exact_unchecked.len())),
            ..ours(
                "selfmodel flow + LM (no collision check)",
                "none",
                &unchecked,
                exact_unchecked.len() - colliding,
                Verdict::default(),
            )
        },
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
            "{n} targets, each the tips' poses at a random configuration the exact check finds collision-free (the links' collision meshes and primitives keep the margin); one answer a target; the median of at least {} passes over {} s after a warm-up pass, every thread of the machine. `collision`: what decides a collision when answering (`exact`: the meshes, spheres their broad phase; `spheres`: the spheres alone; `none`: no check, its answers judged by the exact check afterwards). Exact: within 1 mm and 0.572 degrees and collision-free by the row's own check.{targets_note} `exact_mesh_free_pct`: the answers Pinocchio and coal find free on the exact meshes (the pairs checked and the scene, zero margin); `colliding_in_unchecked_pairs`: the answers they find colliding in one of the {} pairs of links the check leaves out although they may collide (`unchecked_pairs.json`: neither adjacent, as MoveIt's setup assistant counts it, nor touching at the home pose; {} more touch there and are allowed by design). Published rows: cuRobo's own targets, scenes and GPU, not measured here.",
            cfg.repeats, cfg.min_seconds, judged.unchecked_pairs, judged.touching_at_home
        ),
    )?;
    Ok(rows)
}
