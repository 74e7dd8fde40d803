//! Table II of the EMSSL paper: learned inverse kinematics by embodied self-supervision
//! (EMSSL) against direct regression (DRL), distal supervised learning (DSL) and a conditional
//! GAN, in two joint ranges; beyond the paper, a conditional normalizing flow that returns many
//! solutions ([`selfmodel::ik::flow`]), the numerical solver a roboticist would use instead (damped
//! least squares from the home pose) and EMSSL's answers refined by it, restarted from the
//! flow's samples where it stalls.
//!
//! Every method answers the same held-out targets (30,000 in the paper preset); the error is
//! the distance (cm) between the target and the forward kinematics of the answer.
//!
//! - **Training to convergence** (preset `paper`): 5,000 of the 70,000 training samples are
//!   held out; every network (DRL, both of DSL's, the GAN's generator, the flow) trains until
//!   its validation error has not improved for `converge.patience` epochs, its learning rate
//!   halved on plateaus, and keeps its best epoch; EMSSL stops on its validation goals' reach
//!   error. Every validation error is a distance through the arm on the validation targets
//!   (DSL's forward model: its position error on the validation joints). Preset
//!   `paper-schedule` keeps the fixed schedules of the earlier runs (20 epochs each).
//! - **Wrapped output**: in the ranges of `wrapped_ranges_deg` every method also runs with
//!   (cos, sin) per joint instead of the paper's sigmoid ([`JointOutput::Wrapped`]).
//! - Each row also gives its mean error as a ratio to DRL's (the sigmoid DRL of the same range)
//!   beside the paper's ratio: the paper does not name its arm, and DRL's error (the averaging
//!   of redundant solutions) depends on the arm.
//! - Each method writes its answers as CSV (target, joints, reached position) under
//!   `predictions_<range>/` (git-ignored) and the first `prediction_sample_rows` of them under
//!   `predictions_sample/<range>/` (committed), so anyone can check them.
//! - `solutions_per_s` is the rate of answering the test targets once trained: the median of
//!   three passes after a warm-up pass.
//! - **Resumable**: each method's rows, curves and answers are kept under `units/<range>/` with
//!   the settings they ran with; `--resume` reuses every unit whose settings are unchanged.
//! - **Parallel**: a unit being run is claimed (`units/<range>/<unit>.claim`, the process id);
//!   the same command started again beside it (one per core, `RAYON_NUM_THREADS=1`) takes the
//!   units nobody holds. A last `--resume` run, once all are done, writes the whole report.

use std::path::Path;

use selfmodel::core::atomic_file::write_json;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::ik::paper::method::ValidationRow;
use selfmodel::sim::robot::Robot;

mod config;
mod curves;
mod figures;
mod predictions;
mod report;
mod units;

pub use config::{IK_PRESETS, IkComparisonConfig, TABLE2_PRESETS};
pub use curves::{CurveRow, redraw_learning_curve, write_curves};
pub use figures::draw_error_by_base_angle;
pub use predictions::{read_predictions, read_reached, write_predictions};
pub use report::{IkRow, table2_markdown};
pub use units::{RangeOutcome, RangeRun, RevisedIteration, RunScope, run_range};

use figures::validation_figure;
use report::{set_ratios, write_table2};

