//! PyO3 bindings of `didim-core`, imported in Python as `didim._core`.
//!
//! This crate only converts types: numpy arrays in (borrowed read-only, copied
//! only when not contiguous), numpy arrays out, the interpreter lock released
//! around every computation, core errors mapped to the exception classes of
//! `didim._errors`, and panics caught before they can reach Python.

use std::panic::{catch_unwind, AssertUnwindSafe};

use didim_core::error::Error;
use didim_core::filter as flt;
use didim_core::lstsq::{LstsqOptions, SigmaConvention};
use didim_core::model::{DEFAULT_COULOMB_EPS, LAW_SHAPES};
use didim_core::{controller::TransferFunction, lstsq as ls, sim, Controller};
use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyType};

mod convert;
mod decimation;
mod model;
mod problem;
mod robot;
use convert::*;
pub(crate) use model::AnyModel;

/// Runs a core computation without the interpreter lock on this thread's core worker (a thread
/// of its own, see [`submit`]), while this thread answers signals, turning panics into errors.
/// For the computations that take a while (simulations, filters, least squares); [`quick`] runs
/// the others.
fn run<T: Send>(py: Python<'_>, f: impl FnOnce() -> Result<T, Error> + Send) -> PyResult<T> {
    if HELD.load(std::sync::atomic::Ordering::Relaxed) {
        // the program is stopping its thread pool's calls (`hold_stop`): this one does not start
        return Err(pyo3::exceptions::PyKeyboardInterrupt::new_err("interrupted"));
    }
    if !pending() {
        // a signal caught while another thread's call ran is still to be raised where it was caught: its stop
        // stays in force until then
        didim_core::interrupt::reset();
    }
    // The core runs on the worker while this (Python's) thread waits for it and, every POLL,
    // runs Python's signal handlers: Ctrl-C or SIGTERM stop the core at its next check.
    let out = py.detach(|| {
        let (tx, rx) = std::sync::mpsc::channel();
        let job: Box<dyn FnOnce() + Send + '_> = Box::new(move || {
            let _ = tx.send(catch_unwind(AssertUnwindSafe(f)));
        });
        // SAFETY: the job borrows from this call's frame; it is erased to 'static to reach the
        // worker. This function returns (or unwinds) only after `rx` has seen the job's sender
        // either send or be dropped, i.e. after the job has run to its end or been dropped
        // without running: nothing it borrows is used after this frame ends.
        let job: Job = unsafe { std::mem::transmute::<Box<dyn FnOnce() + Send + '_>, Job>(job) };
        if let Err(job) = submit(job) {
            job(); // no worker thread could be started: the computation runs here, without signals
        }
        let wait = catch_unwind(AssertUnwindSafe(|| loop {
            match rx.recv_timeout(POLL) {
                Ok(r) => return Some(r),
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                    if signalled() {
                        didim_core::interrupt::raise();
                    }
                }
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return None,
            }
        }));
        match wait {
            Ok(Some(r)) => r,
            Ok(None) => Err(Box::new("the core's thread ended without a result".to_string())
                as Box<dyn std::any::Any + Send>),
            Err(panic) => {
                // the job still borrows this frame: it must end before the panic goes on
                didim_core::interrupt::raise();
                let _ = rx.recv();
                std::panic::resume_unwind(panic)
            }
        }
    });
    finish(py, out)
}

/// A computation for a core worker, its borrows erased (see [`run`]).
type Job = Box<dyn FnOnce() + Send + 'static>;

thread_local! {
    /// The sender to this (Python) thread's core worker: a thread started at the first core
    /// computation and reused for the next ones, which it runs one at a time. Starting a thread
    /// per computation cost about 60 µs, 6 % of one closed-loop simulation of the EMPS record.
    /// The worker ends when this thread does (its sender dropped).
    /// With the process that started it: a process forked from this one (`multiprocessing`'s
    /// default on Linux) inherits the sender but not the thread, and starts its own.
    static WORKER: std::cell::RefCell<Option<(u32, std::sync::mpsc::Sender<Job>)>> =
        const { std::cell::RefCell::new(None) };
}

