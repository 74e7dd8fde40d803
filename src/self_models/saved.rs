//! A trained self-model saved for use outside its run: every self-model run writes
//! `model/` beside its results, and [`load`] (Python's `SelfModel.load(dir)`) reads it back.
//!
//! - `model.json`: the format, the model's kind and configuration, its image size and inputs,
//!   the robot's joints, the data it was trained on (robot, camera, dataset: the run's
//!   fingerprint of them), the camera of its first image, its test scores, the revision;
//! - `model.bpk`: its weights, where its kind loads ([`SelfModel::load`]; NeuroKin and its
//!   variants, ResNeuroKin-D), with their FNV-1a hash in `model.json`;
//! - `probe.npz`: the first test poses and what the run's own evaluation predicted for them.
//!   A loaded model must predict the same (to 1e-5), or it is refused.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::input_file::file_fnv;
use crate::data::npz::{Array, ArrayData, read_npz, write_npz};
use crate::eval::evaluation::Predictions;
use crate::self_models::harness::{Render, SelfModel};
use crate::self_models::neurokin::NeuroKinConfig;
use crate::self_models::resneurokin_d::ResNeuroKinDConfig;

/// The version of the format this code writes and reads.
pub const FORMAT: u32 = 1;

/// How many test poses the probe keeps.
const PROBE: usize = 4;

/// The kinds whose weights load, each with its loader: one line a kind.
fn loader(kind: &str) -> Option<Loader> {
    match kind {
        NeuroKinConfig::KIND => Some(load_as::<NeuroKinConfig>),
        ResNeuroKinDConfig::KIND => Some(load_as::<ResNeuroKinDConfig>),
        _ => None,
    }
}

type Loader =
    fn(&serde_json::Value, &Path, &Device) -> Result<Option<Box<dyn Render + Send + Sync>>>;

fn load_as<M: SelfModel + serde::de::DeserializeOwned>(
    config: &serde_json::Value,
    weights: &Path,
    device: &Device,
) -> Result<Option<Box<dyn Render + Send + Sync>>> {
    let model: M = serde_json::from_value(config.clone())
        .map_err(|e| Error::data(weights, format!("its model.json's configuration: {e}")))?;
    model.load(weights, device)
}

/// What `model.json` holds.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SavedSelfModel {
    pub format: u32,
    /// Which loader reads it ([`SelfModel::KIND`]).
    pub kind: String,
    /// Its name in the results ("NeuroKin", "NeuroKin (tree encoder)", ...).
    pub name: String,
    /// Its configuration, as its run's `config.json` holds it.
    pub model: serde_json::Value,
    /// `[height, width]` of what it predicts.
    pub image: [usize; 2],
    /// The values it takes per pose: the robot's joints (degrees, metres for prismatic
    /// joints), then the camera's 9 for a camera-conditioned model.
    pub inputs: usize,
    /// The robot's joints, in the order of the inputs (empty where the dataset did not say).
    pub joint_names: Vec<String>,
    /// The robot, camera and dataset it was trained on (the run's fingerprint of its data).
    pub data: serde_json::Value,
    /// The camera of its first image: focal length (px) and camera-to-world matrix.
    pub focal: f64,
    pub camera_pose: [f64; 16],
    /// Whether it predicts depth (metres) beside the silhouette.
    pub predicts_depth: bool,
    /// `model.bpk`'s FNV-1a hash; `None`: this kind saves no weights that load yet.
    pub weights_fnv: Option<String>,
    pub psnr_db_test: f64,
    pub iou_test: f64,
    pub preset: String,
    pub git_revision: String,
}

/// What the run hands over to be saved.
pub struct ToSave<'a, M: SelfModel> {
    pub model: &'a M,
    pub name: &'a str,
    pub renderer: &'a dyn Render,
    pub data: &'a crate::data::dataset::Dataset,
    pub data_fingerprint: serde_json::Value,
    /// The test inputs (on the rendering device) and the run's predictions for them.
    pub test_inputs: &'a Tensor<2>,
    pub predictions: &'a Predictions,
    pub psnr_db_test: f64,
    pub iou_test: f64,
    pub preset: &'a str,
    pub git_revision: &'a str,
}

/// Write `dir` (the run's `model/`).
pub fn save<M: SelfModel>(dir: &Path, s: &ToSave<M>) -> Result<SavedSelfModel> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let weights = dir.join("model.bpk");
    let weights_fnv = if s.renderer.save(&weights)? {
        Some(file_fnv(&weights)?)
    } else {
        None
    };
    let [n, inputs] = s.test_inputs.dims();
    let k = n.min(PROBE);
    let [h, w] = [s.data.height, s.data.width];
    let angles: Vec<f32> = s
        .test_inputs
        .clone()
        .slice([0..k, 0..inputs])
        .into_data()
        .iter::<f32>()
        .collect();
    let pixels = k * h * w;
    let mut arrays = vec![
        ("angles", Array::f32(&[k, inputs], angles)),
        (
            "silhouettes",
            Array::f32(&[k, h, w], s.predictions.silhouettes[..pixels].to_vec()),
        ),
    ];
    if let Some(depth) = &s.predictions.depth {
        arrays.push(("depth", Array::f32(&[k, h, w], depth[..pixels].to_vec())));
    }
    let named: Vec<(&str, &Array)> = arrays.iter().map(|(n, a)| (*n, a)).collect();
    write_npz(&dir.join("probe.npz"), &named)?;
    let saved = SavedSelfModel {
        format: FORMAT,
        kind: M::KIND.into(),
        name: s.name.into(),
        model: serde_json::to_value(s.model).expect("a model configuration serialises"),
        image: [h, w],
        inputs,
        joint_names: s.data.joint_names.clone(),
        data: s.data_fingerprint.clone(),
        focal: s.data.focal,
        camera_pose: s.data.poses.first().copied().unwrap_or_default(),
        predicts_depth: s.predictions.depth.is_some(),
        weights_fnv,
        psnr_db_test: s.psnr_db_test,
        iou_test: s.iou_test,
        preset: s.preset.into(),
        git_revision: s.git_revision.into(),
    };
    write_json(&dir.join("model.json"), &saved)?;
    Ok(saved)
}

