//! K-3DGS, a self-model of Gaussians on the links (self-modeling paper section IV-C): the
//! logic behind the `k3dgs` binary and its rows of `table1`.
//!
//! Training (the reimplementation's code, minus its errors: the robot's real chain and the
//! simulator's camera): one image per step, Adam 5e-3, 3,000 steps, MSE with weight 5 on
//! robot pixels; every 100 steps until step 1,500 the (up to) 30 Gaussians with the largest
//! mean positional gradient above 2e-4 are cloned, every 200 steps those with opacity below
//! 0.02 are pruned, keeping between 200 and 1,000; the optimiser state starts afresh after
//! each change. The faithful image is `sigmoid(T (Σ α − 0.5))` with `T` rising linearly from
//! 1 to 20 over training; the principled one alpha compositing.
//!
//! A trained model ([`K3dgsRenderer`]) also answers what its study reports of it: dense
//! splatting's speed against the culled renders ([`K3dgsRenderer::dense_timings`]), the
//! Gaussians' count through training ([`K3dgsRenderer::counts`]) and where their centres
//! project ([`K3dgsRenderer::projected_centres`]).

pub mod gaussians;
pub mod splatting;

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};

use crate::core::device::DeviceChoice;
use crate::core::error::Result;
use crate::eval::evaluation::DepthPixels;
use crate::eval::inference_speed::{SpeedConfig, Timing, measure};
use crate::self_models::k3dgs::gaussians::{GaussianInit, KinematicGaussians};
use crate::self_models::k3dgs::splatting::Compositing;
use crate::self_models::{
    camera_input::split_views,
    model::{BodyFit, Fit, LoadContext, Loaded, Render, SelfModel, Trained},
    run_config::SelfModelRun,
};
use crate::sim::camera::Camera;
use crate::sim::tensor_kinematics::TensorChain;
use crate::train::{config::TrainConfig, hooks::TrainHooks, trainer::Trainer};

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

/// K-3DGS's model and how it trains (the run around it: [`SelfModelRun`], from [`k3dgs_run`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct K3dgs {
    pub init: GaussianInit,
    pub compositing: K3dgsCompositing,
    pub densification: Densification,
    pub robot_weight: f64,
    /// Splat only pairs within this many standard deviations (the fast path).
    pub cull_sigmas: f64,
    /// How training splats: culled or dense ([`TrainSplatting`]).
    #[serde(default, skip_serializing_if = "TrainSplatting::is_auto")]
    pub train_splatting: TrainSplatting,
    /// Batch sizes at which dense splatting, the slow reference, is timed.
    #[serde(default)]
    pub dense_batches: Vec<usize>,
    /// Output image size `[height, width]`.
    pub image: [usize; 2],
}

/// How K-3DGS splats while it trains. The culled path finds each Gaussian's pixels on the
/// host (a read of the projected Gaussians at every step); the dense path evaluates every
/// (Gaussian, pixel) pair on the device and reads nothing back, which a GPU does faster than
/// it waits for a read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainSplatting {
    /// Culled on the CPU backends, dense on a GPU.
    #[default]
    Auto,
    Culled,
    Dense,
}

impl TrainSplatting {
    fn is_auto(&self) -> bool {
        *self == TrainSplatting::Auto
    }

    /// The culling of training on `device` (`None`: dense).
    pub fn cull(self, cull_sigmas: f64, device: DeviceChoice) -> Option<f64> {
        match self {
            TrainSplatting::Culled => Some(cull_sigmas),
            TrainSplatting::Dense => None,
            TrainSplatting::Auto => (!device.is_gpu()).then_some(cull_sigmas),
        }
    }
}

/// The three K-3DGS models of Table I.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum K3dgsVariant {
    /// Isotropic Gaussians, the reimplementation's (faithful) compositing.
    Isotropic,
    /// The same with alpha compositing.
    IsotropicAlpha,
    /// Anisotropic Gaussians with alpha compositing, half the isotropic count (300 at the
    /// start, at most 500).
    Anisotropic,
}

