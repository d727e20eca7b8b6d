//! PyO3 bindings of `didim-core`, imported in Python as `didim._core`.
//!
//! This crate only converts types: numpy arrays in (borrowed read-only, copied
//! only when not contiguous), numpy arrays out, the interpreter lock released
//! around every computation, core errors mapped to the exception classes of
//! `didim._errors`, and panics caught before they can reach Python.

use std::panic::{catch_unwind, AssertUnwindSafe};

use didim_core::error::Error;
use didim_core::model::{self, Model, DEFAULT_COULOMB_EPS};
use didim_core::{sim, Controller};
use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyType};

mod convert;
use convert::*;

/// Runs a core computation without the interpreter lock, turning panics into errors.
fn run<T: Send>(py: Python<'_>, f: impl FnOnce() -> Result<T, Error> + Send) -> PyResult<T> {
    let out = py.detach(|| catch_unwind(AssertUnwindSafe(f)));
    match out {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(core_error(py, e)),
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".to_string());
            Err(py_error(
                py,
                "DidimError",
                format!(
                    "internal error in didim's core (please report it with the input that caused it): {what}"
                ),
            ))
        }
    }
}

/// Maps a core error to its Python class.
fn core_error(py: Python<'_>, e: Error) -> PyErr {
    match e {
        Error::InvalidInput(m) => py_error(py, "DataError", m),
        Error::Simulation(m) => py_error(py, "SimulationError", m),
        Error::Identifiability(m) => py_error(py, "IdentifiabilityError", m),
    }
}

/// An exception of class `name` from `didim._errors`.
fn py_error(py: Python<'_>, name: &str, msg: String) -> PyErr {
    let class = py
        .import("didim._errors")
        .and_then(|m| m.getattr(name))
        .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
    match class {
        Ok(c) => PyErr::from_type(c, msg),
        Err(_) if name == "DataError" => PyValueError::new_err(msg),
        Err(_) => PyRuntimeError::new_err(msg),
    }
}

/// A model chosen by name: "rigid" (M, Fv, Fc[, OF]) or "flexible" (M1, Fv1, Fc1, M2, Fv2, Fc2, K12).
enum AnyModel {
    Rigid(Model<1>),
    Flexible(Model<2>),
}

fn make_model(kind: &str, offset: bool, coulomb_eps: f64) -> Result<AnyModel, Error> {
    match kind {
        "rigid" => Ok(AnyModel::Rigid(model::rigid(offset, coulomb_eps)?)),
        "flexible" if offset => Err(Error::InvalidInput(
            "offset is only available for the rigid model".into(),
        )),
        "flexible" => Ok(AnyModel::Flexible(model::flexible(coulomb_eps)?)),
        other => Err(Error::InvalidInput(format!(
            "unknown model {other:?}: use \"rigid\" or \"flexible\""
        ))),
    }
}

fn make_controller(kind: &str, gains: &[f64]) -> Result<Controller, Error> {
    let c = match (kind, gains) {
        ("emps", [kp, kv, gtau, vsat]) => Controller::EmpsCascade {
            kp: *kp,
            kv: *kv,
            gtau: *gtau,
            vsat: *vsat,
        },
        ("pd", [kp, kd, tau_max]) => Controller::Pd {
            kp: *kp,
            kd: *kd,
            tau_max: *tau_max,
        },
        ("emps", g) => {
            return Err(Error::InvalidInput(format!(
                "the emps controller takes 4 gains (kp, kv, gtau, vsat), got {}",
                g.len()
            )))
        }
        ("pd", g) => {
            return Err(Error::InvalidInput(format!(
                "the pd controller takes 3 gains (kp, kd, tau_max), got {}",
                g.len()
            )))
        }
        (other, _) => {
            return Err(Error::InvalidInput(format!(
                "unknown controller {other:?}: use \"emps\" or \"pd\""
            )))
        }
    };
    c.validate()?;
    Ok(c)
}

