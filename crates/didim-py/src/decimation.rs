//! `Decimation`: a decimation design (zero-phase low-pass and down-sampling) held on the Rust
//! side, designed once and handed to the problems, the models' decimated columns and `decimate`.

use didim_core::error::Error;
use didim_core::filter::{Decimation as CoreDecimation, FilterForm};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::convert::*;
use crate::{core_error, run, Decimated};

/// Builds a core decimator from the keyword options of `decimate`.
pub fn make_decimation(
    factor: usize,
    kind: &str,
    order: usize,
    cutoff_hz: Option<f64>,
    fs_hz: Option<f64>,
    form: &str,
) -> Result<CoreDecimation, Error> {
    match (kind, cutoff_hz, fs_hz) {
        ("matlab", _, _) => CoreDecimation::matlab(factor),
        ("butter", Some(c), Some(fs)) => {
            let form = match form {
                "sos" => FilterForm::Sos,
                "ba" => FilterForm::Ba,
                other => {
                    return Err(Error::InvalidInput(format!(
                        "unknown filter form {other:?}: use \"sos\" or \"ba\""
                    )))
                }
            };
            CoreDecimation::butterworth(order, c, fs, factor, form)
        }
        ("butter", _, _) => Err(Error::InvalidInput(
            "a Butterworth decimation needs cutoff_hz and fs_hz".into(),
        )),
        (other, _, _) => Err(Error::InvalidInput(format!(
            "unknown decimation kind {other:?}: use \"butter\" or \"matlab\""
        ))),
    }
}

/// A decimation design (zero-phase low-pass and down-sampling), designed once.
#[pyclass(frozen, module = "didim._core")]
pub struct Decimation {
    pub inner: CoreDecimation,
}

#[pymethods]
impl Decimation {
    #[new]
    #[pyo3(signature = (factor, *, kind="butter", order=4, cutoff_hz=None, fs_hz=None, form="sos"))]
    fn new(
        py: Python<'_>,
        factor: usize,
        kind: &str,
        order: usize,
        cutoff_hz: Option<f64>,
        fs_hz: Option<f64>,
        form: &str,
    ) -> PyResult<Self> {
        let inner =
            make_decimation(factor, kind, order, cutoff_hz, fs_hz, form).map_err(|e| core_error(py, e))?;
        Ok(Self { inner })
    }

    /// The share of a sinusoid's amplitude at `f_rel` (its frequency over the Nyquist frequency) that the
    /// zero-phase filter passes.
    fn gain(&self, f_rel: f64) -> f64 {
        self.inner.gain(f_rel)
    }

    /// Number of samples kept from `n`.
    fn output_len(&self, n: usize) -> usize {
        self.inner.output_len(n)
    }

    /// Decimates y (n,) and, when given, every column of w (n, p) alike; returns (y_dec, w_dec).
    #[pyo3(signature = (y, w=None))]
    fn apply<'py>(
        &self,
        py: Python<'py>,
        y: PyReadonlyArray1<'py, f64>,
        w: Option<PyReadonlyArray2<'py, f64>>,
    ) -> PyResult<Decimated<'py>> {
        decimate_arrays(py, &self.inner, y, w)
    }
}

/// `y` (n,) and, when given, every column of `w` (n, p) decimated by `dec`: `(y_dec, w_dec)`
/// (`Decimation.apply` and the module's `decimate`).
pub fn decimate_arrays<'py>(
    py: Python<'py>,
    dec: &CoreDecimation,
    y: PyReadonlyArray1<'py, f64>,
    w: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<Decimated<'py>> {
    let y = slice1(&y);
    let y: &[f64] = &y;
    let (wm, n, p) = match &w {
        Some(w) => Matrix::of(w),
        None => (Matrix::ColMajor(Vec::new().into()), y.len(), 0),
    };
    let (yd, wd) = run(py, || {
        if p > 0 && n != y.len() {
            return Err(Error::InvalidInput(format!(
                "w has {n} rows but y has {} samples",
                y.len()
            )));
        }
        wm.decimate(dec, y, p)
    })?;
    let m = yd.len();
    let wd = match w {
        Some(_) => Some(colmajor_to_array(py, wd, m, p)?),
        None => None,
    };
    Ok((yd.into_pyarray(py), wd))
}
