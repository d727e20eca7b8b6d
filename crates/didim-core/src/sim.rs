//! Fixed-step closed-loop simulation of a model under a digital controller.
//!
//! Every sample period `T` the controller reads the (optionally quantized)
//! motor position and computes a force held constant over the period
//! (zero-order hold), optionally delayed by a whole number of samples. The
//! continuous plant is integrated by the exponential integrator of [`expint`]
//! (exact for the affine part of the model, adaptive where the Coulomb sign is
//! curved; the default) or by classical RK4 over `substeps` equal substeps per
//! period ([`Integrator::Rk4`], the reference). The simulation starts at rest at
//! the first reference position (spring unloaded).
//!
//! Per sample `k` (time `t_k = k·T`) it outputs the commanded force (what the
//! drive logs, after saturation) and the noise-free states at `t_k`: positions,
//! velocities and the accelerations of the direct model under the force applied
//! over `[t_k, t_{k+1})`. Without delay the IDM of these states reproduces the
//! commanded force exactly.

use crate::controller::Controller;
use crate::error::{invalid, Error, Result};
use crate::model::{Law, Model, WithLaw};

pub(crate) mod closed_loop;
pub(crate) mod drive;
pub(crate) mod driver;
mod expint;
mod rk4;
pub use drive::applied_force;
use driver::NoTangent;
use expint::Exponential;
pub use expint::StepStats;
use rk4::Rk4;

/// How the plant is integrated over each sample period.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integrator {
    /// Exact discretization of the affine part of the model (masses, viscous
    /// friction, springs, offsets, the held force) with the nonlinear terms
    /// (Coulomb) by second-order implicit exponential time differencing, one step
    /// per sample period where that meets [`SimOptions::tol`], halved where not
    /// (see `sim::expint`). The default.
    #[default]
    Exponential,
    /// Classical RK4 with [`SimOptions::substeps`] equal substeps per period.
    Rk4,
}

/// Default local tolerance of the exponential integrator, relative to the reference
/// stroke (see [`SimOptions::tol`]).
pub const DEFAULT_TOL: f64 = 1e-9;

/// The actuation options a model carries, by name (the Python layer's `didim.Model`
/// fields of the same names): how the commanded force reaches the plant. A new one is a
/// field of [`SimOptions`] with its default, its check and its arm in
/// [`SimOptions::set_actuation`], and its physics in the drive (`sim::drive`); the binding and the Python
/// layer pass them through by name.
pub const ACTUATION: &[&str] = &["delay", "force_lag"];

/// Options of the simulator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimOptions {
    /// Sample period of the controller and of the outputs (s).
    pub dt: f64,
    /// RK4 substeps per sample period (default 10); used by [`Integrator::Rk4`] only.
    pub substeps: usize,
    /// Resolution of the measured motor position (m); 0 for none. EMPS: 5e-8 m.
    pub quantization: f64,
    /// Extra actuation delay in samples: the force applied over `[t_k, t_{k+1})`
    /// is the command of sample `k − delay` (0 before the first command).
    pub delay: usize,
    /// Time constant (s) of a first-order lag between the command and the force the
    /// motor applies (a current loop's bandwidth, `1/(2π·force_lag)`); 0 for none.
    /// Over each period the applied force relaxes exponentially towards the held
    /// command; the plant sees its mean over the period (exact for the velocity it
    /// gives a mass), the drive logs the command.
    pub force_lag: f64,
    /// The integration scheme (default [`Integrator::Exponential`]).
    pub integrator: Integrator,
    /// Local error tolerance of the exponential integrator per step, as a fraction
    /// of the reference stroke (default [`DEFAULT_TOL`]).
    pub tol: f64,
    /// Samples of lead-in at the head of the reference (and of the external input):
    /// simulated, from rest on the reference's first value, but not output. A log that
    /// begins in motion is simulated from the rest its reference left before the log
    /// began (the caller reconstructs that stretch); the outputs, the sensitivities and
    /// the criteria cover the samples from `lead` on. Default 0.
    pub lead: usize,
}

impl SimOptions {
    /// Options with sample period `dt` and the defaults (10 substeps, no quantization, no delay).
    pub fn new(dt: f64) -> Self {
        Self {
            dt,
            substeps: 10,
            quantization: 0.0,
            delay: 0,
            force_lag: 0.0,
            integrator: Integrator::Exponential,
            tol: DEFAULT_TOL,
            lead: 0,
        }
    }

