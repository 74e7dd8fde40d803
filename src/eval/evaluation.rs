//! Quality of a self-model's predictions on held-out poses (self-modeling paper, Section V).
//!
//! - PSNR as the paper computes it: per image `-10 log10(MSE + 1e-8)` on images in [0, 1],
//!   averaged over images; reported on the paper's subset (the first 100 test images, which
//!   is all NeuroKin and ResNeuroKin-D were scored on) and on the whole test set.
//! - IoU of the silhouettes thresholded at 0.5 (PSNR on mostly-empty images flatters every
//!   model; IoU says whether the arm is where it should be).
//! - Depth error in millimetres, mean absolute over the pixels where the true silhouette is
//!   the robot (for renderers, where the prediction is the robot too: [`DepthPixels`]), beside the error of the best constant depth (the median of the true robot-pixel
//!   depths of the test set, which minimises the mean absolute error of any constant): a depth
//!   head is useful only if it beats that.

/// Predictions for a set of images, on the host.
#[derive(Clone, Debug)]
pub struct Predictions {
    /// `[n, H * W]` silhouette probabilities in [0, 1], row-major.
    pub silhouettes: Vec<f32>,
    /// `[n, H * W]` depth in metres, when the model predicts it.
    pub depth: Option<Vec<f32>>,
    pub pixels: usize,
    /// Which pixels the depth error counts.
    pub depth_pixels: DepthPixels,
}

/// The pixels a depth error is measured on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthPixels {
    /// Every pixel the true silhouette calls robot: for depth heads, which predict everywhere.
    #[default]
    TrueRobot,
    /// Pixels both the true and the predicted silhouette call robot: for renderers (FFKSM,
    /// K-3DGS) whose depth exists only where they draw something; a missed pixel is a
    /// silhouette error (IoU), not a depth error of the whole camera distance.
    Drawn,
}

/// Per-image and mean quality figures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Quality {
    /// Mean PSNR over the first `paper_subset` test images (dB).
    pub psnr_db_paper_subset: f64,
    /// Mean PSNR over the whole test set (dB).
    pub psnr_db_test: f64,
    /// Mean silhouette IoU over the whole test set.
    pub iou_test: f64,
    /// Mean absolute depth error on robot pixels (mm).
    pub depth_mae_mm: Option<f64>,
    /// The same error of the best constant depth: the median true depth of the test set's
    /// robot pixels (mm).
    pub depth_constant_mae_mm: Option<f64>,
    pub paper_subset: usize,
    pub test_images: usize,
    /// Per-image PSNR (dB) and IoU, in test order.
    #[serde(skip)]
    pub per_image_psnr: Vec<f64>,
    #[serde(skip)]
    pub per_image_iou: Vec<f64>,
}

/// The paper's PSNR of one image: `-10 log10(MSE + 1e-8)`, both in [0, 1].
pub fn psnr_db(pred: &[f32], truth: &[f32]) -> f64 {
    let mse = pred
        .iter()
        .zip(truth)
        .map(|(&p, &t)| ((p - t) as f64).powi(2))
        .sum::<f64>()
        / pred.len() as f64;
    -10.0 * (mse + 1e-8).log10()
}

/// IoU of two silhouettes thresholded at 0.5; two empty silhouettes have IoU 1.
pub fn iou(pred: &[f32], truth: &[f32]) -> f64 {
    crate::eval::metrics::iou_where(pred, truth, |v| v >= 0.5)
}

/// Score predictions against the true silhouettes (`[n, H * W]` in [0, 1]) and depth.
pub fn score(
    pred: &Predictions,
    truth: &[f32],
    truth_depth: Option<&[f32]>,
    paper_subset: usize,
) -> Quality {
    let px = pred.pixels;
    let n = truth.len() / px;
    let per_image_psnr: Vec<f64> = (0..n)
        .map(|i| {
            psnr_db(
                &pred.silhouettes[i * px..(i + 1) * px],
                &truth[i * px..(i + 1) * px],
            )
        })
        .collect();
    let per_image_iou: Vec<f64> = (0..n)
        .map(|i| {
            iou(
                &pred.silhouettes[i * px..(i + 1) * px],
                &truth[i * px..(i + 1) * px],
            )
        })
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let subset = paper_subset.min(n);
    let (depth_mae_mm, depth_constant_mae_mm) = match (&pred.depth, truth_depth) {
        (Some(d), Some(t)) => {
            let counted: Vec<bool> = truth
                .iter()
                .zip(&pred.silhouettes)
                .map(|(&t, &p)| {
                    t >= 0.5 && (pred.depth_pixels == DepthPixels::TrueRobot || p >= 0.5)
                })
                .collect();
            let robot = |v: &[f32]| -> Vec<f32> {
                v.iter()
                    .zip(&counted)
                    .filter(|&(_, &c)| c)
                    .map(|(&v, _)| v)
                    .collect()
            };
            let (pred_robot, true_robot) = (robot(d), robot(t));
            let mae_mm = |abs_errors: f64| 1000.0 * abs_errors / true_robot.len().max(1) as f64;
            let model: f64 = pred_robot
                .iter()
                .zip(&true_robot)
                .map(|(p, g)| (p - g).abs() as f64)
                .sum();
            let median = median(&true_robot);
            let constant: f64 = true_robot.iter().map(|g| (g - median).abs() as f64).sum();
            (Some(mae_mm(model)), Some(mae_mm(constant)))
        }
        _ => (None, None),
    };
    Quality {
        psnr_db_paper_subset: mean(&per_image_psnr[..subset]),
        psnr_db_test: mean(&per_image_psnr),
        iou_test: mean(&per_image_iou),
        depth_mae_mm,
        depth_constant_mae_mm,
        paper_subset: subset,
        test_images: n,
        per_image_psnr,
        per_image_iou,
    }
}

/// The median of `v` (0 when empty).
fn median(v: &[f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mut sorted = v.to_vec();
    sorted.sort_by(f32::total_cmp);
    sorted[sorted.len() / 2]
}
