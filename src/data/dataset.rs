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

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::core::provenance::git_revision;
use indicatif::ProgressBar;

use crate::data::npz::{Array, ArrayData, ArrayView, DataView, read_npz, write_npz_views};
use crate::sim::camera::Camera;
use crate::sim::ray_caster::{RayCaster, RenderOptions};
use crate::sim::robot::Robot;
use crate::sim::trajectory::{SamplerKind, babbling, grid, lorenz};

/// How a dataset is made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetConfig {
    /// Preset name this config started from.
    pub preset: String,
    /// Number of samples.
    pub samples: usize,
    /// Training samples (the first ones); the rest are the test set.
    pub train: usize,
    pub sampler: SamplerKind,
    /// Step of the grid sampler, degrees.
    pub grid_step_deg: f64,
    /// Seed of the random samplers.
    pub seed: u64,
    pub camera: Camera,
    /// Frame the robot automatically: `camera`'s eye and target are replaced by a camera
    /// looking at the centre of the volume the robot sweeps over the sampled poses, from
    /// `framing.view`, at the distance that fits it ([`Camera::framing`]). `None`: `camera`
    /// as it is (the papers' arm keeps the papers' camera).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub framing: Option<Framing>,
    pub render: RenderOptions,
    /// Every pose seen from several cameras around the robot ([`Views::cameras`]; `samples`
    /// and `train` then count poses, each giving one image per camera). `None`: `camera`
    /// alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub views: Option<Views>,
}

/// Cameras on a sphere around what a camera looks at, for multi-view datasets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Views {
    /// How many cameras.
    pub cameras: usize,
    /// Their distance from the target (`None`: the camera's own).
    #[serde(default)]
    pub radius: Option<f64>,
    /// Elevations above the horizontal plane through the target (degrees): even-numbered
    /// cameras at the first, odd-numbered at the second.
    pub elevation_deg: [f64; 2],
}

impl Views {
    /// `self.cameras` copies of `camera` at yaws `360 i / n` degrees from `camera`'s own
    /// about the world z axis through its target, camera `i` at elevation
    /// `elevation_deg[i % 2]`, all looking at `camera`'s target: with `elevation_deg[0]` the
    /// camera's own elevation, camera 0 is `camera` (for an upright camera).
    pub fn around(&self, camera: &Camera) -> Vec<Camera> {
        let (yaw0, _, distance) = camera.spherical();
        let radius = self.radius.unwrap_or(distance);
        (0..self.cameras)
            .map(|i| {
                let yaw = yaw0 + std::f64::consts::TAU * i as f64 / self.cameras as f64;
                camera.looking_from(
                    camera.target,
                    radius,
                    yaw,
                    self.elevation_deg[i % 2].to_radians(),
                )
            })
            .collect()
    }
}

/// How a camera frames a robot automatically.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Framing {
    /// Direction from the robot towards the camera (need not be unit length).
    pub view: [f64; 3],
    /// Fraction of the half-image kept free at the border.
    pub margin: f64,
}

impl Default for Framing {
    /// From the front right (+x, +y), a little above: an oblique view, in which fewer joint
    /// motions are hidden than in a view along an axis; 5% margin.
    fn default() -> Self {
        Framing {
            view: [1.0, 0.6, 0.4],
            margin: 0.05,
        }
    }
}

/// Points a camera must keep in view for `robot` at the joint vectors `si` (SI): the corners
/// of each link's bounding boxes two levels into its tree, at every pose.
pub fn swept_points(robot: &Robot, si: &[Vec<f64>]) -> Vec<nalgebra::Point3<f64>> {
    let outlines: Vec<Vec<nalgebra::Point3<f64>>> =
        robot.geometry.iter().map(|g| g.outline(2)).collect();
    let mut points = Vec::new();
    for q in si {
        for (frame, outline) in robot.link_frames(q).iter().zip(&outlines) {
            points.extend(outline.iter().map(|p| frame * p));
        }
    }
    points
}

