//! The GPU check's last part: every figure of every backend it measured (one sub-folder of
//! its output a backend, `cuda/` and `wgpu/`) against PyTorch, and which backend is faster at
//! each, from the CSVs the other parts wrote.

use std::path::{Path, PathBuf};

use crate::studies::bench::decoders::BenchRow;
use selfmodel::core::error::{Error, Result};
use selfmodel::report::table::read_csv;

/// One figure of one backend.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SummaryLine {
    pub figure: String,
    /// The backend's folder (`cuda`, `wgpu`), or `cpu` for the CPU rows.
    pub backend: String,
    pub threads: Option<usize>,
    pub ours: f64,
    pub torch: Option<f64>,
    pub ratio: Option<f64>,
    /// No other backend measured this figure faster.
    pub fastest_backend: bool,
}

impl SummaryLine {
    /// The line the check's console prints.
    pub fn console_line(&self) -> String {
        let threads = self
            .threads
            .map(|t| format!(" {t} threads"))
            .unwrap_or_default();
        let ratio = self.ratio.map_or("-".to_string(), |r| format!("{r:.2}x"));
        format!(
            "  {:<40} {:<10}{threads:<11} {:>10.1} images/s  PyTorch {:>10}  {ratio}{}",
            self.figure,
            self.backend,
            self.ours,
            self.torch.map_or("-".to_string(), |t| format!("{t:.1}")),
            if self.fastest_backend { " *" } else { "" }
        )
    }
}

/// The rows of `csv` under each sub-folder of `out` (a backend's), with the folder's name.
fn rows_by_backend(out: &Path, csv: &str) -> Result<Vec<(String, BenchRow)>> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(out)
        .map_err(|e| Error::io(out, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join(csv).is_file())
        .collect();
    dirs.sort();
    let mut all = Vec::new();
    for dir in dirs {
        let backend = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let rows: Vec<BenchRow> = read_csv(&dir.join(csv))?;
        all.extend(rows.into_iter().map(|r| (backend.clone(), r)));
    }
    Ok(all)
}

/// Every figure of the decoder and CPU CSVs under `out`'s backend folders.
pub fn summarise(out: &Path) -> Result<Vec<SummaryLine>> {
    let mut lines = Vec::new();
    for csv in ["decoders_gpu.csv", "decoders_fill.csv", "cpu_threads.csv"] {
        let rows = rows_by_backend(out, csv)?;
        for (backend, r) in &rows {
            let fastest_backend = rows
                .iter()
                .filter(|(_, o)| {
                    o.model == r.model && o.figure == r.figure && o.threads == r.threads
                })
                .all(|(_, o)| o.ours <= r.ours);
            lines.push(SummaryLine {
                figure: format!("{} {}", r.model, r.figure),
                backend: if csv == "cpu_threads.csv" {
                    "cpu".to_string()
                } else {
                    backend.clone()
                },
                threads: r.threads,
                ours: r.ours,
                torch: r.torch,
                ratio: r.ratio,
                fastest_backend,
            });
        }
    }
    Ok(lines)
}
