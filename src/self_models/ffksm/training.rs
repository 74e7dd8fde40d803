//! Training the occupancy field: the centre crop, the loss, what a checkpoint must match, the
//! steps over rays, the collapse probe and the restarts.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Tensor, TensorData};

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::self_models::ffksm::accelerated_marcher::render_silhouette_skipping;
use crate::self_models::ffksm::dense_step::dense_step;
use crate::self_models::ffksm::field::OccupancyField;
use crate::self_models::ffksm::marcher::render_silhouette;
use crate::self_models::{camera_input::views_of_rows, data_spec::DataSpec, model::Fit};
use crate::sim::camera::Camera;
use crate::train::{
    config::{TrainConfig, TrainLog},
    hooks::Watch,
    trainer::{StepLoss, Trainer},
};

use super::config::{Ffksm, TrainMarcher};

/// Row-major indices of the central `crop x crop` pixels of a `height x width` image.
pub fn centre_crop(height: usize, width: usize, crop: usize) -> Vec<usize> {
    let (ch, cw) = (crop.min(height), crop.min(width));
    let (r0, c0) = ((height - ch) / 2, (width - cw) / 2);
    (r0..r0 + ch)
        .flat_map(|r| (c0..c0 + cw).map(move |c| r * width + c))
        .collect()
}

/// User units (degrees; metres for a prismatic joint) to the field's SI units.
pub(super) fn radians(
    angles_deg: &[f32],
    chain: &crate::sim::kinematics::KinematicChain,
) -> Vec<f64> {
    let user: Vec<f64> = angles_deg.iter().map(|&v| v as f64).collect();
    chain.to_si(&user)
}

/// The weighted MSE of `pred` `[rays]` against `truth` (host, `[rays]` in [0, 1]):
/// `mean(w (pred − truth)²)` with `w = robot_weight` on robot pixels, 1 elsewhere (the
/// paper's equation 10).
pub fn weighted_mse(pred: Tensor<1>, truth: &[f32], robot_weight: f64) -> Tensor<1> {
    let device = pred.device();
    let n = truth.len();
    let weights: Vec<f32> = truth
        .iter()
        .map(|&t| if t >= 0.5 { robot_weight as f32 } else { 1.0 })
        .collect();
    let t = Tensor::<1>::from_data(TensorData::new(truth.to_vec(), [n]), &device);
    let w = Tensor::<1>::from_data(TensorData::new(weights, [n]), &device);
    ((pred - t).square() * w).mean()
}

/// What a checkpoint must match to be resumed: everything that shapes training except the
/// step count (step `k` draws the same image and samples whatever the total, so a longer run
/// continues a shorter one: `--steps 2000` then `--resume` to the preset's 8,000).
pub(super) fn fingerprint(cfg: &Ffksm, train: &TrainConfig, data: &DataSpec) -> serde_json::Value {
    let mut train = serde_json::to_value(train).expect("serialisable");
    if let Some(t) = train.as_object_mut() {
        t.remove("steps");
    }
    let mut print = serde_json::json!({"field": cfg.field, "march": cfg.march, "train": train, "curriculum": cfg.curriculum, "robot_weight": cfg.robot_weight, "data": data.fingerprint()});
    // A scene other than the papers' gets the robot's own virtual frame (`fitted_to_scene`):
    // checkpoints trained before with the paper's frame must not resume into it.
    let papers_scene = data.robot == crate::sim::robots::RobotSpec::default()
        && data.configured_camera() == Some(&Camera::paper());
    if !papers_scene {
        print["virtual_frame"] = serde_json::json!("the robot's first two joints");
    }
    // Only when it is not the default, so checkpoints from before the option still resume.
    if cfg.train_marcher != TrainMarcher::Dense {
        print["train_marcher"] = serde_json::json!(cfg.train_marcher);
    }
    print
}

