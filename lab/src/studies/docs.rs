//! The README and `docs/` are generated: their prose lives in `docs/src/*.md`, and every
//! number in them comes from a CSV (or a file an experiment wrote) through a directive, so
//! no typed result can go stale. `cargo run --release --bin reports` writes them (and
//! refreshes every generated `results.md` under `reports/` from its CSV); `tests/docs.rs`
//! checks the checked-in files equal what it would write.
//!
//! Directives, each on one line of a source file, paths relative to the repository root:
//! - `{{table PATH | cols: a, b, c | where: col=value | names: A, B, C}}`: a Markdown table of
//!   those columns of a CSV (all, without `cols`), of the rows that match every `where`
//!   (several, comma-separated), headed by `names` (the column names, without).
//! - `{{value PATH | row: col=value | col: name}}`: one cell, formatted as in the tables.
//! - `{{md PATH}}`: the tables of a generated Markdown report (what follows its
//!   "Generated from" line).
//! - `{{text PATH}}`: a file as it is (a command's captured output); `| last: N` keeps its
//!   last N lines.
//! - `{{experiments}}`: the registry's experiments, one line and one command each.

use std::path::{Path, PathBuf};

use selfmodel::core::error::{Error, Result};
use selfmodel::report::table::{format_cell, read_cells as read_table};

/// Where the sources are, relative to the repository root.
pub const SOURCES: &str = "docs/src";

/// A directive's options: `key: value` parts after the path.
struct Directive<'a> {
    kind: &'a str,
    path: &'a str,
    options: Vec<(&'a str, &'a str)>,
}

impl<'a> Directive<'a> {
    fn parse(inner: &'a str) -> Option<Self> {
        let mut parts = inner.split('|').map(str::trim);
        let (kind, path) = parts.next()?.split_once(' ')?;
        let options = parts
            .map(|p| p.split_once(':').map(|(k, v)| (k.trim(), v.trim())))
            .collect::<Option<Vec<_>>>()?;
        Some(Directive {
            kind,
            path: path.trim(),
            options,
        })
    }

    fn option(&self, key: &str) -> Option<&'a str> {
        self.options
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| *v)
    }

    fn list(&self, key: &str) -> Vec<&'a str> {
        self.option(key)
            .map(|v| v.split(',').map(str::trim).collect())
            .unwrap_or_default()
    }
}

/// The index of `name` in `header`, or an error naming the file.
fn column(header: &[String], name: &str, path: &Path) -> Result<usize> {
    header
        .iter()
        .position(|h| h == name)
        .ok_or_else(|| Error::data(path, format!("no column `{name}`")))
}

/// Whether `row` matches every `col=value` condition.
fn matches(header: &[String], row: &[String], conditions: &[&str], path: &Path) -> Result<bool> {
    for c in conditions {
        let (col, value) = c
            .split_once('=')
            .ok_or_else(|| Error::data(path, format!("bad condition `{c}` (want col=value)")))?;
        if row[column(header, col.trim(), path)?] != value.trim() {
            return Ok(false);
        }
    }
    Ok(true)
}