/// Hands `job` to this thread's core worker, starting it if need be; the job back when no
/// worker could be started.
fn submit(job: Job) -> Result<(), Job> {
    WORKER.with(|w| {
        let mut w = w.borrow_mut();
        let pid = std::process::id();
        let job = match w.as_ref() {
            Some((owner, tx)) if *owner == pid => match tx.send(job) {
                Ok(()) => return Ok(()),
                Err(back) => back.0, // the worker has ended: a new one
            },
            // none yet, or another process's (forked from it): its thread is not in this one
            _ => job,
        };
        if let Some((owner, tx)) = w.take() {
            if owner != pid {
                std::mem::forget(tx); // the parent's channel: dropping it here would touch its state
            }
        }
        let (tx, rx) = std::sync::mpsc::channel::<Job>();
        let started = std::thread::Builder::new()
            .name("didim-core".to_string())
            .spawn(move || {
                let pool = forked_pool();
                for job in rx {
                    match pool {
                        Some(pool) => pool.install(job),
                        None => job(),
                    }
                }
            });
        if started.is_err() {
            *w = None;
            return Err(job);
        }
        let sent = tx.send(job).map_err(|back| back.0);
        *w = Some((pid, tx));
        sent
    })
}

/// The process that imported this module.
static ORIGIN_PID: std::sync::OnceLock<u32> = std::sync::OnceLock::new();

/// In a process forked from the one that imported this module (`multiprocessing`'s default on
/// Linux), a thread pool of its own for the core's parallel loops: the fork copied rayon's global
/// pool but none of its threads, and a parallel loop there waited forever. None in the process
/// that imported the module (the global pool, no cost).
fn forked_pool() -> Option<&'static rayon::ThreadPool> {
    let pid = std::process::id();
    if *ORIGIN_PID.get_or_init(|| pid) == pid {
        return None;
    }
    static POOL: std::sync::Mutex<Option<(u32, &'static rayon::ThreadPool)>> = std::sync::Mutex::new(None);
    let mut p = POOL.lock().ok()?;
    match *p {
        Some((owner, pool)) if owner == pid => Some(pool),
        _ => {
            // the same threads as the global pool (RAYON_NUM_THREADS, else one per core); kept for the process
            let pool: &'static rayon::ThreadPool =
                Box::leak(Box::new(rayon::ThreadPoolBuilder::new().build().ok()?));
            *p = Some((pid, pool));
            Some(pool)
        }
    }
}

/// Runs a short core computation (building a model, a filter design) on this thread: starting
/// a thread to watch for signals would cost more than the work. Panics become errors.
fn quick<T>(py: Python<'_>, f: impl FnOnce() -> Result<T, Error>) -> PyResult<T> {
    finish(py, catch_unwind(AssertUnwindSafe(f)))
}

