//! Link lengths from images (visual calibration): a self-model that hangs on the kinematic
//! chain (K-3DGS: Gaussians on the links) renders with the chain's joint origins as
//! parameters ([`crate::self_models::model::Render::render_with_origins`]); with the
//! Gaussians frozen, Adam fits the origins' translations to k images of the changed arm at
//! known joint angles. A link's change is the fitted translation's change along the link
//! (mm). This is the EMSSL paper's first adaptation approach (learned link parameters,
//! [`crate::ik::paper::calibration`]) fed by a camera instead of measured tip positions.

use burn::module::{Module, Param};
use burn::tensor::{Tensor, TensorData};

use crate::body::descent::{Descent, views};
use crate::body::observations::{ImageFit, host};
use crate::body::pose::{SilhouetteLoss, row_losses};
use crate::core::error::{Error, Result};

/// How the joint origins are fitted.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VisualCalibrationConfig {
    pub steps: usize,
    /// Adam's learning rate at the start (metres), falling along a half cosine to 1%.
    pub learning_rate: f64,
    pub loss: SilhouetteLoss,
}

impl VisualCalibrationConfig {
    pub fn paper() -> Self {
        VisualCalibrationConfig {
            steps: 200,
            learning_rate: 2e-3,
            loss: SilhouetteLoss::Bce,
        }
    }
}

/// The joint origins' translations `[J, 3]` (metres).
#[derive(Module, Debug)]
struct Origins {
    t: Param<Tensor<2>>,
}

/// The fitted chain: every joint origin's translation and its change along the link.
#[derive(Clone, Debug)]
pub struct FittedOrigins {
    /// Fitted translations (metres), one per joint of the chain.
    pub translations: Vec<[f64; 3]>,
    /// The change of each link's length along itself (mm; 0 for a joint with no length).
    pub change_mm: Vec<f64>,
}

/// Fit the joint origins of the chain of `fit`'s renderer to the images it observes of the
/// robot at the known joint `angles` (degrees).
pub fn fit_joint_origins(
    fit: ImageFit,
    angles: &[Vec<f64>],
    cfg: &VisualCalibrationConfig,
) -> Result<FittedOrigins> {
    let (renderer, device, image, observed) = fit.parts();
    let descent = Descent::checked(cfg.steps, cfg.learning_rate, "visual calibration")?;
    let nominal = renderer.joint_origins().ok_or_else(|| {
        Error::Config("this self-model has no kinematic chain to calibrate (use K-3DGS)".into())
    })?;
    let set = views(observed, angles, image, "pose", device)?;
    let joints = nominal.len();
    let start: Vec<f32> = nominal.iter().flatten().copied().collect();
    let module = Origins {
        t: Param::from_tensor(Tensor::from_data(
            TensorData::new(start, [joints, 3]),
            device,
        )),
    };
    let loss = cfg.loss;
    let fitted = descent.run(module, &set, |m: &Origins, b| {
        let s = renderer
            .render_with_origins(b.inputs.clone(), m.t.val())
            .expect("checked: the model has a chain");
        row_losses(loss, s, b.targets[0].clone()).sum()
    })?;
    let t = host(fitted.t.val())?;
    let translations: Vec<[f64; 3]> = t
        .chunks(3)
        .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64])
        .collect();
    let change_mm = translations
        .iter()
        .zip(&nominal)
        .map(|(f, n)| {
            let n = [n[0] as f64, n[1] as f64, n[2] as f64];
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if len < 1e-3 {
                return 0.0;
            }
            let along = (0..3).map(|i| (f[i] - n[i]) * n[i] / len).sum::<f64>();
            1000.0 * along
        })
        .collect();
    Ok(FittedOrigins {
        translations,
        change_mm,
    })
}
