//! Panels of points side by side, sharing their axes: where an error concentrates along a
//! variable.

use std::path::Path;

use plotters::coord::combinators::BindKeyPoints;
use plotters::prelude::*;

use super::{
    FONT, draw_err, log_ticks, nice_ceil, nice_floor, register_font, save_rgb, tick_label,
};
use crate::core::error::Result;
use crate::report::canvas::Canvas;

/// One panel of [`scatter_panels`]: its title, the points, and a line through them (a
/// running median, say; empty: none).
pub struct ScatterPanel {
    pub title: String,
    pub points: Vec<(f64, f64)>,
    pub line: Vec<(f64, f64)>,
}

/// Panels of points side by side (two a row), sharing a linear x range `x` and a log-y
/// range over every panel's positive values: where an error concentrates along a variable.
pub fn scatter_panels(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    x: std::ops::Range<f64>,
    panels: &[ScatterPanel],
) -> Result<()> {
    register_font();
    let cols = panels.len().clamp(1, 2);
    let rows = panels.len().div_ceil(cols).max(1);
    let (w, h) = (520 * cols as u32, 60 + 330 * rows as u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = Canvas::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let root = root
            .titled(title, (FONT, 22))
            .map_err(|e| draw_err(path, e))?;
        let ys = panels
            .iter()
            .flat_map(|p| p.points.iter().chain(&p.line).map(|q| q.1))
            .filter(|v| *v > 0.0);
        let lo = ys.clone().fold(f64::INFINITY, f64::min);
        let hi = ys.fold(0.0, f64::max);
        let (lo, hi) = if lo.is_finite() && hi > lo {
            (nice_floor(lo), nice_ceil(hi))
        } else {
            (0.1, 10.0)
        };
        for (panel, area) in panels.iter().zip(root.split_evenly((rows, cols))) {
            let mut chart = ChartBuilder::on(&area)
                .caption(&panel.title, (FONT, 16))
                .margin(10)
                .x_label_area_size(36)
                .y_label_area_size(60)
                .build_cartesian_2d(
                    x.clone(),
                    (lo..hi).log_scale().with_key_points(log_ticks(lo, hi)),
                )
                .map_err(|e| draw_err(path, e))?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(y_desc)
                .x_label_formatter(&|v| format!("{v:.0}"))
                .y_label_formatter(&|v| tick_label(*v))
                .label_style((FONT, 12))
                .light_line_style(TRANSPARENT)
                .draw()
                .map_err(|e| draw_err(path, e))?;
            let dot = BLUE.mix(0.3);
            chart
                .draw_series(
                    panel
                        .points
                        .iter()
                        .filter(|p| p.1 > 0.0)
                        .map(|&p| Circle::new(p, 2, dot.filled())),
                )
                .map_err(|e| draw_err(path, e))?;
            if !panel.line.is_empty() {
                chart
                    .draw_series(LineSeries::new(
                        panel.line.iter().copied().filter(|p| p.1 > 0.0),
                        RED.stroke_width(2),
                    ))
                    .map_err(|e| draw_err(path, e))?;
            }
        }
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}
