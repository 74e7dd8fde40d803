//! Encoder drift: the encoders report `true + offset` with a constant offset per joint. From
//! k images and the angles reported with them, the offset is the vector `d` (one for all k
//! images) for which the self-model's renderings of `reported - d` match the images: Adam on
//! `d` through the frozen model, from `d = 0`.

use burn::module::{Module, Param};
use burn::tensor::Tensor;

use crate::body::descent::{Descent, views};
use crate::body::observations::{ImageFit, host};
use crate::body::pose::{SilhouetteLoss, row_losses};
use crate::core::error::Result;

/// How the offsets are fitted.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DriftConfig {
    pub steps: usize,
    /// Adam's learning rate at the start (degrees), falling along a half cosine to 1%.
    pub learning_rate: f64,
    pub loss: SilhouetteLoss,
}

impl DriftConfig {
    pub fn paper() -> Self {
        DriftConfig {
            steps: 200,
            learning_rate: 0.5,
            loss: SilhouetteLoss::Bce,
        }
    }
}

/// The shared offset (degrees), `[1, dof]`.
#[derive(Module, Debug)]
struct Offset {
    d: Param<Tensor<2>>,
}

/// The encoder offsets (degrees, one per joint) that explain the images `fit` observes given
/// the angles the encoders `reported` with each image, through its renderer.
pub fn estimate_offsets(
    fit: ImageFit,
    reported: &[Vec<f64>],
    cfg: &DriftConfig,
) -> Result<Vec<f64>> {
    let (renderer, device, image, observed) = fit.parts();
    let descent = Descent::checked(cfg.steps, cfg.learning_rate, "drift estimation")?;
    let set = views(observed, reported, image, "reported", device)?;
    let dof = set.inputs.dims()[1];
    let module = Offset {
        d: Param::from_tensor(Tensor::zeros([1, dof], device)),
    };
    let loss = cfg.loss;
    let fitted = descent.run(module, &set, |m: &Offset, b| {
        let n = b.inputs.dims()[0];
        let q = b.inputs.clone() - m.d.val().expand([n, dof]);
        row_losses(loss, renderer.render(q).0, b.targets[0].clone()).sum()
    })?;
    let d = host(fitted.d.val())?;
    Ok(d.into_iter().map(f64::from).collect())
}
