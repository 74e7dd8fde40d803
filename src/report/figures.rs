//! Figures generated from results (never drawn by hand): the speed-quality Pareto plot,
//! training curves (plotters, PNG) and the qualitative grid of predictions (image crate).
//!
//! Text uses DejaVu Sans Mono, embedded (assets/fonts, with its licence), so figures render
//! the same on any machine without system fonts.

use std::path::Path;
use std::sync::Once;

use image::ImageEncoder;
use plotters::prelude::*;

use crate::core::atomic_file::write_bytes;
use crate::core::error::{Error, Result};

const FONT: &str = "sans-serif";
static FONT_ONCE: Once = Once::new();

fn register_font() {
    FONT_ONCE.call_once(|| {
        let bytes: &'static [u8] = include_bytes!("../../assets/fonts/DejaVuSansMono.ttf");
        plotters::style::register_font(FONT, FontStyle::Normal, bytes)
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

/// Quality against inference speed, log-x, with the 1,000 FPS control-loop line.
/// `floors`: lower bounds (label, quality), drawn as dashed horizontal lines.
pub fn pareto_plot(
    path: &Path,
    title: &str,
    y_label: &str,
    points: &[ParetoPoint],
    floors: &[(String, f64)],
) -> Result<()> {
    register_font();
    let (w, h) = (900u32, 600u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let fps_min = points
            .iter()
            .map(|p| p.fps)
            .fold(f64::INFINITY, f64::min)
            .min(1.0);
        let fps_max = points.iter().map(|p| p.fps).fold(1.0, f64::max).max(2000.0);
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
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 22))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(
                (fps_min / 2.0..fps_max * 3.0).log_scale(),
                (q_min - pad)..(q_max + pad),
            )
            .map_err(|e| draw_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc("inference images/s at batch 1 (log)")
            .y_desc(y_label)
            .label_style((FONT, 14))
            .draw()
            .map_err(|e| draw_err(path, e))?;
        chart
            .draw_series(LineSeries::new(
                [(1000.0, q_min - pad), (1000.0, q_max + pad)],
                RED.stroke_width(2),
            ))
            .map_err(|e| draw_err(path, e))?
            .label("1,000 FPS (1 kHz control loop)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        for (label, q) in floors {
            let grey = BLACK.mix(0.5);
            let (x0, x1) = (fps_min / 2.0, fps_max * 3.0);
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
        for p in points {
            let color = if p.reference {
                BLACK.mix(0.6)
            } else {
                BLUE.mix(1.0)
            };
            let style = if p.reference {
                color.stroke_width(2)
            } else {
                color.filled()
            };
            chart
                .draw_series(std::iter::once(Circle::new((p.fps, p.quality), 6, style)))
                .map_err(|e| draw_err(path, e))?;
            chart
                .draw_series(std::iter::once(Text::new(
                    p.label.clone(),
                    (p.fps, p.quality),
                    (FONT, 13).into_font().color(&color),
                )))
                .map_err(|e| draw_err(path, e))?;
        }
        // Bottom left: the slow, poor corner no model sits in.
        draw_legend(&mut chart, path, SeriesLabelPosition::LowerLeft)?;
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
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let all = runs.iter().flat_map(|(_, c)| c.iter());
        let max_step = all.clone().map(|p| p.0).max().unwrap_or(1).max(1);
        let pos = all.map(|p| p.1).filter(|v| *v > 0.0);
        let lo = pos.clone().fold(f64::INFINITY, f64::min).min(1.0);
        let hi = pos.fold(0.0, f64::max).max(lo * 10.0);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 22))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0..max_step, (lo * 0.8..hi * 1.2).log_scale())
            .map_err(|e| draw_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style((FONT, 14))
            .draw()
            .map_err(|e| draw_err(path, e))?;
        for (i, (label, curve)) in runs.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(
                    curve.iter().filter(|p| p.1 > 0.0).map(|&(s, v)| (s, v)),
                    color.stroke_width(2),
                ))
                .map_err(|e| draw_err(path, e))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
        }
        draw_legend(&mut chart, path, SeriesLabelPosition::MiddleRight)?;
        root.present().map_err(|e| draw_err(path, e))?;
    }
    save_rgb(path, &buf, w, h)
}

