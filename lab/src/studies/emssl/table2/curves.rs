//! EMSSL's learning curve (Figure 6): its rows as CSV and `learning_curve.png`.

use std::path::Path;

use selfmodel::core::error::Result;
use selfmodel::ik::paper::emssl::EmsslIteration;

/// A row of an EMSSL learning curve (Figure 6), flattened for CSV.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CurveRow {
    pub robot: String,
    pub range_deg: f64,
    pub iteration: usize,
    pub exploration: f64,
    pub learning_rate: f64,
    pub test_mean_cm: f64,
    pub test_median_cm: f64,
    pub test_p95_cm: f64,
    pub train_reach_cm: f64,
    pub disagreement: f64,
    pub sampling_seconds: f64,
    pub training_seconds: f64,
    pub git_revision: String,
    pub preset: String,
}

impl CurveRow {
    /// `git_revision`: that of the run that trained the model.
    pub fn new(
        robot: &str,
        range_deg: f64,
        preset: &str,
        git_revision: &str,
        c: &EmsslIteration,
    ) -> Self {
        CurveRow {
            robot: robot.into(),
            range_deg,
            iteration: c.iteration,
            exploration: c.exploration,
            learning_rate: c.learning_rate,
            test_mean_cm: c.test.mean_cm,
            test_median_cm: c.test.median_cm,
            test_p95_cm: c.test.p95_cm,
            train_reach_cm: c.train_reach_cm,
            disagreement: c.disagreement,
            sampling_seconds: c.sampling_seconds,
            training_seconds: c.training_seconds,
            git_revision: git_revision.into(),
            preset: preset.into(),
        }
    }
}

/// Write `dir/file` (CSV + Markdown) and `learning_curve.png`: test error against iteration,
/// one line per range.
pub fn write_curves(dir: &Path, file: &str, title: &str, rows: &[CurveRow]) -> Result<()> {
    selfmodel::report::table::write_table(
        &dir.join(file),
        rows,
        title,
        "Per EMSSL iteration: the exploration noise and learning rate used, the test error after it (evaluation only), the mean distance between the desired training positions and where the noise-free answers take the arm, the disagreement (the stopping criterion) and the seconds of the sampling and training phases.",
    )?;
    draw_learning_curve(dir, title, rows)
}

/// Redraw `learning_curve.png` in `dir` from the curve rows in `dir/file` (titled by the
/// Markdown table beside it).
pub fn redraw_learning_curve(dir: &Path, file: &str) -> Result<()> {
    let csv = dir.join(file);
    let rows: Vec<CurveRow> = selfmodel::report::table::read_csv(&csv)?;
    let title = selfmodel::report::table::markdown_title(&csv.with_extension("md"))
        .unwrap_or_else(|| "EMSSL learning curve".into());
    draw_learning_curve(dir, &title, &rows)
}

/// `learning_curve.png`: test error against iteration, one line per range.
pub(super) fn draw_learning_curve(dir: &Path, title: &str, rows: &[CurveRow]) -> Result<()> {
    // One line per run: a range's rows start a new run where the iteration count starts
    // again (Table II runs EMSSL with each joint output in a range, in the order of its
    // methods: the sigmoid, then the wrapped).
    let mut runs: Vec<(String, Vec<(usize, f64)>)> = Vec::new();
    let mut last: Option<(f64, usize)> = None;
    for c in rows {
        let continues = last.is_some_and(|(r, i)| r == c.range_deg && c.iteration > i);
        if !continues {
            let earlier = runs
                .iter()
                .filter(|(l, _)| l.starts_with(&format!("+-{:.0} deg", c.range_deg)))
                .count();
            let run = if earlier > 0 {
                format!(", run {}", earlier + 1)
            } else {
                String::new()
            };
            runs.push((
                format!("+-{:.0} deg{run}, test mean", c.range_deg),
                Vec::new(),
            ));
        }
        runs.last_mut()
            .expect("pushed above")
            .1
            .push((c.iteration, c.test_mean_cm));
        last = Some((c.range_deg, c.iteration));
    }
    selfmodel::report::figures::curves(
        &dir.join("learning_curve.png"),
        title,
        "EMSSL iteration",
        "test distance error (cm, log)",
        &runs,
    )
}
