//! `Robot`: a serial manipulator built once from a URDF and frozen; its rigid-body dynamics on
//! one state or many (arrays of shape (N, n)).

use didim_core::error::Error;
use didim_core::model::{Basis, FrictionLaw, LawShape};
use didim_core::robot::{
    map_rows_into, regressor_many, simulate_robot as simulate_robot_core, simulate_robot_sensitivity,
    Directions, Drives, JointKind, RegressorLayout, Robot as CoreRobot, RobotLoopOptions, BODY_PARAMS,
};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::run;

/// One extra term of a joint: its kind, hyper-parameters by name and value.
type JointTerm = (String, Vec<(String, f64)>, f64);

/// One row's outputs, computed, copied into its place.
fn put(dst: &mut [f64], got: Result<Vec<f64>, Error>) -> Result<(), Error> {
    dst.copy_from_slice(&got?);
    Ok(())
}

/// `parts` one after the other into `dst` (a value and its derivatives, as one row).
fn put_parts(dst: &mut [f64], parts: &[&[f64]]) {
    let mut at = 0;
    for p in parts {
        dst[at..at + p.len()].copy_from_slice(p);
        at += p.len();
    }
}

/// A row-major copy of an (N, n) array.
fn flat(a: &PyReadonlyArray2<'_, f64>) -> Vec<f64> {
    a.as_array().iter().copied().collect()
}

/// A serial chain of revolute and prismatic joints under gravity, with each moving body's 10
/// inertial parameters: rigid-body dynamics as Pinocchio computes them.
#[pyclass(frozen, module = "didim._core", name = "Robot")]
pub struct PyRobot {
    pub inner: CoreRobot,
}

impl PyRobot {
    fn batch<'py>(
        &self,
        py: Python<'py>,
        inputs: Vec<Vec<f64>>,
        width: usize,
        shape: Vec<usize>,
        f: impl Fn(&CoreRobot, &[&[f64]], &mut [f64]) -> Result<(), Error> + Sync + Send,
    ) -> PyResult<Bound<'py, PyAny>> {
        let robot = &self.inner;
        let out = run(py, || {
            let refs: Vec<&[f64]> = inputs.iter().map(|v| v.as_slice()).collect();
            map_rows_into(robot, &refs, width, |row, dst| f(robot, row, dst))
        })?;
        Ok(PyArray1::from_vec(py, out).reshape(shape)?.into_any())
    }
}

#[pymethods]
impl PyRobot {
    /// The chain of a URDF document (its text): actuated joints from the root, fixed joints merged;
    /// `joints` picks the actuated ones (the others are locked at zero).
    #[staticmethod]
    #[pyo3(signature = (text, joints=None))]
    fn from_urdf(py: Python<'_>, text: String, joints: Option<Vec<String>>) -> PyResult<Self> {
        let inner = run(py, || CoreRobot::from_urdf(&text, joints.as_deref()))?;
        Ok(PyRobot { inner })
    }

    /// This robot with other inertial parameters (10 per joint, body after body).
    fn with_inertial_params(&self, py: Python<'_>, params: PyReadonlyArray1<'_, f64>) -> PyResult<Self> {
        let pi: Vec<f64> = params.as_array().iter().copied().collect();
        let inner = run(py, || self.inner.with_inertial_params(&pi))?;
        Ok(PyRobot { inner })
    }

