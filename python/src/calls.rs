//! How a call of the native module runs: a panic turned into one line, the library's errors
//! as `ValueError`, long calls in blocks with Python's Ctrl-C asked between them.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// `f`, a method's body, with any panic inside it (a bug: the library's errors are values)
/// turned into a `RuntimeError` of one line that says so, never a `PanicException` that
/// ends a script.
pub(crate) fn guarded<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    selfmodel::core::input_file::catch_panic(f).unwrap_or_else(|panic| {
        let panic = panic.split_whitespace().collect::<Vec<_>>().join(" ");
        Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
            "selfmodel failed inside ({panic}): a bug, please report it with the call that made it"
        )))
    })
}

/// The library's error as Python's `ValueError` (one line).
pub(crate) fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Rows of fk or jacobian between two looks at Ctrl-C (a few hundredths of a second).
pub(crate) const ROWS_A_BLOCK: usize = 1 << 16;

/// Images of render or predict between two looks at Ctrl-C.
pub(crate) const IMAGES_A_BLOCK: usize = 512;

/// Python's own Ctrl-C check, for a long call that released the GIL: `true` once a signal
/// handler raised (KeyboardInterrupt), the exception kept in `raised` for the call to return.
pub(crate) fn interrupted(raised: &std::sync::Mutex<Option<PyErr>>) -> bool {
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
pub(crate) fn in_blocks<T: Send>(
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