impl Preset for DatasetConfig {
    /// The paper's dataset: 2,000 Lorenz samples, 1,600 train and 400 test.
    fn paper() -> Self {
        DatasetConfig {
            preset: "paper".into(),
            samples: 2000,
            train: 1600,
            sampler: SamplerKind::Lorenz,
            grid_step_deg: 9.0,
            seed: 0,
            camera: Camera::paper(),
            framing: None,
            views: None,
            render: RenderOptions::default(),
        }
    }

    /// Tiny, for tests: 40 samples, 32 train.
    fn quick() -> Self {
        DatasetConfig {
            preset: "quick".into(),
            samples: 40,
            train: 32,
            ..Self::paper()
        }
    }
}

impl DatasetConfig {
    /// The camera the dataset renders with: `camera`, or with `framing` the camera that
    /// frames `robot` over the joint vectors `si` (SI).
    pub fn camera_for(&self, robot: &Robot, si: &[Vec<f64>]) -> Result<Camera> {
        match &self.framing {
            None => Ok(self.camera.clone()),
            Some(f) => self
                .camera
                .framing(&swept_points(robot, si), f.view, f.margin),
        }
    }

    /// The cameras [`Dataset::generate`] renders `robot` with, in the order it records them
    /// (one; or with `views`, one per view), without rendering.
    pub fn cameras(&self, robot: &Robot) -> Result<Vec<Camera>> {
        let angles = sample_angles(robot, self)?;
        let si: Vec<Vec<f64>> = angles.iter().map(|q| robot.chain.to_si(q)).collect();
        let camera = self.camera_for(robot, &si)?;
        Ok(match &self.views {
            Some(views) => views.around(&camera),
            None => vec![camera],
        })
    }

    /// Reject impossible settings.
    pub fn validate(&self) -> Result<()> {
        if self.samples == 0 {
            return Err(Error::Config(
                "the dataset needs at least 1 sample (--samples)".into(),
            ));
        }
        // Silhouettes (1 byte) and depth (4 bytes) per pixel are held in memory while the
        // dataset is built: bound them by what a 24 GiB machine holds with room to spare.
        let pixels = (self.camera.width as u128) * (self.camera.height as u128);
        if self.views.as_ref().is_some_and(|v| v.cameras == 0) {
            return Err(Error::Config(
                "a multi-view dataset needs at least 1 camera (--cameras)".into(),
            ));
        }
        let images = self.samples * self.views.as_ref().map_or(1, |v| v.cameras);
        let bytes = pixels * 5 * images as u128;
        if bytes > MAX_DATASET_BYTES as u128 {
            return Err(Error::Config(format!(
                "{} images of {}x{} pixels need {:.1} GiB in memory, above the {} GiB limit; lower --samples or --size",
                images,
                self.camera.width,
                self.camera.height,
                bytes as f64 / (1u64 << 30) as f64,
                MAX_DATASET_BYTES >> 30
            )));
        }
        if self.train > self.samples {
            return Err(Error::Config(format!(
                "impossible split: {} training samples out of {} (--train must be at most --samples)",
                self.train, self.samples
            )));
        }
        self.camera.validate()
    }
}

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

