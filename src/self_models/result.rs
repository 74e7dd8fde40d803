//! One row of Table I: what every self-model run reports, with columns for published figures
//! to stand beside ours (empty unless a study fills them). Every self-model run writes these
//! rows to `results.csv`; a table gathers them without knowing which models exist.

/// One trained model, measured. Units are in the column names.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModelResult {
    /// Model (or ablation setting) name.
    pub model: String,
    /// `clean` or `paper_compatible` (the ground-plane artefact of the paper's dataset).
    pub dataset: String,
    pub preset: String,
    pub device: String,
    /// The dtype it trained in (`precision`; rows written before the column: f32).
    #[serde(default)]
    pub precision: crate::train::precision::Precision,
    /// The learning rate along training (rows written before the column: constant).
    #[serde(default)]
    pub schedule: crate::train::config::LrSchedule,
    pub git_revision: String,
    pub parameters: usize,
    pub train_samples: usize,
    pub train_steps: usize,
    pub batch: usize,
    pub train_time_s: f64,
    /// Images per second through forward, backward and the optimiser step.
    pub train_img_per_s: f64,
    /// PSNR over the first 100 test images (the paper's subset for the decoders).
    pub psnr_db_first100: f64,
    pub psnr_db_test: f64,
    pub iou_test: f64,
    pub depth_mae_mm: Option<f64>,
    /// The best constant depth's error on the same pixels, for reference.
    #[serde(default)]
    pub depth_constant_mae_mm: Option<f64>,
    pub infer_b1_img_per_s: f64,
    pub latency_b1_ms: f64,
    pub infer_b256_img_per_s: f64,
    /// A paper's figures for the same model, for reference only (filled by the study that
    /// compares with them; empty from the library's harness).
    pub paper_psnr_db: Option<f64>,
    pub paper_fps: Option<f64>,
    pub paper_latency_ms: Option<f64>,
    pub paper_train_time_s: Option<f64>,
    /// Anything a reader must know (a shortened run, a different protocol).
    pub note: String,
    /// `--steps N` when the run changed its preset's step count (then not a `preset` run in
    /// full: `table1 --reuse` takes it only for the same `--steps`).
    #[serde(default)]
    pub steps_override: Option<usize>,
    /// A lower bound every self-model must beat (the best constant image), not a model:
    /// figures draw it as a line (set by the study that says so).
    #[serde(default)]
    pub lower_bound: bool,
}

/// Read rows written by [`crate::report::table::write_csv`].
pub fn read_results(path: &std::path::Path) -> crate::Result<Vec<ModelResult>> {
    crate::report::table::read_csv(path)
}
