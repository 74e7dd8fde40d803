//! Speed of one dense FFKSM training step (every sample of every ray of a 100x100 image, the
//! paper preset's step after the curriculum): burn's autodiff through the dense marcher, the
//! reference, against the hand-written step of [`selfmodel::self_models::ffksm::dense_step`], in the same
//! sitting, for both architectures. The step's arithmetic is counted from the layer shapes,
//! so each path's rate can be set against the machine's matrix-product peak.

use std::time::Instant;

use burn::optim::GradientsParams;

use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::Result;
use selfmodel::self_models::ffksm::dense_step::dense_step;
use selfmodel::self_models::ffksm::marcher::render_silhouette;
use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run, weighted_mse};
use selfmodel::train::trainer::autodiff_device;

/// One architecture through one path.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct StepBenchRow {
    pub model: String,
    /// `autodiff` (burn's graph, the reference) or `hand-written`.
    pub path: String,
    pub rays: usize,
    pub evaluations: usize,
    /// Median and fastest seconds per step over the repeats (after warm-up).
    pub seconds_median: f64,
    pub seconds_min: f64,
    /// Floating-point operations of the step's matrix products (forward and backward).
    pub gflop: f64,
    pub gflop_per_s: f64,
    /// The autodiff step's median over this path's (1 for the reference itself).
    pub speedup: f64,
    /// The loss this path computed (both paths see the same step).
    pub loss: f64,
    pub threads: usize,
    pub preset: String,
    pub device: String,
    pub git_revision: String,
}

/// Time both paths on both architectures: for each path one warm-up step, then `repeats`
/// steps back to back (the same steps, seeds 1..=repeats, for both paths).
pub fn run(device_choice: DeviceChoice, quick: bool, repeats: usize) -> Result<Vec<StepBenchRow>> {
    if repeats == 0 {
        return Err(selfmodel::Error::Config(
            "--repeats 0: a median needs at least one timed step (give 1 or more)".into(),
        ));
    }
    let preset = if quick { "quick" } else { "paper" };
    let device = selfmodel::core::device::select(device_choice)?;
    let tdev = autodiff_device(&device, 0);
    let mut rows = Vec::new();
    for cfg in [
        ffksm_run(preset, FfksmVariant::Reimplementation)?,
        ffksm_run(preset, FfksmVariant::Original)?,
    ] {
        let field = cfg.model.field.init(&tdev, 0)?;
        let camera = cfg.data.dataset.camera.clone();
        let pixels: Vec<usize> = (0..camera.width * camera.height).collect();
        // A silhouette-like truth: a disc of robot pixels in the middle.
        let truth: Vec<f32> = pixels
            .iter()
            .map(|&p| {
                let (r, c) = ((p / camera.width) as f64, (p % camera.width) as f64);
                let (cr, cc) = (camera.height as f64 / 2.0, camera.width as f64 / 2.0);
                if (r - cr).hypot(c - cc) < camera.width as f64 / 6.0 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let view = (&camera, &[0.2, -0.3, 0.5, 0.9][..]);
        let autodiff = |seed: u64| {
            let t0 = Instant::now();
            let pred =
                render_silhouette(&field, view, &pixels, &cfg.model.march, Some(seed), &tdev);
            let loss = weighted_mse(pred, &truth, cfg.model.robot_weight);
            let value = loss.clone().into_scalar::<f32>() as f64;
            let grads = GradientsParams::from_grads(loss.backward(), &field);
            std::hint::black_box(grads);
            (t0.elapsed().as_secs_f64(), value)
        };
        let hand_written = |seed: u64| {
            let t0 = Instant::now();
            let step = dense_step(
                &field,
                view,
                &pixels,
                &truth,
                cfg.model.robot_weight,
                &cfg.model.march,
                Some(seed),
                &device,
            );
            std::hint::black_box(&step.gradients);
            (t0.elapsed().as_secs_f64(), step.loss)
        };
        // Each path's repeats back to back after its own warm-up: burn's graph allocates
        // ~3.5 GB of activations a step, which stay mapped only while it runs step after step
        // (alternating the paths made its median 35% slower, measured).
        let timed = |step: &dyn Fn(u64) -> (f64, f64)| {
            step(0);
            let runs: Vec<(f64, f64)> = (0..repeats).map(|k| step(1 + k as u64)).collect();
            let loss = runs.last().map_or(f64::NAN, |r| r.1);
            (runs.into_iter().map(|r| r.0).collect::<Vec<f64>>(), loss)
        };
        let (mut times_a, loss_a) = timed(&autodiff);
        let (mut times_h, loss_h) = timed(&hand_written);
        let evaluations = pixels.len() * cfg.model.march.samples;
        let gflop = field.step_flop(evaluations) / 1e9;
        let median_a = median(&mut times_a);
        for (path, times, loss) in [
            ("autodiff", &mut times_a, loss_a),
            ("hand-written", &mut times_h, loss_h),
        ] {
            let m = median(times);
            rows.push(StepBenchRow {
                model: cfg.name.clone(),
                path: path.into(),
                rays: pixels.len(),
                evaluations,
                seconds_median: m,
                seconds_min: times.iter().copied().fold(f64::INFINITY, f64::min),
                gflop,
                gflop_per_s: gflop / m,
                speedup: median_a / m,
                loss,
                threads: rayon::current_num_threads(),
                preset: preset.into(),
                device: device_choice.to_string(),
                git_revision: selfmodel::core::provenance::git_revision(),
            });
        }
    }
    Ok(rows)
}

fn median(t: &mut [f64]) -> f64 {
    selfmodel::core::timing::median(t)
}
