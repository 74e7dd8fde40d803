//! The reference solvers (`scripts/ik_reference.py`, a child process) on the same targets,
//! and their rows read back beside ours.

use std::path::Path;

use selfmodel::core::error::{Error, Result};
use selfmodel::core::spread::format_significant;
use selfmodel::ik::solve::learned::LearnedIk;
use selfmodel::sim::robot::Robot;
use selfmodel::sim::robots::RobotSpec;

use super::{BenchIkRow, EQUAL_PRECISION_MM_DEG, Sitting};

/// The references on the same targets file (`scripts/ik_reference.py`), on as many processes
/// as we have threads and on one; skipped, saying why, where they cannot run.
pub(super) fn references(
    sitting: &mut Sitting,
    model: &LearnedIk,
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
    let script = crate::workspace().join("scripts/ik_reference.py");
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

/// What `scripts/ik_reference.py` wrote.
#[derive(serde::Deserialize)]
pub(super) struct ReferenceRow {
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

pub(super) fn read_reference(path: &Path, s: &Sitting) -> Result<Vec<BenchIkRow>> {
    let rows: Vec<ReferenceRow> = selfmodel::report::table::read_csv(path)?;
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
            git_revision: selfmodel::core::provenance::git_revision(),
        })
        .collect())
}
