//! Scoring a trained model: its silhouettes rendered in batches, PSNR and IoU against the
//! truth from each camera, trained and held out, with the view-blind bound beside them.

use burn::tensor::{Device, Tensor, TensorData};

use selfmodel::eval::evaluation::{iou, psnr_db};
use selfmodel::self_models::camera_input::camera_input;
use selfmodel::sim::camera::Camera;
use selfmodel::sim::ray_caster::silhouettes as truth;

use super::{MultiviewConfig, MultiviewRow};

/// Host silhouettes `[n, H * W]` in [0, 1] of `renderer` over `inputs` (`n` rows of `width`),
/// rendered in batches of 64, and the images per second of the pass (after a warm-up batch).
pub(super) fn rendered(
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
pub(super) fn quality(pred: &[f32], truth: &[f32], px: usize) -> (f64, f64) {
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
pub(super) fn inputs(angles: &[Vec<f64>], camera: Option<&Camera>) -> (Vec<f32>, usize) {
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

/// The renderer a trained model is scored with: its last (the accelerated one, where a
/// model has two).
pub(super) fn scored_renderer(
    fitted: &selfmodel::self_models::harness::Fitted<Box<dyn selfmodel::Render>>,
) -> &dyn selfmodel::self_models::model::Render {
    fitted
        .trained
        .renderers
        .last()
        .expect("a renderer")
        .1
        .as_ref()
}

/// What scoring one trained model needs.
pub(super) struct Scoring<'a> {
    pub(super) cfg: &'a MultiviewConfig,
    pub(super) name: &'a str,
    /// Trained cameras.
    pub(super) n: usize,
    pub(super) fitted: &'a selfmodel::self_models::harness::Fitted<Box<dyn selfmodel::Render>>,
    pub(super) robot: &'a selfmodel::sim::robot::Robot,
    pub(super) options: &'a selfmodel::sim::ray_caster::RenderOptions,
    pub(super) revision: &'a str,
    pub(super) device_name: &'a str,
}

/// One model's rows, its grid row (the first held-out pose from each held-out camera) and,
/// where it carries the view-blind bound, the true images of that row.
pub(super) struct Scored {
    pub(super) rows: Vec<MultiviewRow>,
    pub(super) grid_row: Vec<Vec<f32>>,
    pub(super) grid_truth: Vec<Vec<f32>>,
}

/// Score a trained model on the held-out poses: from its trained cameras (the harness's test
/// set, rendered by the model's own `render`), and from each held-out camera (`held_out`
/// renders poses from a camera: images and images per second); with `view_blind`, also the
/// view-blind bound's rows.
pub(super) fn score(
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
