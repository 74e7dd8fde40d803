//! Figures generated from results (never drawn by hand): the speed-quality Pareto plot,
//! training curves (plotters, PNG) and the qualitative grid of predictions (image crate).
//! Every figure draws on a `Canvas` (`report::canvas`: the embedded font, glyphs placed right).

use std::path::Path;
use std::sync::Once;

use image::ImageEncoder;
use plotters::coord::combinators::BindKeyPoints;
use plotters::prelude::*;

use super::canvas::{Canvas, FONT_BYTES};
use crate::core::atomic_file::write_bytes;
use crate::core::error::{Error, Result};

const FONT: &str = "sans-serif";
static FONT_ONCE: Once = Once::new();

fn register_font() {
    FONT_ONCE.call_once(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
            .unwrap_or_else(|_| panic!("embedded font is valid"));
    });
}

/// Encode an RGB buffer as PNG, atomically.
fn save_rgb(path: &Path, buf: &[u8], w: u32, h: u32) -> Result<()> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(buf, w, h, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::data(path, format!("cannot encode PNG: {e}")))?;
    write_bytes(path, &png)
}

fn draw_err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::data(path, format!("cannot draw figure: {e}"))
}

/// The series legend every chart draws.
fn draw_legend<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    path: &Path,
    position: SeriesLabelPosition,
) -> Result<()>
where
    DB: DrawingBackend + 'a,
    X: plotters::coord::ranged1d::Ranged,
    Y: plotters::coord::ranged1d::Ranged,
{
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()
        .map_err(|e| draw_err(path, e))
}

/// One line per run, each in its palette colour with its label in the legend.
fn draw_line_runs<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    path: &Path,
    runs: impl IntoIterator<Item = (String, Vec<(X::ValueType, Y::ValueType)>)>,
) -> Result<()>
where
    DB: DrawingBackend + 'a,
    X: plotters::coord::ranged1d::Ranged,
    Y: plotters::coord::ranged1d::Ranged,
    X::ValueType: Clone + 'static,
    Y::ValueType: Clone + 'static,
{
    for (i, (label, points)) in runs.into_iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(points, color.stroke_width(2)))
            .map_err(|e| draw_err(path, e))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    Ok(())
}

/// A dot of `radius` pixels at every point of every run, in the run's colour.
fn draw_markers<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    path: &Path,
    runs: &[(String, Vec<(X::ValueType, Y::ValueType)>)],
    radius: i32,
) -> Result<()>
where
    DB: DrawingBackend + 'a,
    X: plotters::coord::ranged1d::Ranged,
    Y: plotters::coord::ranged1d::Ranged,
    X::ValueType: Clone + 'static,
    Y::ValueType: Clone + 'static,
{
    for (i, (_, points)) in runs.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(
                points
                    .iter()
                    .map(|p| Circle::new(p.clone(), radius, color.filled())),
            )
            .map_err(|e| draw_err(path, e))?;
    }
    Ok(())
}

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

/// Tick values on a log axis over `[lo, hi]`: 1-2-5 in each decade over up to two decades,
/// 1-3 up to four, the decades beyond; one label per tick, no minor lines.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo) {
        return vec![];
    }
    let decades = hi.log10() - lo.log10();
    let mantissas: &[f64] = if decades <= 2.2 {
        &[1.0, 2.0, 5.0]
    } else if decades <= 4.5 {
        &[1.0, 3.0]
    } else {
        &[1.0]
    };
    let mut ticks = Vec::new();
    for k in (lo.log10().floor() as i32)..=(hi.log10().ceil() as i32) {
        for m in mantissas {
            let v = m * 10f64.powi(k);
            if v >= lo * 0.999 && v <= hi * 1.001 {
                ticks.push(v);
            }
        }
    }
    ticks
}

/// The smallest 1-2-5 value at or above `v` (> 0), so a log axis ends on a labelled tick.
pub fn nice_ceil(v: f64) -> f64 {
    let k = v.log10().floor();
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * 10f64.powf(k))
        .find(|&x| x >= v * 0.9999)
        .unwrap_or(v)
}

/// The largest 1-2-5 value at or below `v` (> 0).
pub fn nice_floor(v: f64) -> f64 {
    let k = v.log10().floor();
    [5.0, 2.0, 1.0]
        .iter()
        .map(|m| m * 10f64.powf(k))
        .find(|&x| x <= v * 1.0001)
        .unwrap_or(v)
}

