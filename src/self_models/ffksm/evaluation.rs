//! FFKSM's own measurements: dense marching against the accelerated marcher on the same
//! model, and novel views (the camera turned about the vertical), as rows.

use std::time::Instant;

use burn::tensor::{Device, Tensor};

use crate::eval::evaluation::DepthPixels;
use crate::eval::evaluation::{Predictions, iou, psnr_db};
use crate::self_models::ffksm::accelerated_marcher::{AcceleratedConfig, render_accelerated};
use crate::self_models::ffksm::field::OccupancyField;
use crate::self_models::ffksm::marcher::render_dense;
use crate::sim::camera::Camera;
use crate::sim::robot::Robot;

use super::{config::Ffksm, training::radians};

/// Dense marching against the accelerated marcher, the same model and test images.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RendererRow {
    pub model: String,
    pub renderer: String,
    pub test_images: usize,
    /// Mean network evaluations per image (the accelerated marcher's include its grid).
    pub evaluations_per_image: f64,
    pub grid_evaluations_per_image: f64,
    /// Mean fraction of grid cells occupied (1 for dense marching, which has no grid).
    pub grid_occupancy: f64,
    /// Dense evaluations per image divided by this renderer's.
    pub fewer_evaluations: f64,
    pub img_per_s: f64,
    pub psnr_db_test: f64,
    pub iou_test: f64,
    /// PSNR of this renderer's images against dense marching's (infinite for dense itself).
    pub psnr_db_vs_dense: f64,
    pub depth_mae_mm: Option<f64>,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// Quality from a camera the model was never trained on.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct NovelViewRow {
    pub model: String,
    /// Camera orbited about the world z axis by this angle (0: the training camera).
    pub yaw_deg: f64,
    pub test_images: usize,
    pub psnr_db: f64,
    pub iou: f64,
    pub depth_mae_mm: Option<f64>,
    /// A view-blind model's score: the training camera's true silhouette offered as the
    /// prediction for this camera (what a 2-D decoder such as NeuroKin can at best output).
    pub view_blind_psnr_db: f64,
    pub view_blind_iou: f64,
    pub renderer: String,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// Images rendered by one renderer, with per-image evaluations and seconds.
pub(super) struct Rendered {
    pub(super) predictions: Predictions,
    evaluations: Vec<usize>,
    pub(super) grid_evaluations: Vec<usize>,
    pub(super) grid_occupancy: Vec<f64>,
    seconds: Vec<f64>,
}

impl Rendered {
    pub(super) fn empty() -> Self {
        Rendered {
            predictions: Predictions {
                silhouettes: Vec::new(),
                depth: Some(Vec::new()),
                pixels: 0,
                depth_pixels: DepthPixels::Drawn,
            },
            evaluations: Vec::new(),
            grid_evaluations: Vec::new(),
            grid_occupancy: Vec::new(),
            seconds: Vec::new(),
        }
    }

    /// Append `other`'s images.
    pub(super) fn extend(&mut self, other: Rendered) {
        self.predictions.pixels = other.predictions.pixels;
        self.predictions
            .silhouettes
            .extend(other.predictions.silhouettes);
        if let (Some(d), Some(o)) = (self.predictions.depth.as_mut(), other.predictions.depth) {
            d.extend(o);
        }
        self.evaluations.extend(other.evaluations);
        self.grid_evaluations.extend(other.grid_evaluations);
        self.grid_occupancy.extend(other.grid_occupancy);
        self.seconds.extend(other.seconds);
    }

    /// The first `n` images (the test set: the harness renders it before it times).
    pub(super) fn first(&self, n: usize) -> Rendered {
        let px = self.predictions.pixels;
        let n = n.min(self.evaluations.len());
        Rendered {
            predictions: Predictions {
                silhouettes: self.predictions.silhouettes[..n * px].to_vec(),
                depth: self
                    .predictions
                    .depth
                    .as_ref()
                    .map(|d| d[..n * px].to_vec()),
                pixels: px,
                depth_pixels: self.predictions.depth_pixels,
            },
            evaluations: self.evaluations[..n].to_vec(),
            grid_evaluations: self.grid_evaluations[..n].to_vec(),
            grid_occupancy: self.grid_occupancy[..n].to_vec(),
            seconds: self.seconds[..n].to_vec(),
        }
    }

