//! K-3DGS training, evaluation and reports (self-modeling paper section IV-C): the logic
//! behind the `k3dgs` binary and its rows of `table1`.
//!
//! Training (the reimplementation's code, minus its errors: the robot's real chain and the
//! simulator's camera): one image per step, Adam 5e-3, 3,000 steps, MSE with weight 5 on
//! robot pixels; every 100 steps until step 1,500 the (up to) 30 Gaussians with the largest
//! mean positional gradient above 2e-4 are cloned, every 200 steps those with opacity below
//! 0.02 are pruned, keeping between 200 and 1,000; the optimiser state starts afresh after
//! each change. The faithful image is `sigmoid(T (Σ α − 0.5))` with `T` rising linearly from
//! 1 to 20 over training; the principled one alpha compositing.
//!
//! A run writes `config.json`, `results.csv`/`results.md` (one row), `render_speed.csv`
//! (culled against dense splatting at batch 1 and 256), `curve.csv`, `training_curve.png`,
//! `qualitative.png` and `gaussians.png` (the Gaussians' centres over the silhouette).

pub mod gaussians;
pub mod splatting;
use std::path::Path;

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Tensor, TensorData};

use crate::core::atomic_file::write_json;
use crate::core::device::DeviceChoice;
use crate::core::error::{Error, Result};
use crate::eval::evaluation::{Predictions, score};
use crate::eval::inference_speed::{SpeedConfig, measure};
use crate::report::table::write_table;
use crate::self_models::harness::{DataSpec, device_set, host_targets, qualitative_figure};
use crate::self_models::k3dgs::gaussians::{GaussianInit, KinematicGaussians};
use crate::self_models::k3dgs::splatting::Compositing;
use crate::self_models::result::{ModelResult, PaperReference};
use crate::sim::tensor_kinematics::TensorChain;
use crate::train::trainer::{TrainConfig, TrainHooks, TrainLog, autodiff_device, train_with_hooks};

/// When and how the set of Gaussians changes during training.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Densification {
    pub every: usize,
    pub until: usize,
    /// Clone at most this many per densification...
    pub max_clones: usize,
    /// ...of those whose mean positional gradient norm exceeds this.
    pub gradient_threshold: f64,
    pub prune_every: usize,
    pub min_opacity: f64,
    pub min_gaussians: usize,
    pub max_gaussians: usize,
}

/// How the image is composited during training and evaluation.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum K3dgsCompositing {
    /// The reimplementation's `sigmoid(T (Σ α − 0.5))`, `T` from `start` to `end`.
    SigmoidSum {
        start: f64,
        end: f64,
    },
    Alpha,
}

/// Everything that defines one K-3DGS run.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct K3dgsConfig {
    pub name: String,
    pub preset: String,
    pub init: GaussianInit,
    pub compositing: K3dgsCompositing,
    pub densification: Densification,
    pub train: TrainConfig,
    pub robot_weight: f64,
    /// Splat only pairs within this many standard deviations (the fast path).
    pub cull_sigmas: f64,
    pub data: DataSpec,
    pub paper_subset: usize,
    pub speed: SpeedConfig,
    /// Batch sizes at which dense splatting, the slow reference, is timed.
    #[serde(default)]
    pub dense_batches: Vec<usize>,
    pub reference: PaperReference,
    pub note: String,
    #[serde(default)]
    pub steps_override: Option<usize>,
}

/// `paper`, `short` and `quick`.
pub const K3DGS_PRESETS: &[&str] = &["paper", "short", "quick"];

impl PaperReference {
    /// K-3DGS in the paper: 17.01 dB at 37 FPS, 30.3 s of training, on a T4.
    pub fn k3dgs() -> Self {
        PaperReference {
            psnr_db: Some(17.01),
            fps: Some(37.0),
            latency_ms: Some(1000.0 / 37.0),
            train_time_s: Some(30.3),
        }
    }
}