/// A tick value as a label: no trailing zeros, thousands unseparated ("0.02", "5", "2000").
pub fn tick_label(v: f64) -> String {
    if v >= 1.0 || v == 0.0 {
        format!("{v:.0}")
    } else {
        let decimals = (-v.log10().floor()) as usize;
        format!("{v:.decimals$}")
    }
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
        let fps_min = points
            .iter()
            .map(|p| p.fps)
            .fold(f64::INFINITY, f64::min)
            .min(1.0);
        let fps_max = points.iter().map(|p| p.fps).fold(1.0, f64::max).max(2000.0);
        let (x0, x1) = (fps_min / 2.0, fps_max * 3.0);
        let q_min = points
            .iter()
            .map(|p| p.quality)
            .chain(floors.iter().map(|f| f.1))
            .fold(f64::INFINITY, f64::min);
        let q_max = points
            .iter()
            .map(|p| p.quality)
            .chain(floors.iter().map(|f| f.1))
            .fold(f64::NEG_INFINITY, f64::max);
        let pad = ((q_max - q_min) * 0.15).max(0.5 * q_max.abs().max(1e-3) * 0.02);
        let (y0, y1) = (q_min - pad, q_max + pad);
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
        // Labels where they overlap nothing; a number and a key entry elsewhere.
        let font_px = 13;
        let char_w = 8;
        let (xr, yr) = chart.plotting_area().get_pixel_range();
        let (px0, px1, py0, py1) = (xr.start, xr.end, yr.start, yr.end);
        let area = Rect {
            x0: px0,
            y0: py0,
            x1: px1,
            y1: py1,
        };
        let sized: Vec<(i32, i32, i32, i32)> = points
            .iter()
            .map(|p| {
                let (x, y) = chart.backend_coord(&(p.fps, p.quality));
                (x, y, char_w * p.label.chars().count() as i32, font_px + 2)
            })
            .collect();
        // The legend goes in the corner where it covers the fewest points.
        let entries = 1
            + floors.len()
            + [false, true]
                .iter()
                .filter(|&&r| points.iter().any(|p| p.reference == r))
                .count();
        let legend_w = 50
            + char_w
                * floors
                    .iter()
                    .map(|(l, _)| l.chars().count() + 8)
                    .chain([30])
                    .max()
                    .unwrap_or(30) as i32;
        let legend_h = 12 + 17 * entries as i32;
        let corners = [
            (SeriesLabelPosition::LowerLeft, px0, py1 - legend_h),
            (
                SeriesLabelPosition::LowerRight,
                px1 - legend_w,
                py1 - legend_h,
            ),
            (SeriesLabelPosition::UpperLeft, px0, py0),
            (SeriesLabelPosition::UpperRight, px1 - legend_w, py0),
        ];
        let (legend_pos, legend_rect) = corners
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
            .expect("four corners");
        let spots = place_labels(&sized, area, &[legend_rect]);
        let mut key = Vec::new();
        for ((p, spot), &(x, y, _, _)) in points.iter().zip(&spots).zip(&sized) {
            let color = if p.reference { BLACK } else { BLUE };
            let font = (FONT, font_px).into_font().color(&color);
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
        draw_legend(&mut chart, path, legend_pos)?;
        // The key of numbered labels: in the top corner the legend does not take.
        let key_x = if legend_rect.y0 == py0 && legend_rect.x0 == px0 {
            px1 - 10 - char_w * key.iter().map(|k| k.chars().count()).max().unwrap_or(0) as i32
        } else {
            px0 + 10
        };
        for (i, line) in key.iter().enumerate() {
            root.draw(&Text::new(
                line.clone(),
                (key_x, py0 + 8 + i as i32 * (font_px + 4)),
                (FONT, font_px).into_font(),
            ))
            .map_err(|e| draw_err(path, e))?;
        }
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}

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

/// Lines of positive `(x, y)` points, one per run, both axes logarithmic (sweeps over batch
/// sizes or thread counts), with a marker on every measured point. The x ticks are the
/// measured x values themselves (counts: 1, 2, 3, 4 threads; 64, 512 batch), the y ticks
/// 1-2-5 per decade.
pub fn log_log_lines(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    runs: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    marked_lines(path, title, x_desc, y_desc, runs, true)
}

/// [`log_log_lines`] with a linear y axis (a share in percent against a time, say), its
/// range padded around the points.
pub fn lines_log_x(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    runs: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    marked_lines(path, title, x_desc, y_desc, runs, false)
}

fn marked_lines(
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
            ($y_spec:expr) => {{
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
                draw_legend(
                    &mut chart,
                    path,
                    if log_y {
                        SeriesLabelPosition::UpperRight
                    } else {
                        SeriesLabelPosition::LowerRight
                    },
                )?;
            }};
        }
        if log_y {
            let (y_lo, y_hi) = log_range(bounds(|p| p.1));
            draw_on!(
                (nice_floor(y_lo)..nice_ceil(y_hi))
                    .log_scale()
                    .with_key_points(log_ticks(nice_floor(y_lo), nice_ceil(y_hi)))
            );
        } else {
            let (lo, hi) = bounds(|p| p.1).unwrap_or((0.0, 1.0));
            let pad = ((hi - lo) * 0.08).max(0.5);
            draw_on!((lo - pad)..(hi + pad));
        }
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}

