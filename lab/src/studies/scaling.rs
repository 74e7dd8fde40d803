//! Self-models against the robot's joint count and their training poses (issue 75): every
//! self-model's Table I row on the papers' arm (4 joints), the UR5 (6), the Panda (7) and the
//! G1's whole body (29), each on 1,600 training poses with the paper preset, gathered from the
//! CSVs their runs wrote into `reports/scaling/joints.csv`, and the Panda's and the G1's on
//! 1,600 and 9,600 poses into `poses.csv` (generated, as the docs are, by the `reports`
//! binary); `joints.png` drawn from the first (`reports --figures`).

use std::path::{Path, PathBuf};

use selfmodel::core::error::Result;
use selfmodel::report::figures::{LinePlot, line_plot};
use selfmodel::self_models::result::{ModelResult, read_results};

/// A column of a scaling table: a robot's rows on some number of training poses.
struct Column {
    robot: &'static str,
    /// What the column is named by after the robot: its joints (`joints.csv`) or its training
    /// poses (`poses.csv`).
    key: usize,
    /// The folders whose `results.csv` hold its rows (a Table I, and LinkSplat's run, which
    /// joins a Table I only on request).
    folders: &'static [&'static str],
    train_samples: usize,
}

/// The robots, each on the paper preset's 1,600 poses, named by their joints.
const JOINTS: &[Column] = &[
    Column {
        robot: "arm4",
        key: 4,
        folders: &["reports/table1", "reports/link_splat"],
        train_samples: 1600,
    },
    Column {
        robot: "ur5",
        key: 6,
        folders: &[
            "reports/robots/ur5/table1",
            "reports/robots/ur5/table1/link_splat",
        ],
        train_samples: 1600,
    },
    Column {
        robot: "panda",
        key: 7,
        folders: &[
            "reports/robots/panda/table1",
            "reports/robots/panda/table1/link_splat",
        ],
        train_samples: 1600,
    },
    Column {
        robot: "g1",
        key: 29,
        folders: &[
            "reports/robots/g1/table1",
            "reports/robots/g1/table1/link_splat",
        ],
        train_samples: 1600,
    },
];

/// The robots with a Table I on six times the poses, on 1,600 and on 9,600.
const POSES: &[Column] = &[
    Column {
        robot: "panda",
        key: 1600,
        folders: &[
            "reports/robots/panda/table1",
            "reports/robots/panda/table1/link_splat",
        ],
        train_samples: 1600,
    },
    Column {
        robot: "panda",
        key: 9600,
        folders: &[
            "reports/robots/panda/table1_9600",
            "reports/robots/panda/table1_9600/link_splat",
        ],
        train_samples: 9600,
    },
    Column {
        robot: "g1",
        key: 1600,
        folders: &[
            "reports/robots/g1/table1",
            "reports/robots/g1/table1/link_splat",
        ],
        train_samples: 1600,
    },
    Column {
        robot: "g1",
        key: 9600,
        folders: &[
            "reports/robots/g1/table1_9600",
            "reports/robots/g1/table1_9600/link_splat",
        ],
        train_samples: 9600,
    },
];

/// Where the tables and the figure live.
pub const DIR: &str = "reports/scaling";

/// Each column's rows: the paper preset's, on the clean data and the column's poses.
fn rows(
    root: &Path,
    columns: &'static [Column],
) -> Result<Vec<(&'static Column, Vec<ModelResult>)>> {
    let mut out = Vec::new();
    for column in columns {
        let mut rows = Vec::new();
        for folder in column.folders {
            let csv = root.join(folder).join("results.csv");
            if csv.is_file() {
                rows.extend(read_results(&csv)?.into_iter().filter(|r| {
                    r.preset == "paper"
                        && r.dataset == "clean"
                        && r.train_samples == column.train_samples
                }));
            }
        }
        out.push((column, rows));
    }
    Ok(out)
}