/// The outcome of a core computation as Python sees it.
fn finish<T>(py: Python<'_>, out: std::thread::Result<Result<T, Error>>) -> PyResult<T> {
    match out {
        // a signal caught while the computation ran to its end anyway: raised now, as Python would have
        Ok(Ok(v)) => take_pending().map_or(Ok(v), Err),
        Ok(Err(Error::Interrupted)) => {
            Err(take_pending()
                .unwrap_or_else(|| pyo3::exceptions::PyKeyboardInterrupt::new_err("interrupted")))
        }
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

/// The exception a signal handler raised while the core was running (Ctrl-C's KeyboardInterrupt, the CLI's
/// SIGTERM exception), with the thread whose call caught it (Python's main thread): re-raised there when its core
/// has stopped. Another thread's call that the same stop ends raises a plain KeyboardInterrupt, so that the
/// handler's own exception (e.g. the CLI's SIGTERM class, which sets the exit code) reaches the main thread.
static PENDING: std::sync::Mutex<Option<(std::thread::ThreadId, PyErr)>> = std::sync::Mutex::new(None);

/// Set while the program stops every call of its thread pools (`hold_stop(True)`): running calls stop at their next
/// check, new ones raise KeyboardInterrupt at once, until `hold_stop(False)`.
static HELD: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// hold_stop(on)
/// --
///
/// ``True``: every running core computation stops at its next check and every new one raises KeyboardInterrupt at
/// once, on every thread (a thread pool's workers, whose calls a signal caught on the main thread does not reach);
/// ``False``: computations run again. For ``didim._parallel.map_threads`` on an interrupt or an error.
#[pyfunction]
fn hold_stop(on: bool) {
    HELD.store(on, std::sync::atomic::Ordering::Relaxed);
    if on {
        didim_core::interrupt::raise();
    } else if !pending() {
        didim_core::interrupt::reset();
    }
}

/// Whether a signal's exception waits to be raised.
fn pending() -> bool {
    PENDING.lock().map(|p| p.is_some()).unwrap_or(false)
}

/// The signal's exception waiting for this thread, taken.
fn take_pending() -> Option<PyErr> {
    let me = std::thread::current().id();
    let mut p = PENDING.lock().ok()?;
    if p.as_ref().is_some_and(|(t, _)| *t == me) {
        p.take().map(|(_, e)| e)
    } else {
        None
    }
}

/// How often a waiting call runs Python's signal handlers.
const POLL: std::time::Duration = std::time::Duration::from_millis(50);

/// Runs Python's signal handlers (they only run on the main thread; elsewhere this is a no-op) and keeps the
/// exception one of them raised; true when there was one.
fn signalled() -> bool {
    Python::attach(|py| match py.check_signals() {
        Ok(()) => false,
        Err(e) => {
            if let Ok(mut p) = PENDING.lock() {
                p.get_or_insert((std::thread::current().id(), e));
            }
            true
        }
    })
}

/// A batch's per-set results, or the error that ends the whole batch: the user stopped it, or memory ran out
/// (not one failed set among others).
pub(crate) fn interrupted<T>(mut results: Vec<Result<T, Error>>) -> Result<Vec<Result<T, Error>>, Error> {
    if let Some(i) = results
        .iter()
        .position(|r| matches!(r, Err(Error::Interrupted | Error::OutOfMemory(_))))
    {
        return Err(results.swap_remove(i).err().expect("an error at i"));
    }
    Ok(results)
}

/// Maps a core error to its Python class.
fn core_error(py: Python<'_>, e: Error) -> PyErr {
    match e {
        Error::InvalidInput(m) => py_error(py, "DataError", m),
        Error::Simulation(m) => py_error(py, "SimulationError", m),
        Error::Identifiability(m) => py_error(py, "IdentifiabilityError", m),
        Error::Interrupted => pyo3::exceptions::PyKeyboardInterrupt::new_err("interrupted"),
        Error::OutOfMemory(m) => pyo3::exceptions::PyMemoryError::new_err(m),
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

pub(crate) fn make_controller(kind: &str, gains: &[f64]) -> Result<Controller, Error> {
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
        ("tf", [saturation, gain, lens @ ..]) if lens.len() >= 4 => {
            let counts: Vec<usize> = lens[..4].iter().map(|&x| x.max(0.0) as usize).collect();
            let coeffs = &lens[4..];
            if lens[..4].iter().any(|&x| x.fract() != 0.0 || x < 1.0)
                || counts.iter().sum::<usize>() != coeffs.len()
            {
                return Err(Error::InvalidInput(
                    "the tf controller takes (saturation, gain, len b_r, len a_r, len b_y, len a_y, coefficients...)"
                        .into(),
                ));
            }
            let mut parts = Vec::with_capacity(4);
            let mut at = 0;
            for c in counts {
                parts.push(&coeffs[at..at + c]);
                at += c;
            }
            Controller::TransferFunction(TransferFunction::new(
                parts[0],
                parts[1],
                parts[2],
                parts[3],
                *saturation,
                *gain,
            )?)
        }
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
                "unknown controller {other:?}: use \"emps\", \"pd\" or \"tf\""
            )))
        }
    };
    c.validate()?;
    Ok(c)
}

fn parse_integrator(name: &str) -> Result<sim::Integrator, Error> {
    match name {
        "exponential" => Ok(sim::Integrator::Exponential),
        "rk4" => Ok(sim::Integrator::Rk4),
        other => Err(Error::InvalidInput(format!(
            "unknown integrator {other:?}: use \"exponential\" (default) or \"rk4\""
        ))),
    }
}

