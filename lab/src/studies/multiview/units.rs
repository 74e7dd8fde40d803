//! A scored model kept as a unit (its rows and grid images, with the settings it ran with),
//! so `--resume` reuses it.

use std::path::Path;

use serde::{Deserialize, Serialize};

use selfmodel::core::error::{Error, Result};

use super::{
    scoring::Scored,
    {MultiviewConfig, MultiviewRow},
};

/// The file a scored unit is kept in, inside its folder; its grid images beside it.
pub(super) const UNIT: &str = "unit.json";
pub(super) const UNIT_GRID: &str = "unit_grid.png";

/// A scored unit as kept: its rows, and how many grid images (then true images) its
/// `unit_grid.png` holds side by side.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct KeptUnit {
    rows: Vec<MultiviewRow>,
    size: [usize; 2],
    grid_images: usize,
    truth_images: usize,
}

/// What a kept unit must have been made with: the model's run and how it is scored.
pub(super) fn unit_fingerprint<T: Serialize>(
    cfg: &MultiviewConfig,
    run: &T,
) -> Result<serde_json::Value> {
    selfmodel::core::unit_cache::fingerprint(&serde_json::json!({
        "run": selfmodel::core::unit_cache::fingerprint(run)?,
        "held_out": cfg.held_out,
        "test_poses": cfg.test_poses,
        "preset": cfg.preset,
    }))
}

/// A unit's scores and image size: with `resume`, the ones kept in `unit` if made with
/// `fingerprint`; otherwise `make`'s, then kept. Grid images are kept at 8 bits, and a run
/// draws them from what it kept, so a resumed run draws the same figure.
pub(super) fn kept_unit(
    unit: &Path,
    fingerprint: &serde_json::Value,
    resume: bool,
    make: impl FnOnce() -> Result<(Scored, [usize; 2])>,
) -> Result<(Scored, [usize; 2])> {
    let (json, png) = (unit.join(UNIT), unit.join(UNIT_GRID));
    // A unit as kept: its rows, and its images split into the grid's and the truth's.
    let read = || {
        let kept = selfmodel::core::unit_cache::load::<KeptUnit>(&json, fingerprint)?;
        let mut grid_row = read_strip(&png, kept.size, kept.grid_images + kept.truth_images)?;
        let grid_truth = grid_row.split_off(kept.grid_images);
        let scored = Scored {
            rows: kept.rows,
            grid_row,
            grid_truth,
        };
        Some((scored, kept.size))
    };
    if resume && let Some((scored, size)) = read() {
        let model = scored.rows.first().map_or("a unit", |r| r.model.as_str());
        eprintln!("multiview: {model} kept from {}", json.display());
        return Ok((scored, size));
    }
    let (scored, size) = make()?;
    let images: Vec<Vec<f32>> = scored
        .grid_row
        .iter()
        .chain(&scored.grid_truth)
        .cloned()
        .collect();
    write_strip(&png, size, &images)?;
    let kept = KeptUnit {
        rows: scored.rows,
        size,
        grid_images: scored.grid_row.len(),
        truth_images: scored.grid_truth.len(),
    };
    selfmodel::core::unit_cache::save(&json, fingerprint, &kept)?;
    // Read back as a resumed run would: the same 8-bit images either way.
    read().ok_or_else(|| Error::data(&json, "cannot read back the unit just written"))
}

/// `images` (each `[h, w]`, values in [0, 1]) side by side in one 8-bit grey PNG.
pub(super) fn write_strip(path: &Path, [h, w]: [usize; 2], images: &[Vec<f32>]) -> Result<()> {
    let k = images.len();
    let mut buf = vec![0u8; k.max(1) * w * h];
    for (i, im) in images.iter().enumerate() {
        for y in 0..h {
            for x in 0..w {
                buf[y * k * w + i * w + x] = (im[y * w + x].clamp(0.0, 1.0) * 255.0).round() as u8;
            }
        }
    }
    let mut png = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        &buf,
        (k.max(1) * w) as u32,
        h as u32,
        image::ExtendedColorType::L8,
    )
    .map_err(|e| Error::data(path, format!("cannot encode PNG: {e}")))?;
    selfmodel::core::atomic_file::write_bytes(path, &png)
}

/// The `k` images of a strip [`write_strip`] wrote, if it reads and has their size.
pub(super) fn read_strip(path: &Path, [h, w]: [usize; 2], k: usize) -> Option<Vec<Vec<f32>>> {
    let img = image::open(path).ok()?.to_luma8();
    if img.height() as usize != h || img.width() as usize != k.max(1) * w {
        return None;
    }
    let raw = img.into_raw();
    Some(
        (0..k)
            .map(|i| {
                (0..h * w)
                    .map(|p| raw[(p / w) * k * w + i * w + p % w] as f32 / 255.0)
                    .collect()
            })
            .collect(),
    )
}
