//! Our learned full-pose IK beside the solvers robotics users pick, on the same random reachable
//! targets in the same sitting (as `bench_decoders` sits beside PyTorch): the share of targets
//! solved exactly (1 mm and 0.572 degrees, every joint inside its limits) and exact solutions
//! per second, at several time budgets (the success-against-time figure, IKFlow's runtime
//! curve), the family of answers for k samples a target, and the learned model alone beside
//! IKFlow's published Panda errors.
//!
//! Ours: the saved model's flow samples refined by Levenberg-Marquardt ([`PoseModel::solve`]),
//! the budget being the random starts allowed where the samples stall; the same solver from
//! random starts only (no model), the model's slow reference. The references come from
//! `scripts/ik_reference.py` (the Robotics Toolbox's compiled `ik_LM` and TRAC-IK through
//! PyPI `pytracik`, on the same URDF), run as a child process on the targets file written here;
//! skipped, with the reason printed, when Python or the packages are absent.

use std::path::{Path, PathBuf};

use burn::tensor::Device;

use crate::core::error::{Error, Result};
use crate::core::spread::format_significant;
use crate::core::timing::{Repeats, median, median_seconds};
use crate::ik::pose::{LmConfig, PoseSolution, PoseTarget, pose_error, solve_batch};
use crate::ik::pose_model::{PoseModel, SolveStats};
use crate::ik::targets::{random_targets, targets_csv};
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;

/// IKFlow's published Panda model (`panda_full_tpm`, trained on 25M poses on a GPU): mean
/// position and rotation errors of its samples without refinement, from jstmn/ikflow's
/// `model_performances.md` (500 test targets, 2023-03-28). A reference column, not ours.
pub const IKFLOW_PANDA_MM_DEG: (f64, f64) = (10.6033, 4.60678);

/// The common precision every solver is ranked at (mm, degrees): our default convergence
/// tolerance (`ik::pose::CONVERGENCE_M`, `CONVERGENCE_DEG`), which each reference reaches at
/// its tightest setting. An answer counts at it when its pose is within both and every joint
/// inside its limits.
pub const EQUAL_PRECISION_MM_DEG: (f64, f64) = (1e-4, 1e-4);

/// What the benchmark runs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BenchIkConfig {
    pub preset: String,
    /// Random reachable targets: the tip's pose at joints drawn uniformly within the model's
    /// ranges.
    pub targets: usize,
    pub seed: u64,
    /// Random starts allowed after the model's sample stalls (the budgets of the curve).
    pub random_starts: Vec<usize>,
    /// Random starts of the solver without a model (its curve).
    pub random_only_starts: Vec<usize>,
    /// Samples a target for the family of answers.
    pub k: usize,
}

impl BenchIkConfig {
    pub fn named(preset: &str, k: usize) -> Result<Self> {
        let targets = match preset {
            "paper" => 10_000,
            "quick" => 200,
            other => {
                return Err(Error::Config(format!(
                    "unknown preset \"{other}\" (paper or quick)"
                )));
            }
        };
        Ok(BenchIkConfig {
            preset: preset.into(),
            targets,
            seed: 1,
            random_starts: vec![0, 1, 3, 10, 100],
            random_only_starts: vec![1, 3, 10, 100],
            k,
        })
    }
}