/// The robots' rows and the models measured on two robots or more (in order of first
/// appearance). `None` where no robot has rows.
type Columns = Vec<(&'static Column, Vec<ModelResult>)>;
fn table(root: &Path, columns: &'static [Column]) -> Result<Option<(Columns, Vec<String>)>> {
    let robots = rows(root, columns)?;
    if robots.iter().all(|(_, r)| r.is_empty()) {
        return Ok(None);
    }
    let mut models: Vec<String> = Vec::new();
    for (_, rows) in &robots {
        for r in rows {
            if !models.contains(&r.model) {
                models.push(r.model.clone());
            }
        }
    }
    models.retain(|m| robots.iter().filter(|(_, r)| on(m, r).is_some()).count() >= 2);
    Ok(Some((robots, models)))
}

/// `model`'s row among `rows`.
fn on<'a>(model: &str, rows: &'a [ModelResult]) -> Option<&'a ModelResult> {
    rows.iter().find(|r| r.model == model)
}

/// The generated tables, each its path and text: `joints.csv` (the robots by joints) and
/// `poses.csv` (the Panda and the G1 on 1,600 and 9,600 poses). A row a model measured in two
/// columns or more, its PSNR and IoU on each column's test poses (empty where it was not run).
pub fn tables(root: &Path) -> Result<Vec<(PathBuf, String)>> {
    let mut out = Vec::new();
    for (name, columns) in [("joints.csv", JOINTS), ("poses.csv", POSES)] {
        if let Some(text) = csv(root, columns)? {
            out.push((Path::new(DIR).join(name), text));
        }
    }
    Ok(out)
}

/// One table's text: columns `<robot>_<key>_psnr_db`, then `<robot>_<key>_iou`.
fn csv(root: &Path, columns: &'static [Column]) -> Result<Option<String>> {
    let Some((robots, models)) = table(root, columns)? else {
        return Ok(None);
    };
    let mut header = vec!["model".to_string()];
    for metric in ["psnr_db", "iou"] {
        header.extend(
            robots
                .iter()
                .map(|(c, _)| format!("{}_{}_{metric}", c.robot, c.key)),
        );
    }
    let mut csv = csv::Writer::from_writer(Vec::new());
    let written = |e: csv::Error| selfmodel::Error::Config(format!("{DIR}: {e}"));
    csv.write_record(&header).map_err(written)?;
    for m in &models {
        let mut record = vec![m.clone()];
        for metric in [0, 1] {
            record.extend(robots.iter().map(|(_, rows)| {
                on(m, rows).map_or(String::new(), |r| {
                    format!("{}", [r.psnr_db_test, r.iou_test][metric])
                })
            }));
        }
        csv.write_record(&record).map_err(written)?;
    }
    let bytes = csv
        .into_inner()
        .map_err(|e| selfmodel::Error::Config(format!("{DIR}: {e}")))?;
    Ok(Some(String::from_utf8_lossy(&bytes).into_owned()))
}

/// `joints.png`: PSNR on the test poses against the robot's joints (log), a line a model
/// kind of `joints.csv` (its name before any " ("): the variant with the best mean PSNR.
/// Returns whether it drew (there is a table).
pub fn draw_joints(root: &Path) -> Result<bool> {
    let Some((robots, models)) = table(root, JOINTS)? else {
        return Ok(false);
    };
    let kind = |m: &str| m.split(" (").next().unwrap_or(m).to_string();
    let mean = |m: &str| {
        let psnr: Vec<f64> = robots
            .iter()
            .filter_map(|(_, rows)| on(m, rows).map(|r| r.psnr_db_test))
            .collect();
        psnr.iter().sum::<f64>() / psnr.len().max(1) as f64
    };
    let best: Vec<&String> = models
        .iter()
        .filter(|m| {
            models
                .iter()
                .filter(|o| kind(o) == kind(m))
                .all(|o| mean(o) <= mean(m))
        })
        .collect();
    let lines: Vec<(String, Vec<(f64, f64)>)> = best
        .iter()
        .map(|m| {
            let points = robots
                .iter()
                .filter_map(|(c, rows)| on(m, rows).map(|r| (c.key as f64, r.psnr_db_test)))
                .collect();
            (m.to_string(), points)
        })
        .collect();
    let dir = root.join(DIR);
    std::fs::create_dir_all(&dir).map_err(|e| selfmodel::Error::io(&dir, e))?;
    line_plot(
        &dir.join("joints.png"),
        "Self-models against the robot's joints (1,600 training poses each)",
        (
            "joints (log): arm4 4, UR5 6, Panda 7, G1 whole body 29",
            "PSNR on the test poses (dB)",
        ),
        &lines,
        LinePlot::LOG_X,
    )?;
    Ok(true)
}