/// Joint vectors (user units) for a config, from its sampler.
pub fn sample_angles(robot: &Robot, cfg: &DatasetConfig) -> Result<Vec<Vec<f64>>> {
    // Before anything is drawn: a sample count the images could never fit is refused now,
    // not after drawing its joint vectors.
    cfg.validate()?;
    let ranges = robot.chain.joint_ranges_user();
    match cfg.sampler {
        SamplerKind::Lorenz => lorenz(cfg.samples, &ranges),
        SamplerKind::Babbling => Ok(babbling(cfg.samples, &ranges, cfg.seed)),
        SamplerKind::Grid => {
            // Degrees for rotational joints; a prismatic joint's range in as many steps as
            // +-90 degrees would take.
            let steps: Vec<f64> = robot
                .chain
                .movable_joints()
                .zip(&ranges)
                .map(|(j, r)| {
                    if j.kind.is_rotational() {
                        cfg.grid_step_deg
                    } else {
                        (r[1] - r[0]).max(1e-9) * cfg.grid_step_deg / 180.0
                    }
                })
                .collect();
            let points = grid(cfg.samples, &ranges, &steps, cfg.seed)?;
            if points.len() < cfg.samples {
                return Err(Error::Config(format!(
                    "a grid step of {} degrees gives {} joint vectors, fewer than the {} samples asked: lower --grid-step or ask fewer --samples",
                    cfg.grid_step_deg,
                    points.len(),
                    cfg.samples
                )));
            }
            Ok(points)
        }
    }
}

impl Dataset {
    /// Render `angles` (user units, one row per sample) with `cfg`'s camera and options.
    pub fn render(
        robot: &Robot,
        cfg: &DatasetConfig,
        angles: Vec<Vec<f64>>,
        progress: Option<&ProgressBar>,
    ) -> Result<Self> {
        // The configuration's own limits first, then what this machine holds.
        cfg.validate()?;
        check_memory(cfg)?;
        if angles.len() != cfg.samples {
            return Err(Error::Config(format!(
                "{} joint vectors for {} samples",
                angles.len(),
                cfg.samples
            )));
        }
        let si: Vec<Vec<f64>> = angles.iter().map(|q| robot.chain.to_si(q)).collect();
        let camera = cfg.camera_for(robot, &si)?;
        if let Some(views) = &cfg.views {
            return Self::render_views(
                robot,
                &angles,
                &views.around(&camera),
                cfg.train,
                &cfg.render,
            );
        }
        let caster = RayCaster::new(robot, camera.clone(), cfg.render.clone());
        let (w, h) = (cfg.camera.width, cfg.camera.height);
        let mut images = Vec::with_capacity(si.len() * w * h);
        let mut depth = Vec::with_capacity(si.len() * w * h);
        // In blocks, each copied in as it is rendered (the frames of the whole set are never
        // held twice), with Ctrl-C asked between blocks: a fraction of a second apart.
        for (b, block) in si.chunks(RENDER_BLOCK).enumerate() {
            if crate::core::interrupt::requested() {
                return Err(Error::Interrupted(format!(
                    "stopped after {} of {} images; nothing was written",
                    b * RENDER_BLOCK,
                    si.len()
                )));
            }
            for f in caster.render_batch(block, progress) {
                images.extend_from_slice(&f.silhouette);
                depth.extend_from_slice(&f.depth);
            }
        }
        let pose = camera.pose_matrix();
        let pose: [f64; 16] = std::array::from_fn(|i| pose[(i / 4, i % 4)]);
        Ok(Dataset {
            angles,
            images,
            depth,
            width: w,
            height: h,
            focal: camera.focal_px(),
            poses: vec![pose; cfg.samples],
            n_train: cfg.train,
            joint_names: robot.chain.joint_names(),
        })
    }