/// Map an error in [0, 1] to blue (0) through yellow to red (1).
fn error_color(e: f32) -> [u8; 3] {
    let e = e.clamp(0.0, 1.0);
    if e < 0.5 {
        let t = e * 2.0;
        [
            (255.0 * t) as u8,
            (255.0 * t) as u8,
            (255.0 * (1.0 - t)) as u8,
        ]
    } else {
        let t = (e - 0.5) * 2.0;
        [255, (255.0 * (1.0 - t)) as u8, 0]
    }
}

/// One row of the qualitative grid: per column, `[H * W]` values and how to colour them.
pub enum GridRow<'a> {
    /// Grey levels in [0, 1].
    Grey(Vec<&'a [f32]>),
    /// Absolute errors in [0, 1], blue (right) to red (wrong).
    Error(Vec<Vec<f32>>),
    /// Depth in metres, shown in [lo, hi] (near bright); 0 is background (black).
    Depth(Vec<&'a [f32]>, [f32; 2]),
}

/// A grid of images (rows of equal length), each pixel drawn `scale` times, 2 px gaps, with
/// each row's title on the left (`titles`, one per row), a caption under each column
/// (`captions`: per-sample scores; empty: none) and, right of every error or depth row, a
/// colour bar with its scale.
pub fn image_grid(
    path: &Path,
    rows: &[GridRow],
    titles: &[&str],
    captions: &[String],
    width: usize,
    height: usize,
    scale: usize,
) -> Result<()> {
    register_font();
    let cols = rows
        .iter()
        .map(|r| match r {
            GridRow::Grey(v) | GridRow::Depth(v, _) => v.len(),
            GridRow::Error(v) => v.len(),
        })
        .max()
        .unwrap_or(0);
    let gap = 2;
    let font_px = 13;
    let left = if titles.iter().any(|t| !t.is_empty()) {
        8 + 8 * titles.iter().map(|t| t.chars().count()).max().unwrap_or(0)
    } else {
        0
    };
    let bars = rows
        .iter()
        .any(|r| matches!(r, GridRow::Error(_) | GridRow::Depth(..)));
    let right = if bars { 90 } else { 0 };
    // Captions go one part per line ("24.5 dB, IoU 0.91": two lines), to fit narrow cells.
    let caption_lines = captions
        .iter()
        .map(|c| c.split(", ").count())
        .max()
        .unwrap_or(0);
    let bottom = caption_lines * (font_px + 3) + if caption_lines > 0 { 6 } else { 0 };
    let (cw, ch) = (width * scale + gap, height * scale + gap);
    let (w, h) = (
        left + cols * cw + gap + right,
        rows.len() * ch + gap + bottom,
    );
    let mut img = image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([255, 255, 255]));
    let depth_color = |d: f32, lo: f32, hi: f32| -> [u8; 3] {
        let t = 1.0 - ((d - lo) / (hi - lo).max(1e-6)).clamp(0.0, 1.0);
        let g = (40.0 + 215.0 * t) as u8;
        [g, (g as f32 * 0.85) as u8, 255 - g / 2]
    };
    for (r, row) in rows.iter().enumerate() {
        for c in 0..cols {
            let color = |i: usize| -> Option<[u8; 3]> {
                match row {
                    GridRow::Grey(v) => v.get(c).map(|im| {
                        let g = (im[i].clamp(0.0, 1.0) * 255.0) as u8;
                        [g, g, g]
                    }),
                    GridRow::Error(v) => v.get(c).map(|im| error_color(im[i])),
                    GridRow::Depth(v, [lo, hi]) => v.get(c).map(|im| {
                        if im[i] <= 0.0 {
                            [0, 0, 0]
                        } else {
                            depth_color(im[i], *lo, *hi)
                        }
                    }),
                }
            };
            for y in 0..height {
                for x in 0..width {
                    let Some(px) = color(y * width + x) else {
                        continue;
                    };
                    for dy in 0..scale {
                        for dx in 0..scale {
                            img.put_pixel(
                                (left + gap + c * cw + x * scale + dx) as u32,
                                (gap + r * ch + y * scale + dy) as u32,
                                image::Rgb(px),
                            );
                        }
                    }
                }
            }
        }
        // The colour bar: low at the bottom, high at the top.
        let bar = match row {
            GridRow::Error(_) => Some((0.0f32, 1.0f32, false)),
            GridRow::Depth(_, [lo, hi]) => Some((*lo, *hi, true)),
            GridRow::Grey(_) => None,
        };
        if let Some((lo, hi, depth)) = bar {
            let x0 = left + cols * cw + gap + 6;
            let (y0, bh) = (gap + r * ch + 4, height * scale - 8);
            for y in 0..bh {
                let f = 1.0 - y as f32 / (bh - 1).max(1) as f32;
                let v = lo + f * (hi - lo);
                let px = if depth {
                    depth_color(v, lo, hi)
                } else {
                    error_color(v)
                };
                for x in 0..12 {
                    img.put_pixel((x0 + x) as u32, (y0 + y) as u32, image::Rgb(px));
                }
            }
        }
    }
    let mut buf = img.into_raw();
    {
        let root = Canvas::with_buffer(&mut buf, (w as u32, h as u32)).into_drawing_area();
        let font = (FONT, font_px as f64).into_font().color(&BLACK);
        for (r, title) in titles.iter().enumerate().take(rows.len()) {
            let y = (gap + r * ch + height * scale / 2) as i32 - font_px as i32 / 2;
            root.draw(&Text::new(title.to_string(), (4, y), font.clone()))
                .map_err(|e| draw_err(path, e))?;
        }
        for (c, caption) in captions.iter().enumerate().take(cols) {
            let x = (left + gap + c * cw) as i32 + 2;
            for (k, line) in caption.split(", ").enumerate() {
                let y = (rows.len() * ch + gap + 3 + k * (font_px + 3)) as i32;
                root.draw(&Text::new(line.to_string(), (x, y), font.clone()))
                    .map_err(|e| draw_err(path, e))?;
            }
        }
        for (r, row) in rows.iter().enumerate() {
            let (top, bottom) = match row {
                GridRow::Error(_) => ("1".to_string(), "0".to_string()),
                GridRow::Depth(_, [lo, hi]) => (format!("{hi:.2} m"), format!("{lo:.2} m")),
                GridRow::Grey(_) => continue,
            };
            let x = (left + cols * cw + gap + 22) as i32;
            let y0 = (gap + r * ch + 2) as i32;
            let y1 = (gap + r * ch + height * scale) as i32 - font_px as i32 - 2;
            root.draw(&Text::new(top, (x, y0), font.clone()))
                .map_err(|e| draw_err(path, e))?;
            root.draw(&Text::new(bottom, (x, y1), font.clone()))
                .map_err(|e| draw_err(path, e))?;
        }
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w as u32, h as u32)
}