impl K3dgsVariant {
    /// Every variant with its folder name.
    pub const ALL: [(&str, K3dgsVariant); 3] = [
        ("isotropic", K3dgsVariant::Isotropic),
        ("isotropic_alpha", K3dgsVariant::IsotropicAlpha),
        ("anisotropic", K3dgsVariant::Anisotropic),
    ];
}

/// A K-3DGS run on `preset` (`paper`, `short`, `quick`).
pub fn k3dgs_run(preset: &str, variant: K3dgsVariant) -> Result<SelfModelRun<K3dgs>> {
    let quick = preset == "quick";
    let steps = match preset {
        "paper" => 3000,
        // One image a step: a pass over most of the large preset's 12,000.
        "large" => 9000,
        "short" => 300,
        _ => 300,
    };
    let scale = steps as f64 / 3000.0;
    let at = |s: usize| ((s as f64 * scale) as usize).max(1);
    let mut model = K3dgs {
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
        robot_weight: 5.0,
        cull_sigmas: 3.0,
        train_splatting: TrainSplatting::Auto,
        // A dense batch of 256 takes about a minute: timed in the paper preset only.
        dense_batches: match preset {
            "paper" | "large" => vec![1, 256],
            "short" => vec![1],
            _ => vec![1, 8],
        },
        image: SelfModelRun::<K3dgs>::image(preset)?,
    };
    let name = match variant {
        K3dgsVariant::Isotropic => "K-3DGS (isotropic)",
        K3dgsVariant::IsotropicAlpha => "K-3DGS (isotropic, alpha)",
        K3dgsVariant::Anisotropic => "K-3DGS (anisotropic, alpha)",
    };
    if variant != K3dgsVariant::Isotropic {
        model.compositing = K3dgsCompositing::Alpha;
    }
    if variant == K3dgsVariant::Anisotropic {
        model.init = GaussianInit::anisotropic();
        if quick {
            for (_, n) in &mut model.init.per_link {
                *n /= 5;
            }
        }
        model.densification.max_gaussians = if quick { 100 } else { 500 };
        model.densification.min_gaussians = if quick { 20 } else { 100 };
    }
    let mut run = SelfModelRun::new(preset, name, model, 32)?;
    run.train = TrainConfig {
        precision: Default::default(),
        schedule: Default::default(),
        steps,
        batch: 1,
        learning_rate: 5e-3,
        grad_clip_norm: None,
        input_noise: 0.0,
        seed: 0,
        checkpoint_every: 0,
        log_every: 0,
    };
    if preset == "short" {
        run.note = "short preset: 300 steps instead of 3,000 (CPU time budget)".into();
    }
    Ok(run)
}

impl K3dgs {
    /// The compositing rule at `step` of `steps` (the temperature's schedule).
    pub fn mode_at(&self, step: usize, steps: usize) -> Compositing {
        match self.compositing {
            K3dgsCompositing::SigmoidSum { start, end } => {
                let f = step as f64 / steps.max(1) as f64;
                Compositing::SigmoidSum {
                    temperature: start + (end - start) * f.min(1.0),
                }
            }
            K3dgsCompositing::Alpha => Compositing::Alpha,
        }
    }
}

/// Densify and prune between steps (see the module documentation).
struct Densifier<'a> {
    cfg: &'a Densification,
    /// Sum of positional gradient norms per Gaussian since the last change, and the steps.
    grad_sum: Vec<f64>,
    steps: usize,
    /// The steps' gradient norms not yet added to `grad_sum`: kept on the device and read
    /// in one go when densification needs them, not at every step.
    pending: Vec<Tensor<1>>,
    counts: Vec<(usize, usize)>,
}

impl Densifier<'_> {
    /// Add the pending norms to `grad_sum`, step by step in f64 (one read of the device).
    fn gather(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let n = self.grad_sum.len();
        let rows = Tensor::stack::<2>(std::mem::take(&mut self.pending), 0)
            .into_data()
            .try_into_vec::<f32>()
            .expect("float");
        for step in rows.chunks(n) {
            for (s, v) in self.grad_sum.iter_mut().zip(step) {
                *s += *v as f64;
            }
        }
    }
}

