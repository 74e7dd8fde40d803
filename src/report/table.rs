//! Results are data: experiments write CSV rows; Markdown tables are generated from the CSV.

use std::path::Path;

use crate::core::atomic_file::{write_atomic, write_bytes};
use crate::core::error::{Error, Result};

/// Write serialisable rows as CSV (header from the field names), atomically.
pub fn write_csv<T: serde::Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    write_atomic(path, |w| {
        let mut csv = csv::Writer::from_writer(w);
        for r in rows {
            csv.serialize(r)
                .map_err(|e| Error::data(path, format!("cannot write CSV: {e}")))?;
        }
        csv.flush().map_err(|e| Error::io(path, e))
    })
}

/// Read rows written by [`write_csv`].
pub fn read_csv<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Vec<T>> {
    csv::Reader::from_path(path)
        .and_then(|mut r| r.deserialize().collect())
        .map_err(|e| Error::data(path, format!("cannot read CSV rows: {e}")))
}

/// A Markdown table of a CSV file (numbers with more than 4 decimals are rounded to 4).
pub fn markdown_from_csv(path: &Path) -> Result<String> {
    let mut reader = csv::Reader::from_path(path)
        .map_err(|e| Error::data(path, format!("cannot read CSV: {e}")))?;
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| Error::data(path, format!("bad CSV header: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    let mut out = format!(
        "| {} |\n|{}\n",
        header.join(" | "),
        "---|".repeat(header.len())
    );
    for rec in reader.records() {
        let rec = rec.map_err(|e| Error::data(path, format!("bad CSV row: {e}")))?;
        let cells: Vec<String> = rec
            .iter()
            .map(|c| match c.parse::<f64>() {
                Ok(v) if c.contains('.') && c.split('.').nth(1).is_some_and(|d| d.len() > 4) => {
                    format!("{v:.4}")
                }
                _ => c.to_string(),
            })
            .collect();
        out += &format!("| {} |\n", cells.join(" | "));
    }
    Ok(out)
}

/// Write `results.md` beside `results.csv`: a title, a note, and the generated table.
pub fn write_markdown_report(csv_path: &Path, title: &str, note: &str) -> Result<()> {
    let table = markdown_from_csv(csv_path)?;
    let text = format!(
        "# {title}\n\n{note}\n\nGenerated from `{}`; do not edit by hand.\n\n{table}",
        csv_path.file_name().unwrap_or_default().to_string_lossy()
    );
    write_bytes(&csv_path.with_extension("md"), text.as_bytes())
}

/// A run's training curve: `dir/curve.csv` (step, loss) and `dir/training_curve.png`.
pub fn write_training_curve(
    dir: &Path,
    name: &str,
    log: &crate::train::trainer::TrainLog,
) -> Result<()> {
    #[derive(serde::Serialize)]
    struct CurveRow {
        step: usize,
        loss: f64,
    }
    let rows: Vec<CurveRow> = log
        .curve
        .iter()
        .map(|&(step, loss)| CurveRow { step, loss })
        .collect();
    write_csv(&dir.join("curve.csv"), &rows)?;
    // A single point (a model fitted in one pass: the baselines) draws no line.
    if rows.len() < 2 {
        return Ok(());
    }
    crate::report::figures::training_curves(
        &dir.join("training_curve.png"),
        &format!("{name}: training loss"),
        &[(name.to_string(), log.curve.clone())],
    )
}

/// Write `rows` as CSV at `path` and the Markdown table generated from it beside it.
pub fn write_table<T: serde::Serialize>(
    path: &Path,
    rows: &[T],
    title: &str,
    note: &str,
) -> Result<()> {
    write_csv(path, rows)?;
    write_markdown_report(path, title, note)
}
