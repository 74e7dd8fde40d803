//! Figure 6 of the EMSSL paper: EMSSL's test error against iteration. The same settings as
//! Table II's EMSSL ([`crate::studies::emssl::table2::IkComparisonConfig`]) but with the stopping rule
//! off, so the whole curve shows for a fixed number of iterations; the iteration where the
//! rule would have stopped is reported beside it.

use std::path::Path;

use crate::studies::emssl::table2::{CurveRow, IkComparisonConfig, write_curves};
use selfmodel::core::atomic_file::write_json;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::ik::data::IkData;
use selfmodel::ik::paper::emssl::{EmsslConfig, EmsslIteration, StopRule, emssl};
use selfmodel::sim::robot::Robot;

/// Table II's config with `iterations` EMSSL iterations, no stopping and no polishing
/// (Figure 6 is Algorithm 1's curve).
pub fn config(base: &IkComparisonConfig, iterations: usize) -> IkComparisonConfig {
    IkComparisonConfig {
        emssl: EmsslConfig {
            max_iterations: iterations,
            agreement: 0.0,
            patience: usize::MAX,
            polish_rounds: 0,
            ..base.emssl.clone()
        },
        ..base.clone()
    }
}

/// The iteration at which `rule`'s stopping test would have fired on `curve`, if it did.
pub fn stop_iteration(curve: &[EmsslIteration], rule: &EmsslConfig) -> Option<usize> {
    let mut stop = StopRule::default();
    curve
        .iter()
        .find(|c| stop.observe(c, rule).1)
        .map(|c| c.iteration)
}

/// Run the curve for every range of `cfg` (stopping off); `rule` is the stopping rule to
/// report. Writes `results.csv` (+ Markdown), `learning_curve.png` and `config.json`.
pub fn run(
    cfg: &IkComparisonConfig,
    rule: &EmsslConfig,
    robot: &Robot,
    dir: &Path,
    device_choice: DeviceChoice,
) -> Result<String> {
    let robot_name = robot.label.as_str();
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join("config.json"), cfg)?;
    let device = selfmodel::core::device::select(device_choice)?;
    let mut rows = Vec::new();
    let mut summary = Vec::new();
    let revision = selfmodel::core::provenance::git_revision();
    for &r in &cfg.ranges_deg {
        let data = IkData::generate(&robot.chain, &cfg.data(r))?;
        let model_cfg = cfg.model(robot.dof());
        let (_, curve) = emssl(
            &robot.chain,
            &data,
            &model_cfg,
            &cfg.fit,
            &cfg.emssl,
            &device,
            None,
        )?;
        let last = curve.last().map_or(f64::NAN, |c| c.test.mean_cm);
        let best = curve
            .iter()
            .map(|c| c.test.mean_cm)
            .fold(f64::INFINITY, f64::min);
        summary.push(format!(
            "+-{r:.0} deg: {:.2} cm after {} iterations (best {best:.2}; the stopping rule fires at {})",
            last,
            curve.len(),
            stop_iteration(&curve, rule).map_or("none".to_string(), |i| i.to_string())
        ));
        rows.extend(
            curve
                .iter()
                .map(|c| CurveRow::new(robot_name, r, &cfg.preset, &revision, c)),
        );
    }
    write_curves(
        dir,
        "results.csv",
        "Figure 6: EMSSL test error against iteration",
        &rows,
    )?;
    Ok(summary.join("; "))
}