/// One measured configuration.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BenchIkRow {
    pub robot: String,
    pub solver: String,
    pub budget: String,
    /// The solver's default budget (the table's rows; the others draw the curve).
    pub standard: bool,
    /// Threads (ours) or processes (the references).
    pub threads: usize,
    /// Answers a target.
    pub k: usize,
    pub targets: usize,
    pub exact_pct: f64,
    pub exact_per_s: f64,
    /// Wall milliseconds a target (the whole batch's time over the targets).
    pub ms_per_target: f64,
    pub outside_limits: usize,
    pub iterations_mean: Option<f64>,
    pub starts_mean: Option<f64>,
    /// Distinct exact answers a target (more than 0.1 rad apart in a joint), and the share
    /// of targets with at least 5.
    pub distinct_mean: Option<f64>,
    pub distinct_5_pct: Option<f64>,
    /// Errors of the answers (the learned model alone: its samples without refinement).
    pub pos_err_mm_mean: Option<f64>,
    pub pos_err_mm_median: Option<f64>,
    pub rot_err_deg_mean: Option<f64>,
    pub rot_err_deg_median: Option<f64>,
    /// The answers' precision: the 98th percentile and the largest pose error (ours, every
    /// answer; the references where their script reports it).
    #[serde(default)]
    pub pos_err_mm_p98: Option<f64>,
    #[serde(default)]
    pub pos_err_mm_max: Option<f64>,
    #[serde(default)]
    pub rot_err_deg_p98: Option<f64>,
    #[serde(default)]
    pub rot_err_deg_max: Option<f64>,
    /// Where the solver stops iterating (ours: the convergence tolerance, mm and degrees).
    #[serde(default)]
    pub tolerance: Option<String>,
    /// The solver at its default budget, at any of its tolerances (the summary's rows and the
    /// equal-precision table's: `standard` rows and the references' tighter ones).
    #[serde(default)]
    pub default_budget: bool,
    /// Targets answered within [`EQUAL_PRECISION_MM_DEG`] (%, and such answers a second):
    /// the ranking at equal precision.
    #[serde(default)]
    pub precise_pct: Option<f64>,
    #[serde(default)]
    pub precise_per_s: Option<f64>,
    /// Ours: exact solutions/s over the fastest reference's at its default budget on as many
    /// threads (processes).
    pub vs_fastest_reference: Option<f64>,
    /// Ours: answers within the common precision a second over the best reference's at any of
    /// its tolerances, at its default budget on as many threads (processes).
    #[serde(default)]
    pub vs_best_reference_precise: Option<f64>,
    pub cpu: String,
    pub model_preset: String,
    pub preset: String,
    pub git_revision: String,
}

struct Sitting<'a> {
    cfg: &'a BenchIkConfig,
    robot_name: String,
    cpu: String,
    model_preset: String,
    rows: Vec<BenchIkRow>,
}

/// What names a row of ours: the solver, its budget, whether that is its default, on how
/// many threads.
struct RowLabel<'s> {
    solver: &'s str,
    budget: String,
    standard: bool,
    threads: usize,
}

impl Sitting<'_> {
    /// A row of ours from answers and the median seconds of the batch.
    fn push(
        &mut self,
        label: RowLabel,
        answers: &[Vec<PoseSolution>],
        lm: &LmConfig,
        ranges: &[[f64; 2]],
        seconds: f64,
    ) {
        let RowLabel {
            solver,
            budget,
            standard,
            threads,
        } = label;
        let s = SolveStats::of(answers, lm, ranges);
        let precise = SolveStats::of(answers, &at_equal_precision(lm), ranges);
        let k = answers.first().map_or(1, Vec::len);
        let family = k > 1;
        eprintln!(
            "bench_ik: {solver}, {budget}, {threads} threads: {:.2}% exact, {:.0} exact/s",
            s.exact_pct(),
            s.exact_answers as f64 / seconds
        );
        self.rows.push(BenchIkRow {
            robot: self.robot_name.clone(),
            solver: solver.into(),
            budget,
            standard,
            threads,
            k,
            targets: s.targets,
            exact_pct: s.exact_pct(),
            exact_per_s: s.exact_answers as f64 / seconds,
            ms_per_target: 1000.0 * seconds / s.targets.max(1) as f64,
            outside_limits: s.outside_limits,
            iterations_mean: Some(s.iterations_mean),
            starts_mean: Some(s.starts_mean),
            distinct_mean: family.then_some(s.distinct_mean),
            distinct_5_pct: family.then_some(s.distinct_5_pct),
            pos_err_mm_mean: None,
            pos_err_mm_median: Some(s.position_mm.median),
            rot_err_deg_mean: None,
            rot_err_deg_median: Some(s.rotation_deg.median),
            pos_err_mm_p98: Some(s.position_mm.p98),
            pos_err_mm_max: Some(s.position_mm.max),
            rot_err_deg_p98: Some(s.rotation_deg.p98),
            rot_err_deg_max: Some(s.rotation_deg.max),
            tolerance: Some(format!(
                "{} mm, {} degrees",
                format_significant(1e3 * lm.convergence_m, 2),
                format_significant(lm.convergence_rad.to_degrees(), 2)
            )),
            default_budget: false,
            precise_pct: Some(precise.exact_pct()),
            precise_per_s: Some(precise.exact_answers as f64 / seconds),
            vs_fastest_reference: None,
            vs_best_reference_precise: None,
            cpu: self.cpu.clone(),
            model_preset: self.model_preset.clone(),
            preset: self.cfg.preset.clone(),
            git_revision: crate::core::provenance::git_revision(),
        });
    }
}