    /// Every pose of `angles` (user units) seen by every camera of `cameras`: sample
    /// `pose * cameras.len() + c` is pose `pose` from camera `c`, its camera recorded under
    /// `poses` (as every dataset records its camera); the first `train_poses` poses, each from
    /// every camera, are the training samples. The cameras share one focal length and image
    /// size (the first's).
    pub fn render_views(
        robot: &Robot,
        angles: &[Vec<f64>],
        cameras: &[Camera],
        train_poses: usize,
        render: &RenderOptions,
    ) -> Result<Self> {
        let Some(first) = cameras.first() else {
            return Err(Error::Config("a multi-view dataset needs a camera".into()));
        };
        if let Some(c) = cameras.iter().find(|c| {
            c.width != first.width || c.height != first.height || c.fov_deg != first.fov_deg
        }) {
            return Err(Error::Config(format!(
                "every camera of a dataset has one image size and field of view: {}x{} at {} deg and {}x{} at {} deg",
                first.width, first.height, first.fov_deg, c.width, c.height, c.fov_deg
            )));
        }
        if train_poses > angles.len() {
            return Err(Error::Config(format!(
                "{train_poses} training poses of {}",
                angles.len()
            )));
        }
        for c in cameras {
            c.validate()?;
        }
        let si: Vec<Vec<f64>> = angles.iter().map(|q| robot.chain.to_si(q)).collect();
        let frames: Vec<Vec<crate::sim::ray_caster::Frame>> = cameras
            .iter()
            .map(|c| RayCaster::new(robot, c.clone(), render.clone()).render_batch(&si, None))
            .collect();
        let (w, h) = (first.width, first.height);
        let n = angles.len() * cameras.len();
        let (mut images, mut depth) =
            (Vec::with_capacity(n * w * h), Vec::with_capacity(n * w * h));
        let (mut all_angles, mut poses) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for (p, q) in angles.iter().enumerate() {
            for (c, camera) in cameras.iter().enumerate() {
                let f = &frames[c][p];
                images.extend_from_slice(&f.silhouette);
                depth.extend_from_slice(&f.depth);
                all_angles.push(q.clone());
                let m = camera.pose_matrix();
                poses.push(std::array::from_fn(|i| m[(i / 4, i % 4)]));
            }
        }
        Ok(Dataset {
            angles: all_angles,
            images,
            depth,
            width: w,
            height: h,
            focal: first.focal_px(),
            poses,
            n_train: train_poses * cameras.len(),
            joint_names: robot.chain.joint_names(),
        })
    }

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
                "the robot is out of view in {empty} of {} images: aim the camera at it (--eye, --target, --fov) or let it frame the robot (--view X,Y,Z)",
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

    /// Sample joint vectors with the config's sampler and render them.
    pub fn generate(
        robot: &Robot,
        cfg: &DatasetConfig,
        progress: Option<&ProgressBar>,
    ) -> Result<Self> {
        // `render` validates the config.
        let angles = sample_angles(robot, cfg)?;
        Self::render(robot, cfg, angles, progress)
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

    /// Summary statistics (the stats JSON beside a dataset).
    pub fn stats(&self, joint_names: &[String]) -> DatasetStats {
        let n = self.len();
        let occ: Vec<f64> = (0..n)
            .map(|i| {
                self.image(i).iter().filter(|&&v| v >= 128).count() as f64
                    / (self.width * self.height) as f64
            })
            .collect();
        let summary = |v: &[f64]| {
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64;
            Summary {
                min: v.iter().cloned().fold(f64::INFINITY, f64::min),
                max: v.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
                mean,
                std: var.sqrt(),
            }
        };
        let joints = (0..self.dof())
            .map(|j| {
                let col: Vec<f64> = self.angles.iter().map(|q| q[j]).collect();
                JointStats {
                    name: joint_names
                        .get(j)
                        .cloned()
                        .unwrap_or_else(|| format!("joint{j}")),
                    degrees: summary(&col),
                }
            })
            .collect();
        let hits: Vec<f64> = self
            .depth
            .iter()
            .filter(|&&d| d > 0.0)
            .map(|&d| d as f64)
            .collect();
        let (w, h) = (self.width, self.height);
        let on_border = |img: &[u8]| {
            (0..w).any(|c| img[c] > 0 || img[(h - 1) * w + c] > 0)
                || (0..h).any(|r| img[r * w] > 0 || img[r * w + w - 1] > 0)
        };
        let border_images = (0..n).filter(|&i| on_border(self.image(i))).count();
        let empty_images = (0..n)
            .filter(|&i| self.image(i).iter().all(|&v| v == 0))
            .count();
        DatasetStats {
            border_images,
            empty_images,
            samples: n,
            train: self.n_train,
            test: n - self.n_train,
            width: self.width,
            height: self.height,
            focal_px: self.focal,
            occupancy: summary(&occ),
            joints,
            depth_m: if hits.is_empty() {
                None
            } else {
                Some(summary(&hits))
            },
        }
    }
}

/// Min, max, mean and standard deviation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub std: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointStats {
    pub name: String,
    pub degrees: Summary,
}

