//! numpy <-> Rust conversions: borrow contiguous arrays, copy the others.

use std::borrow::Cow;

use didim_core::filter::Decimation;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyOverflowError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyComplex, PyInt};

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

/// A 2-D array (n, p) to decimate column by column: borrowed row-major when C-contiguous,
/// borrowed column-major when Fortran-contiguous, copied column-major otherwise.
pub enum Matrix<'a> {
    RowMajor(&'a [f64]),
    ColMajor(Cow<'a, [f64]>),
}

impl<'a> Matrix<'a> {
    /// The matrix of `a`, with its shape (n, p).
    pub fn of(a: &'a PyReadonlyArray2<'_, f64>) -> (Self, usize, usize) {
        let (n, p) = (a.shape()[0], a.shape()[1]);
        if let Ok(s) = a.as_slice() {
            if a.is_c_contiguous() {
                return (Matrix::RowMajor(s), n, p);
            }
            if a.is_fortran_contiguous() {
                return (Matrix::ColMajor(Cow::Borrowed(s)), n, p);
            }
        }
        let (c, n, p) = columns2(a);
        (Matrix::ColMajor(Cow::Owned(c)), n, p)
    }

    /// `dec`'s parallel decimation of `y` and the `p` columns of this matrix: (y_dec, w_dec
    /// column-major).
    pub fn decimate(
        &self,
        dec: &Decimation,
        y: &[f64],
        p: usize,
    ) -> Result<(Vec<f64>, Vec<f64>), didim_core::Error> {
        match self {
            Matrix::RowMajor(w) => dec.apply_parallel_rows(y, w, p),
            Matrix::ColMajor(w) => dec.apply_parallel(y, w, p),
        }
    }
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

/// A whole-number argument (a count, an order, a factor, a padding). Any Python `int` is accepted at extraction, so
/// that a negative or too large value becomes a `DataError` naming the argument ([`Whole::get`]) instead of an
/// `OverflowError`; `bool` and non-integers are a `TypeError`.
#[derive(Clone, Debug)]
pub struct Whole(Result<usize, String>);

impl Whole {
    pub const fn new(v: usize) -> Self {
        Whole(Ok(v))
    }

    /// The value, or the error message about argument `name`.
    pub fn get(&self, name: &str) -> Result<usize, didim_core::Error> {
        self.0.clone().map_err(|v| {
            didim_core::Error::InvalidInput(format!(
                "{name} must be a whole number between 0 and {}, got {v}",
                usize::MAX
            ))
        })
    }
}

impl<'a, 'py> FromPyObject<'a, 'py> for Whole {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        if !obj.is_instance_of::<PyInt>() || obj.is_instance_of::<PyBool>() {
            // numpy integer scalars are not int subclasses but implement __index__ (numpy.bool does not)
            if !obj.is_instance_of::<PyBool>() {
                if let Ok(i) = obj.call_method0("__index__") {
                    if i.is_instance_of::<PyInt>() {
                        return Whole::extract(i.as_borrowed());
                    }
                }
            }
            return Err(PyTypeError::new_err(format!(
                "expected a whole number (int), got {}",
                obj.get_type().name()?
            )));
        }
        Ok(Whole(obj.extract::<usize>().map_err(|_| {
            obj.repr()
                .map(|r| r.to_string())
                .unwrap_or_else(|_| "an out-of-range int".into())
        })))
    }
}

/// A real-number argument: like `f64`, but an `int` too large for a float becomes ±infinity (refused by the
/// validation with a `DataError` naming the argument) instead of an `OverflowError`.
#[derive(Clone, Copy, Debug)]
pub struct Real(pub f64);

impl<'a, 'py> FromPyObject<'a, 'py> for Real {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        // a complex number (Python's or numpy's) would otherwise lose its imaginary part with only a warning
        if obj.is_instance_of::<PyComplex>() || obj.get_type().name()?.to_string().contains("complex") {
            return Err(PyTypeError::new_err(format!(
                "expected a real number, got {}",
                obj.get_type().name()?
            )));
        }
        match obj.extract::<f64>() {
            Ok(v) => Ok(Real(v)),
            Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => {
                let negative = obj.lt(0).unwrap_or(false);
                Ok(Real(if negative {
                    f64::NEG_INFINITY
                } else {
                    f64::INFINITY
                }))
            }
            Err(e) => Err(e),
        }
    }
}

/// A list of real numbers (see [`Real`]).
pub fn reals(v: Vec<Real>) -> Vec<f64> {
    v.into_iter().map(|r| r.0).collect()
}
