//! Every method's answers as CSV (target, joints, reached position): written, read back, and
//! found (the committed sample or all of them).

use std::io::Write;
use std::path::{Path, PathBuf};

use nalgebra::Point3;

use selfmodel::core::atomic_file::write_atomic;
use selfmodel::core::error::{Error, Result};
use selfmodel::ik::paper::method::file_name;

/// The columns of a predictions CSV that are not joints.
pub(super) const PREDICTION_COLUMNS: [&str; 6] = [
    "target_x",
    "target_y",
    "target_z",
    "reached_x",
    "reached_y",
    "reached_z",
];

/// Write answers as CSV: target x, y, z (m), the joints (rad) in columns named after them
/// (`names`; `q1..` where they cannot be), reached x, y, z (m) (where the forward kinematics
/// of the joints puts the end effector).
pub fn write_predictions(
    path: &Path,
    targets: &[Point3<f64>],
    joints: &[Vec<f64>],
    reached: &[Point3<f64>],
    names: &[String],
) -> Result<()> {
    write_atomic(path, |w| {
        let io = |e| Error::io(path, e);
        let qs = selfmodel::ik::solve::learned::joint_columns(names, &PREDICTION_COLUMNS);
        writeln!(
            w,
            "target_x,target_y,target_z,{},reached_x,reached_y,reached_z",
            qs.join(",")
        )
        .map_err(io)?;
        for ((t, q), r) in targets.iter().zip(joints).zip(reached) {
            let q: Vec<String> = q.iter().map(|v| format!("{v:.9}")).collect();
            writeln!(
                w,
                "{:.9},{:.9},{:.9},{},{:.9},{:.9},{:.9}",
                t.x,
                t.y,
                t.z,
                q.join(","),
                r.x,
                r.y,
                r.z
            )
            .map_err(io)?;
        }
        Ok(())
    })
}

/// Read the joints back from a predictions CSV ([`write_predictions`]): every column but the
/// targets and the reached positions, named after the joints or `q1..`.
pub fn read_predictions(path: &Path) -> Result<Vec<Vec<f64>>> {
    let mut reader = csv::Reader::from_path(path)
        .map_err(|e| Error::data(path, format!("cannot read predictions: {e}")))?;
    let header = reader
        .headers()
        .map_err(|e| Error::data(path, format!("bad header: {e}")))?
        .clone();
    let cols: Vec<usize> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| !PREDICTION_COLUMNS.contains(h))
        .map(|(i, _)| i)
        .collect();
    reader
        .records()
        .map(|r| {
            let r = r.map_err(|e| Error::data(path, format!("bad row: {e}")))?;
            cols.iter()
                .map(|&i| {
                    r[i].parse::<f64>()
                        .map_err(|e| Error::data(path, format!("bad joint: {e}")))
                })
                .collect()
        })
        .collect()
}

/// Targets and the positions the answers reached, from a predictions CSV
/// ([`write_predictions`]).
pub fn read_reached(path: &Path) -> Result<Vec<(Point3<f64>, Point3<f64>)>> {
    let (header, cells) = selfmodel::report::table::read_cells(path)?;
    let col = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| Error::data(path, format!("no column {name}")))
    };
    let cols = PREDICTION_COLUMNS.map(col);
    let mut idx = [0; 6];
    for (i, c) in cols.into_iter().enumerate() {
        idx[i] = c?;
    }
    cells
        .iter()
        .map(|r| {
            let v: Vec<f64> = idx
                .iter()
                .map(|&i| {
                    r[i].parse::<f64>()
                        .map_err(|e| Error::data(path, format!("bad number {}: {e}", r[i])))
                })
                .collect::<Result<_>>()?;
            Ok((Point3::new(v[0], v[1], v[2]), Point3::new(v[3], v[4], v[5])))
        })
        .collect()
}

/// A row's answers: the committed sample, else all of them (`predictions_<range>/`, where
/// the run was made here and keeps no sample); with whether it is the sample.
pub(super) fn answers_file(dir: &Path, range_deg: f64, method: &str) -> Option<(PathBuf, bool)> {
    let file = format!("{}.csv", file_name(method));
    let all = dir.join(format!("predictions_{range_deg:.0}")).join(&file);
    let sample = dir
        .join("predictions_sample")
        .join(format!("{range_deg:.0}"))
        .join(&file);
    // The committed sample first: what is generated from it is the same in every checkout.
    if sample.is_file() {
        Some((sample, true))
    } else if all.is_file() {
        Some((all, false))
    } else {
        None
    }
}