/// `lm` with its success threshold at the common precision.
fn at_equal_precision(lm: &LmConfig) -> LmConfig {
    LmConfig {
        tolerance_m: EQUAL_PRECISION_MM_DEG.0 / 1e3,
        tolerance_rad: EQUAL_PRECISION_MM_DEG.1.to_radians(),
        ..lm.clone()
    }
}

/// Median seconds of `f` (one warm-up, three timed runs) and its last result.
fn timed<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = None;
    let s = median_seconds(Repeats::exactly(1, 3), || out = Some(f()));
    (s, out.expect("ran"))
}

/// Run `f` on a pool of `threads` threads.
fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> Result<T> {
    let pool = crate::core::denormals::thread_pool(threads)
        .map_err(|e| Error::Config(format!("a pool of {threads} threads: {e}")))?;
    Ok(pool.install(f))
}

/// Benchmark the model saved in `model_dir` on its robot; write `results.csv` (+ Markdown),
/// `targets.csv`, `reference.csv` and `success_against_time.png` into `out`. `python`: the
/// interpreter for the reference script (None: skipped).
pub fn run(
    cfg: &BenchIkConfig,
    model_dir: &Path,
    out: &Path,
    python: Option<&Path>,
    device: &Device,
) -> Result<Vec<BenchIkRow>> {
    crate::core::atomic_file::refuse_overwrite(out, &[], Some(model_dir))?;
    let (model, robot) = PoseModel::load_with_robot(model_dir, device)?;
    if model.position_only() {
        return Err(Error::Config(
            "bench_ik measures full-pose IK: train the model without --position-only".into(),
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    crate::core::atomic_file::write_json(&out.join("config.json"), cfg)?;
    copy_training_curve(model_dir, out)?;
    let (targets, joints) = random_targets(&robot, &model.saved.ranges, cfg.targets, cfg.seed);
    let targets_file = out.join("targets.csv");
    crate::core::atomic_file::write_bytes(
        &targets_file,
        targets_csv(&targets, &joints, &model.saved.joint_names, model.tips()).as_bytes(),
    )?;
    let mut sitting = Sitting {
        cfg,
        robot_name: model.saved.robot.label(),
        cpu: crate::eval::compute_peak::machine_label(false),
        model_preset: model.saved.config.preset.clone(),
        rows: Vec::new(),
    };
    let ours = Ours {
        model: &model,
        chain: &robot.chain,
        targets: &targets,
        device,
    };
    ours.model_alone(&mut sitting);
    ours.at_every_budget(&mut sitting)?;
    ours.family(&mut sitting)?;
    ours.random_starts_only(&mut sitting);
    references(&mut sitting, &model, &robot, &targets_file, out, python)?;
    let mut rows = sitting.rows;
    rank(&mut rows);
    write_report(out, &rows)?;
    Ok(rows)
}

/// The model's training curve beside its benchmark (principle: show the curve).
fn copy_training_curve(model_dir: &Path, out: &Path) -> Result<()> {
    let curve_file = model_dir.join("validation_curve.csv");
    if !curve_file.exists() {
        return Ok(());
    }
    let curve: Vec<crate::train::convergence::ValidationPoint> =
        crate::report::table::read_csv(&curve_file)?;
    crate::report::table::write_csv(&out.join("flow_validation_curve.csv"), &curve)?;
    crate::report::figures::curves(
        &out.join("flow_validation_curve.png"),
        "the flow's validation error (one sample a target, before refinement)",
        "epoch",
        "mean position error, cm (log)",
        &[(
            "validation".to_string(),
            curve.iter().map(|p| (p.epoch, p.validation)).collect(),
        )],
    )
}

/// Our rows: the model and the solver it feeds, on the sitting's targets.
struct Ours<'a> {
    model: &'a PoseModel,
    chain: &'a crate::sim::kinematics::KinematicChain,
    targets: &'a [Vec<PoseTarget>],
    device: &'a Device,
}

impl Ours<'_> {
    fn ranges(&self) -> &[[f64; 2]] {
        &self.model.saved.ranges
    }

    fn standard(&self) -> &LmConfig {
        &self.model.saved.config.lm
    }

    /// The model alone: one sample a target, no refinement.
    fn model_alone(&self, sitting: &mut Sitting) {
        let threads = rayon::current_num_threads();
        let (seconds, samples) = timed(|| self.model.sample(self.targets, self.device));
        let errors: Vec<(f64, f64)> = samples
            .iter()
            .zip(self.targets)
            .map(|(q, t)| {
                let (p, r) = pose_error(self.chain, q, t);
                (1000.0 * p, r.to_degrees())
            })
            .collect();
        let alone: Vec<Vec<PoseSolution>> = samples
            .iter()
            .zip(&errors)
            .map(|(q, &(p, r))| {
                vec![PoseSolution {
                    collides: false,
                    joints: q.clone(),
                    position_error_m: p / 1000.0,
                    rotation_error_rad: r.to_radians(),
                    iterations: 0,
                    starts: 0,
                }]
            })
            .collect();
        sitting.push(
            RowLabel {
                solver: "selfmodel flow alone",
                budget: "1 sample".into(),
                standard: false,
                threads,
            },
            &alone,
            self.standard(),
            self.ranges(),
            seconds,
        );
        let stats = |v: Vec<f64>| (v.iter().sum::<f64>() / v.len().max(1) as f64, median(&v));
        let (pm, pmed) = stats(errors.iter().map(|e| e.0).collect());
        let (rm, rmed) = stats(errors.iter().map(|e| e.1).collect());
        if let Some(row) = sitting.rows.last_mut() {
            row.pos_err_mm_mean = Some(pm);
            row.pos_err_mm_median = Some(pmed);
            row.rot_err_deg_mean = Some(rm);
            row.rot_err_deg_median = Some(rmed);
            row.iterations_mean = None;
            row.starts_mean = None;
            row.tolerance = None;
        }
    }

    /// Ours at every budget (and the model's own), on all threads; the model's own budget on
    /// one thread too.
    fn at_every_budget(&self, sitting: &mut Sitting) -> Result<()> {
        let threads = rayon::current_num_threads();
        let standard = self.standard();
        let mut budgets = sitting.cfg.random_starts.clone();
        budgets.push(standard.random_starts);
        budgets.sort_unstable();
        budgets.dedup();
        for &starts in &budgets {
            let lm = LmConfig {
                random_starts: starts,
                ..standard.clone()
            };
            let solve = || {
                self.model
                    .solve_with(self.chain, self.targets, 1, &lm, self.device)
            };
            let (s, answers) = timed(solve);
            let is_standard = starts == standard.random_starts;
            let budget = format!("{starts} random starts");
            let (ranges, solver) = (self.ranges(), "selfmodel flow + LM");
            sitting.push(
                RowLabel {
                    solver,
                    budget: budget.clone(),
                    standard: is_standard,
                    threads,
                },
                &answers?,
                &lm,
                ranges,
                s,
            );
            if is_standard && threads > 1 {
                let (s, answers) = on_threads(1, || timed(solve))?;
                sitting.push(
                    RowLabel {
                        solver,
                        budget,
                        standard: true,
                        threads: 1,
                    },
                    &answers?,
                    &lm,
                    ranges,
                    s,
                );
            }
        }
        Ok(())
    }

    /// The family: k samples a target, each refined.
    fn family(&self, sitting: &mut Sitting) -> Result<()> {
        let k = sitting.cfg.k;
        let (s, answers) = timed(|| self.model.solve(self.chain, self.targets, k, self.device));
        sitting.push(
            RowLabel {
                solver: "selfmodel flow + LM",
                budget: format!("{k} samples a target"),
                standard: true,
                threads: rayon::current_num_threads(),
            },
            &answers?,
            self.standard(),
            self.ranges(),
            s,
        );
        Ok(())
    }

    /// The same solver without a model: random starts only.
    fn random_starts_only(&self, sitting: &mut Sitting) {
        let standard = self.standard();
        for &starts in &sitting.cfg.random_only_starts.clone() {
            let lm = LmConfig {
                random_starts: starts,
                ..standard.clone()
            };
            let (s, answers) =
                timed(|| solve_batch(self.chain, self.targets, &[], self.ranges(), &lm));
            let answers: Vec<Vec<PoseSolution>> = answers.into_iter().map(|a| vec![a]).collect();
            sitting.push(
                RowLabel {
                    solver: "selfmodel LM from random starts",
                    budget: format!("{starts} random starts"),
                    standard: starts == standard.random_starts,
                    threads: rayon::current_num_threads(),
                },
                &answers,
                &lm,
                self.ranges(),
                s,
            );
        }
    }
}

/// The references on the same targets file (`scripts/ik_reference.py`), on as many processes
/// as we have threads and on one; skipped, saying why, where they cannot run.
fn references(
    sitting: &mut Sitting,
    model: &PoseModel,
    robot: &Robot,
    targets_file: &Path,
    out: &Path,
    python: Option<&Path>,
) -> Result<()> {
    let chain = &robot.chain;
    let threads = rayon::current_num_threads();
    let reference = out.join("reference.csv");
    let one_tip = model.tips().is_empty();
    let (Some(py), RobotSpec::Urdf { path, tip, .. }, true) = (python, &model.saved.robot, one_tip)
    else {
        eprintln!(
            "bench_ik: the references skipped ({})",
            if python.is_none() {
                "no --python given"
            } else if !one_tip {
                "they solve for one tip; this model's targets give several"
            } else {
                "they read a URDF; this model's robot is built in"
            }
        );
        return Ok(());
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/ik_reference.py");
    let tip = tip
        .clone()
        .unwrap_or_else(|| chain.links[chain.tip_link].clone());
    let run = |processes: usize, file: &Path, standard_only: bool| -> Result<()> {
        let mut cmd = std::process::Command::new(py);
        cmd.arg(&script)
            .args(["--targets", &targets_file.to_string_lossy()])
            .args(["--urdf", &path.to_string_lossy()])
            .args(["--base", &chain.links[0]])
            .args(["--tip", &tip])
            .args(["--processes", &processes.to_string()])
            .args([
                "--precision",
                &format!(
                    "{},{}",
                    format_significant(EQUAL_PRECISION_MM_DEG.0, 3),
                    format_significant(EQUAL_PRECISION_MM_DEG.1, 3)
                ),
            ])
            .args(["--out", &file.to_string_lossy()]);
        if standard_only {
            cmd.arg("--standard-only");
        }
        // Each reference at its default budget with tighter tolerances too: the comparison
        // at equal precision.
        cmd.arg("--tight");
        let o = match cmd.output() {
            Ok(o) => o,
            Err(e) => {
                eprintln!(
                    "bench_ik: the references skipped ({} cannot run: {e})",
                    py.display()
                );
                return Ok(());
            }
        };
        let stdout = String::from_utf8_lossy(&o.stdout);
        for line in stdout.lines() {
            eprintln!("bench_ik: {line}");
        }
        if !o.status.success() {
            return Err(Error::Config(format!(
                "{} failed: {}",
                script.display(),
                String::from_utf8_lossy(&o.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            )));
        }
        Ok(())
    };
    run(threads, &reference, false)?;
    let one = out.join("reference_1_process.csv");
    if threads > 1 {
        run(1, &one, true)?;
    }
    for file in [reference.as_path(), one.as_path()] {
        if file.exists() {
            let rows = read_reference(file, sitting)?;
            sitting.rows.extend(rows);
        }
    }
    Ok(())
}

/// Which rows are each solver's default budget (at any tolerance), and ours against the
/// references: exact solutions/s over the fastest at its default budget and tolerance, and
/// answers within the common precision a second over the best at any tolerance, on as many
/// threads (processes).
fn rank(rows: &mut [BenchIkRow]) {
    let default_budget: Vec<bool> = rows
        .iter()
        .map(|r| {
            r.standard
                || rows.iter().any(|s| {
                    s.standard
                        && s.solver == r.solver
                        && s.budget == r.budget
                        && s.threads == r.threads
                        && s.tolerance != r.tolerance
                })
        })
        .collect();
    for (r, d) in rows.iter_mut().zip(default_budget) {
        r.default_budget = d;
    }
    let best = |rows: &[BenchIkRow],
                threads: usize,
                standard_only: bool,
                f: fn(&BenchIkRow) -> Option<f64>| {
        rows.iter()
            .filter(|r| !r.solver.starts_with("selfmodel") && r.threads == threads)
            .filter(|r| r.standard || !standard_only)
            .filter_map(f)
            .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))))
    };
    for i in 0..rows.len() {
        if !rows[i].solver.starts_with("selfmodel") {
            continue;
        }
        let threads = rows[i].threads;
        let fastest = best(rows, threads, true, |r| Some(r.exact_per_s));
        rows[i].vs_fastest_reference = fastest.map(|f| rows[i].exact_per_s / f);
        let best_precise = best(rows, threads, false, |r| r.precise_per_s);
        rows[i].vs_best_reference_precise = match (rows[i].precise_per_s, best_precise) {
            (Some(ours), Some(best)) if best > 0.0 => Some(ours / best),
            _ => None,
        };
    }
}