/// What one directive expands to.
fn expand(root: &Path, d: &Directive) -> Result<String> {
    let path = root.join(d.path);
    let read = |p: &Path| std::fs::read_to_string(p).map_err(|e| Error::io(p, e));
    match d.kind {
        "table" => {
            let (header, rows) = read_table(&path)?;
            let cols: Vec<usize> = match d.list("cols") {
                c if c.is_empty() => (0..header.len()).collect(),
                c => c
                    .iter()
                    .map(|n| column(&header, n, &path))
                    .collect::<Result<_>>()?,
            };
            let names = d.list("names");
            let heads: Vec<&str> = if names.is_empty() {
                cols.iter().map(|&c| header[c].as_str()).collect()
            } else if names.len() == cols.len() {
                names
            } else {
                return Err(Error::data(
                    &path,
                    format!("{} names for {} columns", names.len(), cols.len()),
                ));
            };
            let conditions = d.list("where");
            let mut out = format!(
                "| {} |\n|{}\n",
                heads.join(" | "),
                "---|".repeat(cols.len())
            );
            // A column that holds numbers holds nothing but numbers (NaN: not measured).
            for &c in &cols {
                let numeric = |v: &str| v.parse::<f64>().is_ok();
                if rows.iter().any(|r| numeric(&r[c]) && !r[c].contains("NaN")) {
                    if let Some((i, r)) = rows
                        .iter()
                        .enumerate()
                        .find(|(_, r)| !r[c].is_empty() && !numeric(&r[c]))
                    {
                        return Err(Error::data(
                            &path,
                            format!(
                                "row {} column `{}`: \"{}\" is not a number, in a column of numbers",
                                i + 1,
                                header[c],
                                r[c]
                            ),
                        ));
                    }
                }
            }
            // `first: N`: the first N rows that match (a long table's head: the slowest kernels).
            let first = match d.option("first") {
                Some(n) => n.trim().parse::<usize>().map_err(|_| {
                    Error::data(&path, format!("`first: {n}` is not a number of rows"))
                })?,
                None => usize::MAX,
            };
            let mut kept = 0;
            for r in &rows {
                if kept < first && matches(&header, r, &conditions, &path)? {
                    kept += 1;
                    let cells: Vec<String> = cols.iter().map(|&c| format_cell(&r[c])).collect();
                    out += &format!("| {} |\n", cells.join(" | "));
                }
            }
            Ok(out.trim_end().to_string())
        }
        "value" => {
            let (header, rows) = read_table(&path)?;
            let conditions = d.list("row");
            let col = column(
                &header,
                d.option("col")
                    .ok_or_else(|| Error::data(&path, "a value needs `col: name`"))?,
                &path,
            )?;
            let mut found = None;
            for (i, r) in rows.iter().enumerate() {
                if matches(&header, r, &conditions, &path)? {
                    // A number quoted in prose must be one.
                    let cell = &r[col];
                    if !cell.parse::<f64>().is_ok_and(f64::is_finite) {
                        return Err(Error::data(
                            &path,
                            format!(
                                "row {} column `{}`: \"{cell}\" is not a finite number, and the docs quote it as one",
                                i + 1,
                                header[col]
                            ),
                        ));
                    }
                    found = Some(format_cell(cell));
                    break;
                }
            }
            found.ok_or_else(|| Error::data(&path, format!("no row where {conditions:?}")))
        }
        "md" => {
            let text = read(&path)?;
            let at = text
                .find("Generated from `")
                .ok_or_else(|| Error::data(&path, "not a generated report"))?;
            let rest = &text[at..];
            let tables = &rest[rest.find('\n').unwrap_or(rest.len())..];
            // Its own headings sit one level below the including section's.
            Ok(tables.trim().replace("\n### ", "\n#### "))
        }
        "text" => {
            let text = read(&path)?;
            let lines: Vec<&str> = text.trim_end().lines().collect();
            let keep = match d.option("last") {
                Some(n) => n.trim().parse::<usize>().map_err(|_| {
                    Error::data(&path, format!("`last: {n}` is not a number of lines"))
                })?,
                None => lines.len(),
            };
            Ok(lines[lines.len().saturating_sub(keep)..].join("\n"))
        }
        other => Err(Error::data(&path, format!("unknown directive `{other}`"))),
    }
}

/// `{{experiments}}`: the registry, one line and one command per experiment.
fn experiment_list() -> String {
    let mut out = String::from("| command | what it runs | presets |\n|---|---|---|\n");
    for e in crate::studies::registry::EXPERIMENTS {
        let about = e.about.split(" (").next().unwrap_or(e.about);
        out += &format!(
            "| `cargo run --release --bin {}` | {} | {} |\n",
            e.name,
            about.replace('|', "\\|"),
            e.presets.join(", ")
        );
    }
    out.trim_end().to_string()
}

