//! A trained self-model saved for use outside its run: every self-model run writes
//! `model/` beside its results, and [`crate::self_models::loading::load`] (Python's
//! `SelfModel.load(dir)`) reads it back.
//!
//! - `model.json`: the format, the model's kind and configuration, its image size and inputs,
//!   the robot's joints, the data it was trained on (robot, camera, dataset: the run's
//!   fingerprint of them), the camera of its first image, its test scores, the revision;
//! - `model.bpk`: its weights, where its kind loads (`SelfModel::load`: every self-model but
//!   NearestPose, a lookup table of its training set), with their FNV-1a hash in `model.json`;
//! - `probe.npz`: the first test poses and what the run's own evaluation predicted for them.
//!   A loaded model must predict the same (to 1e-3: another machine sums in another order),
//!   or it is refused.

use std::path::Path;

use burn::tensor::Tensor;

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::input_file::file_fnv;
use crate::data::npz::{Array, write_npz};
use crate::eval::evaluation::Predictions;

/// The version of the format this code writes and reads.
pub const FORMAT: u32 = 1;

/// How many test poses the probe keeps.
pub const PROBE: usize = 4;

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
    /// Per joint input: rotational (degrees in the inputs, radians at the SI edge,
    /// [`crate::self_models::loading::LoadedSelfModel::predict_si`]) or prismatic (metres).
    /// Empty in files saved before it was recorded, or where the robot is not the dataset's:
    /// every joint input rotational.
    #[serde(default)]
    pub rotational: Vec<bool>,
    /// The robot, camera and dataset it was trained on (the run's fingerprint of its data).
    pub data: serde_json::Value,
    /// The camera of its first image: focal length (px) and camera-to-world matrix.
    pub focal: f64,
    pub camera_pose: [f64; 16],
    /// The camera it renders from (the dataset's first).
    pub camera: crate::sim::camera::Camera,
    /// What its renderer needs beside its weights to be rebuilt (K-3DGS: its Gaussians' count).
    #[serde(default)]
    pub state: serde_json::Value,
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
pub struct ToSave<'a> {
    /// The model's kind (`SelfModel::KIND`) and configuration.
    pub kind: &'a str,
    pub model: serde_json::Value,
    pub name: &'a str,
    /// Writes the renderer's weights to the path given and returns its state
    /// (`Render::save`); `None`: it saves none.
    pub save_weights: &'a dyn Fn(&Path) -> Result<Option<serde_json::Value>>,
    pub camera: crate::sim::camera::Camera,
    /// Per joint input, whether it is rotational (empty: not known).
    pub rotational: Vec<bool>,
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
pub fn save(dir: &Path, s: &ToSave) -> Result<SavedSelfModel> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let weights = dir.join("model.bpk");
    let state = (s.save_weights)(&weights)?;
    let weights_fnv = match state {
        Some(_) => Some(file_fnv(&weights)?),
        None => None,
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
        kind: s.kind.into(),
        name: s.name.into(),
        model: s.model.clone(),
        image: [h, w],
        inputs,
        joint_names: s.data.joint_names.clone(),
        rotational: s.rotational.clone(),
        data: s.data_fingerprint.clone(),
        focal: s.data.focal,
        camera_pose: s.data.poses.first().copied().unwrap_or_default(),
        camera: s.camera.clone(),
        state: state.unwrap_or_default(),
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