impl K3dgsConfig {
    /// Isotropic Gaussians, the faithful compositing.
    pub fn isotropic(preset: &str) -> Result<Self> {
        let quick = preset == "quick";
        let (data, speed) = match preset {
            "paper" | "short" => (DataSpec::paper(), SpeedConfig::paper()),
            "quick" => (DataSpec::quick(), SpeedConfig::quick()),
            other => {
                return Err(Error::Config(format!(
                    "unknown preset \"{other}\" (choose paper, short or quick)"
                )));
            }
        };
        let steps = match preset {
            "paper" => 3000,
            "short" => 600,
            _ => 300,
        };
        let scale = steps as f64 / 3000.0;
        let at = |s: usize| ((s as f64 * scale) as usize).max(1);
        Ok(K3dgsConfig {
            name: "K-3DGS (isotropic)".into(),
            preset: preset.into(),
            init: if quick {
                GaussianInit::quick()
            } else {
                GaussianInit::paper()
            },
            compositing: K3dgsCompositing::SigmoidSum {
                start: 1.0,
                end: 20.0,
            },
            densification: Densification {
                every: at(100),
                until: at(1500),
                max_clones: if quick { 6 } else { 30 },
                gradient_threshold: 2e-4,
                prune_every: at(200),
                min_opacity: 0.02,
                min_gaussians: if quick { 40 } else { 200 },
                max_gaussians: if quick { 200 } else { 1000 },
            },
            train: TrainConfig {
                steps,
                batch: 1,
                learning_rate: 5e-3,
                grad_clip_norm: None,
                input_noise: 0.0,
                seed: 0,
                checkpoint_every: 0,
            },
            robot_weight: 5.0,
            cull_sigmas: 3.0,
            data,
            paper_subset: 100,
            speed,
            // A dense batch of 256 takes about a minute: timed in the paper preset only.
            dense_batches: if preset == "paper" {
                vec![1, 256]
            } else {
                vec![1, 8]
            },
            reference: PaperReference::k3dgs(),
            note: if preset == "short" {
                "short preset: 600 steps instead of 3,000 (CPU time budget)".into()
            } else {
                String::new()
            },
            steps_override: None,
        })
    }

    /// The same with alpha compositing.
    pub fn isotropic_alpha(preset: &str) -> Result<Self> {
        let mut cfg = Self::isotropic(preset)?;
        cfg.name = "K-3DGS (isotropic, alpha)".into();
        cfg.compositing = K3dgsCompositing::Alpha;
        Ok(cfg)
    }

    /// Anisotropic Gaussians with alpha compositing, half the isotropic count (300 at the
    /// start, at most 500).
    pub fn anisotropic(preset: &str) -> Result<Self> {
        let mut cfg = Self::isotropic_alpha(preset)?;
        cfg.name = "K-3DGS (anisotropic, alpha)".into();
        let quick = preset == "quick";
        cfg.init = crate::self_models::k3dgs::gaussians::GaussianInit::anisotropic();
        if quick {
            for (_, n) in &mut cfg.init.per_link {
                *n /= 5;
            }
        }
        cfg.densification.max_gaussians = if quick { 100 } else { 500 };
        cfg.densification.min_gaussians = if quick { 20 } else { 100 };
        Ok(cfg)
    }

    pub fn paper_compatible(mut self, on: bool) -> Self {
        self.data.dataset.render.ground_artifact = on;
        self
    }

    /// The compositing rule at `step` of training (the temperature's schedule).
    pub fn mode_at(&self, step: usize) -> Compositing {
        match self.compositing {
            K3dgsCompositing::SigmoidSum { start, end } => {
                let f = step as f64 / self.train.steps.max(1) as f64;
                Compositing::SigmoidSum {
                    temperature: start + (end - start) * f.min(1.0),
                }
            }
            K3dgsCompositing::Alpha => Compositing::Alpha,
        }
    }

    /// The rule after training.
    pub fn final_mode(&self) -> Compositing {
        self.mode_at(self.train.steps)
    }
}

/// Densify and prune between steps (see the module documentation).
struct Densifier<'a> {
    cfg: &'a Densification,
    /// Sum of positional gradient norms per Gaussian since the last change, and the steps.
    grad_sum: Vec<f64>,
    steps: usize,
    counts: Vec<(usize, usize)>,
}

