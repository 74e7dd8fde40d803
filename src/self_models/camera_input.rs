//! A camera as a model input: its pose as 9 numbers (the eye and the continuous 6-D rotation),
//! and multi-view datasets split into views.

use std::ops::Range;

use burn::tensor::Tensor;

use crate::core::error::{Error, Result};
use crate::sim::camera::Camera;

/// What a camera-conditioned model reads of a camera: its pose as 9 numbers, the eye
/// position and the first two columns of its rotation (right and up: the continuous 6-D
/// representation of a rotation, Zhou et al., CVPR 2019; Euler angles and quaternions jump),
/// times [`CAMERA_INPUT_SCALE`] so that they span what the joint angles in degrees span.
pub fn camera_input(camera: &Camera) -> [f32; 9] {
    camera.to_vector().map(|v| (v * CAMERA_INPUT_SCALE) as f32)
}

/// The camera a [`camera_input`] describes (its rotation made orthonormal again), with the
/// field of view and image size of `like`.
pub fn camera_from_input(v: &[f32], like: &Camera) -> Result<Camera> {
    let v: [f64; 9] = std::array::from_fn(|i| f64::from(v[i]) / CAMERA_INPUT_SCALE);
    Camera::from_vector(&v, like)
}

/// Host input rows `[n, width]` split into runs of consecutive rows seen from one camera:
/// `width = dof + 9` rows end with their camera's [`camera_input`]; `width = dof` rows are
/// all seen from `own` (one run). How a 3-D model renders a multi-view batch.
pub fn views_of_rows(
    inputs: &[f32],
    width: usize,
    dof: usize,
    own: &Camera,
) -> Result<Vec<(Range<usize>, Camera)>> {
    let n = inputs.len() / width.max(1);
    if width == dof {
        return Ok(vec![(0..n, own.clone())]);
    }
    if width != dof + 9 {
        return Err(Error::Config(format!(
            "inputs of {width} values per sample: expected the robot's {dof} joint values, optionally followed by 9 of a camera"
        )));
    }
    let camera_of = |i: usize| &inputs[i * width + dof..(i + 1) * width];
    let mut runs: Vec<(Range<usize>, Camera)> = Vec::new();
    let mut start = 0;
    for i in 1..=n {
        if i == n || camera_of(i) != camera_of(start) {
            runs.push((start..i, camera_from_input(camera_of(start), own)?));
            start = i;
        }
    }
    Ok(runs)
}

/// [`views_of_rows`] on a device batch: each run's joint angles `[rows, dof]` with its camera
/// (`inputs` of `dof` columns: one run, seen from `own`, read without leaving the device).
pub fn split_views(
    inputs: &Tensor<2>,
    dof: usize,
    own: &Camera,
) -> Result<Vec<(Tensor<2>, Camera)>> {
    let [_, width] = inputs.dims();
    if width == dof {
        return Ok(vec![(inputs.clone(), own.clone())]);
    }
    let host = inputs
        .clone()
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| Error::Config(format!("camera inputs: {e:?}")))?;
    Ok(views_of_rows(&host, width, dof, own)?
        .into_iter()
        .map(|(rows, camera)| (inputs.clone().slice([rows, 0..dof]), camera))
        .collect())
}

/// Camera inputs are the pose vector times this (eye in centimetres, rotation entries in
/// [-100, 100]): the joint angles' scale in degrees.
pub const CAMERA_INPUT_SCALE: f64 = 100.0;
