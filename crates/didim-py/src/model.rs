//! `Model`: a model structure built once from its specification and handed, frozen, to every
//! computation that needs it (the closed loop, the regressor, names, units and roles).

use didim_core::error::Error;
use didim_core::model::{self, Basis, FrictionLaw, LawShape, Model as CoreModel, DEFAULT_COULOMB_EPS};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::convert::*;
use crate::{quick, run};

/// A model's structure: "rigid" (M, Fv, Fc[, OF]) or "flexible" (M1, Fv1, Fc1, M2, Fv2, Fc2, K12[, OF]), with its terms.
#[derive(Clone, Debug)]
pub enum AnyModel {
    Rigid(CoreModel<1>),
    Flexible(CoreModel<2>),
}

/// One extra term of a model: (name, kind, dof "motor" or "load", named hyper-parameters).
pub type TermSpec = (String, String, String, Vec<(String, f64)>);
/// Extra terms of a model.
pub type Terms = Vec<TermSpec>;
/// A row of the term table as Python reads it: (kind, [(hyper-parameter, unit, default)], description).
type TableRow = (
    &'static str,
    Vec<(&'static str, &'static str, Option<f64>)>,
    &'static str,
);
/// An alias as Python reads it: (alias, kind, [(hyper-parameter, fixed value)]).
type AliasRow = (&'static str, &'static str, Vec<(&'static str, f64)>);

fn dof_index(dof: &str) -> Result<usize, Error> {
    match dof {
        "motor" => Ok(model::MOTOR),
        "load" => Ok(model::LOAD),
        other => Err(Error::InvalidInput(format!(
            "unknown degree of freedom {other:?} of a term: use \"motor\" or \"load\""
        ))),
    }
}

/// The core model of a kind with an offset, extra terms, a backlash gap and a friction law.
pub fn make_model(
    kind: &str,
    offset: bool,
    coulomb_eps: f64,
    coulomb_law: &str,
    terms: &[TermSpec],
    backlash_gap: Option<f64>,
) -> Result<AnyModel, Error> {
    let shape = LawShape::from_name(coulomb_law)?;
    let extra = terms
        .iter()
        .map(|(n, k, d, h)| {
            let h: Vec<(&str, f64)> = h.iter().map(|(a, v)| (a.as_str(), *v)).collect();
            Basis::from_kind(k, &h, dof_index(d)?)
                .map(|b| (n.clone(), b))
                .map_err(|e| Error::InvalidInput(format!("term {n}: {e}")))
        })
        .collect::<Result<Vec<_>, Error>>()?;
    match kind {
        "rigid" => {
            if backlash_gap.is_some() {
                return Err(Error::InvalidInput(
                    "backlash needs the flexible model (a coupling)".into(),
                ));
            }
            Ok(AnyModel::Rigid(
                model::rigid(offset, coulomb_eps)?
                    .with_terms(extra)?
                    .with_law_shape(shape),
            ))
        }
        "flexible" => {
            let mut m = model::flexible_with(offset, coulomb_eps)?
                .with_terms(extra)?
                .with_law_shape(shape);
            if let Some(gap) = backlash_gap {
                m = m.with_basis(
                    "K12",
                    Basis::Backlash {
                        a: model::MOTOR,
                        b: model::LOAD,
                        gap,
                    },
                )?;
            }
            Ok(AnyModel::Flexible(m))
        }
        other => Err(Error::InvalidInput(format!(
            "unknown model {other:?}: use \"rigid\" or \"flexible\""
        ))),
    }
}

impl AnyModel {
    pub fn n_params(&self) -> usize {
        match self {
            AnyModel::Rigid(m) => m.n_params(),
            AnyModel::Flexible(m) => m.n_params(),
        }
    }

    pub fn ndof(&self) -> usize {
        match self {
            AnyModel::Rigid(_) => 1,
            AnyModel::Flexible(_) => 2,
        }
    }

    fn names(&self) -> &[String] {
        match self {
            AnyModel::Rigid(m) => m.names(),
            AnyModel::Flexible(m) => m.names(),
        }
    }

    fn basis(&self) -> &[Basis] {
        match self {
            AnyModel::Rigid(m) => m.basis(),
            AnyModel::Flexible(m) => m.basis(),
        }
    }

    fn law(&self) -> FrictionLaw {
        match self {
            AnyModel::Rigid(m) => m.law(),
            AnyModel::Flexible(m) => m.law(),
        }
    }

    fn regressor(&self, q: &[Vec<f64>], qd: &[Vec<f64>], qdd: &[Vec<f64>]) -> Result<Vec<f64>, Error> {
        match self {
            AnyModel::Rigid(m) => m.regressor(q, qd, qdd),
            AnyModel::Flexible(m) => m.regressor(q, qd, qdd),
        }
    }

    fn regressor_columns(
        &self,
        q: &[Vec<f64>],
        qd: &[Vec<f64>],
        qdd: &[Vec<f64>],
        cols: &[usize],
        dof: usize,
    ) -> Result<Vec<f64>, Error> {
        match self {
            AnyModel::Rigid(m) => m.regressor_columns(q, qd, qdd, cols, dof),
            AnyModel::Flexible(m) => m.regressor_columns(q, qd, qdd, cols, dof),
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn decimated_columns(
        &self,
        q: &[Vec<f64>],
        qd: &[Vec<f64>],
        qdd: &[Vec<f64>],
        cols: &[usize],
        dof: usize,
        dec: &didim_core::filter::Decimation,
    ) -> Result<Vec<Vec<f64>>, Error> {
        match self {
            AnyModel::Rigid(m) => m.decimated_columns(q, qd, qdd, cols, dof, dec),
            AnyModel::Flexible(m) => m.decimated_columns(q, qd, qdd, cols, dof, dec),
        }
    }
}

/// A model structure, built once and frozen: its kind, offset, extra terms (each with its named
/// hyper-parameters), backlash gap and friction law. Every simulation, regressor, name and unit
/// of didim comes from one of these.
#[pyclass(frozen, module = "didim._core", name = "Model")]
pub struct PyModel {
    pub inner: AnyModel,
    kind: String,
    /// The actuation options by name (`didim_core::sim::ACTUATION`), applied to every closed loop of this model.
    pub actuation: Vec<(String, f64)>,
}

#[pymethods]
impl PyModel {
    #[new]
    #[pyo3(signature = (kind, *, offset=false, terms=None, backlash_gap=None, coulomb_eps=Real(DEFAULT_COULOMB_EPS), coulomb_law="algebraic", actuation=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        kind: &str,
        offset: bool,
        terms: Option<Terms>,
        backlash_gap: Option<f64>,
        coulomb_eps: Real,
        coulomb_law: &str,
        actuation: Option<Vec<(String, Real)>>,
    ) -> PyResult<Self> {
        let terms = terms.unwrap_or_default();
        let actuation: Vec<(String, f64)> = actuation
            .unwrap_or_default()
            .into_iter()
            .map(|(n, v)| (n, v.0))
            .collect();
        let inner = quick(py, || {
            // each option checked as the closed loop will take it
            let mut opts = didim_core::sim::SimOptions::new(1.0);
            for (name, value) in &actuation {
                opts.set_actuation(name, *value)?;
            }
            opts.validate()?;
            make_model(kind, offset, coulomb_eps.0, coulomb_law, &terms, backlash_gap)
        })?;
        Ok(Self {
            inner,
            kind: kind.to_string(),
            actuation,
        })
    }

    /// The actuation options by name (delay in samples, force lag in s).
    #[getter]
    fn actuation(&self) -> Vec<(String, f64)> {
        self.actuation.clone()
    }

    /// "rigid" or "flexible".
    #[getter]
    fn kind(&self) -> &str {
        &self.kind
    }

    /// Parameter names, in the order of the parameter vector.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.names().to_vec()
    }

    /// The SI unit (load side) of each parameter.
    #[getter]
    fn units(&self) -> Vec<&'static str> {
        self.inner.basis().iter().map(|b| b.unit()).collect()
    }

    /// What each parameter is: "mass", "friction", "stiffness", "damping" or "force".
    #[getter]
    fn roles(&self) -> Vec<&'static str> {
        self.inner.basis().iter().map(|b| b.role().name()).collect()
    }

    /// Number of degrees of freedom (1 rigid, 2 flexible).
    #[getter]
    fn ndof(&self) -> usize {
        self.inner.ndof()
    }

    /// The Coulomb smoothing speed (m/s or rad/s) of every Coulomb-type term.
    #[getter]
    fn coulomb_eps(&self) -> f64 {
        self.inner.law().eps
    }

    /// The IDM regressor of a trajectory: q, qd, qdd of shape (ndof, n) -> W of shape (ndof, n, p).
    fn regressor<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        qd: PyReadonlyArray2<'py, f64>,
        qdd: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (q, qd, qdd) = (rows2(&q), rows2(&qd), rows2(&qdd));
        let n = q.first().map_or(0, |r| r.len());
        let (ndof, p) = (self.inner.ndof(), self.inner.n_params());
        let w = run(py, || self.inner.regressor(&q, &qd, &qdd))?;
        // core layout [dof][param][sample] -> numpy (ndof, p, n) -> view (ndof, n, p)
        let a = PyArray1::from_vec(py, w).reshape([ndof, p, n])?;
        a.call_method1("transpose", ((0, 2, 1),))
    }

    /// The regressor's columns `cols` (indices among the parameters) on dof `dof`'s rows (0: the
    /// motor's): q, qd, qdd of shape (ndof, n) -> (n, len(cols)), the values `regressor` gives there.
    fn regressor_columns<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        qd: PyReadonlyArray2<'py, f64>,
        qdd: PyReadonlyArray2<'py, f64>,
        cols: Vec<usize>,
        dof: usize,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (q, qd, qdd) = (rows2(&q), rows2(&qd), rows2(&qdd));
        let n = q.first().map_or(0, |r| r.len());
        let k = cols.len();
        let w = run(py, || self.inner.regressor_columns(&q, &qd, &qdd, &cols, dof))?;
        // core layout [column][sample] -> numpy (k, n) -> view (n, k)
        let a = PyArray1::from_vec(py, w).reshape([k, n])?;
        a.call_method1("transpose", ((1, 0),))
    }

    /// The columns of :meth:`regressor_columns` decimated by ``decimation`` (a ``didim._core.Decimation``), (m, k):
    /// bit for bit ``decimation.apply`` of the full-rate columns, computed four at a time so that they never exist
    /// all at once (a doctor's grid of 160 columns of a 25 000-sample record is 32 MB at full rate).
    #[allow(clippy::too_many_arguments)]
    fn decimated_columns<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        qd: PyReadonlyArray2<'py, f64>,
        qdd: PyReadonlyArray2<'py, f64>,
        cols: Vec<usize>,
        dof: usize,
        decimation: PyRef<'py, crate::decimation::Decimation>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (q, qd, qdd) = (rows2(&q), rows2(&qd), rows2(&qdd));
        let k = cols.len();
        let dec = &decimation.inner;
        let w = run(py, || {
            self.inner.decimated_columns(&q, &qd, &qdd, &cols, dof, dec)
        })?;
        let m = dec.output_len(q.first().map_or(0, |r| r.len()));
        colmajor_to_array(py, w.concat(), m, k)
    }
}