    /// Sets the actuation option `name` (one of [`ACTUATION`]) to `value`: a delay in whole
    /// samples, a force lag in s. The value is checked by [`SimOptions::validate`].
    pub fn set_actuation(&mut self, name: &str, value: f64) -> Result<()> {
        match name {
            "delay" => {
                if !(value.is_finite() && value >= 0.0 && value.fract() == 0.0 && value <= 1e9) {
                    return Err(invalid!(
                        "delay must be a whole number of samples >= 0, got {value}"
                    ));
                }
                self.delay = value as usize;
            }
            "force_lag" => self.force_lag = value,
            other => {
                return Err(invalid!(
                    "unknown actuation option {other:?}: use one of {}",
                    ACTUATION.join(", ")
                ))
            }
        }
        Ok(())
    }

    /// The number of output samples of a reference of `n` samples (its lead-in left out).
    pub fn outputs(&self, n: usize) -> usize {
        n.saturating_sub(self.lead)
    }

    /// Checks the options (errors name the option and the accepted range).
    pub fn validate(&self) -> Result<()> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(invalid!(
                "sample period dt must be finite and > 0 s, got {}",
                self.dt
            ));
        }
        if self.substeps == 0 {
            return Err(invalid!("substeps must be at least 1 (default 10)"));
        }
        if self.substeps > 100_000 {
            return Err(invalid!(
                "substeps = {} is unreasonably large (at most 100000)",
                self.substeps
            ));
        }
        if !(self.tol.is_finite() && self.tol > 0.0 && self.tol < 1.0) {
            return Err(invalid!(
                "tol must be a finite fraction of the stroke between 0 and 1 (default {DEFAULT_TOL:e}), got {}",
                self.tol
            ));
        }
        if !(self.force_lag.is_finite() && self.force_lag >= 0.0) {
            return Err(invalid!(
                "force_lag must be a finite time constant >= 0 s (0 = none), got {}",
                self.force_lag
            ));
        }
        if !(self.quantization.is_finite() && self.quantization >= 0.0) {
            return Err(invalid!(
                "quantization must be a finite resolution >= 0 m (0 = none), got {}",
                self.quantization
            ));
        }
        Ok(())
    }
}

/// Result of a closed-loop simulation, `N` degrees of freedom, `n` samples.
#[derive(Clone, Debug, PartialEq)]
pub struct SimOutput {
    /// Commanded motor force per sample (N), as the drive would log it.
    pub force: Vec<f64>,
    /// Positions `q[d][k]` (m): dof 0 the motor `q1`, dof 1 the load `q12`.
    pub q: Signals,
    /// Velocities (m/s), same layout.
    pub qd: Signals,
    /// Accelerations (m/s²), same layout.
    pub qdd: Signals,
}

/// One signal per degree of freedom, `n` samples each, held row after row in one buffer:
/// `s[d]` is the slice of dof `d` (so `s[d][k]` reads like a `Vec<Vec<f64>>`), and the
/// buffer goes to numpy as an `(ndof, n)` array without a copy.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Signals {
    data: Vec<f64>,
    n: usize,
}

impl Signals {
    /// `rows` signals of `n` zeros (`what` names them in an allocation error).
    pub fn zeros(rows: usize, n: usize, what: &str) -> Result<Self> {
        let len = rows
            .checked_mul(n)
            .ok_or_else(|| invalid!("{what}: {rows} × {n} samples overflow"))?;
        Ok(Self {
            data: crate::error::filled(len, 0.0, what)?,
            n,
        })
    }

    /// The number of signals (degrees of freedom).
    #[inline]
    pub fn len(&self) -> usize {
        self.data.len().checked_div(self.n).unwrap_or(0)
    }

    /// Whether there is no signal.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The signals, one slice each.
    pub fn iter(&self) -> impl Iterator<Item = &[f64]> {
        self.data.chunks_exact(self.n.max(1))
    }

    /// The signals as slices, e.g. for [`Model::regressor`].
    pub fn rows(&self) -> Vec<&[f64]> {
        self.iter().collect()
    }

    /// The buffer, signal after signal.
    pub fn into_flat(self) -> Vec<f64> {
        self.data
    }

