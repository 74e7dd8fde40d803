//! Quality against inference speed (the Pareto plot), labels placed where they overlap nothing.

use std::path::Path;

use plotters::coord::combinators::BindKeyPoints;
use plotters::prelude::*;

use super::{
    Chart, F64Axis, FONT, draw_err, draw_legend, log_ticks, register_font, save_rgb, tick_label,
};
use crate::core::error::Result;
use crate::report::canvas::Canvas;

/// One point of the Pareto plot.
#[derive(Clone, Debug)]
pub struct ParetoPoint {
    pub label: String,
    /// Inference images per second (batch 1).
    pub fps: f64,
    /// Quality (PSNR in dB or IoU).
    pub quality: f64,
    /// Paper reference points are drawn hollow.
    pub reference: bool,
}

/// A rectangle in pixels, for placing labels that do not overlap.
#[derive(Clone, Copy)]
struct Rect {
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
}

impl Rect {
    fn overlaps(&self, o: &Rect) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }
    fn inside(&self, o: &Rect) -> bool {
        self.x0 >= o.x0 && self.x1 <= o.x1 && self.y0 >= o.y0 && self.y1 <= o.y1
    }
}

/// Where to put each label beside its point (pixel position of the point, label width and
/// height): the first of a ring of candidate positions that stays inside `area` and clear of
/// every point and label placed so far; `None` where none is clear (the caller numbers it).
fn place_labels(
    points: &[(i32, i32, i32, i32)],
    area: Rect,
    obstacles: &[Rect],
) -> Vec<Option<(i32, i32)>> {
    let marker = |&(x, y, _, _): &(i32, i32, i32, i32)| Rect {
        x0: x - 7,
        y0: y - 7,
        x1: x + 7,
        y1: y + 7,
    };
    let mut taken: Vec<Rect> = points.iter().map(marker).collect();
    taken.extend_from_slice(obstacles);
    let mut out = Vec::with_capacity(points.len());
    for &(x, y, w, h) in points {
        let gap = 9;
        let candidates = [
            (x + gap, y - h / 2),
            (x - gap - w, y - h / 2),
            (x - w / 2, y - gap - h),
            (x - w / 2, y + gap),
            (x + gap, y - gap - h),
            (x + gap, y + gap),
            (x - gap - w, y - gap - h),
            (x - gap - w, y + gap),
            (x + gap, y - 2 * h - gap),
            (x + gap, y + h + gap),
            (x - gap - w, y - 2 * h - gap),
            (x - gap - w, y + h + gap),
        ];
        let spot = candidates.iter().copied().find(|&(cx, cy)| {
            let r = Rect {
                x0: cx - 2,
                y0: cy - 1,
                x1: cx + w + 2,
                y1: cy + h + 1,
            };
            r.inside(&area) && !taken.iter().any(|t| t.overlaps(&r))
        });
        if let Some((cx, cy)) = spot {
            taken.push(Rect {
                x0: cx - 2,
                y0: cy - 1,
                x1: cx + w + 2,
                y1: cy + h + 1,
            });
        }
        out.push(spot);
    }
    out
}