/// What `scripts/ik_reference.py` wrote.
#[derive(serde::Deserialize)]
struct ReferenceRow {
    solver: String,
    budget: String,
    standard: String,
    processes: usize,
    targets: usize,
    exact: usize,
    outside_limits: usize,
    seconds: f64,
    /// Where it stops (`tol 1e-06`, `eps 1e-05`) and its answers' pose errors: absent from
    /// files the script wrote before it reported them.
    #[serde(default)]
    tolerance: Option<String>,
    #[serde(default)]
    pos_err_mm_median: Option<f64>,
    #[serde(default)]
    pos_err_mm_p98: Option<f64>,
    #[serde(default)]
    pos_err_mm_max: Option<f64>,
    #[serde(default)]
    rot_err_deg_median: Option<f64>,
    #[serde(default)]
    rot_err_deg_p98: Option<f64>,
    #[serde(default)]
    rot_err_deg_max: Option<f64>,
    /// Answers within the common precision (`--precision`): absent from older files.
    #[serde(default)]
    precise: Option<usize>,
}

fn read_reference(path: &Path, s: &Sitting) -> Result<Vec<BenchIkRow>> {
    let rows: Vec<ReferenceRow> = crate::report::table::read_csv(path)?;
    Ok(rows
        .into_iter()
        .map(|r| BenchIkRow {
            robot: s.robot_name.clone(),
            solver: r.solver,
            budget: r.budget,
            standard: r.standard == "True",
            threads: r.processes,
            k: 1,
            targets: r.targets,
            exact_pct: 100.0 * r.exact as f64 / r.targets.max(1) as f64,
            exact_per_s: r.exact as f64 / r.seconds,
            ms_per_target: 1000.0 * r.seconds / r.targets.max(1) as f64,
            outside_limits: r.outside_limits,
            iterations_mean: None,
            starts_mean: None,
            distinct_mean: None,
            distinct_5_pct: None,
            pos_err_mm_mean: None,
            pos_err_mm_median: r.pos_err_mm_median,
            rot_err_deg_mean: None,
            rot_err_deg_median: r.rot_err_deg_median,
            pos_err_mm_p98: r.pos_err_mm_p98,
            pos_err_mm_max: r.pos_err_mm_max,
            rot_err_deg_p98: r.rot_err_deg_p98,
            rot_err_deg_max: r.rot_err_deg_max,
            tolerance: r.tolerance,
            default_budget: false,
            precise_pct: r
                .precise
                .map(|p| 100.0 * p as f64 / r.targets.max(1) as f64),
            precise_per_s: r.precise.map(|p| p as f64 / r.seconds),
            vs_fastest_reference: None,
            vs_best_reference_precise: None,
            cpu: s.cpu.clone(),
            model_preset: s.model_preset.clone(),
            preset: s.cfg.preset.clone(),
            git_revision: crate::core::provenance::git_revision(),
        })
        .collect())
}

