//! `bench_ik`'s ranking (ours against the fastest and the best reference), its tables and its
//! success-against-time figure.

use std::path::Path;

use selfmodel::core::error::Result;
use selfmodel::core::spread::format_significant;

use super::{BenchIkRow, EQUAL_PRECISION_MM_DEG, IKFLOW_PANDA_MM_DEG};

/// Which rows are each solver's default budget (at any tolerance), and ours against the
/// references: exact solutions/s over the fastest at its default budget and tolerance, and
/// answers within the common precision a second over the best at any tolerance, on as many
/// threads (processes).
pub(super) fn rank(rows: &mut [BenchIkRow]) {
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

/// The rows a summary shows: each solver's default budget, and the references at that budget
/// with their tighter tolerances (the comparison at equal precision).
pub fn summary_rows(rows: &[BenchIkRow]) -> Vec<&BenchIkRow> {
    rows.iter().filter(|r| r.default_budget).collect()
}

/// `results.csv` and its Markdown, and the success-against-time figure.
pub fn write_report(out: &Path, rows: &[BenchIkRow]) -> Result<()> {
    let robot = rows.first().map_or("", |r| r.robot.as_str());
    selfmodel::report::table::write_table(
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
    let rows: Vec<BenchIkRow> = selfmodel::report::table::read_csv(&dir.join("results.csv"))?;
    draw(dir, &rows)
}

/// Success (%) against wall milliseconds a target, one line per solver (on the most threads).
pub(super) fn draw(out: &Path, rows: &[BenchIkRow]) -> Result<()> {
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
    selfmodel::report::figures::line_plot(
        &out.join("success_against_time.png"),
        &format!("{name}: targets solved exactly against time a target"),
        (
            "wall milliseconds a target (log)",
            "targets solved exactly (%)",
        ),
        &lines,
        selfmodel::report::figures::LinePlot::LOG_X,
    )
}
