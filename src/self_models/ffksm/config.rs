//! FFKSM's config: the model, its curriculum and restarts, the marcher it trains with, the
//! paper's variant and the reimplementation's, and the presets.

use crate::core::error::Result;
use crate::core::preset::Preset;
use crate::eval::inference_speed::SpeedConfig;
use crate::self_models::ffksm::accelerated_marcher::AcceleratedConfig;
use crate::self_models::ffksm::field::OccupancyFieldConfig;
use crate::self_models::ffksm::marcher::MarchConfig;
use crate::self_models::run_config::SelfModelRun;
use crate::train::config::TrainConfig;

/// Train on the central `crop x crop` pixels for the first `steps` steps.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Curriculum {
    pub steps: usize,
    pub crop: usize,
}

/// Restart with a fresh model when the rendered centre of the first training image is all
/// black (every pixel below 1e-3), checked every `every` steps up to step `until`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CollapseRestart {
    pub every: usize,
    pub until: usize,
    pub max_restarts: usize,
}

/// How training renders its rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainMarcher {
    /// Every sample of every ray (the paper's: 640,000 evaluations per 100x100 image).
    #[default]
    Dense,
    /// Only samples in occupied cells of the per-pose grid (`accelerated.grid`), rebuilt
    /// from the current model at every step (beyond the paper).
    Skipping,
}

/// How a dense training step's gradients are computed. Both give the same gradients
/// (`tests/ffksm.rs` compares them); they differ in speed.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DenseGradients {
    /// The hand-written step of [`crate::self_models::ffksm::dense_step`] on the CPU backends (2-3x
    /// burn's graph on 2 cores, `bench_ffksm_step`); burn's autodiff on a GPU.
    #[default]
    HandWrittenOnCpu,
    /// burn's autodiff through the dense marcher everywhere (the reference).
    Autodiff,
}

/// FFKSM's model and how it trains (the run around it: [`SelfModelRun`], from [`ffksm_run`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Ffksm {
    pub field: OccupancyFieldConfig,
    pub march: MarchConfig,
    pub accelerated: AcceleratedConfig,
    pub curriculum: Curriculum,
    #[serde(default)]
    pub train_marcher: TrainMarcher,
    /// How dense steps are differentiated (not part of a checkpoint's fingerprint: both paths
    /// compute the same gradients, so a run may resume on the other).
    #[serde(default)]
    pub dense_gradients: DenseGradients,
    /// MSE weight of robot pixels (1: the code's plain MSE; the text's 5).
    pub robot_weight: f64,
    pub restart: Option<CollapseRestart>,
    /// Novel views: the training camera orbited about the world z axis by these angles (deg).
    pub novel_views_deg: Vec<f64>,
    /// Rays per network call when marching densely.
    pub chunk_rays: usize,
    /// After the curriculum, train each step on this many pixels drawn at random (seeded by
    /// the step) instead of the whole image (NeRF-style ray batches; none: every pixel, the
    /// papers').
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rays_per_step: Option<usize>,
    /// Output image size `[height, width]`.
    pub image: [usize; 2],
    /// Also render with dense marching (the paper's renderer, the accelerated marcher's
    /// reference, ~1 s an image) and write the renderer comparison and novel views; off in the
    /// `short` preset, which shows the accelerated marcher's row only.
    #[serde(default = "yes")]
    pub reference_renderers: bool,
    /// World metres per field unit: the field learns the scene shrunk by this about the
    /// origin (1 for the papers' arm; set by `fit` for a robot framed automatically, so the
    /// field's inputs span what they span for the papers' arm). Derived from the data, so
    /// neither saved nor fingerprinted.
    #[serde(skip, default = "unit_scale")]
    pub scene_scale: f64,
}

pub(super) fn unit_scale() -> f64 {
    1.0
}

pub(super) fn yes() -> bool {
    true
}

/// The three FFKSM models of Table I.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FfksmVariant {
    /// The reimplementation (the paper preset = its code).
    Reimplementation,
    /// The original authors' model: L = 10, the shorter predictive module, their virtual
    /// frame, a 200-step curriculum and restarts on collapse.
    Original,
    /// The reimplementation trained with empty-space skipping (beyond the paper): the same
    /// model, data and schedule, each step marching only the samples in occupied cells of a
    /// grid probed from the current model.
    Skipping,
}

impl FfksmVariant {
    /// Every variant with its folder name.
    pub const ALL: [(&str, FfksmVariant); 3] = [
        ("ffksm", FfksmVariant::Reimplementation),
        ("ffksm_original", FfksmVariant::Original),
        ("ffksm_skipping", FfksmVariant::Skipping),
    ];

