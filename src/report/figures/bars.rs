//! Horizontal bars, a row per link: how far each set of collision spheres stands outside each
//! link (its largest protrusion, and the mean over its outer surface inside it).

use std::path::Path;

use plotters::prelude::*;

use super::{FONT, draw_err, draw_legend, register_font, save_rgb};
use crate::core::error::Result;
use crate::report::canvas::Canvas;

/// Each series (a set of spheres: its label, and per link its name, largest and mean
/// protrusion in mm) as a pair of bars a link: the largest light, the mean dark over it.
pub fn protrusion_bars(
    path: &Path,
    title: &str,
    series: &[(String, Vec<(String, f64, f64)>)],
) -> Result<()> {
    register_font();
    let mut links: Vec<&str> = Vec::new();
    for (_, rows) in series {
        for (link, _, _) in rows {
            if !links.contains(&link.as_str()) {
                links.push(link);
            }
        }
    }
    let n = links.len().max(1);
    let k = series.len().max(1);
    let top = series
        .iter()
        .flat_map(|(_, r)| r.iter().map(|x| x.1))
        .fold(1.0, f64::max);
    let top = (top * 1.05 / 10.0).ceil() * 10.0;
    // A row below the links' holds the legend, clear of every bar.
    let legend_rows = (12 + 18 * k as u32).div_ceil(22 * k as u32 + 8) as f64;
    let (w, h) = (
        900u32,
        120 + (22 * k as u32 + 8) * (n as u32 + legend_rows as u32),
    );
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = Canvas::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let root = root
            .titled(title, (FONT, 20))
            .map_err(|e| draw_err(path, e))?;
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .margin_right(30)
            .x_label_area_size(40)
            .y_label_area_size(190)
            .build_cartesian_2d(0.0..top, -legend_rows..n as f64)
            .map_err(|e| draw_err(path, e))?;
        let label_of = |v: &f64| {
            let i = (n as f64 - v - 0.5).round();
            let near = (n as f64 - v - 0.5 - i).abs() < 1e-6;
            match (near, links.get(i as usize)) {
                (true, Some(l)) if i >= 0.0 => l.to_string(),
                _ => String::new(),
            }
        };
        chart
            .configure_mesh()
            .x_desc("protrusion outside the link (mm): largest (light), mean over the spheres' outer surface (dark)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_labels(2 * (n + legend_rows as usize) + 1)
            .y_label_formatter(&label_of)
            .label_style((FONT, 13))
            .disable_y_mesh()
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(|e| draw_err(path, e))?;
        let band = 0.8 / k as f64;
        for (s, (label, rows)) in series.iter().enumerate() {
            let color = Palette99::pick(s).to_rgba();
            let light = color.mix(0.35);
            let bar = |i: usize| {
                let y1 = n as f64 - i as f64 - 0.1 - band * s as f64;
                (y1 - band * 0.9, y1)
            };
            let placed: Vec<(usize, f64, f64)> = rows
                .iter()
                .filter_map(|(l, max, mean)| {
                    links.iter().position(|x| x == l).map(|i| (i, *max, *mean))
                })
                .collect();
            chart
                .draw_series(placed.iter().map(|&(i, max, _)| {
                    let (y0, y1) = bar(i);
                    Rectangle::new([(0.0, y0), (max, y1)], light.filled())
                }))
                .map_err(|e| draw_err(path, e))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 18, y + 5)], color.filled())
                });
            chart
                .draw_series(placed.iter().map(|&(i, _, mean)| {
                    let (y0, y1) = bar(i);
                    Rectangle::new([(0.0, y0), (mean, y1)], color.filled())
                }))
                .map_err(|e| draw_err(path, e))?;
        }
        draw_legend(&mut chart, path, SeriesLabelPosition::LowerRight)?;
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}
