//! FFKSM's own reports: its marchers compared on the same test images (`renderers.csv`), its
//! novel views (`novel_views.csv`, `novel_views.png`), and each row's network evaluations per
//! image, from what the trained field measures of itself
//! ([`selfmodel::self_models::ffksm::FfksmRenderer::comparison`]).

use std::path::Path;

use selfmodel::core::error::Result;
use selfmodel::report::figures::{GridRow, image_grid};
use selfmodel::report::table::write_table;
use selfmodel::self_models::ffksm::{FfksmRenderer, NovelViewRow, RendererRow};
use selfmodel::self_models::harness::{grid_picks, nth_image};
use selfmodel::self_models::model::ReportContext;
use selfmodel::self_models::result::ModelResult;

/// Start each row's note with its renderer's network evaluations per image, and write the
/// comparison the accelerated marcher makes (where the model keeps its reference renderers).
pub fn write(rows: &mut [ModelResult], ctx: &ReportContext<FfksmRenderer>) -> Result<()> {
    let tested = ctx.test.len();
    for (row, (_, renderer)) in rows.iter_mut().zip(ctx.renderers) {
        let said = renderer.evaluations_note(tested);
        row.note = if row.note.is_empty() {
            said
        } else {
            format!("{said}; {}", row.note)
        };
    }
    for (_, renderer) in ctx.renderers {
        if let Some(c) = renderer.comparison(ctx)? {
            write_tables(ctx.dir, ctx.name, &c.renderers, &c.novel_views)?;
            novel_view_figure(
                &ctx.dir.join("novel_views.png"),
                &c.novel_images,
                &c.yaws_deg,
                c.image,
            )?;
        }
    }
    Ok(())
}

fn write_tables(
    dir: &Path,
    name: &str,
    renderers: &[RendererRow],
    novel: &[NovelViewRow],
) -> Result<()> {
    write_table(
        &dir.join("renderers.csv"),
        renderers,
        &format!("{name}: dense marching against the accelerated marcher"),
        "Same model, same test images. `fewer_evaluations` is dense marching's network evaluations per image over this renderer's (the grid's probes included); `psnr_db_vs_dense` compares the two renderers' images directly. Images/s: median time per image after one warm-up image, batch 1, this machine.",
    )?;
    write_table(
        &dir.join("novel_views.csv"),
        novel,
        &format!("{name}: views it was never trained on"),
        "The training camera turned about the vertical through the point it looks at (the papers' camera: the world z axis); the truth is the simulator's image from that camera. `view_blind_*`: the training camera's true silhouette offered as the prediction, what a 2-D decoder (NeuroKin) can at best output for another camera.",
    )
}

/// For each novel view (camera yaw `yaws_deg`), a row of truths then a row of predictions (six
/// poses).
fn novel_view_figure(
    path: &Path,
    views: &[(Vec<f32>, Vec<f32>)],
    yaws_deg: &[f64],
    size: [usize; 2],
) -> Result<()> {
    let px = size[0] * size[1];
    let Some(first) = views.first() else {
        return Ok(());
    };
    // The same six test poses from every view.
    let picks = grid_picks(first.0.len() / px);
    let mut rows = Vec::new();
    for (truth, pred) in views {
        rows.push(GridRow::Grey(
            picks.iter().map(|&i| nth_image(truth, i, px)).collect(),
        ));
        rows.push(GridRow::Grey(
            picks.iter().map(|&i| nth_image(pred, i, px)).collect(),
        ));
    }
    let titles: Vec<String> = yaws_deg
        .iter()
        .flat_map(|y| {
            [
                format!("{y:.0} deg: truth"),
                format!("{y:.0} deg: prediction"),
            ]
        })
        .collect();
    let titles: Vec<&str> = titles.iter().map(String::as_str).collect();
    // Under each column: that pose's PSNR and IoU from each view, a line per view.
    let captions: Vec<String> = picks
        .iter()
        .map(|&i| {
            views
                .iter()
                .zip(yaws_deg)
                .map(|((truth, pred), yaw)| {
                    let (t, p) = (nth_image(truth, i, px), nth_image(pred, i, px));
                    format!(
                        "{yaw:.0} deg: {:.1} dB IoU {:.2}",
                        selfmodel::eval::evaluation::psnr_db(p, t),
                        selfmodel::eval::evaluation::iou(p, t)
                    )
                })
                .collect::<Vec<_>>()
                .join(", ")
        })
        .collect();
    image_grid(path, &rows, &titles, &captions, size[1], size[0], 2)
}
