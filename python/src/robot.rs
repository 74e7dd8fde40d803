//! `selfmodel.Robot`: a robot as ROS ships it, its forward kinematics, Jacobians, rendering
//! and collision checks.

use std::path::PathBuf;

use numpy::{IntoPyArray, PyArray2, PyArray3};
use pyo3::prelude::*;

use selfmodel::ik::solve::collision::CollisionCheck;
use selfmodel::sim::collision::model::CollisionModel;
use selfmodel::sim::kinematics::JointGroup;
use selfmodel::sim::robot::Robot;
use selfmodel::sim::robots::RobotSpec;
use selfmodel::sim::urdf_loader::GeometryKind;

use crate::arrays::*;
use crate::calls::*;

/// A robot: its joints (names, limits, in depth-first order from the root) and forward
/// kinematics.
#[pyclass(name = "Robot", module = "selfmodel", frozen)]
pub(crate) struct PyRobot {
    robot: Robot,
    /// The description as loaded, for its collision geometry; the SRDF named with it (else
    /// the one beside the URDF).
    spec: RobotSpec,
    srdf: Option<PathBuf>,
    /// Built on the first collision query: spheres and the checked pairs.
    collision: std::sync::OnceLock<CollisionCheck>,
}

#[pymethods]
impl PyRobot {
    /// Load a URDF as ROS ships it. `tip`: the end-effector link (default: the last link of
    /// the longest chain); `joints`: "all" or a list of joint names; `tips`: several links
    /// (the union of their chains); `geometry`: "visual", "collision" or "none"; `group`: a
    /// planning group of the SRDF file beside the URDF (or `srdf`), as `--group` reads it.
    #[staticmethod]
    #[pyo3(signature = (path, tip=None, joints=None, tips=None, geometry="visual", group=None, srdf=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_urdf(
        py: Python<'_>,
        path: PathBuf,
        tip: Option<String>,
        joints: Option<Names>,
        tips: Option<Names>,
        geometry: &str,
        group: Option<String>,
        srdf: Option<PathBuf>,
    ) -> PyResult<Self> {
        guarded(|| {
            let geometry = match geometry {
                "visual" => GeometryKind::Visual,
                "collision" => GeometryKind::Collision,
                "none" => GeometryKind::None,
                other => {
                    return Err(value_error(format!(
                        "geometry \"{other}\": choose visual, collision or none"
                    )));
                }
            };
            let joints = JointGroup::from_args(
                joints.as_ref().map(|n| n.0.as_slice()),
                tips.as_ref().map(|n| n.0.as_slice()),
                group.as_deref(),
                srdf.as_deref(),
                Some(&path),
            )
            .map_err(value_error)?;
            let spec = RobotSpec::Urdf {
                path,
                base_xyz: [0.0; 3],
                base_rpy: [0.0; 3],
                tip,
                geometry,
                joints,
            };
            let robot = py.allow_threads(|| spec.load()).map_err(value_error)?;
            spec.require_movable(
                &robot,
                "forward kinematics, a self-model or inverse kinematics",
            )
            .map_err(value_error)?;
            Ok(PyRobot {
                robot,
                spec,
                srdf,
                collision: std::sync::OnceLock::new(),
            })
        })
    }

    /// Each link's collision spheres, fitted to its `<collision>` meshes (every point of their
    /// surface inside one): `{link: array (k, 4)}` of x, y, z (metres, in the link's frame) and
    /// radius.
    #[getter]
    fn collision_spheres<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        guarded(|| {
            let model = self.collision_model(py)?;
            let out = pyo3::types::PyDict::new(py);
            for (name, spheres) in self.robot.chain.links.iter().zip(&model.spheres) {
                if spheres.is_empty() {
                    continue;
                }
                let rows: Vec<f64> = spheres
                    .iter()
                    .flat_map(|s| [s.center[0], s.center[1], s.center[2], s.radius])
                    .collect();
                let a = numpy::ndarray::Array2::from_shape_vec((spheres.len(), 4), rows)
                    .expect("k x 4");
                out.set_item(name, a.into_pyarray(py))?;
            }
            Ok(out)
        })
    }

    /// The pairs of links checked for collisions (all but those the SRDF beside the URDF, or
    /// `srdf`, disables; without one, those MoveIt's setup assistant would disable).
    #[getter]
    fn collision_pairs(&self, py: Python<'_>) -> PyResult<Vec<(String, String)>> {
        guarded(|| {
            let model = self.collision_model(py)?;
            let links = &self.robot.chain.links;
            Ok(model
                .pairs
                .iter()
                .map(|&(a, b)| (links[a].clone(), links[b].clone()))
                .collect())
        })
    }

    /// Whether each configuration of `q` (N, dof; radians, metres) collides with itself (a
    /// checked pair of links closer than `margin`, metres, on their collision meshes, the
    /// spheres their broad phase) or, with `scene` (a cuRobo world-configuration YAML file),
    /// with an obstacle.
    #[pyo3(signature = (q, scene=None, margin=0.0))]
    fn collides<'py>(
        &self,
        py: Python<'py>,
        q: Matrix,
        scene: Option<PathBuf>,
        margin: f64,
    ) -> PyResult<Bound<'py, numpy::PyArray1<bool>>> {
        guarded(|| {
            let hit = self.per_configuration(py, q, scene, |model, frames, scene| {
                model.collides(frames, scene, margin)
            })?;
            Ok(numpy::ndarray::Array1::from_vec(hit).into_pyarray(py))
        })
    }

    /// The clearance of each configuration of `q` (N, dof): the smallest signed distance
    /// (metres) between a checked pair of links on their collision meshes, and with `scene`
    /// between a moving link and an obstacle, negative where they overlap; at most `cap` (a
    /// larger clearance is reported as `cap`).
    #[pyo3(signature = (q, scene=None, cap=1.0))]
    fn clearance<'py>(
        &self,
        py: Python<'py>,
        q: Matrix,
        scene: Option<PathBuf>,
        cap: f64,
    ) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        guarded(|| {
            let c = self.clearances(py, q, scene, cap)?;
            Ok(numpy::ndarray::Array1::from_vec(c).into_pyarray(py))
        })
    }

    /// For the tests of the boundary: a panic, as a bug would make one.
    #[staticmethod]
    fn _panic_for_test() -> PyResult<()> {
        guarded(|| panic!("a deliberate panic"))
    }

    /// The number of joints.
    #[getter]
    fn dof(&self) -> usize {
        self.robot.dof()
    }

    /// The joints' names, in the joint vector's order.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.robot.chain.joint_names()
    }

    /// The links whose poses `fk` gives by default (the tip, or the `tips`).
    #[getter]
    fn tip_names(&self) -> Vec<String> {
        self.robot.chain.tip_names()
    }

    /// Each joint's limits (dof, 2): radians, metres for a prismatic joint (a rotational
    /// joint without limits: +-90 degrees, what the samplers draw).
    #[getter]
    fn limits<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let r = self.robot.chain.joint_ranges();
        let flat: Vec<f64> = r.iter().flatten().copied().collect();
        numpy::ndarray::Array2::from_shape_vec((r.len(), 2), flat)
            .expect("dof x 2")
            .into_pyarray(py)
    }

    /// World poses (N, 4, 4) of the tip (or of `link`) at joint vectors `q` (N, dof), SI.
    #[pyo3(signature = (q, link=None))]
    fn fk<'py>(
        &self,
        py: Python<'py>,
        q: Matrix,
        link: Option<String>,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        guarded(|| {
            let chain = &self.robot.chain;
            let dof = chain.dof();
            let (n, v) = rows(q, dof, "q")?;
            let link = match link {
                None => None,
                Some(name) => {
                    Some(chain.links.iter().position(|l| *l == name).ok_or_else(|| {
                        value_error(format!(
                            "\"{name}\" is not a link of this robot; its links: {}",
                            chain.links.join(", ")
                        ))
                    })?)
                }
            };
            let width = dof.max(1);
            let out: Vec<f64> = in_blocks(py, n, ROWS_A_BLOCK, |rows| {
                use rayon::prelude::*;
                Ok(v[rows.start * width..rows.end * width]
                    .par_chunks(width)
                    .flat_map_iter(|q| {
                        let pose = match link {
                            Some(l) => chain.link_frames(q)[l],
                            None => chain.tip_poses(q)[0],
                        };
                        let m = pose.to_homogeneous();
                        (0..16).map(move |i| m[(i / 4, i % 4)])
                    })
                    .collect())
            })?;
            Ok(numpy::ndarray::Array3::from_shape_vec((n, 4, 4), out)
                .expect("n x 4 x 4")
                .into_pyarray(py))
        })
    }

    /// The tip's pose Jacobian (N, 6, dof) at `q` (N, dof): linear rows, then angular
    /// (world frame).
    fn jacobian<'py>(&self, py: Python<'py>, q: Matrix) -> PyResult<Bound<'py, PyArray3<f64>>> {
        guarded(|| {
            let chain = &self.robot.chain;
            let dof = chain.dof();
            let (n, v) = rows(q, dof, "q")?;
            let width = dof.max(1);
            let out: Vec<f64> = in_blocks(py, n, ROWS_A_BLOCK, |rows| {
                use rayon::prelude::*;
                Ok(v[rows.start * width..rows.end * width]
                    .par_chunks(width)
                    .flat_map_iter(|q| {
                        let j = chain.pose_jacobian(q);
                        (0..6 * dof).map(move |i| j[(i / dof, i % dof)])
                    })
                    .collect())
            })?;
            Ok(numpy::ndarray::Array3::from_shape_vec((n, 6, dof), out)
                .expect("n x 6 x dof")
                .into_pyarray(py))
        })
    }

    /// Silhouettes (N, size, size) uint8 (255 where the robot is) and depth (N, size, size)
    /// float32 (metres along the camera axis, 0 where empty) of the robot at `q` (N, dof),
    /// from our ray caster, by a camera that frames every pose of `q` from `view` (default:
    /// front right, a little above), as the command line frames a dataset (`fov`: degrees,
    /// default the datasets' 42).
    #[pyo3(signature = (q, size=100, view=None, fov=None))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        q: Matrix,
        size: i64,
        view: Option<[f64; 3]>,
        fov: Option<f64>,
    ) -> PyResult<(Bound<'py, PyArray3<u8>>, Bound<'py, PyArray3<f32>>)> {
        guarded(|| {
            use selfmodel::Preset;
            use selfmodel::data::dataset::{DatasetConfig, Framing, swept_points};
            use selfmodel::sim::ray_caster::{RayCaster, RenderOptions};
            let robot = &self.robot;
            let dof = robot.dof();
            let (n, v) = rows(q, dof, "q")?;
            let size = count(size, "size", 1, 2048)?;
            if (n as u64) * (size * size) as u64 > 1 << 30 {
                return Err(value_error(format!(
                    "{n} images of {size}x{size}: size must be 1 to 2048 and all images at most 2^30 pixels"
                )));
            }
            let si: Vec<Vec<f64>> = v.chunks(dof.max(1)).take(n).map(<[f64]>::to_vec).collect();
            let framing = Framing::default();
            let mut camera = DatasetConfig::paper().camera;
            (camera.width, camera.height) = (size, size);
            camera.fov_deg = fov.unwrap_or(camera.fov_deg);
            camera.validate().map_err(value_error)?;
            let camera = camera
                .framing(
                    &swept_points(robot, &si),
                    view.unwrap_or(framing.view),
                    framing.margin,
                )
                .map_err(value_error)?;
            let caster = RayCaster::new(robot, camera, RenderOptions::default());
            let frames = in_blocks(py, n, IMAGES_A_BLOCK, |rows| {
                Ok(caster.render_batch(&si[rows], None))
            })?;
            let (mut silhouettes, mut depth) = (
                Vec::with_capacity(n * size * size),
                Vec::with_capacity(n * size * size),
            );
            for f in frames {
                silhouettes.extend_from_slice(&f.silhouette);
                depth.extend_from_slice(&f.depth);
            }
            Ok((
                numpy::ndarray::Array3::from_shape_vec((n, size, size), silhouettes)
                    .expect("n x size x size")
                    .into_pyarray(py),
                numpy::ndarray::Array3::from_shape_vec((n, size, size), depth)
                    .expect("n x size x size")
                    .into_pyarray(py),
            ))
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Robot({}, {} joints: {})",
            self.robot.name,
            self.robot.dof(),
            self.robot.chain.joint_names().join(", ")
        )
    }
}
impl PyRobot {
    /// The collision model, built once: the description reloaded with its collision geometry
    /// (as `ik solve --self-collision` builds it).
    fn collision_model(&self, py: Python<'_>) -> PyResult<&CollisionModel> {
        if let Some(c) = self.collision.get() {
            return Ok(&c.model);
        }
        let check = py
            .allow_threads(|| {
                CollisionCheck::for_robot(&self.spec, self.srdf.as_deref(), None, true, 0.0)
            })
            .map_err(value_error)?;
        Ok(&self.collision.get_or_init(|| check).model)
    }

