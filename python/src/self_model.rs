//! `selfmodel.SelfModel`: a self-model a run saved, predicting images from joint values.

use std::path::PathBuf;

use numpy::{IntoPyArray, PyArray3};
use pyo3::prelude::*;

use crate::arrays::*;
use crate::calls::*;

/// A self-model a self-model run saved (its `model/` folder): joint values in, the robot's
/// silhouette (and depth, for a model that predicts it) out.
#[pyclass(name = "SelfModel", module = "selfmodel", frozen)]
pub(crate) struct PySelfModel {
    model: selfmodel::self_models::loading::LoadedSelfModel,
}

#[pymethods]
impl PySelfModel {
    /// Load a run's saved model: the run's folder (e.g. runs/neurokin) or its `model/`.
    /// Refused, with why, when its weights were changed or its kind keeps none.
    #[staticmethod]
    fn load(py: Python<'_>, model_dir: PathBuf) -> PyResult<Self> {
        guarded(|| {
            py.allow_threads(|| {
                let device =
                    selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu)?;
                selfmodel::self_models::loading::load(&model_dir, &device)
            })
            .map(|model| PySelfModel { model })
            .map_err(value_error)
        })
    }

    /// Its name in the results ("NeuroKin", "ResNeuroKin-D", ...).
    #[getter]
    fn name(&self) -> String {
        self.model.saved.name.clone()
    }

    /// The joints of an input row, in order.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.model.saved.joint_names.clone()
    }

    /// (height, width) of what it predicts.
    #[getter]
    fn image(&self) -> (usize, usize) {
        let [h, w] = self.model.saved.image;
        (h, w)
    }

    /// Values of an input row (the joints; then the camera's 9 for a camera-conditioned model).
    #[getter]
    fn inputs(&self) -> usize {
        self.model.saved.inputs
    }

    /// Everything its model.json says, as a dict (configuration, data, test scores, revision).
    #[getter]
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        guarded(|| {
            let text = serde_json::to_string(&self.model.saved).map_err(value_error)?;
            py.import("json")?.call_method1("loads", (text,))
        })
    }

    /// Joint values q (N, inputs), radians (metres for a prismatic joint; a camera-conditioned
    /// model's camera inputs as they are) -> silhouette probabilities (N, H, W) float32 in
    /// [0, 1], and depth (N, H, W) float32 in metres for a model that predicts it (else None).
    fn predict<'py>(
        &self,
        py: Python<'py>,
        q: Matrix,
    ) -> PyResult<(Bound<'py, PyArray3<f32>>, Option<Bound<'py, PyArray3<f32>>>)> {
        guarded(|| {
            let (n, v) = rows(q, self.model.saved.inputs, "q")?;
            let [h, w] = self.model.saved.image;
            if (n as u64) * (h * w) as u64 > 1 << 30 {
                return Err(value_error(format!(
                    "q: {n} images of {h}x{w}, more than the 2^30 pixels one call returns; call it in batches"
                )));
            }
            let inputs = self.model.saved.inputs;
            // Blocks of images, each with its depth map where the model predicts one.
            let predict = |rows: std::ops::Range<usize>| {
                let q = &v[rows.start * inputs..rows.end * inputs];
                Ok(vec![
                    self.model.predict_si(q, rows.len()).map_err(value_error)?,
                ])
            };
            let blocks = match n {
                0 => predict(0..0)?,
                _ => in_blocks(py, n, IMAGES_A_BLOCK, predict)?,
            };
            let s: Vec<f32> = blocks.iter().flat_map(|(s, _)| s.iter().copied()).collect();
            let d: Option<Vec<f32>> = blocks
                .iter()
                .map(|(_, d)| d.as_deref())
                .collect::<Option<Vec<&[f32]>>>()
                .map(|d| d.concat());
            let shape = |v: Vec<f32>| {
                numpy::ndarray::Array3::from_shape_vec((n, h, w), v)
                    .expect("n x h x w")
                    .into_pyarray(py)
            };
            Ok((shape(s), d.map(shape)))
        })
    }

    fn __repr__(&self) -> String {
        let [h, w] = self.model.saved.image;
        format!(
            "SelfModel({}, {} inputs -> {h}x{w}, test {:.2} dB, IoU {:.3})",
            self.model.saved.name,
            self.model.saved.inputs,
            self.model.saved.psnr_db_test,
            self.model.saved.iou_test
        )
    }
}
