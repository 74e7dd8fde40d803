//! A dataset's joint vectors: drawn by its sampler, or read from a file a user gives.

use std::path::Path;

use super::DatasetConfig;
use crate::core::error::{Error, Result};
use crate::data::npz::read_npz;
use crate::sim::robot::Robot;
use crate::sim::trajectory::{SamplerKind, babbling, grid, lorenz};

/// Joint vectors (user units) for a config, from its sampler.
pub fn sample_angles(robot: &Robot, cfg: &DatasetConfig) -> Result<Vec<Vec<f64>>> {
    // Before anything is drawn: a sample count the images could never fit is refused now,
    // not after drawing its joint vectors.
    cfg.validate()?;
    let ranges = robot.chain.joint_ranges_user();
    match cfg.sampler {
        SamplerKind::Lorenz => lorenz(cfg.samples, &ranges),
        SamplerKind::Babbling => Ok(babbling(cfg.samples, &ranges, cfg.seed)),
        SamplerKind::Grid => {
            // Degrees for rotational joints; a prismatic joint's range in as many steps as
            // +-90 degrees would take.
            let steps: Vec<f64> = robot
                .chain
                .movable_joints()
                .zip(&ranges)
                .map(|(j, r)| {
                    if j.kind.is_rotational() {
                        cfg.grid_step_deg
                    } else {
                        (r[1] - r[0]).max(1e-9) * cfg.grid_step_deg / 180.0
                    }
                })
                .collect();
            let points = grid(cfg.samples, &ranges, &steps, cfg.seed)?;
            if points.len() < cfg.samples {
                return Err(Error::Config(format!(
                    "a grid step of {} degrees gives {} joint vectors, fewer than the {} samples asked: lower `grid_step` or ask fewer `samples`",
                    cfg.grid_step_deg,
                    points.len(),
                    cfg.samples
                )));
            }
            Ok(points)
        }
    }
}

/// The largest joint value [`read_angles`] takes: one turn, in degrees.
pub const MAX_JOINT_VALUE: f64 = 360.0;

/// Read joint vectors (user units) from a CSV (one row per pose, one column per joint, an
/// optional header) or an `.npz` with an `angles` (N, DOF) array. Checks the column count
/// and that every value is finite.
pub fn read_angles(path: &Path, dof: usize) -> Result<Vec<Vec<f64>>> {
    let bad = |msg: String| Error::data(path, msg);
    let rows: Vec<Vec<f64>> = if path.extension().is_some_and(|e| e == "npz") {
        let mut arrays = read_npz(path)?;
        let a = arrays
            .remove("angles")
            .ok_or_else(|| bad("missing key \"angles\"".into()))?;
        let [_, cols] = a.shape[..] else {
            return Err(bad(format!(
                "\"angles\" must have shape (N, {dof}), found {:?}",
                a.shape
            )));
        };
        if cols == 0 {
            return Err(bad("\"angles\" has no columns".into()));
        }
        a.to_f64().chunks(cols).map(<[f64]>::to_vec).collect()
    } else {
        let max = crate::core::input_file::MAX_TABLE_BYTES;
        crate::core::input_file::check_user_file(path, "angles file", max)?;
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(file);
        let mut rows = Vec::new();
        for (i, rec) in reader.records().enumerate() {
            if i % crate::core::interrupt::ROWS_BETWEEN_CHECKS == 0 {
                crate::core::interrupt::check(|| {
                    format!("stopped reading {} at line {}", path.display(), i + 1)
                })?;
            }
            let rec = rec.map_err(|e| bad(format!("line {}: {e}", i + 1)))?;
            let line = rec.iter().collect::<Vec<_>>().join(",");
            if rec.len() == 1 && [';', '\t', ' '].iter().any(|c| line.contains(*c)) {
                return Err(bad(format!(
                    "line {}: \"{line}\" is one field; separate the joints with commas",
                    i + 1
                )));
            }
            let parsed: Vec<Option<f64>> = rec.iter().map(|f| f.parse::<f64>().ok()).collect();
            // A header is a first line of names only: a line with one bad number is a typo.
            if i == 0 && parsed.iter().all(Option::is_none) {
                continue;
            }
            match parsed.into_iter().collect::<Option<Vec<f64>>>() {
                Some(v) => rows.push(v),
                None => {
                    return Err(bad(format!(
                        "line {}: not a list of numbers: \"{line}\"",
                        i + 1
                    )));
                }
            }
        }
        rows
    };
    if rows.is_empty() {
        return Err(bad("no joint vectors (zero samples)".into()));
    }
    for (i, r) in rows.iter().enumerate() {
        if r.len() != dof {
            return Err(bad(format!(
                "row {} has {} values, the robot has {dof} joints",
                i + 1,
                r.len()
            )));
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("row {} has a NaN or infinite angle", i + 1)));
        }
        if let Some(v) = r.iter().find(|v| v.abs() > MAX_JOINT_VALUE) {
            let v = if v.abs() >= 1e6 {
                format!("{v:e}")
            } else {
                v.to_string()
            };
            return Err(bad(format!(
                "row {}: {v} is outside +-{MAX_JOINT_VALUE} (degrees for a rotational joint: one turn either way)",
                i + 1
            )));
        }
    }
    Ok(rows)
}