#[allow(clippy::too_many_arguments)]
fn sim_options(
    py: Python<'_>,
    dt: f64,
    substeps: usize,
    quantization: f64,
    integrator: &str,
    tol: f64,
    lead: usize,
) -> PyResult<sim::SimOptions> {
    let integrator = parse_integrator(integrator).map_err(|e| core_error(py, e))?;
    Ok(sim::SimOptions {
        substeps,
        quantization,
        integrator,
        tol,
        lead,
        ..sim::SimOptions::new(dt)
    })
}

/// QR least squares with covariance, paper eqs. (11)-(15). W is (r, n), y is (r,).
#[pyfunction]
#[pyo3(signature = (w, y, *, rank_tol=None, sigma="paper"))]
fn lstsq<'py>(
    py: Python<'py>,
    w: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray1<'py, f64>,
    rank_tol: Option<Real>,
    sigma: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let rank_tol = rank_tol.map(|r| r.0);
    let sigma = match sigma {
        "paper" => SigmaConvention::Paper,
        "sample_std" => SigmaConvention::SampleStd,
        other => {
            return Err(core_error(
                py,
                Error::InvalidInput(format!(
                    "unknown sigma convention {other:?}: use \"paper\" or \"sample_std\""
                )),
            ))
        }
    };
    let (wc, r, c) = columns2(&w);
    let y = slice1(&y);
    let y: &[f64] = &y;
    let opts = LstsqOptions { rank_tol, sigma };
    let sol = run(py, || ls::lstsq(&wc, r, c, y, &opts))?;
    let d = PyDict::new(py);
    d.set_item("params", sol.params.into_pyarray(py))?;
    d.set_item("std", sol.std.into_pyarray(py))?;
    d.set_item("rel_std_pct", sol.rel_std_pct.into_pyarray(py))?;
    d.set_item(
        "covariance",
        PyArray1::from_vec(py, sol.covariance).reshape([c, c])?,
    )?;
    d.set_item("base_columns", sol.base_columns)?;
    let deps: Vec<(usize, Vec<(usize, f64)>)> = sol
        .dependencies
        .into_iter()
        .map(|x| (x.column, x.combination))
        .collect();
    d.set_item("dependencies", deps)?;
    d.set_item("rank", sol.rank)?;
    d.set_item("rows", sol.rows)?;
    d.set_item("residual_norm", sol.residual_norm)?;
    d.set_item("sigma_rho", sol.sigma_rho)?;
    d.set_item("relative_error", sol.relative_error)?;
    d.set_item("condition_number", sol.condition_number)?;
    d.set_item("residual", sol.residual.into_pyarray(py))?;
    Ok(d)
}

/// Butterworth low-pass design: (b, a), or the sos array (n, 6) with `sos=True`.
#[pyfunction]
#[pyo3(signature = (order, wn, *, sos=false))]
fn butter<'py>(py: Python<'py>, order: Whole, wn: Real, sos: bool) -> PyResult<Bound<'py, PyAny>> {
    let order = order.get("order").map_err(|e| core_error(py, e))?;
    let wn = wn.0;
    design(
        py,
        sos,
        move || flt::butter(order, wn),
        move || flt::butter_sos(order, wn),
    )
}

/// Chebyshev type I low-pass design: (b, a), or the sos array (n, 6) with `sos=True`.
#[pyfunction]
#[pyo3(signature = (order, rp_db, wn, *, sos=false))]
fn cheby1<'py>(
    py: Python<'py>,
    order: Whole,
    rp_db: Real,
    wn: Real,
    sos: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let order = order.get("order").map_err(|e| core_error(py, e))?;
    let (rp_db, wn) = (rp_db.0, wn.0);
    design(
        py,
        sos,
        move || flt::cheby1(order, rp_db, wn),
        move || flt::cheby1_sos(order, rp_db, wn),
    )
}

