//! A trained field as a [`Render`]: images, depth, other views, and the field's own
//! measurements (its marchers compared, novel views), every rendered image kept for them.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use burn::tensor::{Device, Tensor, TensorData};

use crate::core::error::{Error, Result};
use crate::data::dataset::Dataset;
use crate::eval::evaluation::DepthPixels;
use crate::eval::evaluation::{Predictions, Quality, score};
use crate::self_models::ffksm::accelerated_marcher::AcceleratedConfig;
use crate::self_models::ffksm::field::OccupancyField;
use crate::self_models::{
    camera_input::views_of_rows,
    harness::host_targets,
    model::{BodyFit, Render, ReportContext},
};
use crate::sim::camera::Camera;
use crate::sim::robot::Robot;

use super::{
    config::Ffksm,
    evaluation::{NovelViewRow, Rendered, RendererRow, mean_iou, mean_psnr, render_all},
};

/// How far the papers' arm reaches from its base (m): a framed robot's scene is shrunk to it.
pub(super) const PAPERS_ARM_REACH_M: f64 = 0.45;

/// A trained field and what its renderers share: every image they render is kept.
pub(super) struct FfksmShared {
    pub(super) field: OccupancyField,
    pub(super) model: Ffksm,
    pub(super) camera: Camera,
    pub(super) robot: Robot,
    pub(super) device: Device,
    /// Per renderer label: the images rendered so far (the test set first).
    pub(super) stats: Mutex<BTreeMap<String, Rendered>>,
}

/// One of a trained field's renderers (dense marching, or the accelerated marcher).
pub struct FfksmRenderer {
    pub(super) shared: Arc<FfksmShared>,
    pub(super) accelerated: Option<AcceleratedConfig>,
    pub(super) label: String,
}

impl FfksmRenderer {
    fn render_from(&self, camera: &Camera, angles_deg: &[Vec<f64>], label: &str) -> Rendered {
        let s = &self.shared;
        render_all(
            &s.field,
            &s.robot,
            (camera, angles_deg),
            &s.model,
            self.accelerated.as_ref(),
            &s.device,
            label,
        )
    }
}

/// `[n, dof]` degrees as host rows.
pub(super) fn angle_rows(angles: Tensor<2>) -> Vec<Vec<f64>> {
    let [_, dof] = angles.dims();
    let v = angles
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .expect("float");
    v.chunks(dof.max(1))
        .map(|r| r.iter().map(|&a| a as f64).collect())
        .collect()
}

/// What a saved FFKSM keeps beside its field's weights: its configuration as fitted to the
/// scene, and which marcher renders.
#[derive(serde::Serialize, serde::Deserialize)]
pub(super) struct FfksmState {
    pub(super) fitted: Ffksm,
    pub(super) accelerated: Option<AcceleratedConfig>,
    pub(super) label: String,
}

impl Render for FfksmRenderer {
    fn save(&self, path: &std::path::Path) -> Result<Option<serde_json::Value>> {
        crate::train::checkpoint::save_module(&self.shared.field, path)?;
        let state = FfksmState {
            fitted: self.shared.model.clone(),
            accelerated: self.accelerated.clone(),
            label: self.label.clone(),
        };
        Ok(Some(
            serde_json::to_value(state).expect("FFKSM's state serialises"),
        ))
    }

