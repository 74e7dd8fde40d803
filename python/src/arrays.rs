//! Arrays and values as Python hands them over, checked for size before they are copied,
//! then for shape and finiteness.

use numpy::PyReadonlyArray2;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;

use crate::calls::*;

/// A 2-D array of numbers as Python hands it over: any float, integer or bool dtype, either
/// byte order, any strides (a broadcast view included), cast to float64 once its size is
/// known to be one a call takes. Anything else is a `TypeError` (not numbers) or a
/// `ValueError` (not 2-D, too many rows) of one line.
pub(crate) struct Matrix {
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
pub(crate) struct Names(pub(crate) Vec<String>);

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
pub(crate) fn count(value: i64, what: &str, lo: usize, hi: usize) -> PyResult<usize> {
    usize::try_from(value)
        .ok()
        .filter(|v| (lo..=hi).contains(v))
        .ok_or_else(|| value_error(format!("{what} must be {lo} to {hi}, got {value}")))
}

/// The rows of a 2-D array with `width` columns, finite: `(rows, values)`.
pub(crate) fn rows(a: Matrix, width: usize, what: &str) -> PyResult<(usize, Vec<f64>)> {
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
pub(crate) const MAX_ROWS: usize = 10_000_000;