/// Quality against inference speed, log-x, with the 1,000 FPS control-loop line.
/// `floors`: lower bounds (label, quality), drawn as dashed horizontal lines. Our points are
/// filled blue, the paper's hollow black (another machine: a T4 GPU); labels are placed
/// beside their points where they overlap nothing, and numbered in a key below the legend
/// where no place is free.
pub fn pareto_plot(
    path: &Path,
    title: &str,
    y_label: &str,
    points: &[ParetoPoint],
    floors: &[(String, f64)],
) -> Result<()> {
    register_font();
    let (w, h) = (1000u32, 650u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = Canvas::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let ((x0, x1), (y0, y1)) = ranges(points, floors);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 22))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(60)
            .build_cartesian_2d(
                (x0..x1).log_scale().with_key_points(log_ticks(x0, x1)),
                y0..y1,
            )
            .map_err(|e| draw_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc(if points.iter().any(|p| p.reference) {
                "inference images/s at batch 1 (log): ours on this CPU, the paper's on a T4 GPU"
            } else {
                "inference images/s at batch 1 (log), on this CPU"
            })
            .y_desc(y_label)
            .x_label_formatter(&|v| tick_label(*v))
            .label_style((FONT, 14))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(|e| draw_err(path, e))?;
        chart
            .draw_series(LineSeries::new(
                [(1000.0, y0), (1000.0, y1)],
                RED.stroke_width(2),
            ))
            .map_err(|e| draw_err(path, e))?
            .label("1,000 FPS (1 kHz control loop)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        draw_floors(&mut chart, floors, (x0, x1), path)?;
        draw_points(&mut chart, points, path)?;
        // Labels where they overlap nothing; a number and a key entry elsewhere.
        let (xr, yr) = chart.plotting_area().get_pixel_range();
        let area = Rect {
            x0: xr.start,
            y0: yr.start,
            x1: xr.end,
            y1: yr.end,
        };
        let sized: Vec<(i32, i32, i32, i32)> = points
            .iter()
            .map(|p| {
                let (x, y) = chart.backend_coord(&(p.fps, p.quality));
                (x, y, CHAR_W * p.label.chars().count() as i32, FONT_PX + 2)
            })
            .collect();
        let (legend_pos, legend_rect) = legend_corner(points, floors, &sized, area);
        let spots = place_labels(&sized, area, &[legend_rect]);
        let key = draw_labels(&root, points, &sized, &spots, path)?;
        draw_legend(&mut chart, path, legend_pos)?;
        // The key of numbered labels: in the top corner the legend does not take.
        let key_x = if legend_rect.y0 == area.y0 && legend_rect.x0 == area.x0 {
            area.x1 - 10 - CHAR_W * key.iter().map(|k| k.chars().count()).max().unwrap_or(0) as i32
        } else {
            area.x0 + 10
        };
        for (i, line) in key.iter().enumerate() {
            root.draw(&Text::new(
                line.clone(),
                (key_x, area.y0 + 8 + i as i32 * (FONT_PX + 4)),
                (FONT, FONT_PX).into_font(),
            ))
            .map_err(|e| draw_err(path, e))?;
        }
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}

/// The labels' font size and the width of a character in it (pixels).
const FONT_PX: i32 = 13;
const CHAR_W: i32 = 8;

/// The plot's ranges: images/s from half the slowest point (1 at most) to three times the
/// fastest (2,000 at least), log; the qualities and floors, padded.
fn ranges(points: &[ParetoPoint], floors: &[(String, f64)]) -> ((f64, f64), (f64, f64)) {
    let fps_min = points
        .iter()
        .map(|p| p.fps)
        .fold(f64::INFINITY, f64::min)
        .min(1.0);
    let fps_max = points.iter().map(|p| p.fps).fold(1.0, f64::max).max(2000.0);
    let qualities = || {
        points
            .iter()
            .map(|p| p.quality)
            .chain(floors.iter().map(|f| f.1))
    };
    let q_min = qualities().fold(f64::INFINITY, f64::min);
    let q_max = qualities().fold(f64::NEG_INFINITY, f64::max);
    let pad = ((q_max - q_min) * 0.15).max(0.5 * q_max.abs().max(1e-3) * 0.02);
    ((fps_min / 2.0, fps_max * 3.0), (q_min - pad, q_max + pad))
}

/// The lower bounds as dashed grey lines across the log axis `x0..x1`.
fn draw_floors<'a, DB: DrawingBackend + 'a, X: F64Axis, Y: F64Axis>(
    chart: &mut Chart<'a, DB, X, Y>,
    floors: &[(String, f64)],
    (x0, x1): (f64, f64),
    path: &Path,
) -> Result<()> {
    for (label, q) in floors {
        let grey = BLACK.mix(0.5);
        // Dashes: short segments across the log axis.
        let n = 60;
        let segments: Vec<Vec<(f64, f64)>> = (0..n)
            .step_by(2)
            .map(|k| {
                let at = |t: f64| x0 * (x1 / x0).powf(t / n as f64);
                vec![(at(k as f64), *q), (at(k as f64 + 1.0), *q)]
            })
            .collect();
        chart
            .draw_series(
                segments
                    .into_iter()
                    .map(|s| PathElement::new(s, grey.stroke_width(2))),
            )
            .map_err(|e| draw_err(path, e))?
            .label(format!("{label} ({q:.2})"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(2))
            });
    }
    Ok(())
}

