//! The study's figures: the grid, PSNR against the angle to the nearest trained camera, and
//! PSNR against the number of cameras.

use std::path::Path;

use selfmodel::core::error::Result;
use selfmodel::report::figures::{GridRow, image_grid};

use super::{HeldOutCamera, MultiviewConfig, MultiviewRow};

/// The grid, PSNR against the angle to the nearest trained camera, and PSNR against N.
pub(super) fn draw(
    out: &Path,
    cfg: &MultiviewConfig,
    rows: &[MultiviewRow],
    grid_truth: &[Vec<f32>],
    grid: &[(String, Vec<Vec<f32>>)],
    [h, w]: [usize; 2],
) -> Result<()> {
    if !grid_truth.is_empty() {
        let mut grid_rows = vec![GridRow::Grey(
            grid_truth.iter().map(Vec::as_slice).collect(),
        )];
        let mut titles = vec!["truth".to_string()];
        for (name, images) in grid {
            grid_rows.push(GridRow::Grey(images.iter().map(Vec::as_slice).collect()));
            titles.push(name.clone());
        }
        let titles: Vec<&str> = titles.iter().map(String::as_str).collect();
        let captions: Vec<String> = cfg.held_out.iter().map(HeldOutCamera::label).collect();
        image_grid(
            &out.join("grid.png"),
            &grid_rows,
            &titles,
            &captions,
            w,
            h,
            if w < 64 { 4 } else { 2 },
        )?;
    }
    // One line per model and N: the multi-head model at the largest N only, the view-blind
    // bound at N = 1 only (lines of several N would join unrelated points).
    let largest = cfg.cameras.iter().copied().max().unwrap_or(1);
    let key_of = |r: &MultiviewRow| {
        let name = r.model.split(" (").next().unwrap_or(&r.model);
        format!("{name} (N = {})", r.cameras_trained)
    };
    let mut models: Vec<String> = Vec::new();
    for r in rows {
        let key = key_of(r);
        if !models.contains(&key) {
            models.push(key);
        }
    }
    let runs: Vec<(String, Vec<(f64, f64)>)> = models
        .iter()
        .filter(|m| !m.starts_with("view-blind") || m.ends_with("(N = 1)"))
        .filter(|m| {
            !m.starts_with("NeuroKin multi-head") || m.ends_with(&format!("(N = {largest})"))
        })
        .map(|m| {
            let mut pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| &key_of(r) == m && r.psnr_db.is_finite())
                .map(|r| (r.angle_to_nearest_deg, r.psnr_db))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            (m.clone(), pts)
        })
        .collect();
    selfmodel::report::figures::line_plot(
        &out.join("psnr_vs_angle.png"),
        "PSNR on held-out poses against the angle to the nearest trained camera",
        ("angle to the nearest trained camera (degrees)", "PSNR (dB)"),
        &runs,
        selfmodel::report::figures::LinePlot::LINEAR.marked(),
    )?;
    if cfg.cameras.len() > 1 {
        let mut cams = vec!["trained".to_string()];
        cams.extend(cfg.held_out.iter().map(HeldOutCamera::label));
        let runs: Vec<(String, Vec<(f64, f64)>)> = cams
            .iter()
            .map(|c| {
                (
                    if c == "trained" {
                        "trained cameras".to_string()
                    } else {
                        c.clone()
                    },
                    rows.iter()
                        .filter(|r| {
                            r.model.starts_with("NeuroKin camera-conditioned") && &r.camera == c
                        })
                        .map(|r| (r.cameras_trained as f64, r.psnr_db))
                        .collect(),
                )
            })
            .collect();
        selfmodel::report::figures::line_plot(
            &out.join("psnr_vs_cameras.png"),
            "Camera-conditioned NeuroKin: PSNR on held-out poses against trained cameras",
            ("trained cameras (N)", "PSNR (dB)"),
            &runs,
            selfmodel::report::figures::LinePlot::LOG_X,
        )?;
    }
    Ok(())
}
