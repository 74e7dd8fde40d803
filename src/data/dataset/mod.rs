//! The self-modeling datasets: silhouettes, depth maps and joint angles of a robot seen by
//! a fixed camera (self-modeling paper, section IV-A).
//!
//! File format (`.npz`, the keys of the papers' PyTorch code plus ours):
//! - `images` (N, H, W) uint8, 0 or 255: the silhouette;
//! - `angles` (N, DOF) float64: joint values, degrees (metres for prismatic joints);
//! - `focal` () float64: focal length in pixels;
//! - `poses` (N, 4, 4) float64: camera-to-world matrix of each image (OpenGL axes);
//! - `depth` (N, H, W) float32: metres along the camera axis, 0 where empty;
//! - `n_train` () int64: the first `n_train` samples are the training split, the rest test.
//!   Files without `depth` or `n_train` (the papers') load with depth 0 and an 80/20 split.
//! - `joint_names` (DOF,) unicode: the joints of the columns of `angles`, in the robot's
//!   order (depth-first from the root); absent from the papers' files. A robot whose joints
//!   differ in names or order is refused for a dataset that names its joints.
//!
//! Splits are sequential, as in the paper: with a Lorenz trajectory, the test set is the
//! continuation of the training trajectory.
//!
//! The folder: `config` (how a dataset is made), `angles` (the joint vectors: sampled or read),
//! `render` (the images drawn, in blocks), `file` (the `.npz` format), `stats` (what the
//! stats JSON holds), `build` (render and save, as the `dataset` binary does).

mod angles;
mod build;
mod config;
mod file;
mod render;
mod stats;

pub use angles::{MAX_JOINT_VALUE, read_angles, sample_angles};
pub use build::{BuildReport, build_and_save};
pub use config::{CameraChoice, DatasetConfig, Framing, MAX_DATASET_BYTES, Views, swept_points};
pub use stats::{DatasetStats, JointStats, Summary};

use crate::core::error::{Error, Result};
use crate::sim::camera::Camera;

/// Images, depth maps and joint values of one robot from one camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// Joint values per sample (degrees for rotational joints).
    pub angles: Vec<Vec<f64>>,
    /// Silhouettes, `N * H * W`, 0 or 255.
    pub images: Vec<u8>,
    /// Depth maps, `N * H * W`, metres along the camera axis, 0 where empty.
    pub depth: Vec<f32>,
    pub width: usize,
    pub height: usize,
    /// Focal length (px).
    pub focal: f64,
    /// Camera-to-world matrix (row-major 4x4) of every image.
    pub poses: Vec<[f64; 16]>,
    /// The first `n_train` samples are the training split.
    pub n_train: usize,
    /// The joints of the columns of `angles` (empty where the file does not say).
    pub joint_names: Vec<String>,
}

impl Dataset {
    /// The camera that took sample `i` (its recorded pose, the focal length, the size).
    pub fn camera_of(&self, i: usize) -> Camera {
        Camera::from_record(&self.poses[i], self.focal, self.width, self.height)
    }

    /// Refuse a dataset in which the robot is out of view in most images (a camera that
    /// misses the robot), with what to do about it.
    pub fn check_in_view(&self) -> Result<()> {
        let empty = self.empty_images();
        if 2 * empty > self.len() {
            return Err(Error::Config(format!(
                "the robot is out of view in {empty} of {} images: aim the camera at it (`eye`, `target`, `fov`) or let it frame the robot (`view`)",
                self.len()
            )));
        }
        Ok(())
    }

    /// Images without a single robot pixel.
    pub fn empty_images(&self) -> usize {
        (0..self.len())
            .filter(|&i| self.image(i).iter().all(|&v| v == 0))
            .count()
    }

    pub fn len(&self) -> usize {
        self.angles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.angles.is_empty()
    }

    pub fn dof(&self) -> usize {
        self.angles.first().map_or(0, Vec::len)
    }

    /// Silhouette of sample `i` (`H * W`).
    pub fn image(&self, i: usize) -> &[u8] {
        let n = self.width * self.height;
        &self.images[i * n..(i + 1) * n]
    }

    /// Depth map of sample `i` (`H * W`).
    pub fn depth_map(&self, i: usize) -> &[f32] {
        let n = self.width * self.height;
        &self.depth[i * n..(i + 1) * n]
    }

    /// The camera the dataset records (the first image's pose, the focal length, the size).
    pub fn camera(&self) -> Camera {
        Camera::from_record(&self.poses[0], self.focal, self.width, self.height)
    }

    /// Indices of the training and test samples.
    pub fn split(&self) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        (0..self.n_train, self.n_train..self.len())
    }
}