impl TrainHooks<KinematicGaussians> for Densifier<'_> {
    fn wants_gradients(&self) -> bool {
        true
    }
    fn gradients(&mut self, model: &KinematicGaussians, grads: &GradientsParams, step: usize) {
        let n = model.len();
        if self.grad_sum.len() != n {
            self.grad_sum = vec![0.0; n];
            self.pending.clear();
            self.steps = 0;
        }
        // Past the last densification nothing reads them.
        if step < self.cfg.until
            && let Some(g) = grads.get::<2>(model.positions.id)
        {
            self.pending.push(g.square().sum_dim(1).sqrt().reshape([n]));
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
        if densify {
            self.gather();
        }
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
        self.pending.clear();
        self.steps = 0;
        Ok((rebuilt, true))
    }
}

impl SelfModel for K3dgs {
    const KIND: &'static str = "k3dgs";
    type Renderer = K3dgsRenderer;

    fn image(&self) -> [usize; 2] {
        self.image
    }

    fn needs_robot(&self) -> bool {
        true
    }

    fn renders_any_view(&self) -> bool {
        true
    }

    /// One image per step, the robot pixels weighted, densified and pruned between steps
    /// (no checkpoints: a run takes seconds to minutes and its Gaussians change in number).
    fn fit(&self, fit: &Fit) -> Result<Trained<K3dgsRenderer>> {
        if fit.plan.resume {
            // Densification changes the parameters' shapes as it trains, so the shared
            // checkpoint (weights loaded into the initial model's shapes) cannot hold it.
            eprintln!(
                "{}: resuming: K-3DGS keeps no checkpoint (the paper preset trains in about a minute); training starts from step 0",
                fit.label
            );
        }
        let robot = fit.robot;
        let chain = TensorChain::new(&robot.chain);
        let camera = fit.camera.clone();
        let (links, positions) = self.init.positions(robot, fit.train.seed)?;
        let long_axis: Vec<usize> = (0..robot.chain.links.len())
            .map(|l| GaussianInit::long_axis(robot, l))
            .collect();
        let model =
            KinematicGaussians::new(&links, &positions, &self.init, &long_axis, fit.train_device);
        let mut hooks = Densifier {
            cfg: &self.densification,
            grad_sum: Vec::new(),
            steps: 0,
            pending: Vec::new(),
            counts: vec![(0, model.len())],
        };
        let pixels = camera.width * camera.height;
        let steps = fit.train.steps;
        let cull = self
            .train_splatting
            .cull(self.cull_sigmas, fit.device_choice);
        let dof = robot.dof();
        let (model, log) = Trainer::new(fit.train, fit.label).hooks(&mut hooks).fit(
            model,
            fit.train_set,
            |m: &KinematicGaussians, b| {
                // Each run of the batch from its camera (one, unless the data is multi-view).
                let views = split_views(&b.inputs, dof, &camera)
                    .expect("the harness built the camera inputs from valid cameras");
                let sil = Tensor::cat(
                    views
                        .into_iter()
                        .map(|(angles, view)| {
                            m.render(
                                &chain,
                                chain.from_user(angles),
                                &view,
                                self.mode_at(b.step, steps),
                                cull,
                            )
                            .0
                        })
                        .collect(),
                    0,
                );
                let y = b.targets[0].clone().reshape([b.inputs.dims()[0], pixels]);
                let w = y
                    .clone()
                    .mul_scalar(self.robot_weight - 1.0)
                    .add_scalar(1.0);
                ((sil - y).square() * w).mean()
            },
        )?;
        let model = model.valid();
        let counts = hooks.counts;
        Ok(Trained {
            parameters: model.num_params(),
            note: format!(
                "{} Gaussians at the end ({} at the start)",
                model.len(),
                counts.first().map_or(0, |c| c.1)
            ),
            renderers: vec![(
                String::new(),
                K3dgsRenderer {
                    mode: self.mode_at(steps, steps),
                    model,
                    chain,
                    camera,
                    cull_sigmas: self.cull_sigmas,
                    dense_batches: self.dense_batches.clone(),
                    counts,
                },
            )],
            log,
        })
    }