/// Parameter names of a model, in the order of the parameter vector.
#[pyfunction]
#[pyo3(signature = (model, offset=false))]
fn param_names(py: Python<'_>, model: &str, offset: bool) -> PyResult<Vec<String>> {
    let m = run(py, || make_model(model, offset, DEFAULT_COULOMB_EPS))?;
    Ok(match m {
        AnyModel::Rigid(m) => m.names().to_vec(),
        AnyModel::Flexible(m) => m.names().to_vec(),
    })
}

/// Closed-loop simulation; returns a dict of arrays: force (n,), q, qd, qdd (ndof, n).
#[pyfunction]
#[pyo3(signature = (model, params, qr, dt, controller, gains, *, u_ext=None, substeps=10, quantization=0.0, delay=0, coulomb_eps=DEFAULT_COULOMB_EPS, offset=false))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    model: &str,
    params: PyReadonlyArray1<'py, f64>,
    qr: PyReadonlyArray1<'py, f64>,
    dt: f64,
    controller: &str,
    gains: Vec<f64>,
    u_ext: Option<PyReadonlyArray1<'py, f64>>,
    substeps: usize,
    quantization: f64,
    delay: usize,
    coulomb_eps: f64,
    offset: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let chi = slice1(&params);
    let qr = slice1(&qr);
    let u = u_ext.as_ref().map(slice1);
    let opts = sim::SimOptions {
        dt,
        substeps,
        quantization,
        delay,
    };
    let (chi, qr, u): (&[f64], &[f64], Option<&[f64]>) = (&chi, &qr, u.as_deref());
    let out = run(py, || {
        let c = make_controller(controller, &gains)?;
        match make_model(model, offset, coulomb_eps)? {
            AnyModel::Rigid(m) => sim::simulate(&m, chi, &c, qr, u, &opts),
            AnyModel::Flexible(m) => sim::simulate(&m, chi, &c, qr, u, &opts),
        }
    })?;
    let d = PyDict::new(py);
    d.set_item("force", out.force.into_pyarray(py))?;
    d.set_item("q", rows_to_array(py, out.q)?)?;
    d.set_item("qd", rows_to_array(py, out.qd)?)?;
    d.set_item("qdd", rows_to_array(py, out.qdd)?)?;
    Ok(d)
}

/// The IDM regressor of a trajectory: q, qd, qdd of shape (ndof, n) -> W of shape (ndof, n, p).
#[pyfunction]
#[pyo3(signature = (model, q, qd, qdd, *, coulomb_eps=DEFAULT_COULOMB_EPS, offset=false))]
fn regressor<'py>(
    py: Python<'py>,
    model: &str,
    q: PyReadonlyArray2<'py, f64>,
    qd: PyReadonlyArray2<'py, f64>,
    qdd: PyReadonlyArray2<'py, f64>,
    coulomb_eps: f64,
    offset: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let (q, qd, qdd) = (rows2(&q), rows2(&qd), rows2(&qdd));
    let n = q.first().map_or(0, |r| r.len());
    let (ndof, p, w) = run(py, || match make_model(model, offset, coulomb_eps)? {
        AnyModel::Rigid(m) => Ok((1, m.n_params(), m.regressor(&q, &qd, &qdd)?)),
        AnyModel::Flexible(m) => Ok((2, m.n_params(), m.regressor(&q, &qd, &qdd)?)),
    })?;
    // core layout [dof][param][sample] -> numpy (ndof, p, n) -> view (ndof, n, p)
    let a = PyArray1::from_vec(py, w).reshape([ndof, p, n])?;
    a.call_method1("transpose", ((0, 2, 1),))
}

/// The compiled core of didim. Use the `didim` package, not this module.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("DEFAULT_COULOMB_EPS", DEFAULT_COULOMB_EPS)?;
    m.add_function(wrap_pyfunction!(param_names, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(regressor, m)?)?;
    Ok(())
}
