//! `multiview`: beyond one camera (the self-modeling paper's Section VI-D1). NeuroKin learns
//! one view; here it learns N views, two ways: **camera-conditioned** (f(theta, c): the
//! camera's pose joins the joint angles at the input, so any camera renders) and
//! **multi-head** (one output per trained camera). Both train through the one harness on a
//! multi-view dataset (every pose from N cameras on a sphere around the robot) and are tested
//! on held-out poses, from the trained cameras and from cameras never trained on (yawed and
//! raised away from the first). Against: FFKSM (the original model) and K-3DGS, trained on
//! the first camera and on the same N cameras (reading each image's camera from its inputs,
//! [`selfmodel::self_models::model::SelfModel::renders_any_view`]) and rendering the held-out
//! cameras in 3-D, and the view-blind bound (the
//! nearest trained camera's true image of the same pose: the best a model of the trained
//! views can show). Writes `reports/multiview/`:
//! - `results.csv`: `model,cameras_trained,camera,held_out,psnr_db,iou,img_per_s`, the
//!   angle to the nearest trained camera, and the provenance;
//! - `grid.png`: one held-out pose, truth and each model (columns: the held-out cameras);
//! - `psnr_vs_angle.png`: PSNR against the angle to the nearest trained camera;
//! - `psnr_vs_cameras.png`: the camera-conditioned model's PSNR against N.

mod figures;
mod scoring;
mod three_d;
mod units;

use std::path::Path;

use serde::{Deserialize, Serialize};

use selfmodel::core::atomic_file::write_json;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::preset::Preset;
use selfmodel::core::provenance::git_revision;
use selfmodel::data::dataset::Views;
use selfmodel::report::table::write_table;
use selfmodel::self_models::neurokin::{CameraUse, neurokin_run};
use selfmodel::self_models::{camera_input::camera_input, harness::fit_run};
use selfmodel::sim::camera::Camera;

use figures::draw;
use scoring::{Scoring, inputs, rendered, score};
use units::{kept_unit, unit_fingerprint};

/// A camera never trained on, placed relative to the first trained camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeldOutCamera {
    /// Yaw about the world z axis through the target, from the first camera's (degrees).
    pub yaw_deg: f64,
    /// Elevation above the horizontal plane through the target (degrees).
    pub elevation_deg: f64,
}

impl HeldOutCamera {
    fn label(&self) -> String {
        format!("yaw {} elevation {}", self.yaw_deg, self.elevation_deg)
    }

    fn camera(&self, first: &Camera) -> Camera {
        let (yaw, _, radius) = first.spherical();
        first.looking_from(
            first.target,
            radius,
            yaw + self.yaw_deg.to_radians(),
            self.elevation_deg.to_radians(),
        )
    }
}

fn one_camera() -> Vec<usize> {
    vec![1]
}

/// The study's settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MultiviewConfig {
    pub preset: String,
    /// The self-model preset: data (poses, image size), NeuroKin, FFKSM and K-3DGS.
    pub model_preset: String,
    /// Trained cameras, one run per count (the first camera is the dataset's own).
    pub cameras: Vec<usize>,
    /// Elevations of the even- and odd-numbered trained cameras ([`Views`]).
    pub elevation_deg: [f64; 2],
    pub held_out: Vec<HeldOutCamera>,
    /// NeuroKin's optimiser steps for every N (`None`: the preset's): one budget, however
    /// many views it is spread over.
    pub steps: Option<usize>,
    /// Also the multi-head NeuroKin (for N > 1; at N = 1 it is NeuroKin).
    pub multi_head: bool,
    /// Also FFKSM (the original model) and K-3DGS, trained on the first camera.
    pub three_d: bool,
    /// The 3-D models are also trained on each of these camera counts above 1 (the same
    /// cameras as NeuroKin's, their preset's steps: one budget over all views).
    #[serde(default = "one_camera")]
    pub three_d_cameras: Vec<usize>,
    /// Test poses scored (the first of the test split; `None`: all).
    pub test_poses: Option<usize>,
}