    #[getter]
    fn name(&self) -> String {
        self.inner.name.clone()
    }

    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.inner.joints.iter().map(|j| j.name.clone()).collect()
    }

    /// "revolute" or "prismatic", per joint.
    #[getter]
    fn joint_kinds(&self) -> Vec<&'static str> {
        self.inner
            .joints
            .iter()
            .map(|j| match j.kind {
                JointKind::Revolute => "revolute",
                JointKind::Prismatic => "prismatic",
            })
            .collect()
    }

    /// The URDF's movable joints left out (locked at zero): a gripper's fingers by default.
    #[getter]
    fn locked_joints(&self) -> Vec<String> {
        self.inner.locked.clone()
    }

    #[getter]
    fn ndof(&self) -> usize {
        self.inner.ndof()
    }

    /// `<param>_<joint>`: m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz per body.
    #[getter]
    fn param_names(&self) -> Vec<String> {
        self.inner.param_names()
    }

    #[getter]
    fn inertial_params<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.inertial_params())
    }

    /// Per joint: (lower, upper, velocity, effort) limits from the URDF (infinite where it gives none).
    #[getter]
    fn limits(&self) -> Vec<(f64, f64, f64, f64)> {
        self.inner
            .joints
            .iter()
            .map(|j| (j.lower, j.upper, j.velocity_limit, j.effort_limit))
            .collect()
    }

    #[getter]
    fn gravity_vector(&self) -> (f64, f64, f64) {
        let g = self.inner.gravity;
        (g.x, g.y, g.z)
    }

    /// Inverse dynamics of N states: q, v, a of shape (N, n) -> torques (N, n).
    fn rnea<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        v: PyReadonlyArray2<'py, f64>,
        a: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (n, rows) = (self.inner.ndof(), q.as_array().nrows());
        self.batch(
            py,
            vec![flat(&q), flat(&v), flat(&a)],
            n,
            vec![rows, n],
            |r, x, dst| put(dst, r.rnea(x[0], x[1], x[2])),
        )
    }

    /// Inverse dynamics of N states with its exact derivatives: q, v, a (N, n) -> (N, n + 2 n²), each
    /// row the torques, then ∂τ/∂q and ∂τ/∂q̇ (n × n each, row-major: entry (i, j) is ∂τ_i/∂x_j).
    fn rnea_derivatives<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        v: PyReadonlyArray2<'py, f64>,
        a: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (n, rows) = (self.inner.ndof(), q.as_array().nrows());
        let width = n + 2 * n * n;
        self.batch(
            py,
            vec![flat(&q), flat(&v), flat(&a)],
            width,
            vec![rows, width],
            |r, x, dst| {
                let d = r.rnea_derivatives(x[0], x[1], x[2])?;
                put_parts(dst, &[&d.tau, &d.dtau_dq, &d.dtau_dv]);
                Ok(())
            },
        )
    }

    /// Forward dynamics of N states with its exact derivatives: q, v, tau (N, n) -> (N, n + 3 n²),
    /// each row the accelerations, then ∂q̈/∂q, ∂q̈/∂q̇ and ∂q̈/∂τ (n × n each, row-major);
    /// `armature` (n,) on the mass matrix's diagonal.
    #[pyo3(signature = (q, v, tau, armature=None))]
    fn aba_derivatives<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        v: PyReadonlyArray2<'py, f64>,
        tau: PyReadonlyArray2<'py, f64>,
        armature: Option<Vec<f64>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (n, rows) = (self.inner.ndof(), q.as_array().nrows());
        let width = n + 3 * n * n;
        self.batch(
            py,
            vec![flat(&q), flat(&v), flat(&tau)],
            width,
            vec![rows, width],
            move |r, x, dst| {
                let d = r.aba_derivatives(x[0], x[1], x[2], armature.as_deref())?;
                put_parts(dst, &[&d.qdd, &d.dqdd_dq, &d.dqdd_dv, &d.dqdd_dtau]);
                Ok(())
            },
        )
    }

    /// Forward dynamics of N states: q, v, tau (N, n) -> accelerations (N, n); `armature` (n,)
    /// added to the mass matrix's diagonal.
    #[pyo3(signature = (q, v, tau, armature=None))]
    fn aba<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        v: PyReadonlyArray2<'py, f64>,
        tau: PyReadonlyArray2<'py, f64>,
        armature: Option<Vec<f64>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (n, rows) = (self.inner.ndof(), q.as_array().nrows());
        self.batch(
            py,
            vec![flat(&q), flat(&v), flat(&tau)],
            n,
            vec![rows, n],
            move |r, x, dst| put(dst, r.aba(x[0], x[1], x[2], armature.as_deref())),
        )
    }

    /// Gravity torques of N positions (N, n) -> (N, n).
    fn gravity<'py>(&self, py: Python<'py>, q: PyReadonlyArray2<'py, f64>) -> PyResult<Bound<'py, PyAny>> {
        let (n, rows) = (self.inner.ndof(), q.as_array().nrows());
        self.batch(py, vec![flat(&q)], n, vec![rows, n], |r, x, dst| {
            put(dst, r.gravity_torque(x[0]))
        })
    }

    /// Mass matrices of N positions (N, n) -> (N, n, n).
    fn mass_matrix<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (n, rows) = (self.inner.ndof(), q.as_array().nrows());
        self.batch(py, vec![flat(&q)], n * n, vec![rows, n, n], |r, x, dst| {
            // nalgebra is column-major; the matrix is symmetric
            put(dst, r.mass_matrix(x[0]).map(|m| m.as_slice().to_vec()))
        })
    }

    /// The inverse-dynamics regressor of N states (N, n) -> (N, n, 10 n), linear in
    /// `inertial_params`; with `columns`, only those standard parameters' columns
    /// (N, n, len(columns)), the others never stored. `by_joint`: laid out (n, m, N) instead,
    /// each joint's columns a series over the states (its `[j].T` a column-major matrix).
    #[pyo3(signature = (q, v, a, columns=None, by_joint=false))]
    fn regressor<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        v: PyReadonlyArray2<'py, f64>,
        a: PyReadonlyArray2<'py, f64>,
        columns: Option<Vec<usize>>,
        by_joint: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let robot = &self.inner;
        let (n, rows) = (robot.ndof(), q.as_array().nrows());
        let m = columns.as_ref().map_or(BODY_PARAMS * n, Vec::len);
        let (q, v, a) = (flat(&q), flat(&v), flat(&a));
        let cols = columns.as_deref();
        let (layout, shape) = if by_joint {
            (RegressorLayout::Series, vec![n, m, rows])
        } else {
            (RegressorLayout::Rows, vec![rows, n, m])
        };
        let out = run(py, || regressor_many(robot, &q, &v, &a, cols, layout))?;
        Ok(PyArray1::from_vec(py, out).reshape(shape)?.into_any())
    }
}

