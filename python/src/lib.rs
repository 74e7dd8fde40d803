//! The Python package's native module (`selfmodel._selfmodel`): a thin layer over the crate.
//! Arrays come in as numpy arrays of numbers (any float or integer dtype, either byte order,
//! any strides), are checked for size before they are copied, then for shape and finiteness
//! (a `ValueError` or `TypeError` of one line, never a crash), and the GIL is released while
//! Rust computes.

use std::path::PathBuf;

use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArray2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

use selfmodel::ik::collision::CollisionCheck;
use selfmodel::ik::pose::PoseTarget;
use selfmodel::ik::pose_model::{PoseModel, target_columns, target_from_values};
use selfmodel::sim::collision::model::CollisionModel;
use selfmodel::sim::kinematics::JointGroup;
use selfmodel::sim::robot::Robot;
use selfmodel::sim::robots::RobotSpec;
use selfmodel::sim::urdf_loader::GeometryKind;

/// `f`, a method's body, with any panic inside it (a bug: the library's errors are values)
/// turned into a `RuntimeError` of one line that says so, never a `PanicException` that
/// ends a script.
fn guarded<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    selfmodel::core::input_file::catch_panic(f).unwrap_or_else(|panic| {
        let panic = panic.split_whitespace().collect::<Vec<_>>().join(" ");
        Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
            "selfmodel failed inside ({panic}): a bug, please report it with the call that made it"
        )))
    })
}

/// The library's error as Python's `ValueError` (one line).
fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// A 2-D array of numbers as Python hands it over: any float, integer or bool dtype, either
/// byte order, any strides (a broadcast view included), cast to float64 once its size is
/// known to be one a call takes. Anything else is a `TypeError` (not numbers) or a
/// `ValueError` (not 2-D, too many rows) of one line.
struct Matrix {
    shape: [usize; 2],
    values: Vec<f64>,
}

impl<'py> FromPyObject<'py> for Matrix {
    fn extract_bound(obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        let numpy = obj.py().import("numpy")?;
        // No copy for an array; a list of lists becomes one.
        let a = numpy.call_method1("asanyarray", (obj,))?;
        let dtype = a.getattr("dtype")?;
        let kind: String = dtype.getattr("kind")?.extract()?;
        if !matches!(kind.as_str(), "f" | "i" | "u" | "b") {
            return Err(PyTypeError::new_err(format!(
                "expected an array of numbers (float64 or any dtype numpy casts to it), got dtype {}",
                dtype.str()?
            )));
        }
        let shape: Vec<usize> = a.getattr("shape")?.extract()?;
        let [n, w] = shape[..] else {
            return Err(value_error(format!(
                "expected a 2-D array (N rows), got shape {shape:?}"
            )));
        };
        // Checked before the copy: a broadcast view of 10^9 rows costs numpy nothing and would
        // cost this copy gigabytes.
        if n > MAX_ROWS {
            return Err(value_error(format!(
                "{n} rows, more than the {MAX_ROWS} one call takes; call it in batches"
            )));
        }
        let kwargs = pyo3::types::PyDict::new(obj.py());
        kwargs.set_item("dtype", numpy.getattr("float64")?)?;
        let c = numpy.call_method("ascontiguousarray", (a,), Some(&kwargs))?;
        let c: PyReadonlyArray2<f64> = c.extract()?;
        Ok(Matrix {
            shape: [n, w],
            values: c.as_slice()?.to_vec(),
        })
    }
}

/// Names as Python gives them: one string (`joints="all"`, `tips="hand"`) or a sequence.
struct Names(Vec<String>);

impl<'py> FromPyObject<'py> for Names {
    fn extract_bound(obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        if let Ok(one) = obj.extract::<String>() {
            return Ok(Names(vec![one]));
        }
        obj.extract::<Vec<String>>()
            .map(Names)
            .map_err(|_| PyTypeError::new_err("expected a name or a list of names (strings)"))
    }
}

/// A count Python gives (`k`, `size`): an integer from `lo` to `hi`, else a `ValueError`
/// naming `what` (a negative one included, which pyo3 would call an overflow).
fn count(value: i64, what: &str, lo: usize, hi: usize) -> PyResult<usize> {
    usize::try_from(value)
        .ok()
        .filter(|v| (lo..=hi).contains(v))
        .ok_or_else(|| value_error(format!("{what} must be {lo} to {hi}, got {value}")))
}