impl Preset for MultiviewConfig {
    /// The paper's 2,000 Lorenz poses (1,600 to train, 400 to test) from 1, 4, 8 and 16
    /// cameras at the paper camera's distance, even-numbered at its elevation (0 degrees),
    /// odd-numbered 30 degrees up; NeuroKin's paper network for 6,000 steps of 32 images at
    /// every N; held out: yawed 30 and 60 degrees, and raised to 50 degrees.
    fn paper() -> Self {
        MultiviewConfig {
            preset: "paper".into(),
            model_preset: "paper".into(),
            cameras: vec![1, 4, 8, 16],
            elevation_deg: [0.0, 30.0],
            held_out: vec![
                HeldOutCamera {
                    yaw_deg: 30.0,
                    elevation_deg: 0.0,
                },
                HeldOutCamera {
                    yaw_deg: 60.0,
                    elevation_deg: 0.0,
                },
                HeldOutCamera {
                    yaw_deg: 0.0,
                    elevation_deg: 50.0,
                },
            ],
            steps: Some(6000),
            multi_head: true,
            three_d: true,
            three_d_cameras: vec![1, 4],
            test_poses: None,
        }
    }

    /// The quick self-models (32x32, 200 steps), 1 and 4 cameras, 16 test poses: seconds.
    fn quick() -> Self {
        MultiviewConfig {
            preset: "quick".into(),
            model_preset: "quick".into(),
            cameras: vec![1, 4],
            steps: None,
            test_poses: Some(16),
            ..Self::paper()
        }
    }
}

/// One model on one camera (or the trained cameras together).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MultiviewRow {
    pub model: String,
    pub cameras_trained: usize,
    /// `trained` (every trained camera, held-out poses) or the held-out camera.
    pub camera: String,
    pub held_out: bool,
    /// Means over the test images.
    pub psnr_db: f64,
    pub iou: f64,
    /// Images rendered per second (one pass over the test images, in batches of 64, after a
    /// warm-up batch; `None`: the view-blind bound renders nothing).
    pub img_per_s: Option<f64>,
    /// The angle between this camera's view direction and the nearest trained camera's
    /// (degrees; 0 for the trained cameras).
    pub angle_to_nearest_deg: f64,
    pub images: usize,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// Run the study into `out`.