    /// Its Gaussians (as many as densification left, on the links the state names) on the robot's
    /// chain, seen from the saved camera.
    fn load(&self, weights: &std::path::Path, ctx: &LoadContext) -> Result<Loaded> {
        let state: K3dgsState = serde_json::from_value(ctx.state.clone())
            .map_err(|e| crate::Error::data(weights, format!("its saved state: {e}")))?;
        let robot = ctx
            .robot
            .ok_or_else(|| crate::Error::Config("K-3DGS loads with its robot".into()))?;
        let long_axis: Vec<usize> = (0..robot.chain.links.len())
            .map(|l| GaussianInit::long_axis(robot, l))
            .collect();
        let n = state.links.len();
        let template = KinematicGaussians::new(
            &state.links,
            &vec![[0.0; 3]; n],
            &self.init,
            &long_axis,
            ctx.device,
        );
        Ok(Some(Box::new(K3dgsRenderer {
            model: crate::train::checkpoint::load_module(template, weights)?,
            chain: TensorChain::new(&robot.chain),
            camera: ctx.camera.clone(),
            mode: state.mode,
            cull_sigmas: self.cull_sigmas,
            dense_batches: self.dense_batches.clone(),
            counts: Vec::new(),
        })))
    }
}

/// What a saved K-3DGS model keeps beside its weights.
#[derive(serde::Serialize, serde::Deserialize)]
struct K3dgsState {
    /// The link of each Gaussian densification left (burn's record keeps the parameters, not
    /// this constant).
    links: Vec<usize>,
    /// How they composite at the end of training.
    mode: Compositing,
}

/// A trained K-3DGS model with what it renders with.
pub struct K3dgsRenderer {
    pub model: KinematicGaussians,
    chain: TensorChain,
    camera: Camera,
    mode: Compositing,
    cull_sigmas: f64,
    dense_batches: Vec<usize>,
    /// `(step, Gaussians)` after each change of the set.
    pub counts: Vec<(usize, usize)>,
}

impl K3dgsRenderer {
    /// Silhouettes `[b, 1, H, W]` of `angles` (degrees), culled (`cull`) or dense, dense in
    /// parts of 8 images (256 at once would hold 256 x N x P floats).
    /// Inputs of `dof + 9` columns (trained on several views): each row from its camera.
    fn splat(&self, angles: Tensor<2>, cull: Option<f64>) -> (Tensor<4>, Tensor<4>) {
        let views = split_views(&angles, self.chain.dof(), &self.camera)
            .expect("camera inputs of valid cameras");
        let (sil, depth): (Vec<_>, Vec<_>) = views
            .into_iter()
            .map(|(angles, view)| self.splat_from(&view, angles, cull))
            .unzip();
        (Tensor::cat(sil, 0), Tensor::cat(depth, 0))
    }

    /// [`K3dgsRenderer::splat`] seen from `camera`.
    fn splat_from(
        &self,
        camera: &Camera,
        angles: Tensor<2>,
        cull: Option<f64>,
    ) -> (Tensor<4>, Tensor<4>) {
        let [b, _] = angles.dims();
        let q = self.chain.from_user(angles);
        let part = if cull.is_some() { b.max(1) } else { 8 };
        let (mut sil, mut depth) = (Vec::new(), Vec::new());
        for s in (0..b).step_by(part) {
            let (si, de) = self.model.render(
                &self.chain,
                q.clone().slice([s..(s + part).min(b)]),
                camera,
                self.mode,
                cull,
            );
            sil.push(si);
            depth.push(de);
        }
        let shape = [b, 1, camera.height, camera.width];
        (
            Tensor::cat(sil, 0).reshape(shape),
            Tensor::cat(depth, 0).reshape(shape),
        )
    }
}

