//! How a dataset is made: samples, sampler, camera (or several around the robot), framing,
//! presets; the memory it may take.

use serde::{Deserialize, Serialize};

use super::sample_angles;
use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::sim::camera::Camera;
use crate::sim::ray_caster::RenderOptions;
use crate::sim::robot::Robot;
use crate::sim::trajectory::SamplerKind;

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
                "the dataset needs at least 1 sample (`samples`)".into(),
            ));
        }
        // Silhouettes (1 byte) and depth (4 bytes) per pixel are held in memory while the
        // dataset is built: bound them by what a 24 GiB machine holds with room to spare.
        let pixels = (self.camera.width as u128) * (self.camera.height as u128);
        if self.views.as_ref().is_some_and(|v| v.cameras == 0) {
            return Err(Error::Config(
                "a multi-view dataset needs at least 1 camera (`cameras`)".into(),
            ));
        }
        let images = self.samples * self.views.as_ref().map_or(1, |v| v.cameras);
        let bytes = pixels * 5 * images as u128;
        if bytes > MAX_DATASET_BYTES as u128 {
            return Err(Error::Config(format!(
                "{} images of {}x{} pixels need {:.1} GiB in memory, above the {} GiB limit; lower `samples` or `size`",
                images,
                self.camera.width,
                self.camera.height,
                bytes as f64 / (1u64 << 30) as f64,
                MAX_DATASET_BYTES >> 30
            )));
        }
        if self.train > self.samples {
            return Err(Error::Config(format!(
                "impossible split: {} training samples out of {} (`train` must be at most `samples`)",
                self.train, self.samples
            )));
        }
        self.camera.validate()
    }
}

/// The most memory a dataset's images may take (silhouettes and depth): 8 GiB.
pub const MAX_DATASET_BYTES: u64 = 8 << 30;

/// Bytes a pixel of a dataset may take at the peak of building and saving it: its silhouette
/// and depth (5 bytes) and the rendered frames of a block. Measured at 7.4 GB of resident
/// memory for 50,000 images of 100x100 when the arrays were copied to be encoded; they are
/// written without a copy now, and the bound is kept as the margin.
const PEAK_BYTES_PER_PIXEL: u64 = 15;

/// Refuse a dataset this machine cannot hold while it is built and saved, in one line, where
/// it would abort allocating (the machine's available memory, from `/proc/meminfo`).
pub(super) fn check_memory(cfg: &DatasetConfig) -> Result<()> {
    let images = cfg.samples * cfg.views.as_ref().map_or(1, |v| v.cameras);
    let pixels = (cfg.camera.width * cfg.camera.height) as u64;
    let needed = pixels * images as u64 * PEAK_BYTES_PER_PIXEL;
    let Some(available) = crate::core::memory::available_bytes() else {
        return Ok(());
    };
    if needed > available {
        let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
        return Err(Error::Config(format!(
            "{images} images of {}x{} need about {:.1} GiB while they are built and saved; this machine has {:.1} GiB available: lower `samples` or `size`",
            cfg.camera.width,
            cfg.camera.height,
            gib(needed),
            gib(available)
        )));
    }
    Ok(())
}

/// A camera asked for in part, as a user asks for one: fixed (`eye`, `target`), or framed
/// automatically from a `view` direction; its field of view and image size either way.
/// [`CameraChoice::apply`] sets a dataset's camera from it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraChoice {
    pub eye: Option<[f64; 3]>,
    pub target: Option<[f64; 3]>,
    pub fov_deg: Option<f64>,
    pub size: Option<usize>,
    /// The direction automatic framing looks from.
    pub view: Option<[f64; 3]>,
}

impl CameraChoice {
    /// Set `data`'s camera: `eye`/`target` fix it; otherwise a robot that is `framed` (every
    /// robot but the papers' arm), or any robot given a `view`, is framed automatically; the
    /// field of view and size apply either way.
    pub fn apply(&self, data: &mut DatasetConfig, framed: bool) {
        let camera = &mut data.camera;
        if let Some(fov) = self.fov_deg {
            camera.fov_deg = fov;
        }
        if let Some(size) = self.size {
            camera.width = size;
            camera.height = size;
        }
        if self.eye.is_some() || self.target.is_some() {
            if let Some(eye) = self.eye {
                camera.eye = eye;
            }
            if let Some(target) = self.target {
                camera.target = target;
            }
            // Looking straight down (or up): +x is up in the image.
            *camera = camera.clone().upright();
            data.framing = None;
        } else if framed || self.view.is_some() {
            data.framing = Some(Framing {
                view: self.view.unwrap_or(Framing::default().view),
                ..Framing::default()
            });
        }
    }
}
