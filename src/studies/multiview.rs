//! `multiview`: beyond one camera (the self-modeling paper's Section VI-D1). NeuroKin learns
//! one view; here it learns N views, two ways: **camera-conditioned** (f(theta, c): the
//! camera's pose joins the joint angles at the input, so any camera renders) and
//! **multi-head** (one output per trained camera). Both train through the one harness on a
//! multi-view dataset (every pose from N cameras on a sphere around the robot) and are tested
//! on held-out poses, from the trained cameras and from cameras never trained on (yawed and
//! raised away from the first). Against: FFKSM (the original model) and K-3DGS, trained on
//! the first camera and on the same N cameras (reading each image's camera from its inputs,
//! [`crate::self_models::model::SelfModel::renders_any_view`]) and rendering the held-out
//! cameras in 3-D, and the view-blind bound (the
//! nearest trained camera's true image of the same pose: the best a model of the trained
//! views can show). Writes `reports/multiview/`:
//! - `results.csv`: `model,cameras_trained,camera,held_out,psnr_db,iou,img_per_s`, the
//!   angle to the nearest trained camera, and the provenance;
//! - `grid.png`: one held-out pose, truth and each model (columns: the held-out cameras);
//! - `psnr_vs_angle.png`: PSNR against the angle to the nearest trained camera;
//! - `psnr_vs_cameras.png`: the camera-conditioned model's PSNR against N.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::core::provenance::git_revision;
use crate::data::dataset::Views;
use crate::eval::evaluation::{iou, psnr_db};
use crate::report::figures::{GridRow, image_grid, lines_log_x, lines_marked};
use crate::report::table::write_table;
use crate::self_models::ffksm::{FfksmVariant, ffksm_run};
use crate::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
use crate::self_models::neurokin::{CameraUse, neurokin_run};
use crate::self_models::{camera_input::camera_input, harness::fit_run};
use crate::sim::camera::Camera;
use crate::sim::ray_caster::silhouettes as truth;

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

/// Host silhouettes `[n, H * W]` in [0, 1] of `renderer` over `inputs` (`n` rows of `width`),
/// rendered in batches of 64, and the images per second of the pass (after a warm-up batch).
fn rendered(
    render: &dyn Fn(Tensor<2>) -> Tensor<4>,
    inputs: &[f32],
    width: usize,
    device: &Device,
) -> (Vec<f32>, f64) {
    let n = inputs.len() / width.max(1);
    let batch = 64;
    let tensor = |a: usize, b: usize| {
        Tensor::<2>::from_data(
            TensorData::new(inputs[a * width..b * width].to_vec(), [b - a, width]),
            device,
        )
    };
    let _ = render(tensor(0, n.min(batch)));
    let t = std::time::Instant::now();
    let mut out = Vec::new();
    for a in (0..n).step_by(batch) {
        let y = render(tensor(a, (a + batch).min(n)));
        out.extend(
            y.into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .expect("float"),
        );
    }
    (out, n as f64 / t.elapsed().as_secs_f64().max(1e-9))
}

/// Mean PSNR and IoU of `pred` against `truth`, image by image.
fn quality(pred: &[f32], truth: &[f32], px: usize) -> (f64, f64) {
    let n = truth.len() / px;
    let (mut p, mut q) = (0.0, 0.0);
    for i in 0..n {
        let (a, b) = (&pred[i * px..(i + 1) * px], &truth[i * px..(i + 1) * px]);
        p += psnr_db(a, b);
        q += iou(a, b);
    }
    (p / n.max(1) as f64, q / n.max(1) as f64)
}