    pub(super) fn mean_evaluations(&self) -> f64 {
        self.evaluations.iter().sum::<usize>() as f64 / self.evaluations.len().max(1) as f64
    }

    /// Images per second from the median time per image, the first (warm-up) left out.
    pub(super) fn images_per_second(&self) -> f64 {
        let t: Vec<f64> = self.seconds.iter().skip(1).copied().collect();
        let t = if t.is_empty() { &self.seconds } else { &t };
        1.0 / crate::core::timing::median(t).max(1e-12)
    }
}

/// Render every pose of `angles_deg` (`[n][dof]`, degrees) from `camera`, densely (`None`) or
/// with the accelerated marcher.
pub(super) fn render_all(
    field: &OccupancyField,
    robot: &Robot,
    (camera, angles_deg): (&Camera, &[Vec<f64>]),
    cfg: &Ffksm,
    accelerated: Option<&AcceleratedConfig>,
    device: &Device,
    label: &str,
) -> Rendered {
    let camera = &cfg.field_camera(camera);
    let pixels = camera.width * camera.height;
    let all: Vec<usize> = (0..pixels).collect();
    let mut out = Rendered {
        predictions: Predictions {
            silhouettes: Vec::new(),
            depth: Some(Vec::new()),
            pixels,
            depth_pixels: crate::eval::evaluation::DepthPixels::Drawn,
        },
        evaluations: Vec::new(),
        grid_evaluations: Vec::new(),
        grid_occupancy: Vec::new(),
        seconds: Vec::new(),
    };
    let bar = crate::core::progress::progress_bar(angles_deg.len() as u64, label, "images");
    for a in angles_deg {
        let a32: Vec<f32> = a.iter().map(|&v| v as f32).collect();
        let radians = radians(&a32, &robot.chain);
        let view = (camera, radians.as_slice());
        let t0 = Instant::now();
        let (sil, depth, evals, grid, occupancy) = if let Some(acc) = accelerated {
            let img = render_accelerated(field, view, &cfg.march, acc, device);
            (
                img.silhouette,
                img.depth,
                img.evaluations,
                img.grid_evaluations,
                img.grid_occupancy,
            )
        } else {
            let (s, d, e) =
                render_dense(field, view, &all, &cfg.march, None, cfg.chunk_rays, device);
            let host = |t: Tensor<1>| t.into_data().try_into_vec::<f32>().expect("float");
            (host(s), host(d), e, 0, 1.0)
        };
        out.seconds.push(t0.elapsed().as_secs_f64());
        out.predictions.silhouettes.extend(sil);
        if let Some(d) = out.predictions.depth.as_mut() {
            if cfg.scene_scale == 1.0 {
                d.extend(depth);
            } else {
                d.extend(depth.iter().map(|&v| v * cfg.scene_scale as f32));
            }
        }
        out.evaluations.push(evals);
        out.grid_evaluations.push(grid);
        out.grid_occupancy.push(occupancy);
        bar.inc(1);
    }
    bar.finish_and_clear();
    out
}

/// Mean PSNR of `a` against `b`, image by image (`pixels` each).
pub(super) fn mean_psnr(a: &[f32], b: &[f32], pixels: usize) -> f64 {
    let n = a.len() / pixels.max(1);
    (0..n)
        .map(|i| {
            psnr_db(
                &a[i * pixels..(i + 1) * pixels],
                &b[i * pixels..(i + 1) * pixels],
            )
        })
        .sum::<f64>()
        / n.max(1) as f64
}

pub(super) fn mean_iou(a: &[f32], b: &[f32], pixels: usize) -> f64 {
    let n = a.len() / pixels.max(1);
    (0..n)
        .map(|i| {
            iou(
                &a[i * pixels..(i + 1) * pixels],
                &b[i * pixels..(i + 1) * pixels],
            )
        })
        .sum::<f64>()
        / n.max(1) as f64
}