fn design<'py>(
    py: Python<'py>,
    sos: bool,
    ba: impl FnOnce() -> Result<flt::Tf, Error> + Send,
    so: impl FnOnce() -> Result<flt::Sos, Error> + Send,
) -> PyResult<Bound<'py, PyAny>> {
    if sos {
        let s = quick(py, so)?;
        let n = s.n_sections();
        let flat: Vec<f64> = s.sections().iter().flatten().copied().collect();
        Ok(PyArray1::from_vec(py, flat).reshape([n, 6])?.into_any())
    } else {
        let tf = quick(py, ba)?;
        Ok((tf.b.into_pyarray(py), tf.a.into_pyarray(py))
            .into_pyobject(py)?
            .into_any())
    }
}

/// Causal filtering, `scipy.signal.lfilter(b, a, x, zi=zi)[0]` (direct form II transposed; `zi` the initial state,
/// zero when omitted).
#[pyfunction]
#[pyo3(signature = (b, a, x, *, zi=None))]
fn lfilter<'py>(
    py: Python<'py>,
    b: Vec<Real>,
    a: Vec<Real>,
    x: PyReadonlyArray1<'py, f64>,
    zi: Option<Vec<Real>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (b, a) = (reals(b), reals(a));
    if b.is_empty() || a.is_empty() || a[0] == 0.0 {
        return Err(PyValueError::new_err(
            "lfilter: b and a must be non-empty and a[0] non-zero",
        ));
    }
    let zi = zi.map(reals);
    let x = slice1(&x);
    let x: &[f64] = &x;
    let tf = flt::Tf { b, a };
    let y = py.detach(|| flt::lfilter(&tf, x, zi.as_deref()));
    Ok(y.into_pyarray(py))
}

/// The force a joint receives (its mean over each sample period) under the logged commands
/// `force`: `delay` samples late (`held` before the first), through a first-order lag of
/// `force_lag` s; the simulators' own arithmetic (`sim::applied_force`).
#[pyfunction]
#[pyo3(signature = (force, delay, force_lag, dt, *, held=0.0))]
fn applied_force<'py>(
    py: Python<'py>,
    force: PyReadonlyArray1<'py, f64>,
    delay: usize,
    force_lag: f64,
    dt: f64,
    held: f64,
) -> Bound<'py, PyArray1<f64>> {
    let f = slice1(&force);
    sim::applied_force(&f, delay, force_lag, dt, held).into_pyarray(py)
}

/// Zero-phase filtering, `scipy.signal.filtfilt(b, a, x, padtype="odd", padlen=padlen)`.
#[pyfunction]
#[pyo3(signature = (b, a, x, *, padlen=None))]
fn filtfilt<'py>(
    py: Python<'py>,
    b: Vec<Real>,
    a: Vec<Real>,
    x: PyReadonlyArray1<'py, f64>,
    padlen: Option<Whole>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (b, a) = (reals(b), reals(a));
    let padlen = padlen
        .map(|p| p.get("padlen"))
        .transpose()
        .map_err(|e| core_error(py, e))?;
    let x = slice1(&x);
    let x: &[f64] = &x;
    let tf = flt::Tf { b, a };
    Ok(run(py, || flt::filtfilt(&tf, x, padlen))?.into_pyarray(py))
}

/// Zero-phase filtering with second-order sections, `scipy.signal.sosfiltfilt(sos, x, padlen=padlen)`.
#[pyfunction]
#[pyo3(signature = (sos, x, *, padlen=None))]
fn sosfiltfilt<'py>(
    py: Python<'py>,
    sos: PyReadonlyArray2<'py, f64>,
    x: PyReadonlyArray1<'py, f64>,
    padlen: Option<Whole>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let padlen = padlen
        .map(|p| p.get("padlen"))
        .transpose()
        .map_err(|e| core_error(py, e))?;
    let rows = rows2(&sos);
    let x = slice1(&x);
    let x: &[f64] = &x;
    let out = run(py, || {
        let mut secs = Vec::with_capacity(rows.len());
        for r in &rows {
            let s: [f64; 6] = r.as_slice().try_into().map_err(|_| {
                Error::InvalidInput(format!(
                    "sos must have 6 columns (b0 b1 b2 a0 a1 a2), got {}",
                    r.len()
                ))
            })?;
            secs.push(s);
        }
        flt::sosfiltfilt(&flt::Sos(secs), x, padlen)
    })?;
    Ok(out.into_pyarray(py))
}

