//! `selfmodel.IkSolver`: a learned IK model `ik train` saved, answering targets.

use std::path::PathBuf;

use numpy::IntoPyArray;
use pyo3::prelude::*;

use selfmodel::ik::solve::learned::{LearnedIk, target_columns, target_from_values};
use selfmodel::ik::solve::levenberg_marquardt::PoseTarget;
use selfmodel::ik::solve::solver::IkSolver;
use selfmodel::sim::robot::Robot;

use crate::arrays::*;
use crate::calls::*;

/// A learned IK model `ik train` saved, with the robot it was trained for.
#[pyclass(name = "IkSolver", module = "selfmodel", frozen)]
pub(crate) struct PyIkSolver {
    model: LearnedIk,
    robot: Robot,
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
                let (model, robot) = LearnedIk::load_with_robot(&model_dir, &device)?;
                Ok::<_, selfmodel::Error>(PyIkSolver {
                    model,
                    robot,
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
    /// one beside the URDF), and `collides` (N, k) says which answers did not; `collision`
    /// says on what: "exact" (the collision meshes themselves, the spheres their broad phase)
    /// or "spheres" (the spheres alone).
    #[pyo3(signature = (targets, k=1, tolerance=(1e-4, 1e-4), scene=None, self_collision=false, margin=0.005, srdf=None, collision="exact"))]
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
        collision: &str,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        guarded(|| {
            let k = count(k, "k", 1, 1000)?;
            use selfmodel::sim::collision::model::CollisionMode;
            let mode = match collision {
                "exact" => CollisionMode::Exact,
                "spheres" => CollisionMode::Spheres,
                other => {
                    return Err(value_error(format!(
                        "collision {other:?}: give \"exact\" or \"spheres\""
                    )));
                }
            };
            let options = selfmodel::ik::solve::collision::CollisionOptions {
                scene,
                self_collision,
                srdf,
                spheres: None,
                margin,
                mode,
                fit: Default::default(),
            };
            let spec = &self.model.saved.robot;
            let check = py
                .allow_threads(|| options.check(spec, Some(&self.dir)))
                .map_err(value_error)?;
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
                let how = selfmodel::ik::solve::levenberg_marquardt::Answering {
                    lm: &lm,
                    stop: &stop,
                    avoid: check
                        .as_ref()
                        .map(|c| c as &dyn selfmodel::ik::solve::levenberg_marquardt::Avoid),
                };
                self.model.solve(&self.robot.chain, &parsed, k, &how)
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
                        &self.model.answering(),
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
                        &self.model.answering(),
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
