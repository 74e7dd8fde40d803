//! The pinhole camera shared by the renderer and every model.
//!
//! Papers' camera: eye [1, 0, 0] looking at the origin, up +z, 42 degree vertical field of
//! view, 100x100 pixels, so the focal length is 50 / tan(21 deg) = 130.2545 px. Pixel
//! (row a, column b) looks along `forward + (b - W/2)/f * right - (a - H/2)/f * up`, which for
//! the papers' camera is the FFKSM ray convention `(-1, (b - 50)/f, -(a - 50)/f)`: the point
//! straight ahead lands on row 50, column 50 (PyBullet's TinyRenderer puts it on row 49).
//! The forward component of every ray direction is 1, so a hit's ray parameter `t` is its
//! depth along the camera axis in metres.

use nalgebra::{Matrix4, Point3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::core::error::{Error, Result};
use crate::sim::shape::Ray;

/// A pinhole camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Camera position (m).
    pub eye: [f64; 3],
    /// The point the camera looks at (m).
    pub target: [f64; 3],
    /// World direction that appears up in the image.
    pub up: [f64; 3],
    /// Vertical field of view (degrees).
    pub fov_deg: f64,
    pub width: usize,
    pub height: usize,
}

impl Default for Camera {
    fn default() -> Self {
        Camera::paper()
    }
}

/// How far from the origin (m) a camera's eye and target may be.
pub const MAX_CAMERA_COORDINATE: f64 = 1e3;

impl Camera {
    /// The camera of both self-modeling papers.
    pub fn paper() -> Self {
        Camera {
            eye: [1.0, 0.0, 0.0],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            fov_deg: 42.0,
            width: 100,
            height: 100,
        }
    }

    /// The same camera turned by `yaw_deg` about the vertical (world z) axis through its
    /// target (for novel views); [`Camera::orbited_about`] with the target as the pivot. For
    /// the papers' camera the target is the origin, so this is a turn about the world z axis.
    pub fn orbited(&self, yaw_deg: f64) -> Self {
        self.orbited_about(self.target, yaw_deg)
    }