/// Joint angles followed, where `camera` is given, by its input vector, one row per pose.
fn inputs(angles: &[Vec<f64>], camera: Option<&Camera>) -> (Vec<f32>, usize) {
    let c = camera.map(camera_input);
    let width = angles.first().map_or(0, Vec::len) + if c.is_some() { 9 } else { 0 };
    let rows = angles
        .iter()
        .flat_map(|q| {
            let mut row: Vec<f32> = q.iter().map(|&v| v as f32).collect();
            if let Some(c) = c {
                row.extend(c);
            }
            row
        })
        .collect();
    (rows, width)
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
                    let fitted = fit_run(&run, &unit.join("checkpoint"), opts.device, opts.resume)?;
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
    let (three_d_rows, three_d_grid) = three_d(cfg, opts, out, &revision, &device_name)?;
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

/// FFKSM (the original model) and K-3DGS trained on the first camera, and on each N of
/// `three_d_cameras` above 1: their rows and grid rows, each model kept as a unit.
#[allow(clippy::type_complexity)]
fn three_d(
    cfg: &MultiviewConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
    revision: &str,
    device_name: &str,
) -> Result<(Vec<MultiviewRow>, Vec<(String, Vec<Vec<f32>>)>)> {
    let (mut rows, mut grid) = (Vec::new(), Vec::new());
    if !cfg.three_d {
        return Ok((rows, grid));
    }
    // On N cameras (N = 1: the dataset's own camera, as `ffksm` and `k3dgs` train).
    let views = |n: usize| {
        (n > 1).then_some(Views {
            cameras: n,
            radius: None,
            elevation_deg: cfg.elevation_deg,
        })
    };
    let suffix = |n: usize| {
        if n > 1 {
            format!("_{n}")
        } else {
            String::new()
        }
    };
    // One 3-D model on `n` cameras: trained (or continued from `checkpoint`), then scored on
    // the held-out cameras, rendering them in 3-D; kept as a unit in `unit`.
    let mut three_d_unit =
        |name: &str, n: usize, run: &dyn ThreeDRun, unit: &Path, resume: bool| -> Result<()> {
            let (scored, _) = kept_unit(unit, &run.fingerprint(cfg)?, opts.resume, || {
                let (fitted, robot, options) =
                    run.fit(&unit.join("checkpoint"), opts.device, resume)?;
                let renderer = scored_renderer(&fitted);
                let scored = score(
                    &Scoring {
                        cfg,
                        name,
                        n,
                        fitted: &fitted,
                        robot: &robot,
                        options: &options,
                        revision,
                        device_name,
                    },
                    &|camera, poses| {
                        let (x, width) = inputs(poses, None);
                        let view = |q: Tensor<2>| {
                            renderer
                                .render_view(camera, q)
                                .expect("a 3-D model renders any camera")
                        };
                        rendered(&view, &x, width, &fitted.device)
                    },
                    false,
                );
                Ok((scored, [fitted.data.height, fitted.data.width]))
            })?;
            rows.extend(scored.rows);
            grid.push((format!("{name} ({n})"), scored.grid_row));
            Ok(())
        };
    for &n in &cfg.three_d_cameras {
        let mut run = opts.apply(ffksm_run(&cfg.model_preset, FfksmVariant::Original)?)?;
        run.data.dataset.views = views(n);
        let unit = out.join(format!("ffksm_original{}", suffix(n)));
        let dir = unit.join("checkpoint");
        // The committed FFKSM (original model) of `ffksm`, where this preset trained it:
        // continued from its checkpoint instead of hours of training again.
        let carried = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("reports/ffksm/ffksm_original/checkpoint_carried");
        let fingerprint = run.fingerprint(cfg)?;
        let kept = opts.resume
            && crate::core::unit_cache::load::<KeptUnit>(&unit.join(UNIT), &fingerprint).is_some();
        if n == 1 && cfg.model_preset == "paper" && !dir.exists() && carried.exists() && !kept {
            crate::self_models::harness::copy_checkpoint(&carried, &dir)?;
        }
        let resume = opts.resume || (n == 1 && dir.exists());
        let name = run.name.clone();
        three_d_unit(&name, n, &run, &unit, resume)?;
        let mut run = opts.apply(k3dgs_run(&cfg.model_preset, K3dgsVariant::Anisotropic)?)?;
        run.data.dataset.views = views(n);
        // No comma: the docs pick rows by name.
        three_d_unit(
            "K-3DGS (anisotropic)",
            n,
            &run,
            &out.join(format!("k3dgs{}", suffix(n))),
            opts.resume,
        )?;
    }
    Ok((rows, grid))
}

/// A trained 3-D model with its robot and render options.
type FittedScene = (
    crate::self_models::harness::Fitted,
    crate::sim::robot::Robot,
    crate::sim::ray_caster::RenderOptions,
);

/// A 3-D model's run, whichever model it is.
trait ThreeDRun {
    /// Train (or continue from `checkpoint`).
    fn fit(
        &self,
        checkpoint: &Path,
        device: crate::core::device::DeviceChoice,
        resume: bool,
    ) -> Result<FittedScene>;
    /// What its kept unit must have been made with.
    fn fingerprint(&self, cfg: &MultiviewConfig) -> Result<serde_json::Value>;
}

impl<M: crate::self_models::model::SelfModel> ThreeDRun
    for crate::self_models::run_config::SelfModelRun<M>
{
    fn fit(
        &self,
        checkpoint: &Path,
        device: crate::core::device::DeviceChoice,
        resume: bool,
    ) -> Result<FittedScene> {
        Ok((
            fit_run(self, checkpoint, device, resume)?,
            self.data.robot.load()?,
            self.data.dataset.render.clone(),
        ))
    }
    fn fingerprint(&self, cfg: &MultiviewConfig) -> Result<serde_json::Value> {
        unit_fingerprint(cfg, self)
    }
}

/// The file a scored unit is kept in, inside its folder; its grid images beside it.
const UNIT: &str = "unit.json";
const UNIT_GRID: &str = "unit_grid.png";

/// A scored unit as kept: its rows, and how many grid images (then true images) its
/// `unit_grid.png` holds side by side.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct KeptUnit {
    rows: Vec<MultiviewRow>,
    size: [usize; 2],
    grid_images: usize,
    truth_images: usize,
}

