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

/// The title of a generated Markdown table (its first line, without the `# `), if it exists.
pub fn markdown_title(path: &Path) -> Option<String> {
    std::fs::read_to_string(path)
        .ok()?
        .lines()
        .next()
        .map(|l| l.trim_start_matches("# ").to_string())
}

/// The columns of a generated table of self-model results (`ModelResult`) that a reader needs first; the rest
/// follow in a second table (the CSV keeps everything).
pub const SELF_MODEL_COLUMNS: &[&str] = &[
    "model",
    "psnr_db_test",
    "iou_test",
    "depth_mae_mm",
    "infer_b1_img_per_s",
    "infer_b256_img_per_s",
    "train_time_s",
    "paper_psnr_db",
    "paper_fps",
    "paper_train_time_s",
];

/// Columns that say where a row came from, not what it measured: a generated table shows
/// them apart from the results (a footnote when every row agrees, a second table otherwise).
pub const PROVENANCE: &[&str] = &[
    "dataset",
    "preset",
    "device",
    "precision",
    "git_revision",
    "revision",
    "steps_override",
    "note",
    "notes",
];

/// A number as a table shows it: 4 significant digits, no more than 4 decimals, none at
/// 1,000 and above, two significant digits in scientific notation below 0.001 (where four
/// decimals would show 0.0000); anything else as written.
pub fn format_cell(cell: &str) -> String {
    let Ok(v) = cell.parse::<f64>() else {
        return cell.to_string();
    };
    if v.is_nan() {
        // Not measured (the short preset times batch 1 only).
        return "–".to_string();
    }
    if !cell.contains('.') || !v.is_finite() {
        return cell.to_string();
    }
    let a = v.abs();
    if a > 0.0 && a < 1e-3 {
        return format!("{v:.1e}");
    }
    let decimals = if a >= 1000.0 || a == 0.0 {
        0
    } else {
        (3 - a.log10().floor() as i32).clamp(0, 4) as usize
    };
    format!("{v:.decimals$}")
}

/// One Markdown table of `columns` (indices into `header`) of `rows`.
fn markdown_table(header: &[String], rows: &[Vec<String>], columns: &[usize]) -> String {
    let mut out = format!(
        "| {} |\n|{}\n",
        columns
            .iter()
            .map(|&c| header[c].as_str())
            .collect::<Vec<_>>()
            .join(" | "),
        "---|".repeat(columns.len())
    );
    for r in rows {
        let cells: Vec<String> = columns
            .iter()
            .map(|&c| format_cell(&r[c]).replace('|', "\\|"))
            .collect();
        out += &format!("| {} |\n", cells.join(" | "));
    }
    out
}