    /// The same camera turned by `yaw_deg` about the vertical (world z) axis through `pivot`:
    /// eye, target and up turn together, so a pivot on the camera's axis stays where the
    /// camera looks.
    pub fn orbited_about(&self, pivot: [f64; 3], yaw_deg: f64) -> Self {
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians());
        let pivot = Vector3::from(pivot);
        let turn = |p: [f64; 3]| -> [f64; 3] { (pivot + r * (Vector3::from(p) - pivot)).into() };
        Camera {
            eye: turn(self.eye),
            target: turn(self.target),
            up: (r * Vector3::from(self.up)).into(),
            ..self.clone()
        }
    }

    /// The point on the camera's axis (ahead of the eye) nearest `p`. A camera read from a
    /// dataset's record has its target 1 m ahead of the eye, wherever the robot is: this is
    /// where it looks at the robot.
    pub fn axis_point_nearest(&self, p: Point3<f64>) -> [f64; 3] {
        let (fwd, _, _) = self.basis();
        let along = (p - self.eye_point()).dot(&fwd).max(0.0);
        (self.eye_point() + fwd * along).into()
    }

    /// Check the camera is usable.
    pub fn validate(&self) -> Result<()> {
        let fwd = Vector3::from(self.target) - Vector3::from(self.eye);
        if self.width == 0 || self.height == 0 {
            return Err(Error::Config(
                "camera width and height must be positive".into(),
            ));
        }
        if !(self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            return Err(Error::Config(format!(
                "camera fov {} must be in (0, 180) degrees",
                self.fov_deg
            )));
        }
        // A scene of robots is metres across: a camera kilometres away sees nothing, and
        // coordinates far beyond overflow the frame's arithmetic (NaN directions).
        if let Some(v) = self
            .eye
            .iter()
            .chain(&self.target)
            .find(|v| !(v.abs() <= MAX_CAMERA_COORDINATE))
        {
            return Err(Error::Config(format!(
                "camera eye and target must be within {MAX_CAMERA_COORDINATE} m of the origin, got a coordinate of {v:e} m"
            )));
        }
        if fwd.norm() < 1e-12 {
            return Err(Error::Config(format!(
                "the camera's eye and target are the same point ({:?}): it looks nowhere",
                self.eye
            )));
        }
        if fwd.cross(&Vector3::from(self.up)).norm() < 1e-12 {
            return Err(Error::Config(
                "camera eye, target and up must span a frame".into(),
            ));
        }
        Ok(())
    }

    /// The camera with an up direction it can use: unchanged, unless it looks along its up
    /// (straight down or up, with the default up +z), then with +x up in the image.
    pub fn upright(self) -> Self {
        let fwd = Vector3::from(self.target) - Vector3::from(self.eye);
        let up = Vector3::from(self.up);
        if fwd.norm() > 1e-12 && fwd.cross(&up).norm() <= 1e-9 * fwd.norm() * up.norm() {
            return Camera {
                up: [1.0, 0.0, 0.0],
                ..self
            };
        }
        self
    }

    /// Focal length in pixels from the vertical field of view.
    pub fn focal_px(&self) -> f64 {
        (self.height as f64 / 2.0) / (self.fov_deg.to_radians() / 2.0).tan()
    }

    /// Principal point (column, row): (W/2, H/2).
    pub fn principal_point(&self) -> (f64, f64) {
        (self.width as f64 / 2.0, self.height as f64 / 2.0)
    }

    /// Unit forward, right and up vectors of the image.
    pub fn basis(&self) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let fwd = (Vector3::from(self.target) - Vector3::from(self.eye)).normalize();
        let right = fwd.cross(&Vector3::from(self.up)).normalize();
        let up = right.cross(&fwd);
        (fwd, right, up)
    }

    pub fn eye_point(&self) -> Point3<f64> {
        Point3::from(self.eye)
    }

    /// Everything a per-pixel loop needs, computed once.
    pub fn frame(&self) -> CameraFrame {
        let (fwd, right, up) = self.basis();
        let (cx, cy) = self.principal_point();
        CameraFrame {
            eye: self.eye_point(),
            fwd,
            right,
            up,
            focal: self.focal_px(),
            cx,
            cy,
        }
    }

    /// Ray through pixel (row, column); its direction has forward component 1.
    pub fn ray(&self, row: f64, col: f64) -> Ray {
        self.frame().ray(row, col)
    }

    /// Project a world point: (row, column, depth along the camera axis). `None` behind the eye.
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64, f64)> {
        self.frame().project(p)
    }

    /// The camera a dataset records (`poses`: camera-to-world in the OpenGL convention,
    /// `focal` in pixels, the image size), with the principal point at the image centre.
    pub fn from_record(pose: &[f64; 16], focal: f64, width: usize, height: usize) -> Self {
        let column = |c: usize| Vector3::new(pose[c], pose[4 + c], pose[8 + c]);
        let eye = column(3);
        let fwd = -column(2);
        Camera {
            eye: eye.into(),
            target: (eye + fwd).into(),
            up: column(1).into(),
            fov_deg: 2.0 * (height as f64 / 2.0 / focal).atan().to_degrees(),
            width,
            height,
        }
    }

    /// A camera that frames `points` (world): it looks at the centre of their bounding box
    /// from `direction` (from the target towards the eye), with `up` up, at the distance
    /// where every point projects inside the image with `margin` (a fraction of the
    /// half-width) to spare. `fov_deg`, `width` and `height` are this camera's.
    pub fn framing(
        &self,
        points: &[Point3<f64>],
        direction: [f64; 3],
        margin: f64,
    ) -> Result<Self> {
        let dir = Vector3::from(direction);
        if points.is_empty() {
            return Err(Error::Config(
                "nothing to frame: the robot has no geometry (give `eye` and `target`)".into(),
            ));
        }
        if !(dir.norm() > 1e-12) || !dir.iter().all(|v| v.is_finite()) {
            return Err(Error::Config(format!(
                "`view` {direction:?}: the direction to look from must be a non-zero vector"
            )));
        }
        if !(0.0..0.9).contains(&margin) {
            return Err(Error::Config(format!(
                "framing margin {margin} must be in [0, 0.9)"
            )));
        }
        let bounds = crate::sim::shape::Aabb::from_points(points);
        let target = bounds.center();
        let probe = Camera {
            eye: (target + dir.normalize()).into(),
            target: target.into(),
            ..self.clone()
        }
        .upright();
        probe.validate()?;
        let (fwd, right, up) = probe.basis();
        let back = -fwd;
        let ty = (self.fov_deg.to_radians() / 2.0).tan() * (1.0 - margin);
        let tx = ty * self.width as f64 / self.height as f64;
        // At distance d from the target, a point `along` towards the camera is at depth
        // d - along: it is inside when |x| <= tx (d - along) and |y| <= ty (d - along).
        let mut distance: f64 = 0.0;
        for p in points {
            let rel = p - target;
            let along = rel.dot(&back);
            let need = along + (rel.dot(&right).abs() / tx).max(rel.dot(&up).abs() / ty);
            distance = distance.max(need).max(along + 1e-3);
        }
        Ok(Camera {
            eye: (target + back * distance).into(),
            target: target.into(),
            up: probe.up,
            ..self.clone()
        })
    }

    /// The camera's pose as 9 numbers a network reads: the eye (metres), then the image's
    /// right and up axes in the world, the first two columns of its camera-to-world rotation.
    /// This 6-D rotation (Zhou et al., CVPR 2019) is continuous, unlike Euler angles and
    /// quaternions (whose double cover puts one pose at two places), and the third column is
    /// their cross product, so nothing is lost. The field of view and image size are the
    /// camera's own, not part of the vector.
    pub fn to_vector(&self) -> [f64; 9] {
        let (_, right, up) = self.basis();
        [
            self.eye[0],
            self.eye[1],
            self.eye[2],
            right.x,
            right.y,
            right.z,
            up.x,
            up.y,
            up.z,
        ]
    }

    /// The camera of [`Camera::to_vector`]'s `v` (its rotation columns made orthonormal by
    /// Gram-Schmidt), looking one metre ahead, with `fov_deg` and the image size of `like`.
    pub fn from_vector(v: &[f64; 9], like: &Camera) -> Result<Self> {
        let eye = Vector3::new(v[0], v[1], v[2]);
        let a = Vector3::new(v[3], v[4], v[5]);
        let b = Vector3::new(v[6], v[7], v[8]);
        if !(a.norm() > 1e-9) || !v.iter().all(|x| x.is_finite()) {
            return Err(Error::Config(format!("{v:?} is not a camera pose")));
        }
        let right = a.normalize();
        let up = b - right * right.dot(&b);
        if !(up.norm() > 1e-9) {
            return Err(Error::Config(format!(
                "{v:?}: the camera's up axis is parallel to its right axis"
            )));
        }
        let up = up.normalize();
        let fwd = up.cross(&right);
        Ok(Camera {
            eye: eye.into(),
            target: (eye + fwd).into(),
            up: up.into(),
            ..like.clone()
        })
    }

    /// `n` cameras on a sphere of `radius` around `target`, looking at it: yaws evenly spaced
    /// from `yaw0_deg`, elevations (above the horizontal plane through the target) spread
    /// over `elevation_deg` (alternately its ends, for several cameras; its middle for one),
    /// with this camera's field of view, image size and up.
    pub fn on_sphere(
        &self,
        target: [f64; 3],
        radius: f64,
        n: usize,
        yaw0_deg: f64,
        elevation_deg: [f64; 2],
    ) -> Vec<Camera> {
        let [lo, hi] = elevation_deg;
        (0..n)
            .map(|i| {
                let yaw = (yaw0_deg + 360.0 * i as f64 / n as f64).to_radians();
                let elevation = if n == 1 {
                    0.5 * (lo + hi)
                } else if i % 2 == 0 {
                    lo
                } else {
                    hi
                }
                .to_radians();
                self.looking_from(target, radius, yaw, elevation)
            })
            .collect()
    }

    /// This camera moved to look at `target` from `radius` away, at `yaw` about the world z
    /// axis (0: along +x, the papers' view) and `elevation` above the horizontal (radians).
    pub fn looking_from(&self, target: [f64; 3], radius: f64, yaw: f64, elevation: f64) -> Self {
        let t = Vector3::from(target);
        let dir = Vector3::new(
            elevation.cos() * yaw.cos(),
            elevation.cos() * yaw.sin(),
            elevation.sin(),
        );
        Camera {
            eye: (t + dir * radius).into(),
            target,
            up: [0.0, 0.0, 1.0],
            ..self.clone()
        }
    }

    /// Where the eye sits seen from the target: yaw about the world z axis (0: along +x),
    /// elevation above the horizontal (radians) and distance ([`Camera::looking_from`]'s
    /// arguments).
    pub fn spherical(&self) -> (f64, f64, f64) {
        let d = Vector3::from(self.eye) - Vector3::from(self.target);
        let r = d.norm();
        (
            d.y.atan2(d.x),
            (d.z / r.max(1e-300)).clamp(-1.0, 1.0).asin(),
            r,
        )
    }

    /// The angle (degrees) between the directions this camera and `other` look along.
    pub fn angle_to(&self, other: &Camera) -> f64 {
        let (a, b) = (self.basis().0, other.basis().0);
        a.dot(&b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Camera-to-world matrix in the NeRF/OpenGL convention (columns right, up, backward, eye),
    /// as stored under `poses` in the papers' datasets.
    pub fn pose_matrix(&self) -> Matrix4<f64> {
        let (fwd, right, up) = self.basis();
        let e = Vector3::from(self.eye);
        Matrix4::new(
            right.x, up.x, -fwd.x, e.x, //
            right.y, up.y, -fwd.y, e.y, //
            right.z, up.z, -fwd.z, e.z, //
            0.0, 0.0, 0.0, 1.0,
        )
    }
}

/// A camera's eye, unit axes, focal length and principal point, precomputed for the
/// per-pixel loops of the renderer ([`Camera::frame`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraFrame {
    pub eye: Point3<f64>,
    pub fwd: Vector3<f64>,
    pub right: Vector3<f64>,
    pub up: Vector3<f64>,
    /// Focal length (px).
    pub focal: f64,
    /// Principal point: column `cx`, row `cy`.
    pub cx: f64,
    pub cy: f64,
}

impl CameraFrame {
    /// Ray through pixel (row, column); its direction has forward component 1.
    #[inline]
    pub fn ray(&self, row: f64, col: f64) -> Ray {
        Ray {
            origin: self.eye,
            dir: self.fwd + self.right * ((col - self.cx) / self.focal)
                - self.up * ((row - self.cy) / self.focal),
        }
    }

    /// Project a world point: (row, column, depth along the camera axis). `None` behind the eye.
    #[inline]
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64, f64)> {
        ((p - self.eye).dot(&self.fwd) > 1e-9).then(|| self.project_clamped(p, 0.0))
    }

    /// [`CameraFrame::project`] with the depth held at least `min_depth` (m): a point at or
    /// behind the eye lands far out in the image instead of nowhere (as the splatting models'
    /// tensor projections do).
    #[inline]
    pub fn project_clamped(&self, p: &Point3<f64>, min_depth: f64) -> (f64, f64, f64) {
        let v = p - self.eye;
        let z = v.dot(&self.fwd).max(min_depth);
        (
            self.cy - self.focal * v.dot(&self.up) / z,
            self.cx + self.focal * v.dot(&self.right) / z,
            z,
        )
    }
}