    /// Leaves out the first `k` samples of every signal (in place).
    fn drop_front(&mut self, k: usize) {
        if k == 0 || self.data.is_empty() {
            return;
        }
        drop_front_rows(&mut self.data, self.n, k);
        self.n -= k.min(self.n);
    }
}

/// The rows of `n` samples of `data`, each without its first `k` samples, in place: each row's
/// kept samples moved to its new place in order (a row's new place never lies after its old one)
/// and the vector shortened. A collect of the kept samples into a new vector, whose length its
/// iterator did not know, cost a lead-in of 16 samples 0.4 ms per flexible EMPS simulation (1.1 ms).
fn drop_front_rows(data: &mut Vec<f64>, n: usize, k: usize) {
    if n == 0 {
        data.clear();
        return;
    }
    let k = k.min(n);
    let rows = data.len() / n;
    let m = n - k;
    for r in 0..rows {
        data.copy_within(r * n + k..(r + 1) * n, r * m);
    }
    data.truncate(rows * m);
}

impl SimOutput {
    /// Leaves out the first `k` samples (a lead-in).
    fn drop_front(mut self, k: usize) -> Self {
        if k > 0 {
            self.force.drain(..k.min(self.force.len()));
            self.q.drop_front(k);
            self.qd.drop_front(k);
            self.qdd.drop_front(k);
        }
        self
    }
}

impl std::ops::Index<usize> for Signals {
    type Output = [f64];
    #[inline]
    fn index(&self, d: usize) -> &[f64] {
        &self.data[d * self.n..(d + 1) * self.n]
    }
}

impl std::ops::IndexMut<usize> for Signals {
    #[inline]
    fn index_mut(&mut self, d: usize) -> &mut [f64] {
        &mut self.data[d * self.n..(d + 1) * self.n]
    }
}

/// Which build of the closed loop this processor runs: `"avx2+fma"` (x86-64 processors
/// that have both, unless the environment variable `DIDIM_BASELINE_SIMD` is set) or
/// `"baseline"`. Both compute the same operations in the same order: the results are
/// the same, only the time differs.
pub fn simulator_build() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::wide_simd() {
        return "avx2+fma";
    }
    "baseline"
}

/// Simulates `model` with parameters `chi` under `controller` tracking `qr`.
///
/// `u_ext`, when given, is a known external force (N) added to the command at
/// each sample (before saturation), e.g. the injected pulses of the EMPS
/// validation record.
///
/// Errors: [`Error::InvalidInput`] for bad parameters, options or signals;
/// [`Error::Simulation`] when the state becomes non-finite or the tracking error
/// exceeds ten times the reference stroke plus one metre, naming the sample and
/// the parameter set.
pub fn simulate<const N: usize>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
) -> Result<SimOutput> {
    let out = integrate(model, chi, controller, qr, u_ext, opts, true, None)?;
    finite_outputs(out, model, chi, opts)
}

/// The closed loop with the chosen integrator and no tangent; `states`: keep the
/// positions, velocities and accelerations; `stats`: the exponential integrator's
/// step counts.
#[allow(clippy::too_many_arguments)]
fn integrate<const N: usize>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
    states: bool,
    stats: Option<&mut StepStats>,
) -> Result<SimOutput> {
    check_inputs(model, chi, controller, qr, u_ext, opts)?;
    // the loop compiled for the model's friction law: its shape dispatched once, here
    let out = model.law().dispatch(Integrate {
        model,
        chi,
        controller,
        qr,
        u_ext,
        opts,
        states,
        stats,
    })?;
    Ok(out.drop_front(opts.lead))
}

/// The arguments of [`integrate`], run with the model's friction law as a static shape.
struct Integrate<'a, const N: usize> {
    model: &'a Model<N>,
    chi: &'a [f64],
    controller: &'a Controller,
    qr: &'a [f64],
    u_ext: Option<&'a [f64]>,
    opts: &'a SimOptions,
    states: bool,
    stats: Option<&'a mut StepStats>,
}