/// Table II: every method in every range. Writes `results.csv` (+ Markdown), `table2.md`
/// (the compact table beside the paper's), `validation_curves.csv` and one figure per range,
/// predictions (all, and a committed sample), the EMSSL curves (`emssl_curve.csv`,
/// `learning_curve.png`) and the config. With `resume`, finished units are reused.
pub fn run(
    cfg: &IkComparisonConfig,
    robot: &Robot,
    dir: &Path,
    device: DeviceChoice,
    resume: bool,
) -> Result<Table2Outcome> {
    let robot_name = robot.label.as_str();
    let scope = RunScope {
        cfg,
        robot,
        dir,
        device,
        resume,
    };
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join("config.json"), cfg)?;
    let mut rows = Vec::new();
    let mut curves = Vec::new();
    let mut emssl_curves = Vec::new();
    let (mut units_done, mut units) = (0, 0);
    for &r in &cfg.ranges_deg {
        // After every unit: the report so far (a killed or unfinished run leaves one).
        let partial = |range_rows: &[IkRow], range_curves: &[ValidationRow]| {
            let mut all = rows.clone();
            all.extend_from_slice(range_rows);
            let mut all_curves = curves.clone();
            all_curves.extend_from_slice(range_curves);
            write_outputs(cfg, robot_name, dir, all, &all_curves, &emssl_curves, true).map(|_| ())
        };
        let range = run_range(scope, r, &partial)?;
        units_done += range.units_done;
        units += range.units;
        rows.extend(range.rows);
        curves.extend(range.curves);
        emssl_curves.extend(
            range
                .emssl_curve
                .iter()
                .map(|(c, revision)| CurveRow::new(robot_name, r, &cfg.preset, revision, c)),
        );
    }
    let rows = write_outputs(
        cfg,
        robot_name,
        dir,
        rows,
        &curves,
        &emssl_curves,
        units_done < units,
    )?;
    Ok(Table2Outcome {
        rows,
        units_done,
        units,
    })
}

/// What Table II's run wrote: its rows, from how many of its units (fewer where units were
/// left to another process running the same command: the report is then partial).
pub struct Table2Outcome {
    pub rows: Vec<IkRow>,
    pub units_done: usize,
    pub units: usize,
}

impl Table2Outcome {
    /// "partial (N of M units): ..." where it is, for the end of the printout.
    pub fn partial_note(&self) -> Option<String> {
        (self.units_done < self.units).then(|| {
            format!(
                "results.csv is partial ({} of {} units, {} rows): the others are run by another process with the same --out, or wait for them; run the command again with --resume when it has finished",
                self.units_done,
                self.units,
                self.rows.len()
            )
        })
    }
}

/// Write the tables, curves and figures of `rows` (`partial`: the run has not finished).
fn write_outputs(
    cfg: &IkComparisonConfig,
    robot_name: &str,
    dir: &Path,
    mut rows: Vec<IkRow>,
    curves: &[ValidationRow],
    emssl_curves: &[CurveRow],
    partial: bool,
) -> Result<Vec<IkRow>> {
    set_ratios(&mut rows);
    selfmodel::report::table::write_table(
        &dir.join("results.csv"),
        &rows,
        &format!(
            "Table II: learned inverse kinematics, distance error on held-out targets{}",
            if partial {
                " (partial: the run has not finished)"
            } else {
                ""
            }
        ),
        &format!(
            "Robot `{robot_name}` (the UR5 from its standard DH parameters unless stated; the paper does not name its 6-DOF arm), position only. Errors in cm over {} test targets; `ratio_to_drl` is the mean over DRL's of the same range, `paper_mean_cm` and `paper_ratio_to_drl` the paper's Table II for reference. Methods marked (wrapped) write (cos, sin) per joint instead of the paper's sigmoid. `Flow IK`: a conditional normalizing flow (beyond the paper). `DLS`: damped least squares on the analytic Jacobian (beyond the paper). `predictions_<range>/` holds every method's answers, `predictions_sample/<range>/` the first {} of them.",
            cfg.samples - cfg.train,
            cfg.prediction_sample_rows
        ),
    )?;
    write_table2(dir, cfg, &rows)?;
    selfmodel::report::table::write_csv(&dir.join("validation_curves.csv"), curves)?;
    for &r in &cfg.ranges_deg {
        validation_figure(dir, robot_name, r, curves)?;
        if r >= 180.0 {
            draw_error_by_base_angle(dir, r)?;
        }
    }
    if !emssl_curves.is_empty() || !partial {
        write_curves(
            dir,
            "emssl_curve.csv",
            "EMSSL: test error against iteration",
            emssl_curves,
        )?;
    }
    Ok(rows)
}
