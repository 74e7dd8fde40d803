//! A dataset's preview: eight of its silhouettes and depth maps, evenly spaced through it,
//! written beside the dataset as `NAME.preview.png`.

use std::path::Path;

use crate::core::error::Result;
use crate::data::dataset::{BuildReport, Dataset};
use crate::report::figures::{GridRow, image_grid};

/// Draw `data`'s preview beside `out` (the dataset's `.npz`), depth scaled to the range its
/// build `report` measured (0.5 to 1.5 m where it has none).
pub fn dataset_preview(data: &Dataset, report: &BuildReport, out: &Path) -> Result<()> {
    let shown = 8.min(data.len());
    let picks: Vec<usize> = (0..shown).map(|k| k * data.len() / shown).collect();
    let silhouettes: Vec<Vec<f32>> = picks
        .iter()
        .map(|&i| data.image(i).iter().map(|&v| v as f32 / 255.0).collect())
        .collect();
    let range = report
        .stats
        .depth_m
        .as_ref()
        .map_or([0.5, 1.5], |d| [d.min as f32, d.max as f32]);
    let rows = [
        GridRow::Grey(silhouettes.iter().map(Vec::as_slice).collect()),
        GridRow::Depth(picks.iter().map(|&i| data.depth_map(i)).collect(), range),
    ];
    image_grid(
        &out.with_extension("preview.png"),
        &rows,
        &["silhouette", "depth"],
        &[],
        data.width,
        data.height,
        1,
    )
}