/// Lines of positive `(x, y)` points, one per run, both axes logarithmic (sweeps over batch
/// sizes or thread counts), with a marker on every measured point.
pub fn log_log_lines(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    runs: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    register_font();
    let (w, h) = (900u32, 500u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    // Plotted as log10 values on linear axes, labelled with the values themselves: every
    // tick gets a label, not only the decades.
    let logs: Vec<(String, Vec<(f64, f64)>)> = runs
        .iter()
        .map(|(l, c)| {
            let pts = c
                .iter()
                .filter(|p| p.0 > 0.0 && p.1 > 0.0)
                .map(|p| (p.0.log10(), p.1.log10()))
                .collect();
            (l.clone(), pts)
        })
        .collect();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(path, e))?;
        let points = logs.iter().flat_map(|(_, c)| c.iter());
        let range = |f: fn(&(f64, f64)) -> f64| {
            let lo = points.clone().map(f).fold(f64::INFINITY, f64::min);
            let hi = points.clone().map(f).fold(f64::NEG_INFINITY, f64::max);
            if lo.is_finite() && hi.is_finite() {
                let pad = ((hi - lo) * 0.08).max(0.05);
                (lo - pad, hi + pad)
            } else {
                (0.0, 1.0)
            }
        };
        let (x_lo, x_hi) = range(|p| p.0);
        let (y_lo, y_hi) = range(|p| p.1);
        let value = |v: &f64| {
            let x = 10f64.powf(*v);
            let digits = (2 - x.log10().floor() as i32).max(0) as usize;
            format!("{x:.digits$}")
        };
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 20))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)
            .map_err(|e| draw_err(path, e))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .x_labels(10)
            .y_labels(10)
            .x_label_formatter(&value)
            .y_label_formatter(&value)
            .label_style((FONT, 14))
            .draw()
            .map_err(|e| draw_err(path, e))?;
        for (i, (label, pts)) in logs.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                .map_err(|e| draw_err(path, e))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
                .map_err(|e| draw_err(path, e))?;
        }
        draw_legend(&mut chart, path, SeriesLabelPosition::MiddleRight)?;
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

/// A grid of images (rows of equal length), each pixel drawn `scale` times, 2 px gaps.
pub fn image_grid(
    path: &Path,
    rows: &[GridRow],
    width: usize,
    height: usize,
    scale: usize,
) -> Result<()> {
    let cols = rows
        .iter()
        .map(|r| match r {
            GridRow::Grey(v) | GridRow::Depth(v, _) => v.len(),
            GridRow::Error(v) => v.len(),
        })
        .max()
        .unwrap_or(0);
    let gap = 2;
    let (cw, ch) = (width * scale + gap, height * scale + gap);
    let (w, h) = (cols * cw + gap, rows.len() * ch + gap);
    let mut img = image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([200, 200, 200]));
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
                            let t = 1.0 - ((im[i] - lo) / (hi - lo).max(1e-6)).clamp(0.0, 1.0);
                            let g = (40.0 + 215.0 * t) as u8;
                            [g, (g as f32 * 0.85) as u8, 255 - g / 2]
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
                                (gap + c * cw + x * scale + dx) as u32,
                                (gap + r * ch + y * scale + dy) as u32,
                                image::Rgb(px),
                            );
                        }
                    }
                }
            }
        }
    }
    save_rgb(path, img.as_raw(), w as u32, h as u32)
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
) -> Result<()> {
    let gap = 2;
    let (cw, ch) = (width * scale + gap, height * scale + gap);
    let (w, h) = (images.len() * cw + gap, ch + gap);
    let mut img = image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([200, 200, 200]));
    for (c, im) in images.iter().enumerate() {
        for y in 0..height * scale {
            for x in 0..width * scale {
                let g = (im[(y / scale) * width + x / scale].clamp(0.0, 1.0) * 180.0) as u8;
                img.put_pixel(
                    (gap + c * cw + x) as u32,
                    (gap + y) as u32,
                    image::Rgb([g, g, g]),
                );
            }
        }
        for &(r, col) in points.get(c).map(|v| v.as_slice()).unwrap_or(&[]) {
            let (py, px) = ((r + 0.5) * scale as f32, (col + 0.5) * scale as f32);
            if py < 0.0 || px < 0.0 || py >= (height * scale) as f32 || px >= (width * scale) as f32
            {
                continue;
            }
            img.put_pixel(
                (gap + c * cw + px as usize) as u32,
                (gap + py as usize) as u32,
                image::Rgb([40, 220, 60]),
            );
        }
    }
    save_rgb(path, img.as_raw(), w as u32, h as u32)
}
