//! Loading a saved self-model ([`crate::self_models::saved`]) back: its kind's loader builds
//! the renderer and reads its weights, and the loaded model must predict its probe poses as its
//! run did.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};

use crate::core::error::{Error, Result};
use crate::core::input_file::file_fnv;
use crate::data::npz::{ArrayData, read_npz};
use crate::self_models::ffksm::Ffksm;
use crate::self_models::k3dgs::K3dgs;
use crate::self_models::link_splat::LinkSplatConfig;
use crate::self_models::mean_silhouette::MeanSilhouette;
use crate::self_models::neurokin::NeuroKinConfig;
use crate::self_models::resneurokin_d::ResNeuroKinDConfig;
use crate::self_models::saved::{FORMAT, SavedSelfModel};
use crate::self_models::{
    data_spec::DataSpec,
    model::{LoadContext, Loaded, Render, SelfModel},
};

/// The kinds whose weights load, each with its loader: one line a kind.
fn loader(kind: &str) -> Option<Loader> {
    match kind {
        NeuroKinConfig::KIND => Some(load_as::<NeuroKinConfig>),
        ResNeuroKinDConfig::KIND => Some(load_as::<ResNeuroKinDConfig>),
        K3dgs::KIND => Some(load_as::<K3dgs>),
        Ffksm::KIND => Some(load_as::<Ffksm>),
        LinkSplatConfig::KIND => Some(load_as::<LinkSplatConfig>),
        MeanSilhouette::KIND => Some(load_as::<MeanSilhouette>),
        _ => None,
    }
}

type Loader = fn(&SavedSelfModel, &Path, &Device) -> Result<Loaded>;

fn load_as<M: SelfModel + serde::de::DeserializeOwned>(
    saved: &SavedSelfModel,
    weights: &Path,
    device: &Device,
) -> Result<Loaded> {
    let model: M = serde_json::from_value(saved.model.clone())
        .map_err(|e| Error::data(weights, format!("its model.json's configuration: {e}")))?;
    // A model that hangs on the robot's chain gets the robot it was trained on, read again.
    let robot = if model.needs_robot() {
        let data: DataSpec = serde_json::from_value(saved.data.clone())
            .map_err(|e| Error::data(weights, format!("its model.json's data: {e}")))?;
        Some(data.robot.load()?)
    } else {
        None
    };
    let ctx = LoadContext {
        device,
        state: &saved.state,
        robot: robot.as_ref(),
        camera: &saved.camera,
    };
    model.load(weights, &ctx)
}

/// A saved self-model, loaded.
pub struct LoadedSelfModel {
    pub saved: SavedSelfModel,
    pub renderer: Box<dyn Render + Send + Sync>,
    pub device: Device,
}

impl LoadedSelfModel {
    /// [`Self::predict`] from joint values in SI units, as every other call of the library's
    /// edge takes them (radians, metres for a prismatic joint; the camera's 9 values of a
    /// camera-conditioned model as [`crate::self_models::camera_input::camera_input`] writes
    /// them): `[n, inputs]` row-major.
    pub fn predict_si(&self, q: &[f64], n: usize) -> Result<(Vec<f32>, Option<Vec<f32>>)> {
        let inputs = self.saved.inputs.max(1);
        let joints = self.joint_inputs();
        let poses: Vec<f32> = q
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let c = i % inputs;
                let rotational =
                    c < joints && self.saved.rotational.get(c).copied().unwrap_or(true);
                (if rotational { v.to_degrees() } else { v }) as f32
            })
            .collect();
        self.predict(&poses, n)
    }

    /// How many of the inputs are joint values (the rest: a camera's).
    pub fn joint_inputs(&self) -> usize {
        let s = &self.saved;
        if !s.rotational.is_empty() {
            s.rotational.len()
        } else if !s.joint_names.is_empty() {
            s.joint_names.len()
        } else {
            s.inputs
        }
    }

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
        // The same number of pixels in another shape would be a reshaped image, not an error.
        let [h, w] = self.saved.image;
        let drawn = s.dims();
        if drawn[2..] != [h, w] {
            return Err(Error::Config(format!(
                "model.json says {h}x{w} images, its weights draw {}x{}; run the self-model again to save it",
                drawn[2], drawn[3]
            )));
        }
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
        .map_err(|e| {
            if json.symlink_metadata().is_ok() {
                // There, but a FIFO, a device, a folder or too big: say which.
                Error::data(&json, e.to_string())
            } else {
                Error::data(&json, format!("no saved self-model here ({e}); {again}"))
            }
        })?;
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
        // A kind whose weights load always writes their hash: without one the file was edited.
        let msg = if loader(&saved.kind).is_some() {
            format!(
                "has no \"weights_fnv\" (the hash of model.bpk its run wrote): it was edited or damaged; {again}"
            )
        } else {
            format!(
                "{} saves no weights that load: it answers from its training set (a lookup table); every other self-model loads",
                saved.name
            )
        };
        return Err(Error::data(&json, msg));
    };
    let camera_inputs = saved.inputs.checked_sub(saved.joint_names.len());
    if !saved.joint_names.is_empty() && !matches!(camera_inputs, Some(0 | 9)) {
        return Err(Error::data(
            &json,
            format!(
                "names {} joints for {} inputs (the joints, then 9 for a camera-conditioned model); {again}",
                saved.joint_names.len(),
                saved.inputs
            ),
        ));
    }
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
        .map(|l| l(&saved, &weights, device))
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

/// The loaded model must predict for the probe's poses what the run predicted: a model whose
/// `model.json` does not match its weights (another image size, input count) fails here, as
/// does one that predicts NaN; a probe without poses is refused.
fn check_probe(model: &LoadedSelfModel, path: &Path) -> Result<()> {
    let again = "run the self-model again to save it";
    let arrays = read_npz(path)?;
    let get = |name: &str| -> Result<Vec<f32>> {
        match arrays.get(name).map(|a| &a.data) {
            Some(ArrayData::F32(v)) => Ok(v.clone()),
            _ => Err(Error::data(path, format!("no float32 array {name:?}"))),
        }
    };
    let angles = get("angles")?;
    let inputs = model.saved.inputs.max(1);
    let n = angles.len() / inputs;
    if n == 0 || angles.len() % inputs != 0 {
        return Err(Error::data(
            path,
            format!(
                "its \"angles\" hold {} values, not whole poses of {inputs} inputs; {again}",
                angles.len()
            ),
        ));
    }
    // A configuration that disagrees with the weights fails inside burn (a shape error).
    let (s, d) =
        crate::core::input_file::catch_panic(|| model.predict(&angles, n)).map_err(|e| {
            Error::data(
                path,
                format!("model.json does not describe the weights beside it ({e}); {again}"),
            )
        })??;
    // `predict` refused an image of another size than model.json says.
    let mut worst = max_abs_diff(&s, &get("silhouettes")?);
    if let Some(d) = d {
        worst = worst.max(max_abs_diff(&d, &get("depth")?));
    }
    if !(worst <= 1e-3) {
        return Err(Error::data(
            path,
            format!(
                "the loaded model predicts its probe poses {worst:.1e} away from what its run predicted; {again}"
            ),
        ));
    }
    Ok(())
}

/// The largest difference of `a` and `b`: infinite where their lengths differ or either holds
/// NaN (a NaN is never a match).
fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() {
        return f32::INFINITY;
    }
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(
            0.0,
            |m, d| {
                if d.is_nan() { f32::INFINITY } else { m.max(d) }
            },
        )
}