/// Decimated y and, when given, decimated w.
type Decimated<'py> = (Bound<'py, PyArray1<f64>>, Option<Bound<'py, PyAny>>);

/// Parallel decimation of y (n,) and of every column of w (n, p): the same zero-phase low-pass and
/// down-sampling. kind "butter" (order, cutoff_hz, fs_hz, form "sos"|"ba") or "matlab" (MATLAB's decimate).
#[pyfunction]
#[pyo3(signature = (y, w=None, *, factor, kind="butter", order=Whole::new(4), cutoff_hz=None, fs_hz=None, form="sos"))]
#[pyo3(
    text_signature = "(y, w=None, *, factor, kind='butter', order=4, cutoff_hz=None, fs_hz=None, form='sos')"
)]
#[allow(clippy::too_many_arguments)]
fn decimate<'py>(
    py: Python<'py>,
    y: PyReadonlyArray1<'py, f64>,
    w: Option<PyReadonlyArray2<'py, f64>>,
    factor: Whole,
    kind: &str,
    order: Whole,
    cutoff_hz: Option<Real>,
    fs_hz: Option<Real>,
    form: &str,
) -> PyResult<Decimated<'py>> {
    let factor = factor.get("factor").map_err(|e| core_error(py, e))?;
    let order = order.get("order").map_err(|e| core_error(py, e))?;
    let (cutoff_hz, fs_hz) = (cutoff_hz.map(|r| r.0), fs_hz.map(|r| r.0));
    let dec = decimation::make_decimation(factor, kind, order, cutoff_hz, fs_hz, form)
        .map_err(|e| core_error(py, e))?;
    decimation::decimate_arrays(py, &dec, y, w)
}

/// Down-sampling factor keeping the cutoff at 80 % of the new Nyquist frequency.
#[pyfunction]
fn default_factor(fs_hz: Real, cutoff_hz: Real) -> usize {
    flt::default_factor(fs_hz.0, cutoff_hz.0)
}

/// The compiled core of didim. Use the `didim` package, not this module.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    ORIGIN_PID.get_or_init(std::process::id);
    m.add("DEFAULT_COULOMB_EPS", DEFAULT_COULOMB_EPS)?;
    m.add("COULOMB_LAWS", LAW_SHAPES.to_vec())?;
    m.add("DEFAULT_TOL", sim::DEFAULT_TOL)?;
    m.add("SIMULATOR_BUILD", sim::simulator_build())?;
    m.add("TERM_TABLE", model::term_table())?;
    m.add("TERM_ALIASES", model::term_aliases())?;
    m.add("ACTUATION", sim::ACTUATION.to_vec())?;
    m.add_class::<model::PyModel>()?;
    m.add_class::<robot::PyRobot>()?;
    m.add_function(wrap_pyfunction!(robot::simulate_robot, m)?)?;
    m.add_function(wrap_pyfunction!(hold_stop, m)?)?;
    m.add_function(wrap_pyfunction!(model::coulomb_sign, m)?)?;
    m.add_function(wrap_pyfunction!(lstsq, m)?)?;
    m.add_function(wrap_pyfunction!(butter, m)?)?;
    m.add_function(wrap_pyfunction!(cheby1, m)?)?;
    m.add_function(wrap_pyfunction!(lfilter, m)?)?;
    m.add_function(wrap_pyfunction!(applied_force, m)?)?;
    m.add_function(wrap_pyfunction!(filtfilt, m)?)?;
    m.add_function(wrap_pyfunction!(sosfiltfilt, m)?)?;
    m.add_function(wrap_pyfunction!(decimate, m)?)?;
    m.add_function(wrap_pyfunction!(default_factor, m)?)?;
    m.add_class::<decimation::Decimation>()?;
    m.add_class::<problem::Problem>()?;
    Ok(())
}