/// Our points filled blue, the paper's hollow black, each kind with a key entry where it has
/// points.
fn draw_points<'a, DB: DrawingBackend + 'a, X: F64Axis, Y: F64Axis>(
    chart: &mut Chart<'a, DB, X, Y>,
    points: &[ParetoPoint],
    path: &Path,
) -> Result<()> {
    let ours_style = BLUE.filled();
    let paper_style = BLACK.stroke_width(2);
    for (reference, name) in [(false, "ours (this CPU)"), (true, "paper (T4 GPU)")] {
        // No key entry for the paper's points where there are none (another robot).
        if !points.iter().any(|p| p.reference == reference) {
            continue;
        }
        let style = if reference { paper_style } else { ours_style };
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.reference == reference)
                    .map(|p| Circle::new((p.fps, p.quality), 6, style)),
            )
            .map_err(|e| draw_err(path, e))?
            .label(name)
            .legend(move |(x, y)| Circle::new((x + 10, y), 6, style));
    }
    Ok(())
}

/// The legend's corner of the plotting `area`: the one where it covers the fewest points
/// (`sized`: each point's pixel position and label size), and the rectangle it takes.
fn legend_corner(
    points: &[ParetoPoint],
    floors: &[(String, f64)],
    sized: &[(i32, i32, i32, i32)],
    area: Rect,
) -> (SeriesLabelPosition, Rect) {
    let entries = 1
        + floors.len()
        + [false, true]
            .iter()
            .filter(|&&r| points.iter().any(|p| p.reference == r))
            .count();
    let legend_w = 50
        + CHAR_W
            * floors
                .iter()
                .map(|(l, _)| l.chars().count() + 8)
                .chain([30])
                .max()
                .unwrap_or(30) as i32;
    let legend_h = 12 + 17 * entries as i32;
    let corners = [
        (SeriesLabelPosition::LowerLeft, area.x0, area.y1 - legend_h),
        (
            SeriesLabelPosition::LowerRight,
            area.x1 - legend_w,
            area.y1 - legend_h,
        ),
        (SeriesLabelPosition::UpperLeft, area.x0, area.y0),
        (SeriesLabelPosition::UpperRight, area.x1 - legend_w, area.y0),
    ];
    corners
        .into_iter()
        .map(|(pos, x, y)| {
            let r = Rect {
                x0: x,
                y0: y,
                x1: x + legend_w + 10,
                y1: y + legend_h + 10,
            };
            (pos, r)
        })
        .min_by_key(|(_, r)| {
            sized
                .iter()
                .filter(|&&(x, y, w, _)| {
                    r.overlaps(&Rect {
                        x0: x - 7,
                        y0: y - 10,
                        x1: x + w.min(80),
                        y1: y + 10,
                    })
                })
                .count()
        })
        .expect("four corners")
}

/// Each point's label at its free spot, or a number beside the point where none is free: the
/// key lines of the numbered ones.
fn draw_labels<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    points: &[ParetoPoint],
    sized: &[(i32, i32, i32, i32)],
    spots: &[Option<(i32, i32)>],
    path: &Path,
) -> Result<Vec<String>> {
    let mut key = Vec::new();
    for ((p, spot), &(x, y, _, _)) in points.iter().zip(spots).zip(sized) {
        let color = if p.reference { BLACK } else { BLUE };
        let font = (FONT, FONT_PX).into_font().color(&color);
        match spot {
            Some((cx, cy)) => root
                .draw(&Text::new(p.label.clone(), (*cx, *cy), font))
                .map_err(|e| draw_err(path, e))?,
            None => {
                key.push(format!("{}: {}", key.len() + 1, p.label));
                root.draw(&Text::new(format!("{}", key.len()), (x + 8, y - 16), font))
                    .map_err(|e| draw_err(path, e))?;
            }
        }
    }
    Ok(key)
}
