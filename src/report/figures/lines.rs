//! Lines, one per run: against a count on log-y (training curves), on log-x with log or linear y
//! (sweeps), or on linear axes (a ROC curve, a trade-off).

use std::path::Path;

use plotters::coord::combinators::BindKeyPoints;
use plotters::prelude::*;

use super::{
    FONT, draw_err, draw_legend, draw_line_runs, draw_markers, log_ticks, nice_ceil, nice_floor,
    register_font, save_rgb, tick_label,
};
use crate::core::error::Result;
use crate::report::canvas::Canvas;

/// Training loss against step, one line per run (log-y).
pub fn training_curves(
    path: &Path,
    title: &str,
    runs: &[(String, Vec<(usize, f64)>)],
) -> Result<()> {
    curves(path, title, "step", "training loss (log)", runs)
}

/// Lines of positive values against a count (steps, iterations), one per run, log-y.
pub fn curves(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    runs: &[(String, Vec<(usize, f64)>)],
) -> Result<()> {
    register_font();
    let (w, h) = (900u32, 500u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = Canvas::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let all = runs.iter().flat_map(|(_, c)| c.iter());
        let max_step = all.clone().map(|p| p.0).max().unwrap_or(1).max(1);
        let pos = all.map(|p| p.1).filter(|v| *v > 0.0);
        let lo = pos.clone().fold(f64::INFINITY, f64::min);
        let lo = if lo.is_finite() { lo } else { 1.0 };
        let hi = pos.fold(0.0, f64::max).max(lo * 3.0);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 22))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(
                0..max_step,
                (nice_floor(lo * 0.95)..nice_ceil(hi * 1.05))
                    .log_scale()
                    .with_key_points(log_ticks(nice_floor(lo * 0.95), nice_ceil(hi * 1.05))),
            )
            .map_err(|e| draw_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .y_label_formatter(&|v| tick_label(*v))
            .label_style((FONT, 14))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(|e| draw_err(path, e))?;
        draw_line_runs(
            &mut chart,
            path,
            runs.iter().map(|(label, curve)| {
                (
                    label.clone(),
                    curve.iter().copied().filter(|p| p.1 > 0.0).collect(),
                )
            }),
        )?;
        // Falling curves leave the upper right empty.
        draw_legend(&mut chart, path, SeriesLabelPosition::UpperRight)?;
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}