/// A count a run keeps beside its checkpoint (JSON): `None` when the file is not there; an
/// error naming it when it is there but damaged (a resumed run would report wrong counts).
pub(super) fn read_kept<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>> {
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map(Some).map_err(|e| {
        Error::data(
            path,
            format!(
                "damaged ({e}); delete the checkpoint folder it sits in and train again without `resume`"
            ),
        )
    })
}

/// What every training step of the field reads (the training set on the host, read once: a
/// step finds its image's angles, camera and pixels there by the batch's indices rather than
/// reading its batch back from the device) and the counts it keeps, so a resumed run reports
/// all its steps.
pub(super) struct FieldSteps<'a> {
    cfg: &'a Ffksm,
    fit: &'a Fit<'a>,
    hand_written: bool,
    /// The curriculum's centre crop, and every pixel.
    crop: Vec<usize>,
    all: Vec<usize>,
    host_inputs: Vec<f32>,
    host_targets: Vec<f32>,
    columns: usize,
    pixels_per_image: usize,
    /// Network evaluations and steps of training so far.
    evaluations: std::cell::Cell<usize>,
    steps: std::cell::Cell<usize>,
}

impl<'a> FieldSteps<'a> {
    fn new(cfg: &'a Ffksm, fit: &'a Fit<'a>, hand_written: bool, earlier: [usize; 2]) -> Self {
        let camera = cfg.field_camera(fit.camera);
        let (h, w) = (camera.height, camera.width);
        // FFKSM trains without input noise, so these are the batch's inputs.
        debug_assert_eq!(fit.train.input_noise, 0.0);
        let host = |t: Tensor<2>| {
            t.into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .expect("float")
        };
        let train_set = fit.train_set;
        let host_targets = host(train_set.targets[0].clone().flatten::<2>(1, 3));
        FieldSteps {
            cfg,
            fit,
            hand_written,
            crop: centre_crop(h, w, cfg.curriculum.crop),
            all: (0..h * w).collect(),
            host_inputs: host(train_set.inputs.clone()),
            columns: train_set.inputs.dims()[1],
            pixels_per_image: host_targets.len() / train_set.len().max(1),
            host_targets,
            evaluations: std::cell::Cell::new(earlier[0]),
            steps: std::cell::Cell::new(earlier[1]),
        }
    }

    /// The pixels step `step` trains on: the centre crop during the curriculum, then
    /// `rays_per_step` drawn at random (seeded by the step) or every pixel.
    fn pixels(&self, step: usize) -> std::borrow::Cow<'_, [usize]> {
        let train = self.fit.train;
        if step < self.cfg.curriculum.steps {
            std::borrow::Cow::Borrowed(&self.crop)
        } else if let Some(n) = self.cfg.rays_per_step.filter(|&n| n < self.all.len()) {
            use rand::SeedableRng;
            use rand::seq::IndexedRandom;
            let mut rng = rand::rngs::StdRng::seed_from_u64(
                train.seed ^ (step as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
            );
            std::borrow::Cow::Owned(self.all.sample(&mut rng, n).copied().collect())
        } else {
            std::borrow::Cow::Borrowed(&self.all)
        }
    }

