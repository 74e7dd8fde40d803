//! Self-models against the robot's joint count (issue 75): every self-model's Table I row on
//! the papers' arm (4 joints), the UR5 (6), the Panda (7) and the G1's whole body (29), each on
//! 1,600 training poses with the paper preset, gathered from the CSVs their runs wrote into
//! `reports/scaling/joints.csv` (generated, as the docs are, by the `reports` binary) and drawn
//! into `joints.png` (`reports --figures`).

use std::path::{Path, PathBuf};

use selfmodel::core::error::Result;
use selfmodel::report::figures::{LinePlot, line_plot};
use selfmodel::self_models::result::{ModelResult, read_results};

/// The robots: name, joints, and the folders whose `results.csv` hold its rows (its Table I,
/// and LinkSplat's run, which joins a Table I only on request).
const ROBOTS: &[(&str, usize, &[&str])] = &[
    ("arm4", 4, &["reports/table1", "reports/link_splat"]),
    (
        "ur5",
        6,
        &[
            "reports/robots/ur5/table1",
            "reports/robots/ur5/table1/link_splat",
        ],
    ),
    (
        "panda",
        7,
        &[
            "reports/robots/panda/table1",
            "reports/robots/panda/table1/link_splat",
        ],
    ),
    (
        "g1",
        29,
        &[
            "reports/robots/g1/table1",
            "reports/robots/g1/table1/link_splat",
        ],
    ),
];

/// Where the table and figure live.
pub const DIR: &str = "reports/scaling";

/// Each robot's rows: the paper preset's, on the clean data and 1,600 training poses.
fn rows(root: &Path) -> Result<Vec<(&'static str, usize, Vec<ModelResult>)>> {
    let mut out = Vec::new();
    for &(robot, joints, folders) in ROBOTS {
        let mut rows = Vec::new();
        for folder in folders {
            let csv = root.join(folder).join("results.csv");
            if csv.is_file() {
                rows.extend(read_results(&csv)?.into_iter().filter(|r| {
                    r.preset == "paper" && r.dataset == "clean" && r.train_samples == 1600
                }));
            }
        }
        out.push((robot, joints, rows));
    }
    Ok(out)
}

/// The robots' rows and the models measured on two robots or more (in order of first
/// appearance). `None` where no robot has rows.
type Robots = Vec<(&'static str, usize, Vec<ModelResult>)>;
fn table(root: &Path) -> Result<Option<(Robots, Vec<String>)>> {
    let robots = rows(root)?;
    if robots.iter().all(|(_, _, r)| r.is_empty()) {
        return Ok(None);
    }
    let mut models: Vec<String> = Vec::new();
    for (_, _, rows) in &robots {
        for r in rows {
            if !models.contains(&r.model) {
                models.push(r.model.clone());
            }
        }
    }
    models.retain(|m| robots.iter().filter(|(_, _, r)| on(m, r).is_some()).count() >= 2);
    Ok(Some((robots, models)))
}

/// `model`'s row among `rows`.
fn on<'a>(model: &str, rows: &'a [ModelResult]) -> Option<&'a ModelResult> {
    rows.iter().find(|r| r.model == model)
}

/// `joints.csv`'s path and text: a row a model measured on two robots or more, PSNR and IoU
/// on each robot's test poses (empty where it was not run).
pub fn joints_csv(root: &Path) -> Result<Option<(PathBuf, String)>> {
    let Some((robots, models)) = table(root)? else {
        return Ok(None);
    };
    let mut text = String::from("model");
    for metric in ["psnr_db", "iou"] {
        for (robot, joints, _) in &robots {
            text += &format!(",{robot}_{joints}_{metric}");
        }
    }
    text.push('\n');
    for m in &models {
        text += &csv_cell(m);
        for metric in [0, 1] {
            for (_, _, rows) in &robots {
                let cell = on(m, rows).map_or(String::new(), |r| {
                    format!("{}", [r.psnr_db_test, r.iou_test][metric])
                });
                text += &format!(",{cell}");
            }
        }
        text.push('\n');
    }
    Ok(Some((Path::new(DIR).join("joints.csv"), text)))
}

fn csv_cell(s: &str) -> String {
    if s.contains(',') || s.contains('"') {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// `joints.png`: PSNR on the test poses against the robot's joints (log), a line a model
/// kind of `joints.csv` (its name before any " ("): the variant with the best mean PSNR.
/// Returns whether it drew (there is a table).
pub fn draw_joints(root: &Path) -> Result<bool> {
    let Some((robots, models)) = table(root)? else {
        return Ok(false);
    };
    let kind = |m: &str| m.split(" (").next().unwrap_or(m).to_string();
    let mean = |m: &str| {
        let psnr: Vec<f64> = robots
            .iter()
            .filter_map(|(_, _, rows)| on(m, rows).map(|r| r.psnr_db_test))
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
                .filter_map(|(_, joints, rows)| {
                    on(m, rows).map(|r| (*joints as f64, r.psnr_db_test))
                })
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