/// A source's text with every directive expanded.
pub fn render(root: &Path, source: &str) -> Result<String> {
    let mut out = String::new();
    let mut rest = source;
    while let Some(start) = rest.find("{{") {
        out += &rest[..start];
        let end = rest[start..]
            .find("}}")
            .ok_or_else(|| Error::Config("an unclosed `{{` in a docs source".into()))?;
        let inner = &rest[start + 2..start + end];
        if inner.trim() == "experiments" {
            out += &experiment_list();
            rest = &rest[start + end + 2..];
            continue;
        }
        let d = Directive::parse(inner)
            .ok_or_else(|| Error::Config(format!("bad directive `{{{{{inner}}}}}`")))?;
        out += &expand(root, &d)?;
        rest = &rest[start + end + 2..];
    }
    out += rest;
    Ok(out)
}

/// Every generated file (path relative to `root`, contents): the README and `docs/*.md`
/// from their sources, then every `results.md`-style report under `reports/` from its CSV.
pub fn generate(root: &Path) -> Result<Vec<(PathBuf, String)>> {
    let mut out = Vec::new();
    let src_dir = root.join(SOURCES);
    let mut sources: Vec<PathBuf> = std::fs::read_dir(&src_dir)
        .map_err(|e| Error::io(&src_dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    sources.sort();
    for src in sources {
        let name = src
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .to_string();
        let target = if name == "README.md" {
            PathBuf::from("README.md")
        } else {
            Path::new("docs").join(&name)
        };
        let text = std::fs::read_to_string(&src).map_err(|e| Error::io(&src, e))?;
        let banner = format!(
            "<!-- Generated from {SOURCES}/{name} and the CSVs under reports/ by `cargo run --release --bin reports`; edit the source, not this file. -->\n\n"
        );
        out.push((target, banner + &render(root, &text)?));
    }
    let mut dirs = Vec::new();
    collect_dirs(&root.join("reports"), &mut dirs);
    let mut reports: Vec<PathBuf> = dirs
        .iter()
        .filter_map(|d| std::fs::read_dir(d).ok())
        .flat_map(|entries| entries.flatten().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "md"))
        .collect();
    reports.sort();
    // Table II's compact table, from its results and config.
    for d in &dirs {
        if d.join("table2.md").is_file()
            && let Some(text) = crate::studies::emssl::table2::table2_markdown(d)?
        {
            out.push((
                d.join("table2.md")
                    .strip_prefix(root)
                    .unwrap_or(d)
                    .to_path_buf(),
                text,
            ));
        }
    }
    // The self-models against the robot's joints and poses, gathered from the robots' Table I.
    out.extend(crate::studies::scaling::tables(root)?);
    for md in reports {
        if let Some(text) = selfmodel::report::table::regenerated_report(&md)? {
            let rel = md.strip_prefix(root).unwrap_or(&md).to_path_buf();
            out.push((rel, text));
        }
    }
    Ok(out)
}

/// The generated files whose checked-in text differs from what [`generate`] writes.
pub fn stale(root: &Path) -> Result<Vec<PathBuf>> {
    Ok(generate(root)?
        .into_iter()
        .filter(|(p, text)| std::fs::read_to_string(root.join(p)).ok().as_deref() != Some(text))
        .map(|(p, _)| p)
        .collect())
}

/// Write every generated file until they agree (a document may quote another generated
/// one, Table II's `table2.md`); returns how many writes changed a file.
pub fn write_all(root: &Path) -> Result<usize> {
    let mut changed = 0;
    for _ in 0..3 {
        let pass = write_pass(root)?;
        changed += pass;
        if pass == 0 {
            break;
        }
    }
    Ok(changed)
}

fn write_pass(root: &Path) -> Result<usize> {
    let mut changed = 0;
    for (p, text) in generate(root)? {
        let path = root.join(&p);
        if std::fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            selfmodel::core::atomic_file::write_bytes(&path, text.as_bytes())?;
            changed += 1;
        }
    }
    Ok(changed)
}

