//! Table II's figures: each method's validation curve per range, and the error against the
//! target's base angle (where a joint-space regression's seam shows).

use std::path::Path;

use selfmodel::core::error::Result;
use selfmodel::ik::paper::method::ValidationRow;

use super::predictions::{answers_file, read_reached};

/// `error_by_base_angle_<range>.png`: each learned method's error against the target's angle
/// about the base's vertical axis (atan2(y, x)), one panel per method, with the median per
/// 10-degree bin: at +-180 degrees a joint-space regression must jump between solution
/// branches somewhere, and the seam shows as a band of large errors at one angle. From every
/// answer where the run was made in this checkout, else the committed sample. Returns whether
/// there was anything to draw.
pub fn draw_error_by_base_angle(dir: &Path, range_deg: f64) -> Result<bool> {
    let methods = ["EMSSL", "DSL", "EMSSL (wrapped)", "DSL (wrapped)"];
    let mut panels = Vec::new();
    let mut sampled = false;
    for m in methods {
        let Some((path, sample)) = answers_file(dir, range_deg, m) else {
            continue;
        };
        sampled |= sample;
        let points: Vec<(f64, f64)> = read_reached(&path)?
            .iter()
            .map(|(t, q)| (t.y.atan2(t.x).to_degrees(), 100.0 * (t - q).norm()))
            .collect();
        let line: Vec<(f64, f64)> = (0..36)
            .filter_map(|b| {
                let lo = -180.0 + 10.0 * b as f64;
                let mut v: Vec<f64> = points
                    .iter()
                    .filter(|p| p.0 >= lo && p.0 < lo + 10.0)
                    .map(|p| p.1)
                    .collect();
                (!v.is_empty()).then(|| {
                    v.sort_by(f64::total_cmp);
                    (lo + 5.0, v[v.len() / 2])
                })
            })
            .collect();
        panels.push(selfmodel::report::figures::ScatterPanel {
            title: format!("{m}, {} targets", points.len()),
            points,
            line,
        });
    }
    if panels.is_empty() {
        return Ok(false);
    }
    selfmodel::report::figures::scatter_panels(
        &dir.join(format!("error_by_base_angle_{range_deg:.0}.png")),
        &format!(
            "Error against the target's base angle, +-{range_deg:.0} deg{} (red: median per 10 deg)",
            if sampled { ", committed sample" } else { "" }
        ),
        "target's angle about the base axis (deg)",
        "distance error (cm, log)",
        -180.0..180.0,
        &panels,
    )?;
    Ok(true)
}

/// `validation_curves_<range>.png` (and `validation_curves_<range>_wrapped.png` for the wrapped
/// variants): every method's validation error against epoch (EMSSL: iteration), log-y.
pub(super) fn validation_figure(
    dir: &Path,
    robot_name: &str,
    range_deg: f64,
    curves: &[ValidationRow],
) -> Result<()> {
    for (wrapped, suffix) in [(false, ""), (true, "_wrapped")] {
        let mut methods: Vec<&str> = Vec::new();
        for c in curves.iter().filter(|c| c.range_deg == range_deg) {
            if c.method.contains("(wrapped)") == wrapped && !methods.contains(&c.method.as_str()) {
                methods.push(&c.method);
            }
        }
        if methods.is_empty() {
            continue;
        }
        let runs: Vec<(String, Vec<(usize, f64)>)> = methods
            .iter()
            .map(|m| {
                (
                    m.to_string(),
                    curves
                        .iter()
                        .filter(|c| c.range_deg == range_deg && c.method == *m)
                        .map(|c| (c.epoch, c.validation_cm))
                        .collect(),
                )
            })
            .collect();
        selfmodel::report::figures::curves(
            &dir.join(format!("validation_curves_{range_deg:.0}{suffix}.png")),
            &format!(
                "Validation error while training, {} +-{range_deg:.0} deg{}",
                short_name(robot_name),
                if wrapped { ", wrapped output" } else { "" }
            ),
            "epoch (EMSSL: iteration)",
            "validation distance error (cm, log)",
            &runs,
        )?;
    }
    Ok(())
}

/// A robot's name for a figure title: a built-in's in capitals (`UR5`), a URDF's file stem
/// (`panda`).
pub(super) fn short_name(robot_name: &str) -> String {
    let first = robot_name.split_whitespace().next().unwrap_or(robot_name);
    let path = Path::new(first);
    match (path.extension(), path.file_stem()) {
        (Some(_), Some(stem)) => stem.to_string_lossy().to_string(),
        _ => robot_name.to_uppercase(),
    }
}
