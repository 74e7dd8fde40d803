//! MeanSilhouette: the best constant image, a lower bound every self-model must beat. It
//! ignores the joint angles and answers the per-pixel mean of the training silhouettes (the
//! constant of least squared error, so the best PSNR a constant can have). The mean is a
//! blur where the arm moves and reads as background at IoU's 0.5 threshold, so the pixels
//! whose mean reaches the threshold that maximises the IoU on the training silhouettes are
//! raised to 0.5 (counted as robot); the rest keep the mean.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};

use crate::core::error::Result;
use crate::core::preset::Preset;
use crate::eval::evaluation::iou;
use crate::self_models::{
    model::{BodyFit, Fit, LoadContext, Loaded, Render, SelfModel, Trained, load_network},
    run_config::{SelfModelRun, model_preset},
};
use crate::train::config::TrainLog;

/// The constant image's config. Presets: `paper` (100x100), `quick` (32x32).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeanSilhouette {
    /// Output image size `[height, width]`.
    pub image: [usize; 2],
    /// Raise the pixels at or above the IoU-best threshold to 0.5 (false: the plain mean).
    pub tune_threshold: bool,
}

impl Preset for MeanSilhouette {
    fn paper() -> Self {
        MeanSilhouette {
            image: [100, 100],
            tune_threshold: true,
        }
    }

    fn quick() -> Self {
        MeanSilhouette {
            image: [32, 32],
            ..Self::paper()
        }
    }
}

/// The fitted constant image, `[1, 1, H, W]` (a parameter, so that it saves as a network's
/// weights do).
#[derive(Module, Debug)]
pub struct ConstantImage {
    image: Param<Tensor<4>>,
}

impl Render for ConstantImage {
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        let [n, _] = angles.dims();
        (self.image.val().repeat_dim(0, n), None)
    }

    fn save(&self, path: &std::path::Path) -> Result<Option<serde_json::Value>> {
        crate::train::checkpoint::save_module(self, path)?;
        Ok(Some(serde_json::Value::Null))
    }
}

/// Not differentiable here, no chain of its own: nothing for reading the body back.
impl BodyFit for ConstantImage {}

/// The threshold in (0, 0.5] whose mask `mean >= t` has the highest mean IoU with `images`.
fn best_threshold(mean: &[f32], images: &[f32]) -> f32 {
    let px = mean.len();
    let mut best = (f64::NEG_INFINITY, 0.5f32);
    for k in 1..=10 {
        let t = 0.05 * k as f32;
        let mask: Vec<f32> = mean.iter().map(|&m| (m >= t) as u8 as f32).collect();
        let score: f64 = images.chunks(px).map(|img| iou(&mask, img)).sum();
        if score > best.0 {
            best = (score, t);
        }
    }
    best.1
}

impl SelfModel for MeanSilhouette {
    const KIND: &'static str = "mean_silhouette";
    type Renderer = ConstantImage;

    fn image(&self) -> [usize; 2] {
        self.image
    }

    fn fit(&self, fit: &Fit) -> Result<Trained<ConstantImage>> {
        let start = std::time::Instant::now();
        let [n, _, h, w] = fit.train_set.targets[0].dims();
        let images = fit.train_set.targets[0]
            .clone()
            .into_data()
            .try_into_vec::<f32>()
            .expect("float silhouettes");
        let px = h * w;
        let mut mean = vec![0f32; px];
        for img in images.chunks(px) {
            for (m, &v) in mean.iter_mut().zip(img) {
                *m += v / n as f32;
            }
        }
        if self.tune_threshold {
            let t = best_threshold(&mean, &images);
            for m in mean.iter_mut().filter(|m| **m >= t) {
                *m = m.max(0.5);
            }
        }
        // The "training loss": the mean squared error of the constant on the training set.
        let mse = images
            .chunks(px)
            .flat_map(|img| img.iter().zip(&mean).map(|(a, b)| ((a - b) as f64).powi(2)))
            .sum::<f64>()
            / images.len().max(1) as f64;
        let device: &Device = fit.device;
        let image = Tensor::from_data(TensorData::new(mean, [1, 1, h, w]), device);
        Ok(Trained::one(
            ConstantImage {
                image: Param::from_tensor(image),
            },
            px,
            TrainLog {
                step: 1,
                curve: vec![(1, mse)],
                train_seconds: start.elapsed().as_secs_f64(),
                images: n,
                resumed_from: None,
            },
        ))
    }

    fn load(&self, weights: &std::path::Path, ctx: &LoadContext) -> Result<Loaded> {
        let [h, w] = self.image;
        let template = ConstantImage {
            image: Param::from_tensor(Tensor::zeros([1, 1, h, w], ctx.device)),
        };
        load_network(template, weights)
    }
}

/// MeanSilhouette's run on `preset`: one pass over the training silhouettes.
pub fn mean_silhouette_run(preset: &str) -> Result<SelfModelRun<MeanSilhouette>> {
    let mut model = MeanSilhouette::preset(model_preset(preset))?;
    model.image = SelfModelRun::<MeanSilhouette>::image(preset)?;
    let mut run = SelfModelRun::new(preset, "MeanSilhouette", model, 256)?;
    run.note = "the best constant image: a lower bound, not a model".into();
    run.train.steps = 1;
    run.train.batch = run.data.dataset.train;
    Ok(run)
}