    /// One step's loss: one image (its joint angles, then on multi-view data its camera), its
    /// pixels marched densely (our hand-written backward pass where asked) or with skipping.
    fn loss(&self, m: &OccupancyField, b: &crate::train::batcher::Batch) -> StepLoss {
        let (cfg, fit) = (self.cfg, self.fit);
        let dof = fit.robot.dof();
        let i = b.indices[0];
        let a = &self.host_inputs[i * self.columns..(i + 1) * self.columns];
        let ppi = self.pixels_per_image;
        let truth = &self.host_targets[i * ppi..(i + 1) * ppi];
        let pixels = self.pixels(b.step);
        let pixels: &[usize] = &pixels;
        let t: Vec<f32> = pixels.iter().map(|&p| truth[p]).collect();
        let jitter = fit.train.seed ^ (b.step as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let own = views_of_rows(a, a.len(), dof, fit.camera)
            .expect("the harness built the camera inputs from valid cameras")
            .remove(0)
            .1;
        let own = cfg.field_camera(&own);
        let radians = radians(&a[..dof], &fit.robot.chain);
        let view = (&own, radians.as_slice());
        self.steps.set(self.steps.get() + 1);
        match cfg.train_marcher {
            TrainMarcher::Dense => {
                self.evaluations
                    .set(self.evaluations.get() + pixels.len() * cfg.march.samples);
                if self.hand_written {
                    let step = dense_step(
                        m,
                        view,
                        pixels,
                        &t,
                        cfg.robot_weight,
                        &cfg.march,
                        Some(jitter),
                        fit.device,
                    );
                    return StepLoss::Computed {
                        value: step.loss,
                        gradients: step.gradients,
                    };
                }
                let pred = render_silhouette(
                    m,
                    view,
                    pixels,
                    &cfg.march,
                    Some(jitter),
                    &b.inputs.device(),
                );
                StepLoss::Graph(weighted_mse(pred, &t, cfg.robot_weight))
            }
            TrainMarcher::Skipping => {
                let (pred, evaluations) = render_silhouette_skipping(
                    m,
                    &m.valid(),
                    view,
                    pixels,
                    &cfg.march,
                    &cfg.accelerated.grid,
                    Some(jitter),
                    &b.inputs.device(),
                );
                self.evaluations.set(self.evaluations.get() + evaluations);
                StepLoss::Graph(weighted_mse(pred, &t, cfg.robot_weight))
            }
        }
    }

    /// Network evaluations a step over a finished run of `log.step` steps.
    fn per_step(&self, log: &TrainLog) -> f64 {
        let cfg = self.cfg;
        match cfg.train_marcher {
            // Known exactly, however many processes the run took.
            TrainMarcher::Dense => {
                let cropped = log.step.min(cfg.curriculum.steps) * self.crop.len();
                let full = log.step.saturating_sub(cfg.curriculum.steps) * self.all.len();
                ((cropped + full) * cfg.march.samples) as f64 / log.step.max(1) as f64
            }
            TrainMarcher::Skipping => {
                self.evaluations.get() as f64 / self.steps.get().max(1) as f64
            }
        }
    }
}

/// The first training image, where collapse is probed: its angles (from the first camera),
/// and whether its centre crop shows the robot (an all-black probe is a collapse only then;
/// a robot framed automatically may lie outside the crop in that pose).
pub(super) struct CollapseProbe {
    angles: Vec<f32>,
    sees_robot: bool,
}

impl CollapseProbe {
    fn new(fit: &Fit, crop: &[usize]) -> Self {
        // The first training sample's row of a tensor, on the host.
        fn first<const D: usize>(t: &Tensor<D>) -> Vec<f32> {
            t.clone()
                .slice([0..1])
                .into_data()
                .convert::<f32>()
                .try_to_vec::<f32>()
                .expect("float")
        }
        let dof = fit.robot.dof();
        let image = first(&fit.train_set.targets[0]);
        CollapseProbe {
            angles: first(&fit.train_set.inputs)[..dof].to_vec(),
            sees_robot: crop.iter().any(|&p| image[p] >= 0.5),
        }
    }

