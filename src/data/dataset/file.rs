//! The `.npz` format of a dataset (the module's header lists its keys): saved without a copy of
//! its images, loaded with every key, shape, dtype and value checked.

use std::path::Path;

use super::Dataset;
use crate::core::error::{Error, Result};
use crate::data::npz::{Array, ArrayData, ArrayView, DataView, read_npz, write_npz_views};

impl Dataset {
    /// Save as `.npz` (atomically; the images and depth maps are written without a copy).
    pub fn save(&self, path: &Path) -> Result<()> {
        let n = self.len();
        let (h, w) = (self.height, self.width);
        let view = |shape: &[usize], data| ArrayView {
            shape: shape.to_vec(),
            data,
        };
        let angles = self.angles.concat();
        let poses = self.poses.concat();
        let focal = [self.focal];
        let n_train = [self.n_train as i64];
        let mut arrays = vec![
            ("images", view(&[n, h, w], DataView::U8(&self.images))),
            ("angles", view(&[n, self.dof()], DataView::F64(&angles))),
            ("focal", view(&[], DataView::F64(&focal))),
            ("poses", view(&[n, 4, 4], DataView::F64(&poses))),
            ("depth", view(&[n, h, w], DataView::F32(&self.depth))),
            ("n_train", view(&[], DataView::I64(&n_train))),
        ];
        if !self.joint_names.is_empty() {
            let names = DataView::Text(&self.joint_names);
            arrays.push(("joint_names", view(&[self.joint_names.len()], names)));
        }
        write_npz_views(path, &arrays)
    }

    /// Load an `.npz` dataset, ours or the papers', checking keys, shapes, dtypes and values.
    pub fn load(path: &Path) -> Result<Self> {
        let mut arrays = read_npz(path)?;
        let bad = |msg: String| Error::data(path, msg);
        let mut take = |key: &str| {
            arrays
                .remove(key)
                .ok_or_else(|| bad(format!("missing key \"{key}\"")))
        };
        let images = take("images")?;
        let angles = take("angles")?;
        let focal = take("focal")?;
        let poses = take("poses")?;
        let depth = arrays.remove("depth");
        let n_train = arrays.remove("n_train");
        let joint_names = arrays.remove("joint_names");

        let [n, h, w] = images.shape[..] else {
            return Err(bad(format!(
                "\"images\" must have shape (N, H, W), found {:?}",
                images.shape
            )));
        };
        if n == 0 {
            return Err(bad("the dataset has zero samples".into()));
        }
        let ArrayData::U8(images) = images.data else {
            return Err(bad(format!(
                "\"images\" must be uint8, found {}",
                images.dtype_name()
            )));
        };
        let [na, dof] = angles.shape[..] else {
            return Err(bad(format!(
                "\"angles\" must have shape (N, DOF), found {:?}",
                angles.shape
            )));
        };
        if na != n {
            return Err(bad(format!(
                "\"angles\" has {na} rows but \"images\" has {n}"
            )));
        }
        if !matches!(angles.data, ArrayData::F64(_) | ArrayData::F32(_)) {
            return Err(bad(format!(
                "\"angles\" must be float, found {}",
                angles.dtype_name()
            )));
        }
        let flat = angles.to_f64();
        if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
            return Err(bad(format!(
                "\"angles\" row {} is NaN or infinite",
                i / dof
            )));
        }
        let angles: Vec<Vec<f64>> = flat.chunks(dof).map(<[f64]>::to_vec).collect();
        let focal = match focal.to_f64()[..] {
            [f] if f.is_finite() && f > 0.0 => f,
            _ => return Err(bad("\"focal\" must be one positive number".into())),
        };
        let pose_list = camera_poses(path, &poses, n)?;
        let depth = depth_maps(path, depth, [n, h, w])?;
        let n_train = match n_train {
            None => n * 4 / 5,
            Some(a) => match a.to_f64()[..] {
                [t] if t >= 0.0 && t as usize <= n => t as usize,
                _ => return Err(bad(format!("\"n_train\" must be one integer in 0..={n}"))),
            },
        };
        let joint_names = joint_names_of(path, joint_names, dof)?;
        Ok(Dataset {
            angles,
            images,
            depth,
            width: w,
            height: h,
            focal,
            poses: pose_list,
            n_train,
            joint_names,
        })
    }
}

/// A dataset's `poses`: one 4x4 camera pose for all `n` samples or one each, finite.
fn camera_poses(path: &Path, poses: &Array, n: usize) -> Result<Vec<[f64; 16]>> {
    let bad = |msg: String| Error::data(path, msg);
    if matches!(poses.data, ArrayData::Text(_)) {
        return Err(bad("\"poses\" must be float, found unicode text".into()));
    }
    if let Some(i) = poses.to_f64().iter().position(|v| !v.is_finite()) {
        return Err(bad(format!(
            "\"poses\" holds NaN or infinity (camera {})",
            i / 16
        )));
    }
    Ok(match poses.shape[..] {
        [4, 4] => vec![std::array::from_fn(|i| poses.to_f64()[i]); n],
        [np, 4, 4] if np == n => poses
            .to_f64()
            .chunks(16)
            .map(|c| std::array::from_fn(|i| c[i]))
            .collect(),
        _ => {
            return Err(bad(format!(
                "\"poses\" must have shape (N, 4, 4) or (4, 4), found {:?}",
                poses.shape
            )));
        }
    })
}

/// A dataset's `depth` (metres along the camera axis, 0 where empty) of shape `[n, h, w]`, or
/// zeros where it has none.
fn depth_maps(path: &Path, depth: Option<Array>, [n, h, w]: [usize; 3]) -> Result<Vec<f32>> {
    let bad = |msg: String| Error::data(path, msg);
    Ok(match depth {
        None => vec![0.0; n * h * w],
        Some(d) => {
            if d.shape != [n, h, w] {
                return Err(bad(format!(
                    "\"depth\" must have shape {:?}, found {:?}",
                    [n, h, w],
                    d.shape
                )));
            }
            let v: Vec<f32> = match d.data {
                ArrayData::F32(v) => v,
                ArrayData::F64(v) => v.into_iter().map(|x| x as f32).collect(),
                _ => {
                    return Err(bad(format!(
                        "\"depth\" must be float32, found {}",
                        d.dtype_name()
                    )));
                }
            };
            if let Some(i) = v.iter().position(|d| !(d.is_finite() && *d >= 0.0)) {
                return Err(bad(format!(
                    "\"depth\" of sample {} is {}: depth is metres along the camera axis, 0 where empty",
                    i / (h * w),
                    v[i]
                )));
            }
            v
        }
    })
}

/// A dataset's `joint_names`: `dof` distinct strings, or none.
fn joint_names_of(path: &Path, names: Option<Array>, dof: usize) -> Result<Vec<String>> {
    let bad = |msg: String| Error::data(path, msg);
    Ok(match names {
        None => Vec::new(),
        Some(Array {
            data: ArrayData::Text(names),
            shape,
        }) if shape == [dof] => {
            if let Some(i) = (1..dof).find(|&i| names[..i].contains(&names[i])) {
                return Err(bad(format!("\"joint_names\" names \"{}\" twice", names[i])));
            }
            names
        }
        Some(a) => {
            return Err(bad(format!(
                "\"joint_names\" must be {dof} strings (one per column of \"angles\"), found {} of shape {:?}",
                a.dtype_name(),
                a.shape
            )));
        }
    })
}