/// What the stats JSON holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetStats {
    pub samples: usize,
    pub train: usize,
    pub test: usize,
    pub width: usize,
    pub height: usize,
    pub focal_px: f64,
    /// Fraction of robot pixels per image.
    pub occupancy: Summary,
    pub joints: Vec<JointStats>,
    /// Depth of robot pixels (m).
    pub depth_m: Option<Summary>,
    /// Images in which the robot touches the image border (it may be cut off), and those in
    /// which it is not seen at all.
    #[serde(default)]
    pub border_images: usize,
    #[serde(default)]
    pub empty_images: usize,
}

/// The most memory a dataset's images may take (silhouettes and depth): 8 GiB.
pub const MAX_DATASET_BYTES: u64 = 8 << 30;

/// Bytes a pixel of a dataset takes at the peak of building and saving it: its silhouette and
/// depth (5 bytes), and their copies as the arrays are encoded (measured: 7.4 GB of resident
/// memory for 50,000 images of 100x100).
const PEAK_BYTES_PER_PIXEL: u64 = 15;

/// Refuse a dataset this machine cannot hold while it is built and saved, in one line, where
/// it would abort allocating (the machine's available memory, from `/proc/meminfo`).
fn check_memory(cfg: &DatasetConfig) -> Result<()> {
    let images = cfg.samples * cfg.views.as_ref().map_or(1, |v| v.cameras);
    let pixels = (cfg.camera.width * cfg.camera.height) as u64;
    let needed = pixels * images as u64 * PEAK_BYTES_PER_PIXEL;
    let Some(available) = crate::core::memory::available_bytes() else {
        return Ok(());
    };
    if needed > available {
        let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
        return Err(Error::Config(format!(
            "{images} images of {}x{} need about {:.1} GiB while they are built and saved; this machine has {:.1} GiB available: lower --samples or --size",
            cfg.camera.width,
            cfg.camera.height,
            gib(needed),
            gib(available)
        )));
    }
    Ok(())
}

/// Images rendered between two looks at Ctrl-C.
const RENDER_BLOCK: usize = 64;

/// The largest joint value [`read_angles`] takes: one turn, in degrees.
pub const MAX_JOINT_VALUE: f64 = 360.0;