/// The sign of every Coulomb-type term, `law` through zero speed with transition speed `eps`
/// (0: the hard sign), elementwise.
#[pyfunction]
#[pyo3(signature = (v, eps=Real(DEFAULT_COULOMB_EPS), law="algebraic"))]
pub fn coulomb_sign<'py>(
    py: Python<'py>,
    v: PyReadonlyArray1<'py, f64>,
    eps: Real,
    law: &str,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let v = slice1(&v);
    let out = quick(py, || {
        let shape = LawShape::from_name(law)?;
        if !(eps.0.is_finite() && eps.0 >= 0.0) {
            return Err(Error::InvalidInput(format!(
                "eps must be finite and >= 0, got {}",
                eps.0
            )));
        }
        let law = FrictionLaw { shape, eps: eps.0 };
        Ok(v.iter().map(|&x| law.sign(x)).collect::<Vec<f64>>())
    })?;
    Ok(PyArray1::from_vec(py, out))
}

/// The term kinds: (kind, [(hyper-parameter, unit, default or None)], description).
pub fn term_table() -> Vec<TableRow> {
    model::TERM_TABLE
        .iter()
        .map(|k| {
            (
                k.name,
                k.hypers.iter().map(|h| (h.name, h.unit, h.default)).collect(),
                k.doc,
            )
        })
        .collect()
}

/// The older kind names: (alias, kind, [(hyper-parameter, fixed value)]).
pub fn term_aliases() -> Vec<AliasRow> {
    model::TERM_ALIASES
        .iter()
        .map(|(a, k, f)| (*a, *k, f.to_vec()))
        .collect()
}