    /// `Err(Collapsed)` where the field `m` draws the probe all black at `step`, inside the
    /// restart rule's window (the last try, after `max_restarts`, trains to the end whatever it
    /// draws: a robot the field cannot pick up then gets its row and its low score).
    fn check(
        &self,
        cfg: &Ffksm,
        fit: &Fit,
        m: &OccupancyField,
        step: usize,
        restarts: usize,
        crop: &[usize],
    ) -> Result<()> {
        let Some(r) = cfg
            .restart
            .as_ref()
            .filter(|r| self.sees_robot && restarts < r.max_restarts)
        else {
            return Ok(());
        };
        if step > r.until || step % r.every.max(1) != 0 {
            return Ok(());
        }
        let camera = cfg.field_camera(fit.camera);
        let probe = render_silhouette(
            &m.valid(),
            (&camera, &radians(&self.angles, &fit.robot.chain)),
            crop,
            &cfg.march,
            None,
            fit.device,
        );
        if probe.max().into_scalar::<f32>() < 1e-3 {
            Err(Error::Collapsed { step })
        } else {
            Ok(())
        }
    }
}

/// Train the field, restarting with a fresh model on collapse when the config asks for it:
/// the field, its log, the restarts and the network evaluations per step.
pub(super) fn train_field(
    cfg: &Ffksm,
    name: &str,
    fit: &Fit,
    hand_written: bool,
) -> Result<(OccupancyField, TrainLog, usize, f64)> {
    let (plan, train) = (fit.plan, fit.train);
    let resume = plan.resume;
    // Restarts after collapse so far, so a resumed run reports them (and initialises the same
    // model).
    let restarts_path = plan.dir.join("restarts.json");
    let mut restarts: usize = if resume {
        read_kept(&restarts_path)?.unwrap_or(0)
    } else {
        0
    };
    // Network evaluations and steps of training, so a resumed run reports them for all its
    // steps (`[evaluations, steps]`).
    let counts_path = plan.dir.join("evaluations.json");
    let earlier: [usize; 2] = if resume {
        read_kept(&counts_path)?.unwrap_or([0, 0])
    } else {
        [0, 0]
    };
    let steps = FieldSteps::new(cfg, fit, hand_written, earlier);
    let probe = CollapseProbe::new(fit, &steps.crop);
    loop {
        let seed = train.seed + 1000 * restarts as u64;
        let field = cfg.field.init(fit.train_device, seed)?;
        let loss = |m: &OccupancyField, b: &crate::train::batcher::Batch| steps.loss(m, b);
        let watch = |m: &OccupancyField, step: usize| -> Result<()> {
            // The counts go beside each checkpoint (saved right after this), so a run stopped
            // and resumed still reports all its steps.
            let every = train.checkpoint_every;
            if every > 0 && (step % every == 0 || step == train.steps) {
                std::fs::create_dir_all(&plan.dir).map_err(|e| Error::io(&plan.dir, e))?;
                write_json(&counts_path, &[steps.evaluations.get(), steps.steps.get()])?;
            }
            probe.check(cfg, fit, m, step, restarts, &steps.crop)
        };
        let label = if restarts == 0 {
            name.to_string()
        } else {
            format!("{name} (restart {restarts})")
        };
        let mut watch = Watch(watch);
        match Trainer::new(train, &label)
            .checkpoint(Some(plan))
            .hooks(&mut watch)
            .fit(field, fit.train_set, loss)
        {
            Ok((field, log)) => {
                if plan.dir.is_dir() {
                    write_json(&counts_path, &[steps.evaluations.get(), steps.steps.get()])?;
                }
                let per_step = steps.per_step(&log);
                return Ok((field.valid(), log, restarts, per_step));
            }
            Err(Error::Collapsed { step }) => {
                let max = cfg.restart.as_ref().map_or(0, |r| r.max_restarts);
                eprintln!("{label}: all-black image at step {step}; restarting with a fresh model");
                if restarts >= max {
                    return Err(Error::Training(format!(
                        "{}: collapsed to an all-black image {} times; raise the robot-pixel weight or the curriculum",
                        name,
                        restarts + 1
                    )));
                }
                restarts += 1;
                // The checkpoint holds the collapsed model: start the next try from scratch.
                let _ = std::fs::remove_dir_all(&plan.dir);
                if train.checkpoint_every > 0 {
                    std::fs::create_dir_all(&plan.dir).map_err(|e| Error::io(&plan.dir, e))?;
                    write_json(&restarts_path, &restarts)?;
                }
                steps.evaluations.set(0);
                steps.steps.set(0);
            }
            Err(e) => return Err(e),
        }
    }
}