impl TrainHooks<KinematicGaussians> for Densifier<'_> {
    fn gradients(&mut self, model: &KinematicGaussians, grads: &GradientsParams, _step: usize) {
        let n = model.len();
        if self.grad_sum.len() != n {
            self.grad_sum = vec![0.0; n];
            self.steps = 0;
        }
        if let Some(g) = grads.get::<2>(model.positions.id) {
            let norms = g.square().sum_dim(1).sqrt().into_data();
            for (s, v) in self.grad_sum.iter_mut().zip(norms.iter::<f32>()) {
                *s += v as f64;
            }
        }
        self.steps += 1;
    }

    fn after_step(
        &mut self,
        model: KinematicGaussians,
        step: usize,
    ) -> Result<(KinematicGaussians, bool)> {
        let c = self.cfg;
        let densify = step % c.every.max(1) == 0 && step <= c.until;
        let prune = step % c.prune_every.max(1) == 0;
        if !densify && !prune {
            return Ok((model, false));
        }
        let opacity = model
            .opacity_logits
            .val()
            .into_data()
            .try_into_vec::<f32>()
            .expect("float");
        let n = model.len();
        let mut keep: Vec<usize> = (0..n).collect();
        if densify && self.steps > 0 && self.grad_sum.len() == n {
            let mut ranked: Vec<(f64, usize)> = self
                .grad_sum
                .iter()
                .enumerate()
                .map(|(i, s)| (s / self.steps as f64, i))
                .filter(|(g, _)| *g > c.gradient_threshold)
                .collect();
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
            let room = c.max_gaussians.saturating_sub(n);
            keep.extend(ranked.iter().take(c.max_clones.min(room)).map(|r| r.1));
        }
        if prune {
            let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
            let mut low: Vec<(f32, usize)> = (0..n)
                .map(|i| (sigmoid(opacity[i]), i))
                .filter(|(o, _)| (*o as f64) < c.min_opacity)
                .collect();
            low.sort_by(|a, b| a.0.total_cmp(&b.0));
            let removable = keep.len().saturating_sub(c.min_gaussians);
            let drop: std::collections::HashSet<usize> =
                low.iter().take(removable).map(|l| l.1).collect();
            keep.retain(|i| !drop.contains(i));
        }
        if keep.len() == n && keep.iter().enumerate().all(|(k, &i)| k == i) {
            return Ok((model, false));
        }
        let rebuilt = model.select(&keep);
        let m = keep.len();
        self.counts.push((step, m));
        self.grad_sum = vec![0.0; m];
        self.steps = 0;
        Ok((rebuilt, true))
    }
}

/// What a run produced.
pub struct K3dgsOutcome {
    pub result: ModelResult,
    pub speed: Vec<RenderSpeedRow>,
    pub log: TrainLog,
    /// `(step, Gaussians)` after each change.
    pub counts: Vec<(usize, usize)>,
}

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