impl<const N: usize> WithLaw for Integrate<'_, N> {
    type Out = Result<SimOutput>;

    fn call<L: Law>(self, law: L) -> Result<SimOutput> {
        let Self {
            model,
            chi,
            controller,
            qr,
            u_ext,
            opts,
            states,
            stats,
        } = self;
        let nt = &mut NoTangent;
        Ok(match opts.integrator {
            Integrator::Exponential => {
                let stepper = Exponential::new(model, chi, law, qr, opts)?;
                let (out, stepper) =
                    driver::run(model, chi, controller, qr, u_ext, opts, states, stepper, nt)?;
                if let Some(s) = stats {
                    *s = stepper.stats();
                }
                out
            }
            Integrator::Rk4 => {
                let stepper = Rk4::new(model, chi, law, opts)?;
                driver::run(model, chi, controller, qr, u_ext, opts, states, stepper, nt)?.0
            }
        })
    }
}

/// The commanded force of [`simulate`] alone: the states are integrated but not kept
/// (what an output-error criterion on the force needs, without writing and allocating
/// six more signals).
pub fn simulate_force<const N: usize>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
) -> Result<Vec<f64>> {
    let out = integrate(model, chi, controller, qr, u_ext, opts, false, None)?;
    Ok(finite_outputs(out, model, chi, opts)?.force)
}

/// Like [`simulate`], also returning the step counts of the exponential integrator
/// (zeros for RK4).
pub fn simulate_with_stats<const N: usize>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
) -> Result<(SimOutput, StepStats)> {
    let mut stats = StepStats::default();
    let out = integrate(model, chi, controller, qr, u_ext, opts, true, Some(&mut stats))?;
    Ok((finite_outputs(out, model, chi, opts)?, stats))
}

/// Whether every value of `x` is finite: `0·x` is `±0` for a finite `x` and NaN otherwise,
/// summed in eight independent lanes (no early exit, so the compiler vectorises it).
fn all_finite(x: &[f64]) -> bool {
    let mut acc = [0.0f64; 8];
    let chunks = x.chunks_exact(8);
    let tail = chunks.remainder().iter().map(|v| v * 0.0).sum::<f64>();
    for c in chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a += v * 0.0;
        }
    }
    acc.iter().sum::<f64>() + tail == 0.0
}

/// The first sample of `x` that is not finite: a vectorised pass decides ([`all_finite`]), the
/// scan only locates a failure.
fn first_non_finite(x: &[f64]) -> Option<usize> {
    if all_finite(x) {
        None
    } else {
        x.iter().position(|v| !v.is_finite())
    }
}

/// The output, or an error when a logged value is not finite. The positions and velocities are checked as they are
/// integrated, but a command or an acceleration that overflows at the last sample (or a command held back by the
/// delay) never reaches them: absurd gains (`gtau·vsat` beyond f64) or masses (1e-308 kg).
fn finite_outputs<const N: usize>(
    out: SimOutput,
    model: &Model<N>,
    chi: &[f64],
    opts: &SimOptions,
) -> Result<SimOutput> {
    let mut bad: Option<(usize, &str)> = first_non_finite(&out.force).map(|k| (k, "commanded force"));
    for (what, rows) in [
        ("position", &out.q),
        ("velocity", &out.qd),
        ("acceleration", &out.qdd),
    ] {
        for r in rows.iter() {
            if let Some(k) = first_non_finite(r) {
                if bad.is_none_or(|(b, _)| k < b) {
                    bad = Some((k, what));
                }
            }
        }
    }
    match bad {
        None => Ok(out),
        Some((k, what)) => Err(Error::Simulation(format!(
            "the simulated {what} is not finite at sample {k} (t = {:.6} s) with parameters {}: some parameter \
             values (a mass too small?) or controller gains are beyond f64; check their values and units",
            k as f64 * opts.dt,
            describe(model, chi)
        ))),
    }
}

/// Output of [`simulate_sensitivity`]: the simulation and the derivatives of its
/// outputs with respect to the parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct SensOutput {
    /// The simulation itself.
    pub sim: SimOutput,
    /// `∂force[k]/∂χ_j`, layout `[j][k]` (p rows of n samples).
    pub dforce: Vec<f64>,
    /// `∂q_d[k]/∂χ_j`, layout `[d][j][k]`.
    pub dq: Vec<f64>,
}