/// Redraw the figures that are drawn from one CSV beside them, from that CSV: every
/// `pareto.png` beside a self-model `results.csv` (titled by its `results.md`) and every
/// `training_curve.png` beside a `curve.csv`. Returns how many were drawn.
pub fn redraw_figures(root: &Path) -> Result<usize> {
    use crate::studies::pareto::{pareto_floors, pareto_points};
    use selfmodel::self_models::result::read_results;
    type Draw = fn(&Path) -> Result<()>;
    // The studies' own figures, each redrawn by the study's code from its CSVs:
    // (the CSV it reads, a figure it draws, the drawing code).
    let studies: [(&str, &str, Draw); 4] = [
        (
            "results.csv",
            "success_against_time.png",
            crate::studies::bench::ik::draw_figures,
        ),
        (
            "curves.csv",
            "curves_90.png",
            crate::studies::emssl::study::draw_figures,
        ),
        (
            "adaptation_curve.csv",
            "adaptation_ur5.png",
            crate::studies::emssl::adaptation::draw_figures,
        ),
        (
            "thread_sweep.csv",
            "sampling_time_vs_threads.png",
            crate::studies::emssl::sampling_speed::draw_figures,
        ),
    ];
    let mut dirs = Vec::new();
    collect_dirs(&root.join("reports"), &mut dirs);
    dirs.sort();
    let mut drawn = usize::from(crate::studies::scaling::draw_joints(root)?);
    for dir in dirs {
        let results = dir.join("results.csv");
        if dir.join("pareto.png").is_file() && results.is_file() {
            let rows = read_results(&results)?;
            let title = selfmodel::report::table::markdown_title(&dir.join("results.md"))
                .unwrap_or_else(|| "Quality against inference speed".into());
            selfmodel::report::figures::pareto_plot(
                &dir.join("pareto.png"),
                &title,
                "PSNR on the test set (dB)",
                &pareto_points(&rows, |m| m.to_string()),
                &pareto_floors(&rows),
            )?;
            drawn += 1;
        }
        for (csv, figure, draw) in studies {
            if dir.join(csv).is_file() && dir.join(figure).is_file() {
                draw(&dir)?;
                drawn += 1;
            }
        }
        // Table II's error against the base angle at +-180 degrees, from its answers.
        if dir.join("table2.md").is_file()
            && dir.join("error_by_base_angle_180.png").is_file()
            && crate::studies::emssl::table2::draw_error_by_base_angle(&dir, 180.0)?
        {
            drawn += 1;
        }
        // The EMSSL learning curves (Table II's and the long curve's).
        for csv in ["emssl_curve.csv", "results.csv"] {
            if dir.join("learning_curve.png").is_file() && dir.join(csv).is_file() {
                let header = std::fs::read_to_string(dir.join(csv)).unwrap_or_default();
                if header.starts_with("robot,range_deg,iteration,") {
                    crate::studies::emssl::table2::redraw_learning_curve(&dir, csv)?;
                    drawn += 1;
                }
            }
        }
        // An ablation's training curves, one line per setting, from the settings' folders
        // (the data-scale ablation's with its scaling figure).
        if dir.join("training_curves.png").is_file()
            && dir.file_name() == Some(std::ffi::OsStr::new("ablation_data_scale"))
        {
            crate::studies::data_scale::draw(&dir)?;
            drawn += 1;
        } else if dir.join("training_curves.png").is_file()
            && let Some(ablation) = dir
                .file_name()
                .and_then(|n| crate::studies::ablations::Ablation::named(&n.to_string_lossy()))
        {
            crate::studies::ablations::draw_training_curves(ablation, &dir)?;
            drawn += 1;
        }
        if dir.join("training_curve.png").is_file() && dir.join("curve.csv").is_file() {
            // Titled by the model the run trained (its config's name, as the run titled it),
            // else its first result row's.
            let configured = std::fs::read_to_string(dir.join("config.json"))
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .and_then(|c| c.get("name")?.as_str().map(String::from));
            let name = configured
                .or_else(|| {
                    read_results(&results)
                        .ok()
                        .and_then(|r| r.first().map(|r| r.model.clone()))
                })
                .unwrap_or_else(|| dir.file_name().unwrap_or_default().to_string_lossy().into());
            selfmodel::report::table::draw_training_curve(&dir, &name)?;
            drawn += 1;
        }
    }
    Ok(drawn)
}

fn collect_dirs(dir: &Path, out: &mut Vec<PathBuf>) {
    out.push(dir.to_path_buf());
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            if e.path().is_dir() {
                collect_dirs(&e.path(), out);
            }
        }
    }
}