pub fn run(
    cfg: &MultiviewConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
) -> Result<String> {
    if cfg.cameras.is_empty() || cfg.cameras.contains(&0) {
        return Err(Error::Config(
            "multiview: every run needs at least one camera".into(),
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    write_json(&out.join("config.json"), cfg)?;
    let (device_name, revision) = (opts.device.to_string(), git_revision());
    let mut rows: Vec<MultiviewRow> = Vec::new();
    // Grid: per model, the first test pose from every held-out camera.
    let mut grid: Vec<(String, Vec<Vec<f32>>)> = Vec::new();
    let mut grid_truth: Vec<Vec<f32>> = Vec::new();
    let mut size = [0usize; 2];
    let largest = *cfg.cameras.iter().max().expect("checked above");
    for &n in &cfg.cameras {
        let mut base = opts.apply(neurokin_run(&cfg.model_preset)?)?;
        base.data.dataset.views = Some(Views {
            cameras: n,
            radius: None,
            elevation_deg: cfg.elevation_deg,
        });
        if let Some(steps) = cfg.steps {
            base.train.steps = steps;
        }
        let mut variants = vec![(
            "NeuroKin camera-conditioned".to_string(),
            "camera_input",
            CameraUse::Input,
        )];
        if cfg.multi_head && n > 1 {
            variants.push((
                "NeuroKin multi-head".into(),
                "multi_head",
                CameraUse::Heads(Vec::new()),
            ));
        }
        for (name, dir, camera_use) in variants {
            let mut run = base.clone();
            run.name = format!("{name} ({n} cameras)");
            run.model.camera = camera_use;
            if let CameraUse::Heads(heads) = &mut run.model.camera {
                // The heads' cameras: the dataset's, as it places them.
                let robot = base.data.robot.load()?;
                *heads = base
                    .data
                    .dataset
                    .cameras(&robot)?
                    .iter()
                    .map(camera_input)
                    .collect();
            }
            let unit = out.join(format!("{dir}_{n}"));
            let (scored, image_size) =
                kept_unit(&unit, &unit_fingerprint(cfg, &run)?, opts.resume, || {
                    let fitted =
                        fit_run(&run, &unit.join("checkpoint"), opts.device, opts.resume)?.erased();
                    let robot = run.data.robot.load()?;
                    let renderer = fitted.trained.renderers[0].1.as_ref();
                    let scored = score(
                        &Scoring {
                            cfg,
                            name: &name,
                            n,
                            fitted: &fitted,
                            robot: &robot,
                            options: &run.data.dataset.render,
                            revision: &revision,
                            device_name: &device_name,
                        },
                        &|camera, poses| {
                            let (x, width) = inputs(poses, Some(camera));
                            rendered(&|q| renderer.render(q).0, &x, width, &fitted.device)
                        },
                        matches!(run.model.camera, CameraUse::Input),
                    );
                    Ok((scored, [fitted.data.height, fitted.data.width]))
                })?;
            size = image_size;
            rows.extend(scored.rows);
            if n == largest {
                grid.push((format!("{name} ({n})"), scored.grid_row));
                grid_truth.extend(scored.grid_truth);
            }
        }
    }
    // The 3-D models after NeuroKin: FFKSM on several cameras trains for hours.
    let (three_d_rows, three_d_grid) = three_d::three_d(cfg, opts, out, &revision, &device_name)?;
    rows.extend(three_d_rows);
    grid.extend(three_d_grid);
    let note = format!(
        "Trained on every pose of the training split from N cameras at the first camera's distance from its target, yaws 360 i / N degrees from it, elevations {} (even i) and {} (odd i) degrees; tested on the held-out poses{}: `trained`, from the trained cameras; the rest, from cameras never trained on (yaw and elevation relative to the first camera). NeuroKin ({} preset) {} steps at every N. FFKSM (original model) and K-3DGS ({} preset steps at every N): trained on the first camera alone (N = 1){}, rendering the held-out cameras in 3-D. View-blind bound: the nearest trained camera's true image of the same pose. img_per_s: one pass over the test images in batches of 64 after a warm-up batch, on {}.",
        cfg.elevation_deg[0],
        cfg.elevation_deg[1],
        cfg.test_poses
            .map_or(String::new(), |p| format!(" (the first {p})")),
        cfg.model_preset,
        cfg.steps
            .map_or("the preset's".to_string(), |s| s.to_string()),
        cfg.model_preset,
        {
            let more: Vec<String> = cfg
                .three_d_cameras
                .iter()
                .filter(|&&n| n > 1)
                .map(|n| n.to_string())
                .collect();
            if more.is_empty() {
                String::new()
            } else {
                format!(" and on N = {} of the same cameras", more.join(", "))
            }
        },
        device_name
    );
    write_table(
        &out.join("results.csv"),
        &rows,
        "Beyond one camera: held-out views",
        &note,
    )?;
    draw(out, cfg, &rows, &grid_truth, &grid, size)?;
    let summary = rows
        .iter()
        .filter(|r| {
            r.held_out && r.cameras_trained == largest
                || r.cameras_trained == 1 && r.held_out && r.model.contains("FFKSM")
        })
        .map(|r| format!("{} on {}: {:.2} dB", r.model, r.camera, r.psnr_db))
        .collect::<Vec<_>>()
        .join("; ");
    Ok(summary)
}