/// Train, evaluate and report one K-3DGS model into `dir`.
pub fn run(cfg: &K3dgsConfig, dir: &Path, device_choice: DeviceChoice) -> Result<K3dgsOutcome> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join("config.json"), cfg)?;
    let git_revision = crate::core::provenance::git_revision();
    let device = crate::core::device::select(device_choice)?;
    let robot = cfg.data.robot.load()?;
    let chain = TensorChain::new(&robot.chain);
    let camera = cfg.data.dataset.camera.clone();
    let (data, train_range, test_range) = cfg.data.load()?;
    let tdev = autodiff_device(&device, cfg.train.seed);
    let train_set = device_set(
        &data,
        &train_range,
        host_targets(&data, &train_range),
        &tdev,
    );
    let (links, positions) = cfg.init.positions(&robot, cfg.train.seed)?;
    let long_axis: Vec<usize> = (0..robot.chain.links.len())
        .map(|l| GaussianInit::long_axis(&robot, l))
        .collect();
    let model = KinematicGaussians::new(&links, &positions, &cfg.init, &long_axis, &tdev);
    let mut hooks = Densifier {
        cfg: &cfg.densification,
        grad_sum: Vec::new(),
        steps: 0,
        counts: vec![(0, model.len())],
    };
    let pixels = camera.width * camera.height;
    let (model, log) = train_with_hooks(
        model,
        &train_set,
        &cfg.train,
        None,
        &cfg.name,
        |m: &KinematicGaussians, b| {
            let q = b.inputs.clone().mul_scalar(std::f64::consts::PI / 180.0);
            let (sil, _) = m.render(
                &chain,
                q,
                &camera,
                cfg.mode_at(b.step),
                Some(cfg.cull_sigmas),
            );
            let y = b.targets[0].clone().reshape([1, pixels]);
            let w = y.clone().mul_scalar(cfg.robot_weight - 1.0).add_scalar(1.0);
            ((sil - y).square() * w).mean()
        },
        &mut hooks,
    )?;
    let model = model.valid();
    let counts = hooks.counts;
    // Test set: culled splatting, in batches.
    let (truth, truth_depth) = host_targets(&data, &test_range);
    let test_set = device_set(
        &data,
        &test_range,
        (truth.clone(), truth_depth.clone()),
        &device,
    );
    let mode = cfg.final_mode();
    let mut sil = Vec::new();
    let mut depth = Vec::new();
    let n = test_set.len();
    for start in (0..n).step_by(32) {
        let q = test_set
            .inputs
            .clone()
            .slice([start..(start + 32).min(n)])
            .mul_scalar(std::f64::consts::PI / 180.0);
        let (s, d) = model.render(&chain, q, &camera, mode, Some(cfg.cull_sigmas));
        sil.extend(s.into_data().try_into_vec::<f32>().expect("float"));
        depth.extend(d.into_data().try_into_vec::<f32>().expect("float"));
    }
    let predictions = Predictions {
        silhouettes: sil,
        depth: Some(depth),
        pixels,
        depth_pixels: crate::eval::evaluation::DepthPixels::Drawn,
    };
    let quality = score(&predictions, &truth, Some(&truth_depth), cfg.paper_subset);
    // Speed: culled and dense splatting.
    let mut speed = Vec::new();
    // Dense splatting is the slow reference: one warm-up and one timed call per batch size.
    let dense_speed = SpeedConfig {
        warmup: 1,
        min_repeats: 1,
        min_seconds: 0.0,
        batches: cfg.dense_batches.clone(),
    };
    for (label, cull, speed_cfg) in [
        ("culled", Some(cfg.cull_sigmas), &cfg.speed),
        ("dense", None, &dense_speed),
    ] {
        let timings = measure(
            |q| {
                let [b, _] = q.dims();
                let q = q.mul_scalar(std::f64::consts::PI / 180.0);
                // Dense splatting of 256 images at once would hold 256 x N x P floats.
                let parts: Vec<Tensor<2>> = (0..b)
                    .step_by(if cull.is_some() { b } else { 8 })
                    .map(|s| {
                        let e = (s + if cull.is_some() { b } else { 8 }).min(b);
                        model
                            .render(&chain, q.clone().slice([s..e]), &camera, mode, cull)
                            .0
                    })
                    .collect();
                Tensor::cat(parts, 0).reshape([b, 1, camera.height, camera.width])
            },
            robot.dof(),
            &device,
            speed_cfg,
        );
        for t in timings {
            speed.push(RenderSpeedRow {
                model: cfg.name.clone(),
                splatting: label.into(),
                batch: t.batch,
                img_per_s: t.images_per_second(),
                gaussians: model.len(),
                git_revision: git_revision.clone(),
                device: device_choice.to_string(),
                preset: cfg.preset.clone(),
            });
        }
    }
    let culled = |b: usize| {
        speed
            .iter()
            .filter(|r| r.splatting == "culled")
            .find(|r| r.batch == b)
            .map_or(f64::NAN, |r| r.img_per_s)
    };
    let big = cfg.speed.batches.iter().copied().max().unwrap_or(1);
    let result = ModelResult {
        model: cfg.name.clone(),
        dataset: cfg.data.label().into(),
        preset: cfg.preset.clone(),
        device: device_choice.to_string(),
        git_revision: git_revision.clone(),
        parameters: model.num_params(),
        train_samples: train_range.len(),
        train_steps: log.step,
        batch: 1,
        train_time_s: log.train_seconds,
        train_img_per_s: log.images_per_second(),
        psnr_db_first100: quality.psnr_db_paper_subset,
        psnr_db_test: quality.psnr_db_test,
        iou_test: quality.iou_test,
        depth_mae_mm: quality.depth_mae_mm,
        depth_constant_mae_mm: quality.depth_constant_mae_mm,
        infer_b1_img_per_s: culled(1),
        latency_b1_ms: 1000.0 / culled(1),
        infer_b256_img_per_s: culled(big),
        paper_psnr_db: None,
        paper_fps: None,
        paper_latency_ms: None,
        paper_train_time_s: None,
        note: {
            let mut n = vec![format!(
                "{} Gaussians at the end ({} at the start)",
                model.len(),
                counts.first().map_or(0, |c| c.1)
            )];
            if !cfg.note.is_empty() {
                n.push(cfg.note.clone());
            }
            n.join("; ")
        },
        steps_override: cfg.steps_override,
    }
    .with_reference(&cfg.reference);
    let csv = dir.join("results.csv");
    write_table(
        &csv,
        std::slice::from_ref(&result),
        &format!(
            "{} ({} preset, {} dataset)",
            cfg.name,
            cfg.preset,
            cfg.data.label()
        ),
        "PSNR per image over all test images (the paper's K-3DGS figure was over all 400), IoU at 0.5, depth by front-to-back compositing against the simulator's on robot pixels. Inference: culled splatting (`render_speed.csv` has dense beside it). `paper_*`: the paper's figures on a T4, for reference. Config: `config.json`.",
    )?;
    let path = dir.join("render_speed.csv");
    write_table(
        &path,
        &speed,
        &format!("{}: culled against dense splatting", cfg.name),
        "Images/s of the trained model, median of synchronised timed calls after warm-up; dense splatting evaluates every (Gaussian, pixel) pair, culled only those within `cull_sigmas` standard deviations.",
    )?;
    crate::report::table::write_training_curve(dir, &cfg.name, &log)?;
    qualitative_figure(
        &dir.join("qualitative.png"),
        &truth,
        &truth_depth,
        &predictions,
        [camera.height, camera.width],
    )?;
    gaussians_figure(
        &dir.join("gaussians.png"),
        &model,
        &chain,
        &data,
        &test_range,
        &camera,
    )?;
    Ok(K3dgsOutcome {
        result,
        speed,
        log,
        counts,
    })
}

