//! Preview images: grids of silhouettes and depth maps as PNG.

use std::path::Path;

use image::{GrayImage, Luma};

use crate::core::atomic_file::write_bytes;
use crate::core::error::{Error, Result};

/// A grid of `cols` columns: each tile is one `width x height` u8 image; a 2-pixel gray gap.
pub fn tile_grid(tiles: &[Vec<u8>], width: usize, height: usize, cols: usize) -> GrayImage {
    let gap = 2;
    let cols = cols.max(1).min(tiles.len().max(1));
    let rows = tiles.len().div_ceil(cols).max(1);
    let mut img = GrayImage::from_pixel(
        (cols * (width + gap) + gap) as u32,
        (rows * (height + gap) + gap) as u32,
        Luma([96]),
    );
    for (i, tile) in tiles.iter().enumerate() {
        let (ox, oy) = (
            gap + (i % cols) * (width + gap),
            gap + (i / cols) * (height + gap),
        );
        for y in 0..height {
            for x in 0..width {
                img.put_pixel(
                    (ox + x) as u32,
                    (oy + y) as u32,
                    Luma([tile[y * width + x]]),
                );
            }
        }
    }
    img
}

/// A depth map as u8: near is bright, far is dark, empty is black; `range` = (near, far) in m.
pub fn depth_to_gray(depth: &[f32], range: (f32, f32)) -> Vec<u8> {
    let (near, far) = range;
    let span = (far - near).max(1e-6);
    depth
        .iter()
        .map(|&d| {
            if d <= 0.0 {
                0
            } else {
                (255.0 - 200.0 * ((d - near) / span).clamp(0.0, 1.0)) as u8
            }
        })
        .collect()
}

/// Encode a gray image as PNG and write it atomically.
pub fn save_png(path: &Path, img: &GrayImage) -> Result<()> {
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| Error::data(path, format!("cannot encode PNG: {e}")))?;
    write_bytes(path, &bytes)
}
