//! The renderer that replaces PyBullet: ray casting a robot into a silhouette and a metric
//! depth map.
//!
//! Fast path ([`RayCaster::render`]): for each link, the link's bounding box is projected
//! into the image and only the pixels inside it cast rays, into the link's [`Bvh`] in the
//! link frame. Images of a batch render in parallel (rayon). Slow reference
//! ([`RayCaster::render_reference`]): every pixel against every shape of every link, no
//! tree, no culling. Both give the same image (tested).
//!
//! Output: silhouette `H*W` u8 (255 robot, 0 empty) and depth `H*W` f32, metres along the
//! camera axis, 0 where empty, row-major.

use indicatif::ProgressBar;
use nalgebra::Isometry3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::sim::bvh::Bvh;
use crate::sim::camera::{Camera, CameraFrame};
use crate::sim::robot::Robot;

/// Height of the light ground plane of the paper's PyBullet scene (m).
pub const PAPER_GROUND_Z: f64 = -0.109;

/// Rendering options.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RenderOptions {
    /// Reproduce the artefact of the paper's dataset: its silhouettes were `gray < 240/255`,
    /// so the light ground plane at z = -0.109 below the horizon counted as foreground.
    /// Only the silhouette changes; depth stays the robot's. Off by default.
    pub ground_artifact: bool,
}

/// One rendered image.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: usize,
    pub height: usize,
    /// 255 where the robot is, 0 elsewhere; row-major `height * width`.
    pub silhouette: Vec<u8>,
    /// Depth along the camera axis in metres, 0 where empty; row-major.
    pub depth: Vec<f32>,
}

impl Frame {
    /// Fraction of pixels that are foreground.
    pub fn occupancy(&self) -> f64 {
        self.silhouette.iter().filter(|&&v| v > 0).count() as f64 / self.silhouette.len() as f64
    }
}

/// Renders one robot from one camera.
#[derive(Clone, Debug)]
pub struct RayCaster<'a> {
    pub robot: &'a Robot,
    pub camera: Camera,
    pub options: RenderOptions,
}

/// Silhouettes `[n, H * W]` in [0, 1] of `robot` at `angles` (user units: degrees, metres)
/// from `camera`: what a self-model is scored against.
pub fn silhouettes(
    robot: &Robot,
    camera: &Camera,
    options: &RenderOptions,
    angles: &[Vec<f64>],
) -> Vec<f32> {
    let si: Vec<Vec<f64>> = angles.iter().map(|q| robot.chain.to_si(q)).collect();
    RayCaster::new(robot, camera.clone(), options.clone())
        .render_batch(&si, None)
        .iter()
        .flat_map(|f| f.silhouette.iter().map(|&v| v as f32 / 255.0))
        .collect()
}

impl<'a> RayCaster<'a> {
    pub fn new(robot: &'a Robot, camera: Camera, options: RenderOptions) -> Self {
        RayCaster {
            robot,
            camera,
            options,
        }
    }

    /// An empty depth buffer (infinity = nothing hit).
    fn blank(&self) -> Vec<f64> {
        vec![f64::INFINITY; self.camera.width * self.camera.height]
    }

    /// Pixel rectangle (rows, columns, inclusive) that can see the link's geometry.
    fn screen_rect(
        &self,
        cam: &CameraFrame,
        geometry: &Bvh,
        pose: &Isometry3<f64>,
    ) -> Option<([usize; 2], [usize; 2])> {
        let (w, h) = (self.camera.width, self.camera.height);
        let corners = geometry
            .bounds()
            .corners()
            .map(|c| cam.project(&(pose * c)));
        if corners.iter().any(Option::is_none) {
            // Part of the box is behind the eye: test the whole image.
            return Some(([0, h - 1], [0, w - 1]));
        }
        let (mut r0, mut r1, mut c0, mut c1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for (r, c, _) in corners.into_iter().flatten() {
            r0 = r0.min(r);
            r1 = r1.max(r);
            c0 = c0.min(c);
            c1 = c1.max(c);
        }
        // Pixel centres are at integer coordinates.
        let (r0, r1, c0, c1) = (r0.ceil(), r1.floor(), c0.ceil(), c1.floor());
        if r1 < 0.0 || c1 < 0.0 || r0 > (h - 1) as f64 || c0 > (w - 1) as f64 || r0 > r1 || c0 > c1
        {
            return None;
        }
        let clamp = |v: f64, n: usize| v.clamp(0.0, (n - 1) as f64) as usize;
        Some(([clamp(r0, h), clamp(r1, h)], [clamp(c0, w), clamp(c1, w)]))
    }

    /// Render joint values `q` (SI units) with the fast path.
    pub fn render(&self, q: &[f64]) -> Frame {
        let frames = self.robot.link_frames(q);
        let cam = self.camera.frame();
        let w = self.camera.width;
        let mut depth = self.blank();
        for (geometry, pose) in self.robot.geometry.iter().zip(&frames) {
            if geometry.is_empty() {
                continue;
            }
            let Some((rows, cols)) = self.screen_rect(&cam, geometry, pose) else {
                continue;
            };
            for r in rows[0]..=rows[1] {
                for c in cols[0]..=cols[1] {
                    let ray = cam.ray(r as f64, c as f64).to_local(pose);
                    let d = &mut depth[r * w + c];
                    if let Some(t) = geometry.closest_hit(&ray, *d) {
                        *d = t;
                    }
                }
            }
        }
        self.finish(depth, &cam)
    }

    /// Render joint values `q` (SI units) by brute force: the slow reference.
    pub fn render_reference(&self, q: &[f64]) -> Frame {
        let frames = self.robot.link_frames(q);
        let cam = self.camera.frame();
        let (w, h) = (self.camera.width, self.camera.height);
        let mut depth = self.blank();
        for r in 0..h {
            for c in 0..w {
                let world = cam.ray(r as f64, c as f64);
                for (geometry, pose) in self.robot.geometry.iter().zip(&frames) {
                    let d = &mut depth[r * w + c];
                    if let Some(t) = geometry.closest_hit_brute_force(&world.to_local(pose), *d) {
                        *d = t;
                    }
                }
            }
        }
        self.finish(depth, &cam)
    }

    /// Render many joint vectors (SI) in parallel, ticking `progress` once per image.
    pub fn render_batch(&self, qs: &[Vec<f64>], progress: Option<&ProgressBar>) -> Vec<Frame> {
        qs.par_iter()
            .map(|q| {
                let f = self.render(q);
                if let Some(p) = progress {
                    p.inc(1);
                }
                f
            })
            .collect()
    }

    /// Depth buffer (infinity = empty) to a frame, adding the ground artefact if asked.
    fn finish(&self, depth: Vec<f64>, cam: &CameraFrame) -> Frame {
        let (w, h) = (self.camera.width, self.camera.height);
        let mut silhouette: Vec<u8> = depth
            .iter()
            .map(|d| if d.is_finite() { 255 } else { 0 })
            .collect();
        // From an eye above the ground plane, every ray that goes down meets it.
        if self.options.ground_artifact && cam.eye.z > PAPER_GROUND_Z {
            for r in 0..h {
                for c in 0..w {
                    if cam.ray(r as f64, c as f64).dir.z < 0.0 {
                        silhouette[r * w + c] = 255;
                    }
                }
            }
        }
        Frame {
            width: w,
            height: h,
            silhouette,
            depth: depth
                .iter()
                .map(|&d| if d.is_finite() { d as f32 } else { 0.0 })
                .collect(),
        }
    }
}
