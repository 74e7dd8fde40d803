//! A dataset drawn: its joint vectors rendered by the ray caster from the config's camera (or
//! cameras), in blocks with Ctrl-C asked between them.

use indicatif::ProgressBar;

use super::config::check_memory;
use super::{Dataset, DatasetConfig, sample_angles};
use crate::core::error::{Error, Result};
use crate::sim::camera::Camera;
use crate::sim::ray_caster::{Frame, RayCaster, RenderOptions};
use crate::sim::robot::Robot;

/// Images rendered between two looks at Ctrl-C.
const RENDER_BLOCK: usize = 64;

/// Silhouettes and depth maps as they are rendered, one frame after another, by cameras of
/// one image size and focal length (the first's).
struct Frames {
    images: Vec<u8>,
    depth: Vec<f32>,
    camera: Camera,
}

impl Frames {
    /// Room for `n` frames of `camera`'s size.
    fn new(n: usize, camera: &Camera) -> Self {
        let pixels = n * camera.width * camera.height;
        Frames {
            images: Vec::with_capacity(pixels),
            depth: Vec::with_capacity(pixels),
            camera: camera.clone(),
        }
    }

    fn push(&mut self, f: &Frame) {
        self.images.extend_from_slice(&f.silhouette);
        self.depth.extend_from_slice(&f.depth);
    }

    /// The dataset of these frames: sample `i` shows `robot` at `angles[i]` from the camera
    /// at `poses[i]`; the first `n_train` samples train.
    fn into_dataset(
        self,
        robot: &Robot,
        angles: Vec<Vec<f64>>,
        poses: Vec<[f64; 16]>,
        n_train: usize,
    ) -> Dataset {
        Dataset {
            angles,
            width: self.camera.width,
            height: self.camera.height,
            focal: self.camera.focal_px(),
            images: self.images,
            depth: self.depth,
            poses,
            n_train,
            joint_names: robot.chain.joint_names(),
        }
    }
}

/// A camera's pose as a dataset records it: camera-to-world, row-major 4x4.
fn pose_record(camera: &Camera) -> [f64; 16] {
    let m = camera.pose_matrix();
    std::array::from_fn(|i| m[(i / 4, i % 4)])
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
        let mut frames = Frames::new(si.len(), &camera);
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
                frames.push(&f);
            }
        }
        let poses = vec![pose_record(&camera); cfg.samples];
        Ok(frames.into_dataset(robot, angles, poses, cfg.train))
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
        let frames: Vec<Vec<Frame>> = cameras
            .iter()
            .map(|c| RayCaster::new(robot, c.clone(), render.clone()).render_batch(&si, None))
            .collect();
        let n = angles.len() * cameras.len();
        let mut all = Frames::new(n, first);
        let (mut all_angles, mut poses) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for (p, q) in angles.iter().enumerate() {
            for (c, camera) in cameras.iter().enumerate() {
                all.push(&frames[c][p]);
                all_angles.push(q.clone());
                poses.push(pose_record(camera));
            }
        }
        Ok(all.into_dataset(robot, all_angles, poses, train_poses * cameras.len()))
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
}