/// The rows a summary shows: each solver's default budget, and the references at that budget
/// with their tighter tolerances (the comparison at equal precision).
pub fn summary_rows(rows: &[BenchIkRow]) -> Vec<&BenchIkRow> {
    rows.iter().filter(|r| r.default_budget).collect()
}

/// `results.csv` and its Markdown, and the success-against-time figure.
pub fn write_report(out: &Path, rows: &[BenchIkRow]) -> Result<()> {
    let robot = rows.first().map_or("", |r| r.robot.as_str());
    crate::report::table::write_table(
        &out.join("results.csv"),
        rows,
        &format!(
            "Full-pose inverse kinematics on {robot}: ours beside the references, same targets, same sitting"
        ),
        &format!(
            "Random reachable targets (the tip's pose at joints drawn within the limits). Exact: within 1 mm and 0.572 degrees with every joint inside its limits. `threads`: our threads or the references' processes; `ms_per_target`: the batch's wall time over its targets. `standard` marks each solver's default budget at its default tolerance; the other budgets draw `success_against_time.png`; `default_budget` marks the default budget at any tolerance (the references' tighter ones too). `tolerance`: where the solver stops iterating. `pos_err_mm_*`, `rot_err_deg_*`: every returned answer's pose error. `precise_pct`, `precise_per_s`: targets answered within {} mm and {} degrees (inside the limits), the common precision solvers are ranked at; `vs_best_reference_precise`: ours over the best reference at it, at any of its tolerances. The learned model alone is the flow's one sample without refinement: IKFlow's published Panda model (panda_full_tpm, 25M training poses, GPU) has {:.1} mm and {:.2} degrees mean errors (jstmn/ikflow model_performances.md).",
            format_significant(EQUAL_PRECISION_MM_DEG.0, 2),
            format_significant(EQUAL_PRECISION_MM_DEG.1, 2),
            IKFLOW_PANDA_MM_DEG.0,
            IKFLOW_PANDA_MM_DEG.1
        ),
    )?;
    draw(out, rows)
}