/// Read joint vectors (user units) from a CSV (one row per pose, one column per joint, an
/// optional header) or an `.npz` with an `angles` (N, DOF) array. Checks the column count
/// and that every value is finite.
pub fn read_angles(path: &Path, dof: usize) -> Result<Vec<Vec<f64>>> {
    let bad = |msg: String| Error::data(path, msg);
    let rows: Vec<Vec<f64>> = if path.extension().is_some_and(|e| e == "npz") {
        let mut arrays = read_npz(path)?;
        let a = arrays
            .remove("angles")
            .ok_or_else(|| bad("missing key \"angles\"".into()))?;
        let [_, cols] = a.shape[..] else {
            return Err(bad(format!(
                "\"angles\" must have shape (N, {dof}), found {:?}",
                a.shape
            )));
        };
        if cols == 0 {
            return Err(bad("\"angles\" has no columns".into()));
        }
        a.to_f64().chunks(cols).map(<[f64]>::to_vec).collect()
    } else {
        let max = crate::core::input_file::MAX_TABLE_BYTES;
        crate::core::input_file::check_user_file(path, "angles file", max)?;
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(file);
        let mut rows = Vec::new();
        for (i, rec) in reader.records().enumerate() {
            if i % crate::core::interrupt::ROWS_BETWEEN_CHECKS == 0 {
                crate::core::interrupt::check(|| {
                    format!("stopped reading {} at line {}", path.display(), i + 1)
                })?;
            }
            let rec = rec.map_err(|e| bad(format!("line {}: {e}", i + 1)))?;
            let line = rec.iter().collect::<Vec<_>>().join(",");
            if rec.len() == 1 && [';', '\t', ' '].iter().any(|c| line.contains(*c)) {
                return Err(bad(format!(
                    "line {}: \"{line}\" is one field; separate the joints with commas",
                    i + 1
                )));
            }
            let parsed: Vec<Option<f64>> = rec.iter().map(|f| f.parse::<f64>().ok()).collect();
            // A header is a first line of names only: a line with one bad number is a typo.
            if i == 0 && parsed.iter().all(Option::is_none) {
                continue;
            }
            match parsed.into_iter().collect::<Option<Vec<f64>>>() {
                Some(v) => rows.push(v),
                None => {
                    return Err(bad(format!(
                        "line {}: not a list of numbers: \"{line}\"",
                        i + 1
                    )));
                }
            }
        }
        rows
    };
    if rows.is_empty() {
        return Err(bad("no joint vectors (zero samples)".into()));
    }
    for (i, r) in rows.iter().enumerate() {
        if r.len() != dof {
            return Err(bad(format!(
                "row {} has {} values, the robot has {dof} joints",
                i + 1,
                r.len()
            )));
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("row {} has a NaN or infinite angle", i + 1)));
        }
        if let Some(v) = r.iter().find(|v| v.abs() > MAX_JOINT_VALUE) {
            let v = if v.abs() >= 1e6 {
                format!("{v:e}")
            } else {
                v.to_string()
            };
            return Err(bad(format!(
                "row {}: {v} is outside +-{MAX_JOINT_VALUE} (degrees for a rotational joint: one turn either way)",
                i + 1
            )));
        }
    }
    Ok(rows)
}

/// What [`build_and_save`] did.
#[derive(Clone, Debug, Serialize)]
pub struct BuildReport {
    pub stats: DatasetStats,
    pub robot: String,
    pub shapes: usize,
    pub render_seconds: f64,
    pub write_seconds: f64,
    pub images_per_second: f64,
    pub threads: usize,
    pub git_revision: String,
}

/// Sample (or take `angles`), render, and write `out` (.npz) with `.stats.json` and
/// `.config.json` beside it (`report::dataset_preview` draws its `.preview.png`).
/// `progress`: show a progress bar.
pub fn build_and_save(
    robot: &Robot,
    robot_label: &str,
    cfg: &DatasetConfig,
    angles: Option<Vec<Vec<f64>>>,
    out: &Path,
    progress: bool,
) -> Result<(Dataset, BuildReport)> {
    let bar = progress
        .then(|| crate::core::progress::progress_bar(cfg.samples as u64, "render", "images"));
    let start = std::time::Instant::now();
    let data = match angles {
        Some(rows) => Dataset::render(robot, cfg, rows, bar.as_ref())?,
        None => Dataset::generate(robot, cfg, bar.as_ref())?,
    };
    let render_seconds = start.elapsed().as_secs_f64();
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    data.check_in_view()?;
    let write_start = std::time::Instant::now();
    data.save(out)?;
    let write_seconds = write_start.elapsed().as_secs_f64();

    let names: Vec<String> = robot
        .chain
        .movable_joints()
        .map(|j| j.name.clone())
        .collect();
    let stats = data.stats(&names);
    let report = BuildReport {
        stats,
        robot: robot_label.to_string(),
        shapes: robot.shape_count(),
        render_seconds,
        write_seconds,
        images_per_second: data.len() as f64 / render_seconds,
        threads: rayon::current_num_threads(),
        git_revision: git_revision(),
    };
    write_json(&out.with_extension("stats.json"), &report)?;
    write_json(&out.with_extension("config.json"), cfg)?;
    Ok((data, report))
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