/// The rows of a 2-D array with `width` columns, finite: `(rows, values)`.
fn rows(a: Matrix, width: usize, what: &str) -> PyResult<(usize, Vec<f64>)> {
    let [n, w] = a.shape;
    if w != width {
        return Err(value_error(format!(
            "{what}: expected an array of shape (N, {width}), got ({n}, {w})"
        )));
    }
    let v = &a.values;
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(value_error(format!(
            "{what}: row {} holds {}, not a finite number",
            i / width.max(1),
            v[i]
        )));
    }
    Ok((n, a.values))
}

/// The most rows one call takes (the command line's most targets).
const MAX_ROWS: usize = 10_000_000;

/// Rows of fk or jacobian between two looks at Ctrl-C (a few hundredths of a second).
const ROWS_A_BLOCK: usize = 1 << 16;

/// Images of render or predict between two looks at Ctrl-C.
const IMAGES_A_BLOCK: usize = 512;

/// Python's own Ctrl-C check, for a long call that released the GIL: `true` once a signal
/// handler raised (KeyboardInterrupt), the exception kept in `raised` for the call to return.
fn interrupted(raised: &std::sync::Mutex<Option<PyErr>>) -> bool {
    Python::with_gil(|py| match py.check_signals() {
        Ok(()) => false,
        Err(e) => {
            *raised.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
            true
        }
    })
}

/// `f` over rows `0..n` in blocks of `block`, the GIL released, with Ctrl-C asked between
/// blocks (a long fk, jacobian, render or predict stops within a fraction of a second): the
/// blocks' outputs in order, or the KeyboardInterrupt a signal handler raised.
fn in_blocks<T: Send>(
    py: Python<'_>,
    n: usize,
    block: usize,
    f: impl Fn(std::ops::Range<usize>) -> PyResult<Vec<T>> + Send + Sync,
) -> PyResult<Vec<T>> {
    let raised = std::sync::Mutex::new(None);
    let out = py.allow_threads(|| {
        let mut out = Vec::new();
        for start in (0..n).step_by(block.max(1)) {
            if start > 0 && interrupted(&raised) {
                return Ok(out);
            }
            out.extend(f(start..(start + block).min(n))?);
        }
        Ok(out)
    });
    match raised.into_inner().unwrap_or_else(|p| p.into_inner()) {
        Some(e) => Err(e),
        None => out,
    }
}

/// A robot: its joints (names, limits, in depth-first order from the root) and forward
/// kinematics.
#[pyclass(name = "Robot", module = "selfmodel", frozen)]
struct PyRobot {
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

    /// Each link's collision spheres, fitted to its `<collision>` meshes (every vertex inside
    /// one, every surface point within 4 mm): `{link: array (k, 4)}` of x, y, z (metres, in
    /// the link's frame) and radius.
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

    /// Whether each configuration of `q` (N, dof; radians, metres) collides with itself (two
    /// spheres of a checked pair closer than `margin`, metres) or, with `scene` (a cuRobo
    /// world-configuration YAML file), with an obstacle.
    #[pyo3(signature = (q, scene=None, margin=0.0))]
    fn collides<'py>(
        &self,
        py: Python<'py>,
        q: Matrix,
        scene: Option<PathBuf>,
        margin: f64,
    ) -> PyResult<Bound<'py, numpy::PyArray1<bool>>> {
        guarded(|| {
            let clearance = self.clearances(py, q, scene, margin.max(0.0) + 1.0)?;
            let hit: Vec<bool> = clearance.iter().map(|&c| c < margin).collect();
            Ok(numpy::ndarray::Array1::from_vec(hit).into_pyarray(py))
        })
    }

    /// The clearance of each configuration of `q` (N, dof): the smallest signed distance
    /// (metres) between the spheres of a checked pair, and with `scene` between a moving
    /// link's spheres and an obstacle, negative where they overlap; at most `cap` (a larger
    /// clearance is reported as `cap`).
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

/// A learned IK model `ik train` saved, with the robot it was trained for.
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
                .map(|q| model.clearance(&chain.link_frames(q), scene.as_ref(), cap))
                .collect())
        })
    }
}

