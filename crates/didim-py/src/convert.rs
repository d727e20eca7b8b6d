//! numpy <-> Rust conversions: borrow contiguous arrays, copy the others.

use std::borrow::Cow;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

/// A 1-D array as a slice, borrowed when contiguous.
pub fn slice1<'a>(a: &'a PyReadonlyArray1<'_, f64>) -> Cow<'a, [f64]> {
    match a.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
    }
}

/// The rows of a 2-D array as vectors.
pub fn rows2(a: &PyReadonlyArray2<'_, f64>) -> Vec<Vec<f64>> {
    a.as_array()
        .rows()
        .into_iter()
        .map(|r| r.iter().copied().collect())
        .collect()
}

/// The columns of a 2-D array (n, p), column-major, and p.
pub fn columns2(a: &PyReadonlyArray2<'_, f64>) -> (Vec<f64>, usize, usize) {
    let v = a.as_array();
    let (n, p) = (v.shape()[0], v.shape()[1]);
    let mut out = Vec::with_capacity(n * p);
    for col in v.columns() {
        out.extend(col.iter().copied());
    }
    (out, n, p)
}

/// Equal-length rows -> a 2-D numpy array (rows, n).
pub fn rows_to_array<'py>(py: Python<'py>, rows: Vec<Vec<f64>>) -> PyResult<Bound<'py, PyAny>> {
    let r = rows.len();
    let n = rows.first().map_or(0, |x| x.len());
    let flat: Vec<f64> = rows.into_iter().flatten().collect();
    Ok(PyArray1::from_vec(py, flat).reshape([r, n])?.into_any())
}

/// A column-major (n, p) buffer -> a 2-D numpy array (n, p).
pub fn colmajor_to_array<'py>(
    py: Python<'py>,
    data: Vec<f64>,
    n: usize,
    p: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let a = PyArray1::from_vec(py, data).reshape([p, n])?;
    a.call_method0("transpose")
}
