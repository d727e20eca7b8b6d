//! `Problem`: a record's closed loop held on the Rust side (with a `Decimation` of
//! [`crate::decimation`]), so that an identification builds them once and then iterates with one call
//! per step (simulation, decimation, residuals and regressors stay in Rust).

use didim_core::error::Error;
use didim_core::model::Model;
use didim_core::objective::{split_errors, BatchOut, Output, Problem as CoreProblem};
use didim_core::sim::{self, SimOutput};
use didim_core::Controller;
use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::*;
use crate::decimation::Decimation;
use crate::{core_error, interrupted, make_controller, quick, run, sim_options, AnyModel};

type Arr<'py> = Bound<'py, PyArray1<f64>>;
type Costs<'py> = (Arr<'py>, Vec<Option<String>>);
type System<'py> = (Arr<'py>, Bound<'py, PyAny>, Arr<'py>);

fn parse_output(output: &str) -> Result<Output, Error> {
    match output {
        "force" => Ok(Output::Force),
        "position" => Ok(Output::MotorPosition),
        other => Err(Error::InvalidInput(format!(
            "unknown output {other:?}: use \"force\" or \"position\""
        ))),
    }
}

/// A record's closed loop (model structure, controller, reference, external input,
/// simulator options), for repeated simulations with varying parameters.
#[pyclass(frozen, module = "didim._core")]
pub struct Problem {
    model: AnyModel,
    controller: Controller,
    qr: Vec<f64>,
    u_ext: Option<Vec<f64>>,
    opts: sim::SimOptions,
}

/// Runs `f` with the core problem of the right number of dofs.
macro_rules! with_problem {
    ($self:ident, $pb:ident => $body:expr) => {
        match &$self.model {
            AnyModel::Rigid(m) => {
                let $pb = $self.core(m);
                $body
            }
            AnyModel::Flexible(m) => {
                let $pb = $self.core(m);
                $body
            }
        }
    };
}

impl Problem {
    fn core<'a, const N: usize>(&'a self, model: &'a Model<N>) -> CoreProblem<'a, N> {
        CoreProblem {
            model,
            controller: self.controller,
            qr: &self.qr,
            u_ext: self.u_ext.as_deref(),
            opts: self.opts,
        }
    }

    fn n_params_(&self) -> usize {
        self.model.n_params()
    }

    fn ndof_(&self) -> usize {
        self.model.ndof()
    }
}

fn sim_dict<'py>(py: Python<'py>, out: SimOutput) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("force", out.force.into_pyarray(py))?;
    for (key, s) in [("q", out.q), ("qd", out.qd), ("qdd", out.qdd)] {
        let (rows, n) = (s.len(), s.iter().next().map_or(0, <[f64]>::len));
        d.set_item(key, PyArray1::from_vec(py, s.into_flat()).reshape([rows, n])?)?;
        // no copy
    }
    Ok(d)
}