/// What a kept unit must have been made with: the model's run and how it is scored.
fn unit_fingerprint<T: Serialize>(cfg: &MultiviewConfig, run: &T) -> Result<serde_json::Value> {
    crate::core::unit_cache::fingerprint(&serde_json::json!({
        "run": crate::core::unit_cache::fingerprint(run)?,
        "held_out": cfg.held_out,
        "test_poses": cfg.test_poses,
        "preset": cfg.preset,
    }))
}

/// A unit's scores and image size: with `resume`, the ones kept in `unit` if made with
/// `fingerprint`; otherwise `make`'s, then kept. Grid images are kept at 8 bits, and a run
/// draws them from what it kept, so a resumed run draws the same figure.
fn kept_unit(
    unit: &Path,
    fingerprint: &serde_json::Value,
    resume: bool,
    make: impl FnOnce() -> Result<(Scored, [usize; 2])>,
) -> Result<(Scored, [usize; 2])> {
    let (json, png) = (unit.join(UNIT), unit.join(UNIT_GRID));
    // A unit as kept: its rows, and its images split into the grid's and the truth's.
    let read = || {
        let kept = crate::core::unit_cache::load::<KeptUnit>(&json, fingerprint)?;
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
    crate::core::unit_cache::save(&json, fingerprint, &kept)?;
    // Read back as a resumed run would: the same 8-bit images either way.
    read().ok_or_else(|| Error::data(&json, "cannot read back the unit just written"))
}

/// `images` (each `[h, w]`, values in [0, 1]) side by side in one 8-bit grey PNG.
fn write_strip(path: &Path, [h, w]: [usize; 2], images: &[Vec<f32>]) -> Result<()> {
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
    crate::core::atomic_file::write_bytes(path, &png)
}

/// The `k` images of a strip [`write_strip`] wrote, if it reads and has their size.
fn read_strip(path: &Path, [h, w]: [usize; 2], k: usize) -> Option<Vec<Vec<f32>>> {
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

/// The renderer a trained model is scored with: its last (the accelerated one, where a
/// model has two).
fn scored_renderer(
    fitted: &crate::self_models::harness::Fitted,
) -> &dyn crate::self_models::model::Render {
    fitted
        .trained
        .renderers
        .last()
        .expect("a renderer")
        .1
        .as_ref()
}

/// What scoring one trained model needs.
struct Scoring<'a> {
    cfg: &'a MultiviewConfig,
    name: &'a str,
    /// Trained cameras.
    n: usize,
    fitted: &'a crate::self_models::harness::Fitted,
    robot: &'a crate::sim::robot::Robot,
    options: &'a crate::sim::ray_caster::RenderOptions,
    revision: &'a str,
    device_name: &'a str,
}

/// One model's rows, its grid row (the first held-out pose from each held-out camera) and,
/// where it carries the view-blind bound, the true images of that row.
struct Scored {
    rows: Vec<MultiviewRow>,
    grid_row: Vec<Vec<f32>>,
    grid_truth: Vec<Vec<f32>>,
}

/// Score a trained model on the held-out poses: from its trained cameras (the harness's test
/// set, rendered by the model's own `render`), and from each held-out camera (`held_out`
/// renders poses from a camera: images and images per second); with `view_blind`, also the
/// view-blind bound's rows.
fn score(
    s: &Scoring,
    held_out: &dyn Fn(&Camera, &[Vec<f64>]) -> (Vec<f32>, f64),
    view_blind: bool,
) -> Scored {
    let (fitted, n) = (s.fitted, s.n);
    let data = &fitted.data;
    let px = data.width * data.height;
    let trained_cameras: Vec<Camera> = (0..n).map(|c| data.camera_of(c)).collect();
    let renderer = scored_renderer(fitted);
    // The trained cameras at the held-out poses (n images a pose): the harness's test set.
    let test: Vec<usize> = fitted
        .test_range
        .clone()
        .take(s.cfg.test_poses.map_or(usize::MAX, |p| p * n))
        .collect();
    let poses: Vec<Vec<f64>> = test
        .iter()
        .step_by(n)
        .map(|&i| data.angles[i].clone())
        .collect();
    let row = |camera: String,
               held_out: bool,
               (p, q): (f64, f64),
               speed: Option<f64>,
               angle: f64,
               images: usize| MultiviewRow {
        model: s.name.to_string(),
        cameras_trained: n,
        camera,
        held_out,
        psnr_db: p,
        iou: q,
        img_per_s: speed,
        angle_to_nearest_deg: angle,
        images,
        git_revision: s.revision.to_string(),
        device: s.device_name.to_string(),
        preset: s.cfg.preset.clone(),
    };
    let test_inputs: Vec<f32> = fitted
        .test_set
        .inputs
        .clone()
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("float");
    let width = test_inputs.len() / fitted.test_range.len().max(1);
    let own = |q: Tensor<2>| renderer.render(q).0;
    let (pred, speed) = rendered(
        &own,
        &test_inputs[..test.len() * width],
        width,
        &fitted.device,
    );
    let mut out = Scored {
        rows: vec![row(
            "trained".into(),
            false,
            quality(&pred, &fitted.truth[..test.len() * px], px),
            Some(speed),
            0.0,
            test.len(),
        )],
        grid_row: Vec::new(),
        grid_truth: Vec::new(),
    };
    for h in &s.cfg.held_out {
        let camera = h.camera(&trained_cameras[0]);
        let seen = truth(s.robot, &camera, s.options, &poses);
        let (pred, speed) = held_out(&camera, &poses);
        let angle = trained_cameras
            .iter()
            .map(|c| camera.angle_to(c))
            .fold(f64::INFINITY, f64::min);
        out.rows.push(row(
            h.label(),
            true,
            quality(&pred, &seen, px),
            Some(speed),
            angle,
            poses.len(),
        ));
        out.grid_row.push(pred[..px].to_vec());
        // The view-blind bound: the nearest trained camera's true image of the pose.
        if view_blind {
            let nearest = trained_cameras
                .iter()
                .min_by(|a, b| camera.angle_to(a).total_cmp(&camera.angle_to(b)))
                .expect("a camera");
            let blind = truth(s.robot, nearest, s.options, &poses);
            out.rows.push(MultiviewRow {
                model: "view-blind bound".into(),
                ..row(
                    h.label(),
                    true,
                    quality(&blind, &seen, px),
                    None,
                    angle,
                    poses.len(),
                )
            });
            out.grid_truth.push(seen[..px].to_vec());
        }
    }
    out
}

/// The grid, PSNR against the angle to the nearest trained camera, and PSNR against N.
fn draw(
    out: &Path,
    cfg: &MultiviewConfig,
    rows: &[MultiviewRow],
    grid_truth: &[Vec<f32>],
    grid: &[(String, Vec<Vec<f32>>)],
    [h, w]: [usize; 2],
) -> Result<()> {
    if !grid_truth.is_empty() {
        let mut grid_rows = vec![GridRow::Grey(
            grid_truth.iter().map(Vec::as_slice).collect(),
        )];
        let mut titles = vec!["truth".to_string()];
        for (name, images) in grid {
            grid_rows.push(GridRow::Grey(images.iter().map(Vec::as_slice).collect()));
            titles.push(name.clone());
        }
        let titles: Vec<&str> = titles.iter().map(String::as_str).collect();
        let captions: Vec<String> = cfg.held_out.iter().map(HeldOutCamera::label).collect();
        image_grid(
            &out.join("grid.png"),
            &grid_rows,
            &titles,
            &captions,
            w,
            h,
            if w < 64 { 4 } else { 2 },
        )?;
    }
    // One line per model and N: the multi-head model at the largest N only, the view-blind
    // bound at N = 1 only (lines of several N would join unrelated points).
    let largest = cfg.cameras.iter().copied().max().unwrap_or(1);
    let key_of = |r: &MultiviewRow| {
        let name = r.model.split(" (").next().unwrap_or(&r.model);
        format!("{name} (N = {})", r.cameras_trained)
    };
    let mut models: Vec<String> = Vec::new();
    for r in rows {
        let key = key_of(r);
        if !models.contains(&key) {
            models.push(key);
        }
    }
    let runs: Vec<(String, Vec<(f64, f64)>)> = models
        .iter()
        .filter(|m| !m.starts_with("view-blind") || m.ends_with("(N = 1)"))
        .filter(|m| {
            !m.starts_with("NeuroKin multi-head") || m.ends_with(&format!("(N = {largest})"))
        })
        .map(|m| {
            let mut pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| &key_of(r) == m && r.psnr_db.is_finite())
                .map(|r| (r.angle_to_nearest_deg, r.psnr_db))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            (m.clone(), pts)
        })
        .collect();
    lines_marked(
        &out.join("psnr_vs_angle.png"),
        "PSNR on held-out poses against the angle to the nearest trained camera",
        "angle to the nearest trained camera (degrees)",
        "PSNR (dB)",
        &runs,
        true,
    )?;
    if cfg.cameras.len() > 1 {
        let mut cams = vec!["trained".to_string()];
        cams.extend(cfg.held_out.iter().map(HeldOutCamera::label));
        let runs: Vec<(String, Vec<(f64, f64)>)> = cams
            .iter()
            .map(|c| {
                (
                    if c == "trained" {
                        "trained cameras".to_string()
                    } else {
                        c.clone()
                    },
                    rows.iter()
                        .filter(|r| {
                            r.model.starts_with("NeuroKin camera-conditioned") && &r.camera == c
                        })
                        .map(|r| (r.cameras_trained as f64, r.psnr_db))
                        .collect(),
                )
            })
            .collect();
        lines_log_x(
            &out.join("psnr_vs_cameras.png"),
            "Camera-conditioned NeuroKin: PSNR on held-out poses against trained cameras",
            "trained cameras (N)",
            "PSNR (dB)",
            &runs,
        )?;
    }
    Ok(())
}
