//! The CSV files a pose model reads and writes: the joint and target columns, a target from a
//! row's values, the targets file read with Ctrl-C checked between rows.

use std::path::Path;

use nalgebra::Point3;

use crate::core::error::{Error, Result};
use crate::ik::solve::levenberg_marquardt::PoseTarget;

/// The CSV columns of a joint vector: the joints' names, or `q1..qN` where two share a name
/// or a name is one of `taken` (the file's other columns).
pub fn joint_columns(names: &[String], taken: &[&str]) -> Vec<String> {
    let clash = names.iter().enumerate().any(|(i, n)| {
        n.is_empty()
            || n.contains([',', '"', '\n'])
            || taken.contains(&n.as_str())
            || names[..i].contains(n)
    });
    if clash {
        (1..=names.len()).map(|i| format!("q{i}")).collect()
    } else {
        names.to_vec()
    }
}

/// The columns of a target: `x,y,z,qw,qx,qy,qz` (`x,y,z` when `position_only`) for one tip,
/// each prefixed with its tip's name (`A.x,...,B.x,...`) for several.
pub fn target_columns(tips: &[String], position_only: bool) -> Vec<String> {
    let axes: &[&str] = if position_only {
        &["x", "y", "z"]
    } else {
        &["x", "y", "z", "qw", "qx", "qy", "qz"]
    };
    if tips.is_empty() {
        return axes.iter().map(|a| a.to_string()).collect();
    }
    tips.iter()
        .flat_map(|t| axes.iter().map(move |a| format!("{t}.{a}")))
        .collect()
}

/// One target from its values in [`target_columns`] order (finite numbers): an error (what
/// is wrong, for the caller to place) for a position beyond [`MAX_TARGET_COORDINATE`] or a
/// quaternion that is not of unit norm. The one check of every way targets come in (a CSV
/// file, the Python package).
pub fn target_from_values(
    v: &[f64],
    position_only: bool,
    tips: &[String],
) -> std::result::Result<Vec<PoseTarget>, String> {
    let per_tip = if position_only { 3 } else { 7 };
    let want = per_tip * tips.len().max(1);
    if v.len() != want {
        return Err(format!("{} values where a target has {want}", v.len()));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("{x} is not a finite number"));
    }
    let mut row = Vec::with_capacity(v.len() / per_tip);
    for (t, v) in v.chunks(per_tip).enumerate() {
        let position = Point3::new(v[0], v[1], v[2]);
        if position.coords.amax() > MAX_TARGET_COORDINATE {
            return Err(format!(
                "the position ({}, {}, {}) lies more than {MAX_TARGET_COORDINATE} m from the robot's origin: give targets in metres",
                v[0], v[1], v[2]
            ));
        }
        let orientation = if position_only {
            None
        } else {
            let q = nalgebra::Quaternion::new(v[3], v[4], v[5], v[6]);
            let norm = q.norm();
            if !(0.9..=1.1).contains(&norm) {
                let of = tips.get(t).map_or(String::new(), |n| format!(" of {n}"));
                return Err(format!(
                    "the quaternion{of} (qw, qx, qy, qz) has norm {norm:.4}, not 1"
                ));
            }
            Some(nalgebra::UnitQuaternion::from_quaternion(q))
        };
        row.push(PoseTarget {
            position,
            orientation,
        });
    }
    Ok(row)
}

/// The farthest a target may lie from the robot's origin along an axis (m): far beyond any
/// robot's reach, near enough that it stays finite in the network's single precision.
pub const MAX_TARGET_COORDINATE: f64 = 1e3;

/// A target file's rows: [`target_columns`] (metres; a header names the columns, others are
/// ignored). A bad row fails naming its line.
pub fn read_targets(
    path: &Path,
    position_only: bool,
    tips: &[String],
) -> Result<Vec<Vec<PoseTarget>>> {
    let bad = |msg: String| Error::data(path, msg);
    let max = crate::core::input_file::MAX_TABLE_BYTES;
    crate::core::input_file::check_user_file(path, "targets file", max)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(file);
    let header = reader
        .headers()
        .map_err(|e| bad(format!("line 1: {e}")))?
        .clone();
    let need = target_columns(tips, position_only);
    if let Some(n) = need
        .iter()
        .find(|n| header.iter().filter(|h| h == n).count() > 1)
    {
        return Err(bad(format!(
            "line 1: the column \"{n}\" appears twice; keep one"
        )));
    }
    let cols: Vec<usize> = need
        .iter()
        .map(|n| {
            header.iter().position(|h| h == n).ok_or_else(|| {
                bad(format!(
                    "line 1: no column \"{n}\" (the header must name {}{})",
                    need.join(","),
                    if position_only {
                        ""
                    } else {
                        "; a position-only model takes x,y,z"
                    }
                ))
            })
        })
        .collect::<Result<_>>()?;
    let mut out = Vec::new();
    for (i, rec) in reader.records().enumerate() {
        let line = i + 2;
        if i % crate::core::interrupt::ROWS_BETWEEN_CHECKS == 0 {
            crate::core::interrupt::check(|| {
                format!("stopped reading {} at line {line}", path.display())
            })?;
        }
        let rec = rec.map_err(|e| bad(format!("line {line}: {e}")))?;
        let v: Vec<f64> = cols
            .iter()
            .map(|&c| {
                let cell = rec.get(c).unwrap_or("");
                cell.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(format!("line {line}: \"{cell}\" is not a finite number")))
            })
            .collect::<Result<_>>()?;
        let row = target_from_values(&v, position_only, tips)
            .map_err(|e| bad(format!("line {line}: {e}")))?;
        out.push(row);
    }
    if out.is_empty() {
        return Err(bad("no targets (a header and at least one row)".into()));
    }
    Ok(out)
}
