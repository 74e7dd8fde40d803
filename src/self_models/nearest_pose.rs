//! NearestPose: a lookup table, the baseline a learned self-model has to beat to show it
//! generalises. It keeps every training sample and answers the silhouette and depth of the
//! training pose nearest in joint space (Euclidean, degrees). On a dense trajectory this is
//! strong; where the test poses leave the training ones, it is what memorising gives.

use burn::tensor::{Tensor, TensorData};

use crate::core::error::Result;
use crate::core::preset::Preset;
use crate::self_models::{
    model::{BodyFit, Fit, Render, SelfModel, Trained},
    run_config::{SelfModelRun, model_preset},
};
use crate::train::config::TrainLog;

/// The lookup table's config. Presets: `paper` (100x100), `quick` (32x32).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NearestPose {
    /// Output image size `[height, width]`.
    pub image: [usize; 2],
}

impl Preset for NearestPose {
    fn paper() -> Self {
        NearestPose { image: [100, 100] }
    }

    fn quick() -> Self {
        NearestPose { image: [32, 32] }
    }
}

/// The training samples, on the host.
pub struct Table {
    angles: Vec<Vec<f32>>,
    silhouettes: Vec<f32>,
    depth: Vec<f32>,
    size: [usize; 2],
    device: burn::tensor::Device,
}

impl Table {
    /// The index of the stored pose nearest `q` (degrees), skipping `skip`.
    fn nearest(&self, q: &[f32], skip: Option<usize>) -> usize {
        let mut best = (f32::INFINITY, 0);
        for (i, a) in self.angles.iter().enumerate() {
            if Some(i) == skip {
                continue;
            }
            let d: f32 = a.iter().zip(q).map(|(x, y)| (x - y) * (x - y)).sum();
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    }
}

impl Render for Table {
    fn render(&self, angles: Tensor<2>) -> (Tensor<4>, Option<Tensor<4>>) {
        let [n, dof] = angles.dims();
        let q = angles
            .into_data()
            .try_into_vec::<f32>()
            .expect("float angles");
        let px = self.size[0] * self.size[1];
        let (mut sil, mut depth) = (Vec::with_capacity(n * px), Vec::with_capacity(n * px));
        for row in q.chunks(dof.max(1)) {
            let i = self.nearest(row, None);
            sil.extend_from_slice(&self.silhouettes[i * px..(i + 1) * px]);
            depth.extend_from_slice(&self.depth[i * px..(i + 1) * px]);
        }
        let shape = [n, 1, self.size[0], self.size[1]];
        let tensor = |v: Vec<f32>| Tensor::from_data(TensorData::new(v, shape), &self.device);
        (tensor(sil), Some(tensor(depth)))
    }
}

/// Not differentiable here, no chain of its own: nothing for reading the body back.
impl BodyFit for Table {}

impl SelfModel for NearestPose {
    const KIND: &'static str = "nearest_pose";
    type Renderer = Table;

    fn image(&self) -> [usize; 2] {
        self.image
    }

    /// Store the training set; the "training loss" is the leave-one-out MSE of the lookup on
    /// the training silhouettes.
    fn fit(&self, fit: &Fit) -> Result<Trained<Table>> {
        let start = std::time::Instant::now();
        let host = |t: &Tensor<4>| t.clone().into_data().try_into_vec::<f32>().expect("float");
        let [n, dof] = fit.train_set.inputs.dims();
        let angles = fit
            .train_set
            .inputs
            .clone()
            .into_data()
            .try_into_vec::<f32>()
            .expect("float angles");
        let table = Table {
            angles: angles.chunks(dof.max(1)).map(<[f32]>::to_vec).collect(),
            silhouettes: host(&fit.train_set.targets[0]),
            depth: host(&fit.train_set.targets[1]),
            size: self.image,
            device: fit.device.clone(),
        };
        let px = self.image[0] * self.image[1];
        let sil = |i: usize| &table.silhouettes[i * px..(i + 1) * px];
        let loo = (0..n)
            .map(|i| {
                let j = table.nearest(&table.angles[i], Some(i));
                sil(i)
                    .iter()
                    .zip(sil(j))
                    .map(|(a, b)| ((a - b) as f64).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / (n * px).max(1) as f64;
        let parameters = table.angles.len() * (dof + 2 * px);
        Ok(Trained::one(
            table,
            parameters,
            TrainLog {
                step: 1,
                curve: vec![(1, loo)],
                train_seconds: start.elapsed().as_secs_f64(),
                images: n,
                resumed_from: None,
            },
        ))
    }
}

/// NearestPose's run on `preset`: one pass that stores the training set.
pub fn nearest_pose_run(preset: &str) -> Result<SelfModelRun<NearestPose>> {
    let mut model = NearestPose::preset(model_preset(preset))?;
    model.image = SelfModelRun::<NearestPose>::image(preset)?;
    let mut run = SelfModelRun::new(preset, "NearestPose", model, 256)?;
    run.note = "a lookup table: the training images of the nearest training pose".into();
    run.train.steps = 1;
    run.train.batch = run.data.dataset.train;
    Ok(run)
}