/// A CSV file as text: its header and its rows of cells.
pub fn read_cells(path: &Path) -> Result<(Vec<String>, Vec<Vec<String>>)> {
    let mut reader = csv::Reader::from_path(path)
        .map_err(|e| Error::data(path, format!("cannot read CSV: {e}")))?;
    let header = reader
        .headers()
        .map_err(|e| Error::data(path, format!("bad CSV header: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    for rec in reader.records() {
        let rec = rec.map_err(|e| Error::data(path, format!("bad CSV row: {e}")))?;
        rows.push(rec.iter().map(str::to_string).collect());
    }
    Ok((header, rows))
}

/// The columns a table of `header` shows first: a self-model's results
/// ([`SELF_MODEL_COLUMNS`]) or, for any other table, every column but
/// the provenance ones (empty).
fn main_columns(header: &[String]) -> &'static [&'static str] {
    if header.iter().any(|h| h == "psnr_db_test") {
        SELF_MODEL_COLUMNS
    } else {
        &[]
    }
}

/// The Markdown of a CSV file: its main columns ([`main_columns`]) in one table, the others
/// (with the first column, the row's name) in a second, and the provenance columns folded
/// into a footnote where every row agrees.
pub fn markdown_from_csv(path: &Path) -> Result<String> {
    let (header, rows) = read_cells(path)?;
    let main = main_columns(&header);
    let is_provenance = |c: &usize| PROVENANCE.contains(&header[*c].as_str());
    // A paper reference column with no figure in any row (another robot, a setting the paper
    // never ran) is left out of the Markdown; the CSV keeps it.
    let all: Vec<usize> = (0..header.len())
        .filter(|&c| !header[c].starts_with("paper_") || rows.iter().any(|r| !r[c].is_empty()))
        .collect();
    let main_cols: Vec<usize> = if main.is_empty() {
        all.iter().copied().filter(|c| !is_provenance(c)).collect()
    } else {
        main.iter()
            .filter_map(|m| header.iter().position(|h| h == m))
            .filter(|c| all.contains(c))
            .collect()
    };
    let key = main_cols.first().copied().unwrap_or(0);
    let rest: Vec<usize> = all
        .iter()
        .copied()
        .filter(|c| !main_cols.contains(c) && !is_provenance(c))
        .collect();
    let mut out = markdown_table(&header, &rows, &main_cols);
    if !rest.is_empty() {
        out += "\n### More columns\n\n";
        out += &markdown_table(&header, &rows, &[vec![key], rest].concat());
    }
    // Provenance: one line for what every row shares, a table for what differs.
    let (mut same, mut differ) = (Vec::new(), Vec::new());
    for c in all.iter().copied().filter(is_provenance) {
        let first = rows.first().map(|r| r[c].as_str()).unwrap_or("");
        if rows.iter().all(|r| r[c] == first) {
            if !first.is_empty() {
                same.push(format!("{} `{first}`", header[c]));
            }
        } else {
            differ.push(c);
        }
    }
    if !same.is_empty() || !differ.is_empty() {
        out += "\n### Provenance\n\n";
    }
    if !same.is_empty() {
        out += &format!("Every row: {}.\n", same.join(", "));
    }
    if !differ.is_empty() {
        out += "\n";
        out += &markdown_table(&header, &rows, &[vec![key], differ].concat());
    }
    if rows.iter().flatten().any(|c| c.ends_with("-dirty")) {
        out += &format!("\n{DIRTY}\n");
    }
    Ok(out)
}

/// What a `-dirty` revision means, under every generated table that has one.
pub const DIRTY: &str = "A revision ending in `-dirty`: the working tree differed from that commit when the run started, so its code was that commit's plus changes that were not recorded. Runs before 2026-11-23 were marked so by any changed tracked file, a report another run was rewriting included; since then only a change to the code (`src/`, `experiments/`, `Cargo.toml`, `Cargo.lock`) marks a row. Re-running the command on a clean checkout replaces such a row.";

/// Write `results.md` beside `results.csv`: a title, a note, and the generated tables.
pub fn write_markdown_report(csv_path: &Path, title: &str, note: &str) -> Result<()> {
    let text = markdown_report(csv_path, title, note)?;
    write_bytes(&csv_path.with_extension("md"), text.as_bytes())
}

/// The line that marks a Markdown report as generated from the CSV beside it.
const GENERATED: &str = "Generated from `";

/// What [`write_markdown_report`] writes.
pub fn markdown_report(csv_path: &Path, title: &str, note: &str) -> Result<String> {
    let table = markdown_from_csv(csv_path)?;
    Ok(format!(
        "# {title}\n\n{note}\n\n{GENERATED}{}` (every column, full precision); do not edit by hand.\n\n{table}",
        csv_path.file_name().unwrap_or_default().to_string_lossy()
    ))
}

/// A generated Markdown report (`x.md` beside `x.csv`) as it would be written from the CSV
/// now, keeping its title and note: `None` for a file that is not such a report.
pub fn regenerated_report(md_path: &Path) -> Result<Option<String>> {
    let csv_path = md_path.with_extension("csv");
    if !csv_path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(md_path).map_err(|e| Error::io(md_path, e))?;
    let Some(title) = text.lines().next().and_then(|l| l.strip_prefix("# ")) else {
        return Ok(None);
    };
    let body = &text[text.find('\n').unwrap_or(text.len())..];
    let Some(at) = body.find(&format!("\n{GENERATED}")) else {
        return Ok(None);
    };
    let note = body[..at].trim();
    markdown_report(&csv_path, title, note).map(Some)
}

/// One logged point of a training curve (`curve.csv`).
#[derive(serde::Serialize, serde::Deserialize)]
struct CurveRow {
    step: usize,
    loss: f64,
}

/// A run's training curve: `dir/curve.csv` (step, loss) and `dir/training_curve.png`.
pub fn write_training_curve(
    dir: &Path,
    name: &str,
    log: &crate::train::config::TrainLog,
) -> Result<()> {
    let rows: Vec<CurveRow> = log
        .curve
        .iter()
        .map(|&(step, loss)| CurveRow { step, loss })
        .collect();
    write_csv(&dir.join("curve.csv"), &rows)?;
    #[cfg(feature = "figures")]
    draw_training_curve(dir, name)?;
    #[cfg(not(feature = "figures"))]
    let _ = name;
    Ok(())
}

/// The (step, loss) points of a `curve.csv`.
pub fn read_curve(path: &Path) -> Result<Vec<(usize, f64)>> {
    Ok(read_csv::<CurveRow>(path)?
        .into_iter()
        .map(|r| (r.step, r.loss))
        .collect())
}

/// `dir/training_curve.png` from `dir/curve.csv`, titled by the model's `name`.
#[cfg(feature = "figures")]
pub fn draw_training_curve(dir: &Path, name: &str) -> Result<()> {
    let points = read_curve(&dir.join("curve.csv"))?;
    // A single point (a model fitted in one pass: the baselines) draws no line.
    if points.len() < 2 {
        return Ok(());
    }
    crate::report::figures::training_curves(
        &dir.join("training_curve.png"),
        &format!("{name}: training loss"),
        &[(name.to_string(), points)],
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