/// Images side by side (grey levels in [0, 1]), each with points drawn over it as green dots:
/// `points[i]` are (row, column) pixel coordinates on image `i`; points outside are skipped.
pub fn points_over_images(
    path: &Path,
    images: &[&[f32]],
    points: &[Vec<(f32, f32)>],
    width: usize,
    height: usize,
    scale: usize,
    caption: &str,
) -> Result<()> {
    register_font();
    let gap = 2;
    let font_px = 13;
    let top = if caption.is_empty() { 0 } else { font_px + 8 };
    let (cw, ch) = (width * scale + gap, height * scale + gap);
    let (w, h) = (images.len() * cw + gap, top + ch + gap);
    let mut img = image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([255, 255, 255]));
    for (c, im) in images.iter().enumerate() {
        for y in 0..height * scale {
            for x in 0..width * scale {
                let g = (im[(y / scale) * width + x / scale].clamp(0.0, 1.0) * 180.0) as u8;
                img.put_pixel(
                    (gap + c * cw + x) as u32,
                    (top + gap + y) as u32,
                    image::Rgb([g, g, g]),
                );
            }
        }
        // Each centre a 2x2 dot, inside its image.
        for &(r, col) in points.get(c).map(|v| v.as_slice()).unwrap_or(&[]) {
            let (py, px) = ((r + 0.5) * scale as f32, (col + 0.5) * scale as f32);
            if py < 0.0 || px < 0.0 || py >= (height * scale) as f32 || px >= (width * scale) as f32
            {
                continue;
            }
            for (dy, dx) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                let (y, x) = (py as usize + dy, px as usize + dx);
                if y < height * scale && x < width * scale {
                    img.put_pixel(
                        (gap + c * cw + x) as u32,
                        (top + gap + y) as u32,
                        image::Rgb([40, 220, 60]),
                    );
                }
            }
        }
    }
    let mut buf = img.into_raw();
    if !caption.is_empty() {
        let root = Canvas::with_buffer(&mut buf, (w as u32, h as u32)).into_drawing_area();
        let font = (FONT, font_px as f64).into_font().color(&BLACK);
        root.draw(&Text::new(caption.to_string(), (4, 3), font))
            .map_err(|e| draw_err(path, e))?;
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w as u32, h as u32)
}

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

/// Lines of `(x, y)` points, one per run, both axes linear over the points' range (a ROC
/// curve's unit square, say).
pub fn lines(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    runs: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    lines_marked(path, title, x_desc, y_desc, runs, false)
}

/// [`lines`] with a dot at every point (runs of one point: a trade-off between two scores).
pub fn lines_marked(
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