    /// The clearance of every row of `q`, in blocks (Ctrl-C between them).
    fn clearances(
        &self,
        py: Python<'_>,
        q: Matrix,
        scene: Option<PathBuf>,
        cap: f64,
    ) -> PyResult<Vec<f64>> {
        self.per_configuration(py, q, scene, |model, frames, scene| {
            model.clearance(frames, scene, cap)
        })
    }

    /// `f` of the collision model at every row of `q` (its link frames) and the scene read
    /// from `scene`, in blocks (Ctrl-C between them).
    fn per_configuration<T: Send>(
        &self,
        py: Python<'_>,
        q: Matrix,
        scene: Option<PathBuf>,
        f: impl Fn(
            &CollisionModel,
            &[nalgebra::Isometry3<f64>],
            Option<&selfmodel::sim::collision::scene::Scene>,
        ) -> T
        + Sync,
    ) -> PyResult<Vec<T>> {
        let model = self.collision_model(py)?;
        let scene = (scene.as_deref())
            .map(selfmodel::sim::collision::scene::Scene::read)
            .transpose()
            .map_err(value_error)?;
        let chain = &self.robot.chain;
        let dof = chain.dof();
        let (n, v) = rows(q, dof, "q")?;
        let width = dof.max(1);
        in_blocks(py, n, ROWS_A_BLOCK, |rows| {
            use rayon::prelude::*;
            Ok(v[rows.start * width..rows.end * width]
                .par_chunks(width)
                .map(|q| f(model, &chain.link_frames(q), scene.as_ref()))
                .collect())
        })
    }
}