    /// Inputs of `dof + 9` columns (trained on several views): each row from its camera.
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        let dof = self.shared.robot.dof();
        let camera = &self.shared.camera;
        let rows = angle_rows(angles);
        let flat: Vec<f32> = rows.iter().flatten().map(|&v| v as f32).collect();
        let width = rows.first().map_or(dof, Vec::len);
        let views =
            views_of_rows(&flat, width, dof, camera).expect("camera inputs of valid cameras");
        let (mut sil, mut depth) = (Vec::new(), Some(Vec::new()));
        for (run, view) in views {
            let angles: Vec<Vec<f64>> = rows[run].iter().map(|r| r[..dof].to_vec()).collect();
            let r = self.render_from(&view, &angles, &self.label);
            sil.extend_from_slice(&r.predictions.silhouettes);
            depth = depth
                .zip(r.predictions.depth.as_ref())
                .map(|(mut d, more)| {
                    d.extend_from_slice(more);
                    d
                });
            self.shared
                .stats
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .entry(self.label.clone())
                .or_insert_with(Rendered::empty)
                .extend(r);
        }
        let shape = [rows.len(), 1, camera.height, camera.width];
        let tensor =
            |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, shape), &self.shared.device);
        (tensor(sil), depth.map(tensor))
    }

    fn depth_pixels(&self) -> DepthPixels {
        DepthPixels::Drawn
    }

    fn render_view(&self, camera: &Camera, angles: Tensor<2>) -> Option<Tensor<4>> {
        let rows = angle_rows(angles);
        let shape = [rows.len(), 1, camera.height, camera.width];
        let r = self.render_from(camera, &rows, &self.label);
        Some(Tensor::<4>::from_data(
            TensorData::new(r.predictions.silhouettes, shape),
            &self.shared.device,
        ))
    }
}

/// FFKSM's own measurements ([`FfksmRenderer::comparison`]).
pub struct FfksmComparison {
    /// Dense marching, the accelerated marcher, and the accelerated one without early
    /// termination, on the same test images.
    pub renderers: Vec<RendererRow>,
    /// One row per camera: the training camera (yaw 0), then each novel view.
    pub novel_views: Vec<NovelViewRow>,
    /// Per novel view: the simulator's test silhouettes and the accelerated marcher's,
    /// `[n, H * W]` each.
    pub novel_images: Vec<(Vec<f32>, Vec<f32>)>,
    /// The novel views' yaws (degrees), in order.
    pub yaws_deg: Vec<f64>,
    /// `[height, width]`.
    pub image: [usize; 2],
}