/// A saved self-model, loaded.
pub struct LoadedSelfModel {
    pub saved: SavedSelfModel,
    pub renderer: Box<dyn Render + Send + Sync>,
    pub device: Device,
}

impl LoadedSelfModel {
    /// `[n, inputs]` poses (row-major, the joints' units) -> silhouette probabilities
    /// `[n, H, W]` and depth (metres) where the model predicts it, on the host.
    pub fn predict(&self, poses: &[f32], n: usize) -> Result<(Vec<f32>, Option<Vec<f32>>)> {
        let inputs = self.saved.inputs;
        if poses.len() != n * inputs {
            return Err(Error::Config(format!(
                "{} values for {n} poses of {inputs} inputs",
                poses.len()
            )));
        }
        if let Some(i) = poses.iter().position(|v| !v.is_finite()) {
            return Err(Error::Config(format!(
                "pose {}, input {}: {} is not a finite number",
                i / inputs,
                i % inputs,
                poses[i]
            )));
        }
        let q = Tensor::<2>::from_data(TensorData::new(poses.to_vec(), [n, inputs]), &self.device);
        let (s, d) = self.renderer.render(q);
        let host = |t: Tensor<4>| t.into_data().iter::<f32>().collect::<Vec<f32>>();
        Ok((host(s), d.map(host)))
    }
}

/// Load `dir` (a run's `model/`, or the run's folder holding it) onto `device`.
pub fn load(dir: &Path, device: &Device) -> Result<LoadedSelfModel> {
    let dir = if dir.join("model").join("model.json").is_file() {
        dir.join("model")
    } else {
        dir.to_path_buf()
    };
    let json = dir.join("model.json");
    let again = "run the self-model again to save it";
    let bytes = crate::core::input_file::read_regular(&json, "saved self-model", 16 << 20)
        .map_err(|e| Error::data(&json, format!("no saved self-model here ({e}); {again}")))?;
    let text = String::from_utf8_lossy(&bytes);
    let saved: SavedSelfModel = serde_json::from_str(&text)
        .map_err(|e| Error::data(&json, format!("not a saved self-model ({e}); {again}")))?;
    if saved.format != FORMAT {
        return Err(Error::data(
            &json,
            format!(
                "format {} (this build reads {FORMAT}); {again}",
                saved.format
            ),
        ));
    }
    let Some(expected) = &saved.weights_fnv else {
        return Err(Error::data(
            &json,
            format!(
                "{} saves no weights that load (NeuroKin and ResNeuroKin-D do)",
                saved.name
            ),
        ));
    };
    let weights = dir.join("model.bpk");
    if file_fnv(&weights)? != *expected {
        return Err(Error::data(
            &weights,
            format!(
                "differs from the weights saved with model.json (damaged or replaced); {again}"
            ),
        ));
    }
    let renderer = loader(&saved.kind)
        .map(|l| l(&saved.model, &weights, device))
        .transpose()?
        .flatten()
        .ok_or_else(|| {
            Error::data(
                &json,
                format!("a model of kind {:?} does not load", saved.kind),
            )
        })?;
    let loaded = LoadedSelfModel {
        saved,
        renderer,
        device: device.clone(),
    };
    check_probe(&loaded, &dir.join("probe.npz"))?;
    Ok(loaded)
}

/// The loaded model must predict for the probe's poses what the run predicted.
fn check_probe(model: &LoadedSelfModel, path: &Path) -> Result<()> {
    let arrays = read_npz(path)?;
    let get = |name: &str| -> Result<Vec<f32>> {
        match arrays.get(name).map(|a| &a.data) {
            Some(ArrayData::F32(v)) => Ok(v.clone()),
            _ => Err(Error::data(path, format!("no float32 array {name:?}"))),
        }
    };
    let angles = get("angles")?;
    let n = angles.len() / model.saved.inputs.max(1);
    let (s, d) = model.predict(&angles, n)?;
    let mut worst = max_abs_diff(&s, &get("silhouettes")?);
    if let Some(d) = d {
        worst = worst.max(max_abs_diff(&d, &get("depth")?));
    }
    if !(worst <= 1e-5) {
        return Err(Error::data(
            path,
            format!(
                "the loaded model predicts its probe poses {worst:.1e} away from what its run predicted; run the self-model again to save it"
            ),
        ));
    }
    Ok(())
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() {
        return f32::INFINITY;
    }
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}
