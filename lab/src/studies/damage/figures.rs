//! The recovery figures: PSNR against n per method, and each method's trade-off between the
//! damaged arm and the healthy one.

use std::path::Path;

use super::recovery::RecoveryRow;
use selfmodel::core::error::Result;

/// `recovery_damaged.png` and `recovery_healthy.png`: PSNR against n per method, the first
/// damage; `recovery_tradeoff_<damage>.png` per damage: at the n nearest 50, each method's PSNR
/// on the healthy arm against the damaged one's (EWC's weights joined, as a path).
pub(super) fn draw_recovery(out: &Path, rows: &[RecoveryRow]) -> Result<()> {
    let first = &rows[0];
    let same =
        |r: &&RecoveryRow| r.damage == first.damage && r.size == first.size && r.link == first.link;
    let mut methods: Vec<&str> = Vec::new();
    for r in rows.iter().filter(same) {
        if r.method != "from scratch" && !methods.contains(&r.method.as_str()) {
            methods.push(&r.method);
        }
    }
    for (file, what, f) in [
        (
            "recovery_damaged.png",
            "the damaged arm",
            (|r: &RecoveryRow| r.psnr_damaged_db) as fn(&RecoveryRow) -> f64,
        ),
        (
            "recovery_healthy.png",
            "the healthy arm (forgetting)",
            |r: &RecoveryRow| r.psnr_healthy_db,
        ),
    ] {
        let runs: Vec<(String, Vec<(f64, f64)>)> = methods
            .iter()
            .map(|m| {
                (
                    m.to_string(),
                    rows.iter()
                        .filter(same)
                        .filter(|r| r.method == *m)
                        .map(|r| (r.n as f64, f(r)))
                        .collect(),
                )
            })
            .collect();
        selfmodel::report::figures::line_plot(
            &out.join(file),
            &format!(
                "PSNR on {what} after recovery from n images ({} {}, link {})",
                first.damage, first.size, first.link
            ),
            ("images of the damaged arm (n)", "PSNR (dB)"),
            &runs,
            selfmodel::report::figures::LinePlot::LOG_X,
        )?;
    }
    let mut damages: Vec<(&str, f64, usize)> = Vec::new();
    for r in rows {
        let d = (r.damage.as_str(), r.size, r.link);
        if !damages.contains(&d) {
            damages.push(d);
        }
    }
    for (damage, size, link) in damages {
        let of: Vec<&RecoveryRow> = rows
            .iter()
            .filter(|r| (r.damage.as_str(), r.size, r.link) == (damage, size, link))
            .collect();
        let Some(n) = of
            .iter()
            .filter(|r| r.method != "from scratch")
            .map(|r| r.n)
            .min_by_key(|n| n.abs_diff(50))
        else {
            continue;
        };
        let point = |r: &RecoveryRow| (r.psnr_healthy_db, r.psnr_damaged_db);
        let mut runs: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
        let ewc: Vec<(f64, f64)> = of
            .iter()
            .filter(|r| r.n == n && r.method.starts_with("EWC"))
            .map(|r| point(r))
            .collect();
        for r in &of {
            if r.method.starts_with("EWC") || (r.n != n && r.method != "from scratch") {
                continue;
            }
            runs.push((r.method.clone(), vec![point(r)]));
        }
        if !ewc.is_empty() {
            runs.push(("EWC, weight rising".into(), ewc));
        }
        selfmodel::report::figures::line_plot(
            &out.join(format!(
                "recovery_tradeoff_{}.png",
                selfmodel::core::atomic_file::file_name(&format!("{damage} {size} link {link}"))
            )),
            &format!(
                "Damaged arm against healthy arm, {damage} {size} link {link}, n = {n} images"
            ),
            (
                "PSNR on the healthy arm (dB)",
                "PSNR on the damaged arm (dB)",
            ),
            &runs,
            selfmodel::report::figures::LinePlot::LINEAR.marked(),
        )?;
    }
    Ok(())
}