/// Simulates like [`simulate`] and integrates, with the same RK4 stages, the
/// forward sensitivity equations of the closed loop: `Ṡq = Sv`,
/// `Ṡv = ∂q̈/∂q·Sq + ∂q̈/∂q̇·Sv + ∂q̈/∂χ + ∂q̈/∂τ·∂τ/∂χ`, where the held command's
/// sensitivity `∂τ[k]/∂χ` follows from the controller's response to the measured
/// motor position at samples `k` and `k − 2` (zero while saturated). The
/// quantizer is treated as the identity. The derivatives come from the same model
/// definition as the dynamics and the regressor.
pub fn simulate_sensitivity<const N: usize>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
) -> Result<SensOutput> {
    check_inputs(model, chi, controller, qr, u_ext, opts)?; // before sizing the buffers by n and delay
    let (sim, dforce, dq) = if opts.integrator == Integrator::Exponential {
        let mut t = expint::Sens::<N>::new(model, qr.len(), opts.delay)?;
        t.cmd.set_lag(opts.force_lag, opts.dt);
        let stepper = Exponential::new(model, chi, model.law(), qr, opts)?;
        let (sim, _) = driver::run(model, chi, controller, qr, u_ext, opts, true, stepper, &mut t)?;
        (sim, t.cmd.dforce, t.dq)
    } else {
        let mut t = rk4::Sensitivity::<N>::new(model.n_params(), qr.len(), opts.delay)?;
        t.cmd.set_lag(opts.force_lag, opts.dt);
        let stepper = Rk4::new(model, chi, model.law(), opts)?;
        let (sim, _) = driver::run(model, chi, controller, qr, u_ext, opts, true, stepper, &mut t)?;
        (sim, t.cmd.dforce, t.dq)
    };
    let (mut dforce, mut dq) = (dforce, dq);
    drop_front_rows(&mut dforce, qr.len(), opts.lead);
    drop_front_rows(&mut dq, qr.len(), opts.lead);
    let sim = sim.drop_front(opts.lead);
    let sim = finite_outputs(sim, model, chi, opts)?;
    // finite states can still have non-finite sensitivities (e.g. a Coulomb force of 1e308 N at rest, whose
    // derivative is 1e308/eps): an error, not NaN in the Jacobian
    let n = opts.outputs(qr.len());
    let first_bad = dforce
        .iter()
        .chain(&dq)
        .enumerate()
        .filter(|(_, v)| !v.is_finite())
        .map(|(i, _)| i % n)
        .min();
    if let Some(k) = first_bad {
        return Err(Error::Simulation(format!(
            "the sensitivities of the closed loop are not finite from sample {k} (t = {:.6} s) with parameters {}: \
             some parameter values are too large for f64 (or coulomb_eps too small); check their values and units",
            k as f64 * opts.dt,
            describe(model, chi)
        )));
    }
    Ok(SensOutput { sim, dforce, dq })
}

fn validate_signals(qr: &[f64], u_ext: Option<&[f64]>) -> Result<usize> {
    let n = qr.len();
    if n == 0 {
        return Err(invalid!("the reference position qr is empty"));
    }
    if let Some(k) = first_non_finite(qr) {
        return Err(invalid!("reference position qr is not finite at sample {k}"));
    }
    if let Some(u) = u_ext {
        if u.len() != n {
            return Err(invalid!(
                "external input has {} samples but the reference has {n}",
                u.len()
            ));
        }
        if let Some(k) = first_non_finite(u) {
            return Err(invalid!("external input is not finite at sample {k}"));
        }
    }
    Ok(n)
}

/// Every check of the inputs of a simulation; returns the number of samples.
fn check_inputs<const N: usize>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
) -> Result<usize> {
    model.check_params(chi)?;
    controller.validate()?;
    opts.validate()?;
    let n = validate_signals(qr, u_ext)?;
    if opts.lead >= n {
        return Err(invalid!(
            "a lead-in of {} samples leaves none of the reference's {n} samples to output",
            opts.lead
        ));
    }
    if opts.delay >= n {
        return Err(invalid!(
            "actuation delay of {} samples is not shorter than the record ({n} samples): no command would ever act",
            opts.delay
        ));
    }
    Ok(n)
}

/// `name=value` list of a parameter set, for messages.
pub fn describe<const N: usize>(model: &Model<N>, chi: &[f64]) -> String {
    model
        .names()
        .iter()
        .zip(chi)
        .map(|(n, v)| format!("{n}={v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests;
