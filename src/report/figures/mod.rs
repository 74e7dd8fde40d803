//! Figures generated from results (never drawn by hand), on plotters (PNG) and the image
//! crate: `pareto.rs` (quality against speed), `lines.rs` (curves and lines, linear or log
//! axes), `images.rs` (the qualitative grid, points over images), `scatter.rs` (panels of
//! points), `spheres.rs` (a robot's collision spheres over its meshes), `bars.rs` (each link's
//! sphere protrusion); here what every figure shares (the embedded font, PNG writing, legend, lines,
//! markers, ticks). Every figure draws on a `Canvas` (`report::canvas`: the embedded font,
//! glyphs placed right).

pub mod bars;
mod images;
mod lines;
mod pareto;
mod scatter;
mod spheres;

pub use images::{GridRow, image_grid, points_over_images};
pub use lines::{LinePlot, curves, line_plot, training_curves};
pub use pareto::{ParetoPoint, pareto_plot};
pub use scatter::{ScatterPanel, scatter_panels};
pub use spheres::collision_spheres;

use std::path::Path;
use std::sync::Once;

use image::ImageEncoder;
use plotters::coord::ranged1d::Ranged;
use plotters::prelude::*;

use super::canvas::FONT_BYTES;
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
/// Write an RGB image (`w x h`, row-major) as a PNG, whole or not at all.
pub fn save_rgb(path: &Path, buf: &[u8], w: u32, h: u32) -> Result<()> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(buf, w, h, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::data(path, format!("cannot encode PNG: {e}")))?;
    write_bytes(path, &png)
}

/// A chart on a drawing backend `DB` with axes `X` and `Y`.
type Chart<'a, DB, X, Y> = ChartContext<'a, DB, Cartesian2d<X, Y>>;

/// An axis whose values the drawing functions copy into series (plotters' bounds, written once).
trait Axis: Ranged<ValueType: Clone + 'static> {}
impl<T: Ranged<ValueType: Clone + 'static>> Axis for T {}

/// An axis of `f64` values.
trait F64Axis: Ranged<ValueType = f64> {}
impl<T: Ranged<ValueType = f64>> F64Axis for T {}

fn draw_err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::data(path, format!("cannot draw figure: {e}"))
}

/// The series legend every chart draws.
fn draw_legend<'a, DB: DrawingBackend + 'a, X: Ranged, Y: Ranged>(
    chart: &mut Chart<'a, DB, X, Y>,
    path: &Path,
    position: SeriesLabelPosition,
) -> Result<()> {
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
fn draw_line_runs<'a, DB: DrawingBackend + 'a, X: Axis, Y: Axis>(
    chart: &mut Chart<'a, DB, X, Y>,
    path: &Path,
    runs: impl IntoIterator<Item = (String, Vec<(X::ValueType, Y::ValueType)>)>,
) -> Result<()> {
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
fn draw_markers<'a, DB: DrawingBackend + 'a, X: Axis, Y: Axis>(
    chart: &mut Chart<'a, DB, X, Y>,
    path: &Path,
    runs: &[(String, Vec<(X::ValueType, Y::ValueType)>)],
    radius: i32,
) -> Result<()> {
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

/// Tick values on a log axis over `[lo, hi]`: 1-2-5 in each decade over up to two decades,
/// 1-3 up to four, the decades beyond; one label per tick, no minor lines.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo) {
        return vec![];
    }
    let decades = hi.log10() - lo.log10();
    // Under half a decade 1-2-5 may leave one tick (0.045 to 0.07 ms): every integer mantissa.
    let mantissas: &[f64] = if decades <= 0.5 {
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    } else if decades <= 2.2 {
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