/// Lines of positive `(x, y)` points, one per run, the x axis logarithmic (sweeps over batch
/// sizes or thread counts) and the y axis too where `log_y`, with a marker on every measured
/// point. The x ticks are the measured x values themselves (counts: 1, 2, 3, 4 threads; 64,
/// 512 batch), log-y ticks 1-2-5 per decade; a linear y axis is padded around the points.
fn log_x_lines(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    runs: &[(String, Vec<(f64, f64)>)],
    log_y: bool,
) -> Result<()> {
    register_font();
    let (w, h) = (900u32, 500u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let runs: Vec<(String, Vec<(f64, f64)>)> = runs
        .iter()
        .map(|(l, c)| {
            let pts = c
                .iter()
                .copied()
                .filter(|p| p.0 > 0.0 && (p.1 > 0.0 || !log_y))
                .collect();
            (l.clone(), pts)
        })
        .collect();
    {
        let root = Canvas::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let points = runs.iter().flat_map(|(_, c)| c.iter());
        let bounds = |f: fn(&(f64, f64)) -> f64| {
            let lo = points.clone().map(f).fold(f64::INFINITY, f64::min);
            let hi = points.clone().map(f).fold(f64::NEG_INFINITY, f64::max);
            (lo.is_finite() && hi.is_finite()).then_some((lo, hi))
        };
        let log_range = |b: Option<(f64, f64)>| match b {
            Some((lo, hi)) => {
                let pad = ((hi / lo).powf(0.06)).max(1.15);
                (lo / pad, hi * pad)
            }
            None => (1.0, 10.0),
        };
        let (x_lo, x_hi) = log_range(bounds(|p| p.0));
        let mut xs: Vec<f64> = points.clone().map(|p| p.0).collect();
        xs.sort_by(f64::total_cmp);
        xs.dedup();
        // The data's own x values as ticks, unless there are many or two sit so close that
        // their labels would overlap: then the 1-2-5 ticks of the range.
        if xs.len() > 12 || xs.windows(2).any(|w| w[1] < 1.3 * w[0]) {
            xs = log_ticks(x_lo, x_hi);
        }
        let x_spec = (x_lo..x_hi).log_scale().with_key_points(xs);
        // The same chart on either y axis.
        macro_rules! draw_on {
            ($y_spec:expr, $corner:expr) => {{
                let mut chart = ChartBuilder::on(&root)
                    .caption(title, (FONT, 20))
                    .margin(15)
                    .x_label_area_size(40)
                    .y_label_area_size(70)
                    .build_cartesian_2d(x_spec, $y_spec)
                    .map_err(|e| draw_err(path, e))?;
                chart
                    .configure_mesh()
                    .x_desc(x_desc)
                    .y_desc(y_desc)
                    .x_label_formatter(&|v| tick_label(*v))
                    .y_label_formatter(&|v| tick_label(*v))
                    .label_style((FONT, 14))
                    .light_line_style(TRANSPARENT)
                    .draw()
                    .map_err(|e| draw_err(path, e))?;
                draw_line_runs(&mut chart, path, runs.iter().cloned())?;
                draw_markers(&mut chart, path, &runs, 3)?;
                draw_legend(&mut chart, path, $corner)?;
            }};
        }
        if log_y {
            let corner = SeriesLabelPosition::UpperRight;
            let (y_lo, y_hi) = log_range(bounds(|p| p.1));
            draw_on!(
                (nice_floor(y_lo)..nice_ceil(y_hi))
                    .log_scale()
                    .with_key_points(log_ticks(nice_floor(y_lo), nice_ceil(y_hi))),
                corner
            );
        } else {
            let (lo, hi) = bounds(|p| p.1).unwrap_or((0.0, 1.0));
            let pad = ((hi - lo) * 0.08).max(0.5);
            // The legend where the lines leave the most room, lower right if as much.
            let (y0, y1) = (lo - pad, hi + pad);
            let unit = |p: &(f64, f64)| {
                (
                    (p.0 / x_lo).ln() / (x_hi / x_lo).ln(),
                    (p.1 - y0) / (y1 - y0),
                )
            };
            let lines: Vec<Vec<(f64, f64)>> = runs
                .iter()
                .map(|(_, c)| c.iter().map(unit).collect())
                .collect();
            let legend = (0.45, (runs.len() as f64 * 20.0 + 12.0) / (h as f64 - 110.0));
            let (corner, crossed) = emptiest_corner(&lines, legend);
            if crossed > 0 {
                // Every corner is crossed: room above the lines, as tall as the legend.
                let top = y1 + (y1 - y0) * legend.1 / (1.0 - legend.1);
                draw_on!(y0..top, SeriesLabelPosition::UpperRight);
            } else {
                draw_on!(y0..y1, corner);
            }
        }
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}

/// Of the four corners, the one whose box of `size` (a share of each axis) the `lines`
/// (points in the unit square, joined) cross least, lower right where it ties with the least;
/// with how many of the points along the lines fall in it.
fn emptiest_corner(lines: &[Vec<(f64, f64)>], size: (f64, f64)) -> (SeriesLabelPosition, usize) {
    // Points along every segment, twenty a segment.
    let along: Vec<(f64, f64)> = lines
        .iter()
        .flat_map(|l| {
            l.windows(2)
                .flat_map(|w| {
                    (0..20).map(move |k| {
                        let t = k as f64 / 20.0;
                        (
                            w[0].0 + t * (w[1].0 - w[0].0),
                            w[0].1 + t * (w[1].1 - w[0].1),
                        )
                    })
                })
                .chain(l.last().copied())
                .collect::<Vec<_>>()
        })
        .collect();
    let count = |right: bool, upper: bool| {
        along
            .iter()
            .filter(|&&(x, y)| {
                (if right {
                    x >= 1.0 - size.0
                } else {
                    x <= size.0
                }) && (if upper {
                    y >= 1.0 - size.1
                } else {
                    y <= size.1
                })
            })
            .count()
    };
    [
        (SeriesLabelPosition::LowerRight, count(true, false)),
        (SeriesLabelPosition::UpperRight, count(true, true)),
        (SeriesLabelPosition::LowerLeft, count(false, false)),
        (SeriesLabelPosition::UpperLeft, count(false, true)),
    ]
    .into_iter()
    .min_by_key(|(_, n)| *n)
    .unwrap_or((SeriesLabelPosition::LowerRight, 0))
}

/// Lines of `(x, y)` points, one per run, both axes linear over the points' range (a ROC
/// curve's unit square, say), with a dot at every point where `markers` (runs of one point: a
/// trade-off between two scores).
fn linear_lines(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    runs: &[(String, Vec<(f64, f64)>)],
    markers: bool,
) -> Result<()> {
    register_font();
    let (w, h) = (800u32, 600u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = Canvas::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let points = runs.iter().flat_map(|(_, c)| c.iter());
        // Scattered points leave no corner free: with markers, the legend gets room of its
        // own above them.
        let headroom = if markers {
            0.08 * runs.len() as f64
        } else {
            0.02
        };
        let span = |f: fn(&(f64, f64)) -> f64, top: f64| {
            let lo = points.clone().map(f).fold(f64::INFINITY, f64::min);
            let hi = points.clone().map(f).fold(f64::NEG_INFINITY, f64::max);
            if lo.is_finite() && hi > lo {
                let pad = 0.02 * (hi - lo);
                (lo - pad)..(hi + top * (hi - lo))
            } else {
                0.0..1.0
            }
        };
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 20))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(span(|p| p.0, 0.02), span(|p| p.1, headroom))
            .map_err(|e| draw_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style((FONT, 14))
            .light_line_style(TRANSPARENT)
            .draw()
            .map_err(|e| draw_err(path, e))?;
        draw_line_runs(&mut chart, path, runs.iter().cloned())?;
        if markers {
            draw_markers(&mut chart, path, runs, 5)?;
        }
        let corner = if markers {
            SeriesLabelPosition::UpperMiddle
        } else {
            SeriesLabelPosition::LowerRight
        };
        draw_legend(&mut chart, path, corner)?;
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}

/// How a line plot draws its axes and points.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LinePlot {
    /// A logarithmic x axis ticked at the measured x values (sweeps over counts); its points
    /// are always marked.
    pub log_x: bool,
    /// A logarithmic y axis (with `log_x` only).
    pub log_y: bool,
    /// A dot at every point (linear axes).
    pub markers: bool,
}

impl LinePlot {
    /// Both axes linear (a ROC curve).
    pub const LINEAR: Self = Self {
        log_x: false,
        log_y: false,
        markers: false,
    };
    /// A log x axis, a linear y axis (a share against a time).
    pub const LOG_X: Self = Self {
        log_x: true,
        log_y: false,
        markers: true,
    };
    /// Both axes logarithmic (a rate against a batch size or thread count).
    pub const LOG_LOG: Self = Self {
        log_x: true,
        log_y: true,
        markers: true,
    };

    /// The same with a dot at every point.
    pub fn marked(self) -> Self {
        Self {
            markers: true,
            ..self
        }
    }
}

/// Lines of `(x, y)` points, one per run (its label and points), drawn as `style` says.
pub fn line_plot(
    path: &Path,
    title: &str,
    (x_desc, y_desc): (&str, &str),
    runs: &[(String, Vec<(f64, f64)>)],
    style: LinePlot,
) -> Result<()> {
    if style.log_x {
        log_x_lines(path, title, x_desc, y_desc, runs, style.log_y)
    } else {
        linear_lines(path, title, x_desc, y_desc, runs, style.markers)
    }
}