/// [`draw`] from the `results.csv` in `dir` (`reports --figures`).
pub fn draw_figures(dir: &Path) -> Result<()> {
    let rows: Vec<BenchIkRow> = crate::report::table::read_csv(&dir.join("results.csv"))?;
    draw(dir, &rows)
}

/// Success (%) against wall milliseconds a target, one line per solver (on the most threads).
fn draw(out: &Path, rows: &[BenchIkRow]) -> Result<()> {
    let most = rows.iter().map(|r| r.threads).max().unwrap_or(1);
    let mut lines: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    // Each solver's curve at the tolerance of its standard row (a reference's tighter
    // tolerances are table rows, not points of its curve).
    let standard_tolerance = |solver: &str| {
        rows.iter()
            .find(|r| r.solver == solver && r.standard)
            .and_then(|r| r.tolerance.clone())
    };
    for r in rows.iter().filter(|r| r.threads == most && r.k == 1) {
        if r.solver.contains("alone") || r.tolerance != standard_tolerance(&r.solver) {
            continue;
        }
        let label = format!(
            "{} ({} {})",
            r.solver,
            most,
            if r.solver.starts_with("selfmodel") {
                "threads"
            } else {
                "processes"
            }
        );
        match lines.iter_mut().find(|(l, _)| *l == label) {
            Some((_, pts)) => pts.push((r.ms_per_target, r.exact_pct)),
            None => lines.push((label, vec![(r.ms_per_target, r.exact_pct)])),
        }
    }
    // Each line joins its budgets in increasing order (not sorted by time: a noisy timing
    // shows as a step back, not a reordering).
    let robot = rows.first().map_or("", |r| r.robot.as_str());
    let name = Path::new(robot)
        .file_stem()
        .map_or(robot.to_string(), |s| s.to_string_lossy().to_string());
    crate::report::figures::lines_log_x(
        &out.join("success_against_time.png"),
        &format!("{name}: targets solved exactly against time a target"),
        "wall milliseconds a target (log)",
        "targets solved exactly (%)",
        &lines,
    )
}

