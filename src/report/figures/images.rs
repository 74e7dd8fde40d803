//! Images: the qualitative grid (ground truth, prediction, error, depth) and points drawn over
//! images.

use std::path::Path;

use plotters::prelude::*;

use super::{FONT, draw_err, register_font, save_rgb};
use crate::core::error::Result;
use crate::report::canvas::Canvas;

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