#[pymethods]
impl Problem {
    #[new]
    #[pyo3(signature = (model, qr, dt, controller, gains, *, u_ext=None, substeps=Whole::new(10), quantization=Real(0.0), integrator="exponential", tol=Real(sim::DEFAULT_TOL), lead=Whole::new(0)))]
    #[pyo3(
        text_signature = "(model, qr, dt, controller, gains, *, u_ext=None, substeps=10, quantization=0.0, integrator='exponential', tol=..., lead=0)"
    )]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        model: PyRef<'_, crate::model::PyModel>,
        qr: PyReadonlyArray1<'_, f64>,
        dt: Real,
        controller: &str,
        gains: Vec<Real>,
        u_ext: Option<PyReadonlyArray1<'_, f64>>,
        substeps: Whole,
        quantization: Real,
        integrator: &str,
        tol: Real,
        lead: Whole,
    ) -> PyResult<Self> {
        let gains = reals(gains);
        let whole = |w: Whole, name: &str| w.get(name).map_err(|e| core_error(py, e));
        let mut opts = sim_options(
            py,
            dt.0,
            whole(substeps, "substeps")?,
            quantization.0,
            integrator,
            tol.0,
            whole(lead, "lead")?,
        )?;
        let qr = slice1(&qr).into_owned();
        let u_ext = u_ext.as_ref().map(|u| slice1(u).into_owned());
        let actuation = model.actuation.clone();
        let model = model.inner.clone();
        let controller = quick(py, || {
            for (name, value) in &actuation {
                opts.set_actuation(name, *value)?;
            }
            opts.validate()?;
            make_controller(controller, &gains)
        })?;
        Ok(Self {
            model,
            controller,
            qr,
            u_ext,
            opts,
        })
    }

    /// The force the plant receives (mean over each sample period) under the logged commands
    /// `force` (n,): through this loop's actuation delay and force lag, as the simulator applies
    /// them. DIDIM regresses the simulated states against it.
    fn applied_force<'py>(
        &self,
        py: Python<'py>,
        force: PyReadonlyArray1<'py, f64>,
    ) -> Bound<'py, PyArray1<f64>> {
        let f = slice1(&force);
        PyArray1::from_vec(
            py,
            sim::applied_force(&f, self.opts.delay, self.opts.force_lag, self.opts.dt, 0.0),
        )
    }

    /// Number of parameters of the model.
    #[getter]
    fn n_params(&self) -> usize {
        self.n_params_()
    }

    /// Number of degrees of freedom (1 rigid, 2 flexible).
    #[getter]
    fn ndof(&self) -> usize {
        self.ndof_()
    }

    /// Number of output samples (the reference's, its lead-in left out).
    #[getter]
    fn n(&self) -> usize {
        self.opts.outputs(self.qr.len())
    }

    /// One simulation: dict of force (n,), q, qd, qdd (ndof, n).
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        params: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let chi = slice1(&params);
        let chi: &[f64] = &chi;
        let out = run(py, || with_problem!(self, pb => pb.simulate(chi)))?;
        sim_dict(py, out)
    }

    /// One simulation and its forward sensitivities: dict of force (n,), q, qd, qdd (ndof, n),
    /// dforce (p, n) and dq (ndof, p, n), the derivatives of force and q with respect to params.
    fn simulate_sensitivity<'py>(
        &self,
        py: Python<'py>,
        params: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let chi = slice1(&params);
        let chi: &[f64] = &chi;
        let out = run(py, || with_problem!(self, pb => pb.simulate_sensitivity(chi)))?;
        let (p, n, ndof) = (chi.len(), self.opts.outputs(self.qr.len()), self.ndof_());
        let d = sim_dict(py, out.sim)?;
        d.set_item("dforce", PyArray1::from_vec(py, out.dforce).reshape([p, n])?)?;
        d.set_item("dq", PyArray1::from_vec(py, out.dq).reshape([ndof, p, n])?)?;
        Ok(d)
    }

    /// Simulations of the rows of params (m, p) in parallel: dict of force (m, n), q (m, ndof, n),
    /// with states=True also qd and qdd, and errors (a list, None where the simulation succeeded;
    /// the rows of a failed member are NaN).
    #[pyo3(signature = (params, *, states=false))]
    fn simulate_batch<'py>(
        &self,
        py: Python<'py>,
        params: PyReadonlyArray2<'py, f64>,
        states: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let chis = rows2(&params);
        let (n, ndof) = (self.opts.outputs(self.qr.len()), self.ndof_());
        let m = chis.len();
        // the arrays below, and one set's signals per thread while it is copied into them: check that the whole
        // fits before starting (an allocation that fails halfway would abort the process)
        let per_set = n.saturating_mul(1 + ndof * if states { 3 } else { 1 });
        let in_flight = rayon::current_num_threads().saturating_mul(n.saturating_mul(1 + 3 * ndof));
        let total = m
            .saturating_mul(per_set)
            .saturating_add(m.saturating_mul(per_set) / 10)
            .saturating_add(in_flight);
        drop(
            didim_core::error::room(total, &format!("the batch of {m} simulations"))
                .map_err(|e| core_error(py, e))?,
        );
        let big =
            |len: usize, what: &str| didim_core::error::filled(len, 0.0, what).map_err(|e| core_error(py, e));
        let mut force = big(m * n, "the batch's forces")?;
        let mut q = big(m * ndof * n, "the batch's positions")?;
        let (mut qd, mut qdd) = if states {
            (
                big(m * ndof * n, "the batch's velocities")?,
                big(m * ndof * n, "the batch's accelerations")?,
            )
        } else {
            (Vec::new(), Vec::new())
        };
        let results = run(py, || {
            let out = BatchOut {
                force: &mut force,
                q: &mut q,
                qd: states.then_some(&mut qd[..]),
                qdd: states.then_some(&mut qdd[..]),
            };
            interrupted(with_problem!(self, pb => pb.simulate_batch(&chis, out)))
        })?;
        let (_, errs) = split_errors(results);
        let d = PyDict::new(py);
        d.set_item("force", PyArray1::from_vec(py, force).reshape([m, n])?)?;
        d.set_item("q", PyArray1::from_vec(py, q).reshape([m, ndof, n])?)?;
        if states {
            d.set_item("qd", PyArray1::from_vec(py, qd).reshape([m, ndof, n])?)?;
            d.set_item("qdd", PyArray1::from_vec(py, qdd).reshape([m, ndof, n])?)?;
        }
        let errors: Vec<Option<String>> = errs.into_iter().map(|e| e.map(|e| e.to_string())).collect();
        d.set_item("errors", errors)?;
        Ok(d)
    }

    /// ‖measured_dec − decimator(simulated output)‖² (output "force" or "position") over the
    /// decimated rows from `skip` on.
    #[pyo3(signature = (params, measured_dec, decimator, *, output="force", skip=Whole::new(0)))]
    #[pyo3(text_signature = "(self, /, params, measured_dec, decimator, *, output='force', skip=0)")]
    fn squared_error(
        &self,
        py: Python<'_>,
        params: PyReadonlyArray1<'_, f64>,
        measured_dec: PyReadonlyArray1<'_, f64>,
        decimator: &Decimation,
        output: &str,
        skip: Whole,
    ) -> PyResult<f64> {
        let chi = slice1(&params);
        let meas = slice1(&measured_dec);
        let (chi, meas): (&[f64], &[f64]) = (&chi, &meas);
        run(py, || {
            let out = parse_output(output)?;
            let skip = skip.get("skip")?;
            with_problem!(self, pb => pb.squared_error(chi, out, meas, &decimator.inner, skip))
        })
    }

    /// squared_error of the rows of params (m, p) in parallel: (costs (m,), errors), NaN cost where
    /// the simulation failed.
    #[pyo3(signature = (params, measured_dec, decimator, *, output="force", skip=Whole::new(0)))]
    #[pyo3(text_signature = "(self, /, params, measured_dec, decimator, *, output='force', skip=0)")]
    fn squared_error_batch<'py>(
        &self,
        py: Python<'py>,
        params: PyReadonlyArray2<'py, f64>,
        measured_dec: PyReadonlyArray1<'py, f64>,
        decimator: &Decimation,
        output: &str,
        skip: Whole,
    ) -> PyResult<Costs<'py>> {
        let chis = rows2(&params);
        let meas = slice1(&measured_dec);
        let meas: &[f64] = &meas;
        let results = run(py, || {
            let out = parse_output(output)?;
            let skip = skip.get("skip")?;
            interrupted(
                with_problem!(self, pb => pb.squared_error_batch(&chis, out, meas, &decimator.inner, skip)),
            )
        })?;
        let (vals, errs) = split_errors(results);
        let costs: Vec<f64> = vals.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect();
        Ok((
            costs.into_pyarray(py),
            errs.into_iter().map(|e| e.map(|e| e.to_string())).collect(),
        ))
    }

    /// DIDIM's decimated system at params: (y (r,), w (r, len(free)), force_dec) with the rows of
    /// every dof stacked (motor row against force minus the frozen terms, the others against minus
    /// the frozen terms); with `with_q`, the simulated motor position (n,) as a fourth item.
    #[pyo3(signature = (params, force, free, decimator, *, with_q=false))]
    fn didim_system<'py>(
        &self,
        py: Python<'py>,
        params: PyReadonlyArray1<'py, f64>,
        force: PyReadonlyArray1<'py, f64>,
        free: Vec<usize>,
        decimator: &Decimation,
        with_q: bool,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let chi = slice1(&params);
        let f = slice1(&force);
        let (chi, f): (&[f64], &[f64]) = (&chi, &f);
        let nfree = free.len();
        let sys = run(
            py,
            || with_problem!(self, pb => pb.didim_system(chi, f, &free, &decimator.inner)),
        )?;
        let rows = sys.y.len();
        let system: System<'py> = (
            sys.y.into_pyarray(py),
            colmajor_to_array(py, sys.w, rows, nfree)?,
            sys.force_dec.into_pyarray(py),
        );
        if with_q {
            let (y, w, f) = system;
            (y, w, f, sys.q_motor.into_pyarray(py)).into_pyobject(py)
        } else {
            system.into_pyobject(py)
        }
    }

    /// The decimated residual dec(measured − simulated) and Jacobian dec(∂simulated/∂χ_free)
    /// (r, len(free)) from the exact sensitivities.
    #[pyo3(signature = (params, measured, free, decimator, *, output="force"))]
    fn linearize<'py>(
        &self,
        py: Python<'py>,
        params: PyReadonlyArray1<'py, f64>,
        measured: PyReadonlyArray1<'py, f64>,
        free: Vec<usize>,
        decimator: &Decimation,
        output: &str,
    ) -> PyResult<(Arr<'py>, Bound<'py, PyAny>)> {
        let chi = slice1(&params);
        let meas = slice1(&measured);
        let (chi, meas): (&[f64], &[f64]) = (&chi, &meas);
        let nfree = free.len();
        let lin = run(py, || {
            let out = parse_output(output)?;
            with_problem!(self, pb => pb.linearize(chi, out, meas, &free, &decimator.inner))
        })?;
        let rows = lin.residual.len();
        Ok((
            lin.residual.into_pyarray(py),
            colmajor_to_array(py, lin.jacobian, rows, nfree)?,
        ))
    }
}