/// Where `bench_ik` writes by default: `runs/bench_ik/<model folder name>`.
pub fn default_out(model_dir: &Path) -> PathBuf {
    PathBuf::from(crate::studies::run::RUNS)
        .join("bench_ik")
        .join(
            model_dir
                .file_name()
                .map_or("model".into(), |n| n.to_string_lossy().to_string()),
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_common_precision_is_the_default_convergence_tolerance() {
        let (mm, deg) = EQUAL_PRECISION_MM_DEG;
        assert!((mm - 1e3 * crate::ik::pose::CONVERGENCE_M).abs() < 1e-15);
        assert!((deg - crate::ik::pose::CONVERGENCE_DEG).abs() < 1e-15);
        // An answer just inside counts at it; one just outside (or outside the limits) does not.
        let lm = at_equal_precision(&LmConfig::standard());
        let answer = |mm: f64| PoseSolution {
            collides: false,
            joints: vec![0.0],
            position_error_m: mm / 1e3,
            rotation_error_rad: 0.5e-4_f64.to_radians(),
            iterations: 1,
            starts: 1,
        };
        let stats = SolveStats::of(
            &[vec![answer(0.9e-4)], vec![answer(1.1e-4)]],
            &lm,
            &[[-1.0, 1.0]],
        );
        assert_eq!(stats.exact_targets, 1);
    }
}