/// Six test poses: the true silhouette with the Gaussians' projected centres over it.
fn gaussians_figure(
    path: &Path,
    model: &KinematicGaussians,
    chain: &TensorChain,
    data: &crate::data::dataset::Dataset,
    test: &std::ops::Range<usize>,
    camera: &crate::sim::camera::Camera,
) -> Result<()> {
    let n = test.len();
    let picks: Vec<usize> = (0..6.min(n))
        .map(|k| test.start + k * n / 6.min(n).max(1))
        .collect();
    let device = model.positions.val().device();
    let q: Vec<f32> = picks
        .iter()
        .flat_map(|&i| data.angles[i].iter().map(|a| a.to_radians() as f32))
        .collect();
    let dof = data.dof();
    let q = Tensor::<2>::from_data(TensorData::new(q, [picks.len(), dof]), &device);
    let g = model.project(chain, q, camera);
    let rows = g.row.into_data().try_into_vec::<f32>().expect("float");
    let cols = g.col.into_data().try_into_vec::<f32>().expect("float");
    let m = model.len();
    let points: Vec<Vec<(f32, f32)>> = (0..picks.len())
        .map(|b| (0..m).map(|k| (rows[b * m + k], cols[b * m + k])).collect())
        .collect();
    let images: Vec<Vec<f32>> = picks
        .iter()
        .map(|&i| data.image(i).iter().map(|&v| v as f32 / 255.0).collect())
        .collect();
    let refs: Vec<&[f32]> = images.iter().map(|v| v.as_slice()).collect();
    crate::report::figures::points_over_images(path, &refs, &points, camera.width, camera.height, 3)
}