impl Render for K3dgsRenderer {
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        let (s, d) = self.splat(angles, Some(self.cull_sigmas));
        (s, Some(d))
    }

    fn save(&self, path: &std::path::Path) -> Result<Option<serde_json::Value>> {
        crate::train::checkpoint::save_module(&self.model, path)?;
        let state = K3dgsState {
            links: self
                .model
                .links
                .clone()
                .into_data()
                .iter::<i64>()
                .map(|l| l as usize)
                .collect(),
            mode: self.mode,
        };
        Ok(Some(
            serde_json::to_value(state).expect("K-3DGS's state serialises"),
        ))
    }

    fn render_view(&self, camera: &Camera, angles: Tensor<2>) -> Option<Tensor<4>> {
        Some(self.splat_from(camera, angles, Some(self.cull_sigmas)).0)
    }

    /// Depth is drawn where the Gaussians are.
    fn depth_pixels(&self) -> DepthPixels {
        DepthPixels::Drawn
    }
}

impl K3dgsRenderer {
    /// Dense splatting timed at each of its `dense_batches` (the slow reference to the
    /// culled renders the harness times: one warm-up and one timed call per batch), on
    /// `dof`-joint poses on `device`.
    pub fn dense_timings(&self, dof: usize, device: &Device) -> Vec<Timing> {
        let dense_speed = SpeedConfig {
            warmup: 1,
            min_repeats: 1,
            min_seconds: 0.0,
            batches: self.dense_batches.clone(),
        };
        measure(|q| self.splat(q, None).0, dof, device, &dense_speed)
    }

    /// The camera it renders from.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Where its Gaussians' centres project (image row, column) in each of `poses` (joint
    /// angles in degrees).
    pub fn projected_centres(&self, poses: &[Vec<f64>]) -> Vec<Vec<(f32, f32)>> {
        let device = self.model.positions.val().device();
        let dof = self.chain.dof();
        let q: Vec<f32> = poses
            .iter()
            .flat_map(|p| p.iter().map(|&a| a as f32))
            .collect();
        let q = self.chain.from_user(Tensor::<2>::from_data(
            TensorData::new(q, [poses.len(), dof]),
            &device,
        ));
        let g = self.model.project(&self.chain, q, &self.camera);
        let rows = g.row.into_data().try_into_vec::<f32>().expect("float");
        let cols = g.col.into_data().try_into_vec::<f32>().expect("float");
        let m = self.model.len();
        (0..poses.len())
            .map(|b| (0..m).map(|k| (rows[b * m + k], cols[b * m + k])).collect())
            .collect()
    }
}

impl BodyFit for K3dgsRenderer {
    fn differentiable(&self, autodiff: &Device) -> Option<Box<dyn Render>> {
        Some(Box::new(K3dgsRenderer {
            model: self.model.clone().fork(autodiff).freeze(),
            chain: self.chain.clone(),
            camera: self.camera.clone(),
            mode: self.mode,
            cull_sigmas: self.cull_sigmas,
            dense_batches: self.dense_batches.clone(),
            counts: self.counts.clone(),
        }))
    }

    fn joint_origins(&self) -> Option<Vec<[f32; 3]>> {
        let (_, t, _) = self.chain.origin_rows();
        Some(t.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
    }

    fn render_with_origins(&self, angles: Tensor<2>, origin_t: Tensor<2>) -> Option<Tensor<4>> {
        let [b, _] = angles.dims();
        let device = angles.device();
        let (r, _, _) = self.chain.origin_rows();
        let joints = self.chain.joint_count();
        let origin_r = Tensor::<3>::from_data(TensorData::new(r, [joints, 3, 3]), &device);
        let q = self.chain.from_user(angles);
        let (fr, ft) = self.chain.link_frames_with(q, origin_r, origin_t);
        let g = self.model.project_frames(fr, ft, &self.camera);
        let (s, _) = self
            .model
            .composite(g, &self.camera, self.mode, Some(self.cull_sigmas));
        Some(s.reshape([b, 1, self.camera.height, self.camera.width]))
    }
}