impl FfksmRenderer {
    /// Its network evaluations per image over the first `test_images` it rendered (the test
    /// set), said in its row.
    pub fn evaluations_note(&self, test_images: usize) -> String {
        let evals = self
            .shared
            .stats
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&self.label)
            .map_or(0.0, |r| r.first(test_images).mean_evaluations());
        format!("{evals:.0} network evaluations per image; tested on {test_images} images")
    }

    /// The field's own measurements, from the accelerated marcher (the last renderer) once
    /// the harness has rendered the test set: both marchers and the accelerated one without
    /// early termination on the same test images, and the novel views (the training camera
    /// turned about the vertical) against the simulator's images. `None` from dense marching,
    /// or where the model keeps no reference renderers.
    pub fn comparison(
        &self,
        ctx: &ReportContext<FfksmRenderer>,
    ) -> Result<Option<FfksmComparison>> {
        if self.accelerated.is_none() || !self.shared.model.reference_renderers {
            return Ok(None);
        }
        let s = &self.shared;
        let (truth, truth_depth) = ctx.truth;
        let pixels = s.camera.width * s.camera.height;
        let n = ctx.test.len();
        let test_angles: Vec<Vec<f64>> = ctx
            .test
            .clone()
            .map(|i| ctx.data.angles[i].clone())
            .collect();
        let score_of =
            |p: &Predictions, t: &[f32], d: &[f32]| score(p, t, Some(d), ctx.paper_subset);
        let first = |label: &str| -> Result<Rendered> {
            s.stats
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get(label)
                .map(|r| r.first(n))
                .ok_or_else(|| Error::Training(format!("{label}: nothing rendered")))
        };
        let dense = first("dense marching")?;
        let fast = first("accelerated")?;
        // What early termination adds to the grid: the same marcher without it.
        let no_termination = FfksmRenderer {
            shared: s.clone(),
            accelerated: Some(AcceleratedConfig {
                termination: None,
                ..s.model.accelerated.clone()
            }),
            label: "skipping only".into(),
        };
        let skipping_only = no_termination.render_from(&s.camera, &test_angles, "skipping only");
        let dense_evals = dense.mean_evaluations();
        let renderer_row = |name: &str, r: &Rendered| {
            let q = score_of(&r.predictions, truth, truth_depth);
            RendererRow {
                model: ctx.name.into(),
                renderer: name.into(),
                test_images: q.test_images,
                evaluations_per_image: r.mean_evaluations(),
                grid_evaluations_per_image: r.grid_evaluations.iter().sum::<usize>() as f64
                    / r.grid_evaluations.len().max(1) as f64,
                grid_occupancy: r.grid_occupancy.iter().sum::<f64>()
                    / r.grid_occupancy.len().max(1) as f64,
                fewer_evaluations: dense_evals / r.mean_evaluations().max(1.0),
                img_per_s: r.images_per_second(),
                psnr_db_test: q.psnr_db_test,
                iou_test: q.iou_test,
                psnr_db_vs_dense: mean_psnr(
                    &r.predictions.silhouettes,
                    &dense.predictions.silhouettes,
                    pixels,
                ),
                depth_mae_mm: q.depth_mae_mm,
                git_revision: ctx.git_revision.into(),
                device: ctx.device_name.clone(),
                preset: ctx.preset.into(),
            }
        };
        let renderers = vec![
            renderer_row("dense marching", &dense),
            renderer_row("accelerated", &fast),
            renderer_row("accelerated without early termination", &skipping_only),
        ];
        // Novel views: the simulator's images from orbited cameras, the accelerated marcher.
        let fast_q = score_of(&fast.predictions, truth, truth_depth);
        let view_row = |yaw: f64, q: &Quality, blind: (f64, f64)| NovelViewRow {
            model: ctx.name.into(),
            yaw_deg: yaw,
            test_images: q.test_images,
            psnr_db: q.psnr_db_test,
            iou: q.iou_test,
            depth_mae_mm: q.depth_mae_mm,
            view_blind_psnr_db: blind.0,
            view_blind_iou: blind.1,
            renderer: "accelerated".into(),
            git_revision: ctx.git_revision.into(),
            device: ctx.device_name.clone(),
            preset: ctx.preset.into(),
        };
        let mut novel = vec![view_row(0.0, &fast_q, (f64::INFINITY, 1.0))];
        let mut novel_images = Vec::new();
        // The cameras turn about the vertical through the point they look at: the configured
        // target, or for a framed or recorded camera (whose record keeps no target) the point
        // on its axis nearest the centre of the robot's poses.
        let pivot = if let Some(configured) = ctx.spec.configured_camera() {
            configured.target
        } else {
            let si: Vec<Vec<f64>> = ctx
                .data
                .angles
                .iter()
                .map(|q| s.robot.chain.to_si(q))
                .collect();
            let points = crate::data::dataset::swept_points(&s.robot, &si);
            s.camera
                .axis_point_nearest(crate::sim::shape::Aabb::from_points(&points).center())
        };
        for &yaw in &s.model.novel_views_deg {
            // The simulator's view of the same poses from the orbited camera.
            let mut spec = ctx.spec.dataset.clone();
            spec.camera = s.camera.orbited_about(pivot, yaw);
            spec.framing = None;
            spec.samples = ctx.data.len();
            spec.train = ctx.data.n_train;
            let view_data = Dataset::render(&s.robot, &spec, ctx.data.angles.clone(), None)?;
            let (vt, vd) = host_targets(&view_data, ctx.test);
            let r = self.render_from(&spec.camera, &test_angles, &format!("novel view {yaw} deg"));
            let q = score_of(&r.predictions, &vt, &vd);
            novel.push(view_row(
                yaw,
                &q,
                (mean_psnr(truth, &vt, pixels), mean_iou(truth, &vt, pixels)),
            ));
            novel_images.push((vt, r.predictions.silhouettes));
        }
        Ok(Some(FfksmComparison {
            renderers,
            novel_views: novel,
            novel_images,
            yaws_deg: s.model.novel_views_deg.clone(),
            image: [s.camera.height, s.camera.width],
        }))
    }
}

/// Not differentiable here, no chain of its own: nothing for reading the body back.
impl BodyFit for FfksmRenderer {}