#[pyclass(name = "IkSolver", module = "selfmodel", frozen)]
struct PyIkSolver {
    model: PoseModel,
    robot: Robot,
    device: burn::tensor::Device,
    /// The model's folder (its kept collision model).
    dir: PathBuf,
}

#[pymethods]
impl PyIkSolver {
    /// Load the model `ik train` wrote into `model_dir` and the robot description it names
    /// (refused, with why, when they do not match).
    #[staticmethod]
    fn load(py: Python<'_>, model_dir: PathBuf) -> PyResult<Self> {
        guarded(|| {
            py.allow_threads(|| {
                let device =
                    selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu)?;
                let (model, robot) = PoseModel::load_with_robot(&model_dir, &device)?;
                Ok::<_, selfmodel::Error>(PyIkSolver {
                    model,
                    robot,
                    device,
                    dir: model_dir.clone(),
                })
            })
            .map_err(value_error)
        })
    }

    /// The joints of an answer, in order.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.model.saved.joint_names.clone()
    }

    /// The columns of a target row: x, y, z, qw, qx, qy, qz (x, y, z for a position-only
    /// model; each tip's, prefixed, for a model of several tips).
    #[getter]
    fn target_columns(&self) -> Vec<String> {
        target_columns(self.model.tips(), self.model.position_only())
    }

    /// Answer targets (N, len(target_columns)), metres: `k` answers each, each iterated until
    /// every tip is within `tolerance` (millimetres, degrees; 1e-4 and 1e-4 by default).
    /// Returns a dict: `joints` (N, k, dof), `pos_err_mm` and `rot_err_deg` (N, k, the worst
    /// tip's), `exact` (N, k; within 1 mm and 0.572 degrees, the success threshold).
    /// With `scene` (a cuRobo world-configuration YAML file) or `self_collision`, an answer is
    /// exact only if it also keeps `margin` (metres) from the obstacles and from itself
    /// (`srdf`: the file whose `<disable_collisions>` say which links may touch; default the
    /// one beside the URDF), and `collides` (N, k) says which answers did not.
    #[pyo3(signature = (targets, k=1, tolerance=(1e-4, 1e-4), scene=None, self_collision=false, margin=0.005, srdf=None))]
    // Python's keyword arguments, each named at the call.
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        targets: Matrix,
        k: i64,
        tolerance: (f64, f64),
        scene: Option<PathBuf>,
        self_collision: bool,
        margin: f64,
        srdf: Option<PathBuf>,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        guarded(|| {
            let k = count(k, "k", 1, 1000)?;
            let check = if scene.is_some() || self_collision || srdf.is_some() {
                let scene = scene
                    .as_deref()
                    .map(selfmodel::sim::collision::scene::Scene::read)
                    .transpose()
                    .map_err(value_error)?;
                let spec = &self.model.saved.robot;
                Some(
                    py.allow_threads(|| {
                        selfmodel::ik::collision::CollisionCheck::with_spheres(
                            spec,
                            selfmodel::ik::collision::Spheres::KeptIn(&self.dir),
                            srdf.as_deref(),
                            scene,
                            true,
                            margin,
                        )
                    })
                    .map_err(value_error)?,
                )
            } else {
                None
            };
            let lm = self
                .model
                .saved
                .config
                .lm
                .clone()
                .converging_to(tolerance.0, tolerance.1)
                .map_err(|e| value_error(format!("tolerance: {e}")))?;
            let width = self.target_columns().len();
            let (n, v) = rows(targets, width, "targets")?;
            let parsed: Vec<Vec<PoseTarget>> = v
                .chunks(width)
                .take(n)
                .enumerate()
                .map(|(i, row)| {
                    target_from_values(row, self.model.position_only(), self.model.tips())
                        .map_err(|e| value_error(format!("targets row {i}: {e}")))
                })
                .collect::<PyResult<_>>()?;
            // Ctrl-C reaches Python between blocks of targets (well under a second apart).
            let raised = std::sync::Mutex::new(None);
            let answers = py.allow_threads(|| {
                let stop = || interrupted(&raised);
                let how = selfmodel::ik::pose_model::Answering {
                    lm: &lm,
                    stop: &stop,
                    avoid: check.as_ref().map(|c| c as &dyn selfmodel::ik::pose::Avoid),
                };
                self.model
                    .solve_until(&self.robot.chain, &parsed, k, &how, &self.device)
            });
            if let Some(e) = raised.into_inner().unwrap_or_else(|p| p.into_inner()) {
                return Err(e);
            }
            let answers = answers.map_err(value_error)?;
            let dof = self.model.dof();
            let (mut joints, mut pos, mut rot, mut exact) = (
                Vec::with_capacity(n * k * dof),
                Vec::with_capacity(n * k),
                Vec::with_capacity(n * k),
                Vec::with_capacity(n * k),
            );
            let mut collides = Vec::with_capacity(n * k);
            for a in answers.iter().flatten() {
                joints.extend_from_slice(&a.joints);
                pos.push(1000.0 * a.position_error_m);
                rot.push(a.rotation_error_rad.to_degrees());
                exact.push(a.exact(&lm));
                collides.push(a.collides);
            }
            let out = pyo3::types::PyDict::new(py);
            let shape2 = |v: Vec<f64>| {
                numpy::ndarray::Array2::from_shape_vec((n, k), v)
                    .expect("n x k")
                    .into_pyarray(py)
            };
            out.set_item(
                "joints",
                numpy::ndarray::Array3::from_shape_vec((n, k, dof), joints)
                    .expect("n x k x dof")
                    .into_pyarray(py),
            )?;
            out.set_item("pos_err_mm", shape2(pos))?;
            out.set_item("rot_err_deg", shape2(rot))?;
            out.set_item(
                "exact",
                numpy::ndarray::Array2::from_shape_vec((n, k), exact)
                    .expect("n x k")
                    .into_pyarray(py),
            )?;
            if check.is_some() {
                out.set_item(
                    "collides",
                    numpy::ndarray::Array2::from_shape_vec((n, k), collides)
                        .expect("n x k")
                        .into_pyarray(py),
                )?;
            }
            Ok(out)
        })
    }

    /// One target (a sequence of len(target_columns) numbers): the joints of one answer, for
    /// a control loop.
    fn solve_one(&self, py: Python<'_>, target: Vec<f64>) -> PyResult<Vec<f64>> {
        guarded(|| {
            let row = target_from_values(&target, self.model.position_only(), self.model.tips())
                .map_err(|e| value_error(format!("target: {e}")))?;
            let mut a = py
                .allow_threads(|| {
                    self.model.solve(
                        &self.robot.chain,
                        std::slice::from_ref(&row),
                        1,
                        &self.device,
                    )
                })
                .map_err(value_error)?;
            Ok(std::mem::take(&mut a[0][0].joints))
        })
    }

    /// For the benchmark (python/bench): the median seconds of the solver's own work on one
    /// target, timed inside Rust over `repeats` calls, to subtract from a Python call's time.
    fn _solve_one_seconds(&self, target: Vec<f64>, repeats: usize) -> PyResult<f64> {
        guarded(|| {
            let row = target_from_values(&target, self.model.position_only(), self.model.tips())
                .map_err(|e| value_error(format!("target: {e}")))?;
            let mut times: Vec<f64> = (0..repeats.max(1))
                .map(|_| -> selfmodel::Result<f64> {
                    let t0 = std::time::Instant::now();
                    let a = self.model.solve(
                        &self.robot.chain,
                        std::slice::from_ref(&row),
                        1,
                        &self.device,
                    )?;
                    std::hint::black_box(a);
                    Ok(t0.elapsed().as_secs_f64())
                })
                .collect::<selfmodel::Result<_>>()
                .map_err(value_error)?;
            times.sort_by(f64::total_cmp);
            Ok(times[times.len() / 2])
        })
    }
}

/// A self-model a self-model run saved (its `model/` folder): joint values in, the robot's
/// silhouette (and depth, for a model that predicts it) out.
#[pyclass(name = "SelfModel", module = "selfmodel", frozen)]
struct PySelfModel {
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

/// The native module.
#[pymodule]
fn _selfmodel(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRobot>()?;
    m.add_class::<PyIkSolver>()?;
    m.add_class::<PySelfModel>()?;
    Ok(())
}
