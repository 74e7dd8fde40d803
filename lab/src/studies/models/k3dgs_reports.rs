//! K-3DGS's own reports: `render_speed.csv` (culled, as the harness timed it, against dense
//! splatting), `gaussian_counts.csv` (the set's size through training) and `gaussians.png`
//! (the Gaussians' centres over the true silhouette).

use selfmodel::core::error::Result;
use selfmodel::eval::inference_speed::Timing;
use selfmodel::report::table::{write_csv, write_table};
use selfmodel::self_models::harness::grid_picks;
use selfmodel::self_models::k3dgs::K3dgsRenderer;
use selfmodel::self_models::model::ReportContext;

/// Culled against dense splatting.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RenderSpeedRow {
    pub model: String,
    pub splatting: String,
    pub batch: usize,
    pub img_per_s: f64,
    pub gaussians: usize,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// The Gaussians' count after each change of the set during training.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CountRow {
    pub step: usize,
    pub gaussians: usize,
}

/// Write the three reports of the (one) trained model into `ctx.dir`.
pub fn write(ctx: &ReportContext<K3dgsRenderer>) -> Result<()> {
    let Some((_, k3dgs)) = ctx.renderers.first() else {
        return Ok(());
    };
    let dense = k3dgs.dense_timings(ctx.data.dof(), ctx.device);
    let row = |splatting: &str, t: &Timing| RenderSpeedRow {
        model: ctx.name.into(),
        splatting: splatting.into(),
        batch: t.batch,
        img_per_s: t.images_per_second(),
        gaussians: k3dgs.model.len(),
        git_revision: ctx.git_revision.into(),
        device: ctx.device_name.clone(),
        preset: ctx.preset.into(),
    };
    let speed: Vec<RenderSpeedRow> = ctx.rendered[0]
        .timings
        .iter()
        .map(|t| row("culled", t))
        .chain(dense.iter().map(|t| row("dense", t)))
        .collect();
    write_table(
        &ctx.dir.join("render_speed.csv"),
        &speed,
        &format!("{}: culled against dense splatting", ctx.name),
        "Images/s of the trained model, median of synchronised timed calls after warm-up; dense splatting evaluates every (Gaussian, pixel) pair, culled only those within `cull_sigmas` standard deviations.",
    )?;
    let counts: Vec<CountRow> = k3dgs
        .counts
        .iter()
        .map(|&(step, gaussians)| CountRow { step, gaussians })
        .collect();
    write_csv(&ctx.dir.join("gaussian_counts.csv"), &counts)?;
    gaussians_figure(ctx, k3dgs)
}

/// Six test poses: the true silhouette with the Gaussians' projected centres over it.
fn gaussians_figure(ctx: &ReportContext<K3dgsRenderer>, k3dgs: &K3dgsRenderer) -> Result<()> {
    let picks: Vec<usize> = grid_picks(ctx.test.len())
        .into_iter()
        .map(|k| ctx.test.start + k)
        .collect();
    let poses: Vec<Vec<f64>> = picks.iter().map(|&i| ctx.data.angles[i].clone()).collect();
    let points = k3dgs.projected_centres(&poses);
    let images: Vec<Vec<f32>> = picks
        .iter()
        .map(|&i| {
            ctx.data
                .image(i)
                .iter()
                .map(|&v| v as f32 / 255.0)
                .collect()
        })
        .collect();
    let refs: Vec<&[f32]> = images.iter().map(|v| v.as_slice()).collect();
    let camera = k3dgs.camera();
    let caption = format!(
        "{} Gaussians: their projected centres (green) over the true silhouette (grey), six test poses",
        k3dgs.model.len()
    );
    selfmodel::report::figures::points_over_images(
        &ctx.dir.join("gaussians.png"),
        &refs,
        &points,
        camera.width,
        camera.height,
        3,
        &caption,
    )
}
