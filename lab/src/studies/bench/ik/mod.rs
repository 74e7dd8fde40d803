//! Our learned full-pose IK beside the solvers robotics users pick, on the same random reachable
//! targets in the same sitting (as `bench_decoders` sits beside PyTorch): the share of targets
//! solved exactly (1 mm and 0.572 degrees, every joint inside its limits) and exact solutions
//! per second, at several time budgets (the success-against-time figure, IKFlow's runtime
//! curve), the family of answers for k samples a target, and the learned model alone beside
//! IKFlow's published Panda errors.
//!
//! Ours: the saved model's flow samples refined by Levenberg-Marquardt ([`LearnedIk::solve`]),
//! the budget being the random starts allowed where the samples stall; the same solver from
//! random starts only (no model), the model's slow reference. The references come from
//! `scripts/ik_reference.py` (the Robotics Toolbox's compiled `ik_LM` and TRAC-IK through
//! PyPI `pytracik`, on the same URDF), run as a child process on the targets file written here;
//! skipped, with the reason printed, when Python or the packages are absent.

mod references;
mod report;

use std::path::{Path, PathBuf};

use burn::tensor::Device;

use selfmodel::core::error::{Error, Result};
use selfmodel::core::spread::format_significant;
use selfmodel::core::timing::{Repeats, median, median_seconds};
use selfmodel::ik::solve::learned::{LearnedIk, SolveStats};
use selfmodel::ik::solve::levenberg_marquardt::Answering;
use selfmodel::ik::solve::levenberg_marquardt::{
    LmConfig, PoseSolution, PoseTarget, pose_error, solve_batch,
};
use selfmodel::ik::solve::solver::IkSolver;
use selfmodel::ik::solve::targets::{random_targets, targets_csv};

use references::references;
use report::rank;

pub use report::{draw_figures, summary_rows, write_report};

/// IKFlow's published Panda model (`panda_full_tpm`, trained on 25M poses on a GPU): mean
/// position and rotation errors of its samples without refinement, from jstmn/ikflow's
/// `model_performances.md` (500 test targets, 2023-03-28). A reference column, not ours.
pub const IKFLOW_PANDA_MM_DEG: (f64, f64) = (10.6033, 4.60678);

/// The common precision every solver is ranked at (mm, degrees): our default convergence
/// tolerance (`ik::solve::levenberg_marquardt::CONVERGENCE_M`, `CONVERGENCE_DEG`), which each reference reaches at
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
            git_revision: selfmodel::core::provenance::git_revision(),
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
    let pool = selfmodel::core::denormals::thread_pool(threads)
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
    selfmodel::core::atomic_file::refuse_overwrite(out, &[], Some(model_dir))?;
    let (model, robot) = LearnedIk::load_with_robot(model_dir, device)?;
    if model.position_only() {
        return Err(Error::Config(
            "bench_ik measures full-pose IK: train the model without --position-only".into(),
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    selfmodel::core::atomic_file::write_json(&out.join("config.json"), cfg)?;
    copy_training_curve(model_dir, out)?;
    let (targets, joints) = random_targets(&robot, &model.saved.ranges, cfg.targets, cfg.seed);
    let targets_file = out.join("targets.csv");
    selfmodel::core::atomic_file::write_bytes(
        &targets_file,
        targets_csv(&targets, &joints, &model.saved.joint_names, model.tips()).as_bytes(),
    )?;
    let mut sitting = Sitting {
        cfg,
        robot_name: model.saved.robot.label(),
        cpu: selfmodel::eval::compute_peak::machine_label(false),
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
    let curve: Vec<selfmodel::train::convergence::ValidationPoint> =
        selfmodel::report::table::read_csv(&curve_file)?;
    selfmodel::report::table::write_csv(&out.join("flow_validation_curve.csv"), &curve)?;
    selfmodel::report::figures::curves(
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
    model: &'a LearnedIk,
    chain: &'a selfmodel::sim::kinematics::KinematicChain,
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
                let how = Answering::with(&lm);
                self.model.solve(self.chain, self.targets, 1, &how)
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
        let (s, answers) = timed(|| {
            self.model
                .solve(self.chain, self.targets, k, &self.model.answering())
        });
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
        assert!(
            (mm - 1e3 * selfmodel::ik::solve::levenberg_marquardt::CONVERGENCE_M).abs() < 1e-15
        );
        assert!((deg - selfmodel::ik::solve::levenberg_marquardt::CONVERGENCE_DEG).abs() < 1e-15);
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