    /// The variants a run trains: on the papers' arm all three, but under `short` (the few
    /// minutes of the main command) only the one that learns in that time, the original
    /// model. On any other robot only the original model, at every preset: the
    /// reimplementation and its skipping variant reproduce the paper's FFKSM figure on the
    /// papers' arm (17.35 dB), the original model is the best FFKSM (21.8 dB against 17.9 on
    /// that arm), and each of the others would add about two hours of training on 2 cores.
    pub fn of_run(preset: &str, papers_arm: bool) -> &'static [(&'static str, FfksmVariant)] {
        if preset == "short" || !papers_arm {
            &Self::ALL[1..2]
        } else {
            &Self::ALL
        }
    }
}

/// Training steps of the `short` preset (the main command's few minutes).
pub(super) const SHORT_STEPS: usize = 300;
/// Pixels per training step of the `short` preset (of 10,000).
pub(super) const SHORT_RAYS: usize = 1500;
/// Test images the `short` preset scores (the accelerated marcher: ~0.1 s an image).
pub(super) const SHORT_TEST_IMAGES: usize = 20;

/// An FFKSM run on `preset`: `paper`, `short` (the paper's model and data, trained on
/// [`SHORT_RAYS`] random pixels a step for [`SHORT_STEPS`] steps and scored on [`SHORT_TEST_IMAGES`] test images, for
/// the main command), `quick` (tiny, seconds; 24 test images).
pub fn ffksm_run(preset: &str, variant: FfksmVariant) -> Result<SelfModelRun<Ffksm>> {
    let quick = preset == "quick";
    let mut model = Ffksm {
        field: if quick {
            OccupancyFieldConfig::quick()
        } else {
            OccupancyFieldConfig::paper()
        },
        march: if quick {
            MarchConfig {
                samples: 32,
                ..MarchConfig::paper()
            }
        } else {
            MarchConfig::paper()
        },
        accelerated: AcceleratedConfig::paper(),
        curriculum: Curriculum {
            steps: if quick { 50 } else { 500 },
            crop: if quick { 16 } else { 50 },
        },
        train_marcher: TrainMarcher::Dense,
        dense_gradients: DenseGradients::default(),
        robot_weight: 1.0,
        restart: None,
        novel_views_deg: vec![30.0, 60.0],
        chunk_rays: 2048,
        rays_per_step: None,
        image: SelfModelRun::<Ffksm>::image(preset)?,
        reference_renderers: preset != "short",
        scene_scale: 1.0,
    };
    if quick {
        model.accelerated.grid.block = 2;
    }
    let mut run = SelfModelRun::new(preset, "FFKSM", model, 16)?;
    run.train = TrainConfig {
        precision: Default::default(),
        schedule: Default::default(),
        steps: if quick { 400 } else { 8000 },
        batch: 1,
        learning_rate: if quick { 5e-3 } else { 5e-4 },
        grad_clip_norm: None,
        input_noise: 0.0,
        seed: 0,
        checkpoint_every: if quick { 100 } else { 250 },
        log_every: 0,
    };
    // Rendering is per image: timed at batch 1 (median of 3 after one warm-up image).
    run.speed = SpeedConfig {
        warmup: 1,
        min_repeats: 3,
        min_seconds: 0.0,
        batches: vec![1],
    };
    let mut test_images = quick.then_some(24);
    if preset == "short" {
        run.train.steps = SHORT_STEPS;
        run.model.curriculum.steps = SHORT_STEPS / 4;
        run.model.rays_per_step = Some(SHORT_RAYS);
        test_images = Some(SHORT_TEST_IMAGES);
        run.note = format!(
            "short preset: {SHORT_STEPS} steps instead of 8,000, each on {SHORT_RAYS} random pixels after the crop curriculum, scored on the first {SHORT_TEST_IMAGES} test images, rendered by the accelerated marcher only (CPU time budget)"
        );
    }
    // Dense marching of the paper preset costs ~1 s per image on a 2-core CPU.
    if let Some(k) = test_images {
        let start = run.data.dataset.train;
        run.data.test = Some(start..start + k.min(run.data.dataset.samples - start));
    }
    match variant {
        FfksmVariant::Reimplementation => {}
        FfksmVariant::Original => {
            run.name = "FFKSM (original model)".into();
            let m = &mut run.model;
            m.field = if quick {
                OccupancyFieldConfig {
                    bands: 5,
                    ..OccupancyFieldConfig::quick()
                }
            } else {
                OccupancyFieldConfig::original()
            };
            m.field.relu_before_output = false;
            m.field.virtual_frame =
                crate::self_models::ffksm::virtual_frame::VirtualFrame::Original;
            m.curriculum.steps = m.curriculum.steps * 2 / 5;
            m.restart = Some(CollapseRestart {
                every: if quick { 25 } else { 100 },
                until: m.curriculum.steps * 5,
                max_restarts: 5,
            });
        }
        FfksmVariant::Skipping => {
            run.name = "FFKSM (trained with skipping)".into();
            run.model.train_marcher = TrainMarcher::Skipping;
        }
    }
    Ok(run)
}