/// The closed loop of `robot` (its inertial parameters) with the drives (per joint: rotor
/// inertia, viscous and Coulomb friction, offset; each joint's friction law: `coulomb_law` its
/// shape and `coulomb_eps` its smoothing speed, rad/s or m/s), one controller per joint
/// (`(kind, gains)` as `Problem` takes them), following `qr` (N, n) from rest at `qr[0]`, the
/// controllers' output starting at `force0`; `u_ext` (N, n) a known force added to each
/// command, `delay` each joint's actuation delay (samples), `force_lag` each joint's lag from
/// command to force (s); `stiffness` each joint's spring from rotor to link (N·m/rad or N/m,
/// `inf` on a rigid joint; None: all rigid) and `damping` the springs' (N·m·s/rad): a dict of
/// q, qd, qdd (the link side), force (N, n; the force is the commands) and, with an elastic
/// joint, theta, thetad, thetadd (the motor side; the link side's on rigid joints). `terms`: each
/// joint's extra terms, a list per joint of `(kind, [(hyper-parameter, value), ...], value)` of
/// the one-axis model's kinds (`TERM_TABLE`), acting where the joint's friction acts;
/// `load_friction` each joint's friction growing with the torque it carries (μ, 0 for none);
/// `backlash` each elastic joint's dead zone between rotor and link (total width, rad or m; 0 for
/// none; None: none on any joint). With `directions` (P, p): the forward sensitivities of the
/// forces along p directions of the P physical parameters (`PhysLayout`: per joint the rotor
/// inertia, then the bodies' 10 each, then per joint Fv, Fc, offset, K, D, backlash, μ, ε, then the
/// terms' values), `dforce0` (n, p) those of `force0`: `dforce` (n, p, N) in the dict.
#[pyfunction]
#[pyo3(signature = (robot, armature, viscous, coulomb, offset, controllers, qr, dt, *, quantization, force0, substeps=0, coulomb_eps, coulomb_law, u_ext=None, delay=None, force_lag=None, stiffness=None, damping=None, terms=None, load_friction=None, backlash=None, directions=None, dforce0=None))]
#[allow(clippy::too_many_arguments)]
pub fn simulate_robot<'py>(
    py: Python<'py>,
    robot: &PyRobot,
    armature: Vec<f64>,
    viscous: Vec<f64>,
    coulomb: Vec<f64>,
    offset: Vec<f64>,
    controllers: Vec<(String, Vec<f64>)>,
    qr: PyReadonlyArray2<'py, f64>,
    dt: f64,
    quantization: Vec<f64>,
    force0: Vec<f64>,
    substeps: usize,
    coulomb_eps: Vec<f64>,
    coulomb_law: Vec<String>,
    u_ext: Option<PyReadonlyArray2<'py, f64>>,
    delay: Option<Vec<usize>>,
    force_lag: Option<Vec<f64>>,
    stiffness: Option<Vec<f64>>,
    damping: Option<Vec<f64>>,
    terms: Option<Vec<Vec<JointTerm>>>,
    load_friction: Option<Vec<f64>>,
    backlash: Option<Vec<f64>>,
    directions: Option<PyReadonlyArray2<'py, f64>>,
    dforce0: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let (rows, n) = (qr.as_array().nrows(), robot.inner.ndof());
    let qr = flat(&qr);
    let p = directions.as_ref().map_or(0, |d| d.as_array().ncols());
    let directions = directions.as_ref().map(flat);
    let dforce0 = match (&directions, dforce0) {
        (Some(_), Some(d)) if d.as_array().dim() != (n, p) => {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "dforce0 must be (joints, directions) = ({n}, {p}), got {:?}",
                d.as_array().dim()
            )))
        }
        (_, Some(d)) => flat(&d),
        (_, None) => vec![0.0; n * p],
    };
    if let Some(u) = &u_ext {
        let shape = u.as_array().dim();
        if shape != (rows, n) {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "u_ext must be (samples, joints) = ({rows}, {n}) like qr, got {shape:?}"
            )));
        }
    }
    let u_ext: Vec<f64> = u_ext.as_ref().map(flat).unwrap_or_default();
    let out = run(py, || {
        if coulomb_eps.len() != coulomb_law.len() {
            return Err(Error::InvalidInput(format!(
                "{} smoothing speeds for {} friction laws: give one of each per joint",
                coulomb_eps.len(),
                coulomb_law.len()
            )));
        }
        let laws = coulomb_law
            .iter()
            .zip(&coulomb_eps)
            .map(|(shape, &eps)| {
                Ok(FrictionLaw {
                    shape: LawShape::from_name(shape)?,
                    eps,
                })
            })
            .collect::<Result<Vec<_>, Error>>()?;
        let terms = terms
            .unwrap_or_default()
            .iter()
            .map(|joint| {
                joint
                    .iter()
                    .map(|(kind, hypers, value)| {
                        let h: Vec<(&str, f64)> = hypers.iter().map(|(k, v)| (k.as_str(), *v)).collect();
                        Ok((Basis::from_kind(kind, &h, 0)?, *value))
                    })
                    .collect::<Result<Vec<_>, Error>>()
            })
            .collect::<Result<Vec<_>, Error>>()?;
        let drives = Drives {
            armature,
            viscous,
            coulomb,
            offset,
            laws,
            stiffness: stiffness.unwrap_or_default(),
            damping: damping.unwrap_or_default(),
            backlash: backlash.unwrap_or_default(),
            terms,
            load_friction: load_friction.unwrap_or_default(),
        };
        let control = controllers
            .iter()
            .map(|(kind, gains)| crate::make_controller(kind, gains).and_then(|c| c.law(dt)))
            .collect::<Result<Vec<_>, Error>>()?;
        let mut opts = RobotLoopOptions::new(dt, substeps, quantization, force0);
        opts.u_ext = u_ext;
        opts.delay = delay.unwrap_or_default();
        opts.force_lag = force_lag.unwrap_or_default();
        match &directions {
            None => simulate_robot_core(&robot.inner, &drives, &control, &qr, &opts).map(|o| (o, Vec::new())),
            Some(dirs) => simulate_robot_sensitivity(
                &robot.inner,
                &drives,
                &control,
                &qr,
                &opts,
                Directions {
                    count: p,
                    physical: dirs,
                    force0: &dforce0,
                },
            ),
        }
    })?;
    let (out, dforce) = out;
    let d = pyo3::types::PyDict::new(py);
    for (name, x) in [
        ("q", out.q),
        ("qd", out.qd),
        ("qdd", out.qdd),
        ("force", out.force),
        ("theta", out.theta),
        ("thetad", out.thetad),
        ("thetadd", out.thetadd),
    ] {
        if !x.is_empty() {
            d.set_item(name, PyArray1::from_vec(py, x).reshape([rows, n])?)?;
        }
    }
    if directions.is_some() {
        d.set_item("dforce", PyArray1::from_vec(py, dforce).reshape([n, p, rows])?)?;
    }
    Ok(d)
}
