//! The Python package's native module (`selfmodel._selfmodel`): a thin layer over the crate.
//! Arrays come in as numpy arrays of numbers (any float or integer dtype, either byte order,
//! any strides), are checked for size before they are copied, then for shape and finiteness
//! (a `ValueError` or `TypeError` of one line, never a crash), and the GIL is released while
//! Rust computes.

mod arrays;
mod calls;
mod ik_solver;
mod robot;
mod self_model;

use pyo3::prelude::*;

use ik_solver::PyIkSolver;
use robot::PyRobot;
use self_model::PySelfModel;

/// The native module.
#[pymodule]
fn _selfmodel(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRobot>()?;
    m.add_class::<PyIkSolver>()?;
    m.add_class::<PySelfModel>()?;
    Ok(())
}
