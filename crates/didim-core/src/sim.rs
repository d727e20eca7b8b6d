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

use crate::controller::{Controller, FilterState, TransferFunction, MAX_TAPS};
use crate::error::{filled, invalid, room, Error, Result};
use crate::model::Model;
use nalgebra::SVector;

mod expint;
pub use expint::StepStats;

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
    /// The integration scheme (default [`Integrator::Exponential`]).
    pub integrator: Integrator,
    /// Local error tolerance of the exponential integrator per step, as a fraction
    /// of the reference stroke (default [`DEFAULT_TOL`]).
    pub tol: f64,
}

impl SimOptions {
    /// Options with sample period `dt` and the defaults (10 substeps, no quantization, no delay).
    pub fn new(dt: f64) -> Self {
        Self {
            dt,
            substeps: 10,
            quantization: 0.0,
            delay: 0,
            integrator: Integrator::Exponential,
            tol: DEFAULT_TOL,
        }
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
    pub q: Vec<Vec<f64>>,
    /// Velocities (m/s), same layout.
    pub qd: Vec<Vec<f64>>,
    /// Accelerations (m/s²), same layout.
    pub qdd: Vec<Vec<f64>>,
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
    match opts.integrator {
        Integrator::Exponential => expint::run(
            model,
            chi,
            controller,
            qr,
            u_ext,
            opts,
            states,
            stats,
            &mut expint::NoHook,
        ),
        Integrator::Rk4 => run(model, chi, controller, qr, u_ext, opts, states, &mut NoTangent),
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

/// The output, or an error when a logged value is not finite. The positions and velocities are checked as they are
/// integrated, but a command or an acceleration that overflows at the last sample (or a command held back by the
/// delay) never reaches them: absurd gains (`gtau·vsat` beyond f64) or masses (1e-308 kg).
fn finite_outputs<const N: usize>(
    out: SimOutput,
    model: &Model<N>,
    chi: &[f64],
    opts: &SimOptions,
) -> Result<SimOutput> {
    let first = |x: &[f64]| x.iter().position(|v| !v.is_finite());
    let mut bad: Option<(usize, &str)> = first(&out.force).map(|k| (k, "commanded force"));
    for (what, rows) in [
        ("position", &out.q),
        ("velocity", &out.qd),
        ("acceleration", &out.qdd),
    ] {
        for r in rows.iter() {
            if let Some(k) = first(r) {
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
        let sim = expint::run(model, chi, controller, qr, u_ext, opts, true, None, &mut t)?;
        (sim, t.dforce, t.dq)
    } else {
        let mut t = Sensitivity::<N>::new(model.n_params(), qr.len(), opts.delay)?;
        let sim = run(model, chi, controller, qr, u_ext, opts, true, &mut t)?;
        (sim, t.dforce, t.dq)
    };
    let sim = finite_outputs(sim, model, chi, opts)?;
    // finite states can still have non-finite sensitivities (e.g. a Coulomb force of 1e308 N at rest, whose
    // derivative is 1e308/eps): an error, not NaN in the Jacobian
    let n = qr.len();
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

/// One RK4 stage of the state: position, velocity, acceleration.
type Stage<const N: usize> = (SVector<f64, N>, SVector<f64, N>, SVector<f64, N>);

/// What rides along the state through the simulation loop: nothing for a plain
/// simulation, the sensitivity matrices for [`simulate_sensitivity`].
trait Tangent<const N: usize> {
    /// The command of sample `k` has been computed by `law` (`active`: not saturated).
    fn command(&mut self, k: usize, law: &TransferFunction, active: bool);
    /// Records the state outputs of sample `k`.
    fn record(&mut self, k: usize);
    /// Advances by one RK4 substep of length `h` through the state's four stages.
    fn substep(
        &mut self,
        model: &Model<N>,
        chi: &[f64],
        inv_mass: &SVector<f64, N>,
        stages: &[Stage<N>; 4],
        h: f64,
    );
}

struct NoTangent;

impl<const N: usize> Tangent<N> for NoTangent {
    #[inline(always)]
    fn command(&mut self, _: usize, _: &TransferFunction, _: bool) {}
    #[inline(always)]
    fn record(&mut self, _: usize) {}
    #[inline(always)]
    fn substep(&mut self, _: &Model<N>, _: &[f64], _: &SVector<f64, N>, _: &[Stage<N>; 4], _: f64) {}
}

/// Sensitivities `Sq = ∂q/∂χ`, `Sv = ∂q̇/∂χ` (dof × parameter, flat `[d * p + j]`)
/// and the work buffers of their RK4 integration.
struct Sensitivity<const N: usize> {
    p: usize,
    n: usize,
    sq: Vec<f64>,
    sv: Vec<f64>,
    /// The controller's state on `∂q1/∂χ`, one per parameter.
    ctl: Vec<FilterState>,
    /// Sensitivity of the force applied over the current period.
    dtau: Vec<f64>,
    /// Delayed command sensitivities (ring buffer, like the commands).
    pending: Vec<Vec<f64>>,
    dforce: Vec<f64>,
    dq: Vec<f64>,
    // RK4 work buffers
    kq: [Vec<f64>; 4],
    kv: [Vec<f64>; 4],
    stage_q: Vec<f64>,
    stage_v: Vec<f64>,
    phi: Vec<f64>,
}

impl<const N: usize> Sensitivity<N> {
    fn new(p: usize, n: usize, delay: usize) -> Result<Self> {
        let z = vec![0.0; N * p];
        Ok(Self {
            p,
            n,
            sq: z.clone(),
            sv: z.clone(),
            ctl: vec![[0.0; MAX_TAPS]; p],
            dtau: vec![0.0; p],
            pending: vec![vec![0.0; p]; delay],
            dforce: filled(p * n, 0.0, "the force sensitivities")?,
            dq: filled(N * p * n, 0.0, "the position sensitivities")?,
            kq: [z.clone(), z.clone(), z.clone(), z.clone()],
            kv: [z.clone(), z.clone(), z.clone(), z.clone()],
            stage_q: z.clone(),
            stage_v: z.clone(),
            phi: z,
        })
    }
}

impl<const N: usize> Tangent<N> for Sensitivity<N> {
    fn command(&mut self, k: usize, law: &TransferFunction, active: bool) {
        let (p, n, d) = (self.p, self.n, self.pending.len());
        // ∂τ[k]/∂χ: the controller's law on ∂q1/∂χ (zero while the command saturates).
        let cmd = if d == 0 {
            &mut self.dtau
        } else {
            // the slot of sample k held the command of sample k − d: apply it now
            let slot = &mut self.pending[k % d];
            std::mem::swap(&mut self.dtau, slot);
            slot
        };
        let gain = if active { law.gain() } else { 0.0 };
        for j in 0..p {
            cmd[j] = gain * law.sensitivity_step(&mut self.ctl[j], self.sq[j]);
            self.dforce[j * n + k] = cmd[j];
        }
    }

    fn record(&mut self, k: usize) {
        let (p, n) = (self.p, self.n);
        for d in 0..N {
            for j in 0..p {
                self.dq[(d * p + j) * n + k] = self.sq[d * p + j];
            }
        }
    }

    fn substep(
        &mut self,
        model: &Model<N>,
        chi: &[f64],
        inv_mass: &SVector<f64, N>,
        stages: &[Stage<N>; 4],
        h: f64,
    ) {
        let p = self.p;
        let len = N * p;
        for (i, (q, v, a)) in stages.iter().enumerate() {
            if i == 0 {
                self.stage_q.copy_from_slice(&self.sq);
                self.stage_v.copy_from_slice(&self.sv);
            } else {
                let f = if i == 3 { h } else { 0.5 * h };
                for x in 0..len {
                    self.stage_q[x] = self.sq[x] + f * self.kq[i - 1][x];
                    self.stage_v[x] = self.sv[x] + f * self.kv[i - 1][x];
                }
            }
            let (aq, av) = model.accel_partials(chi, inv_mass, q, v);
            model.regressor_into(q, v, a, &mut self.phi);
            for d in 0..N {
                for j in 0..p {
                    let mut s = -self.phi[d * p + j] * inv_mass[d];
                    for e in 0..N {
                        s += aq[(d, e)] * self.stage_q[e * p + j] + av[(d, e)] * self.stage_v[e * p + j];
                    }
                    if d == 0 {
                        s += inv_mass[0] * self.dtau[j];
                    }
                    self.kv[i][d * p + j] = s;
                    self.kq[i][d * p + j] = self.stage_v[d * p + j];
                }
            }
        }
        for x in 0..len {
            self.sq[x] += h / 6.0 * (self.kq[0][x] + 2.0 * (self.kq[1][x] + self.kq[2][x]) + self.kq[3][x]);
            self.sv[x] += h / 6.0 * (self.kv[0][x] + 2.0 * (self.kv[1][x] + self.kv[2][x]) + self.kv[3][x]);
        }
    }
}

fn validate_signals(qr: &[f64], u_ext: Option<&[f64]>) -> Result<usize> {
    let n = qr.len();
    if n == 0 {
        return Err(invalid!("the reference position qr is empty"));
    }
    if let Some(k) = qr.iter().position(|v| !v.is_finite()) {
        return Err(invalid!("reference position qr is not finite at sample {k}"));
    }
    if let Some(u) = u_ext {
        if u.len() != n {
            return Err(invalid!(
                "external input has {} samples but the reference has {n}",
                u.len()
            ));
        }
        if let Some(k) = u.iter().position(|v| !v.is_finite()) {
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
    if opts.delay >= n {
        return Err(invalid!(
            "actuation delay of {} samples is not shorter than the record ({n} samples): no command would ever act",
            opts.delay
        ));
    }
    Ok(n)
}

/// The simulation loop shared by [`simulate`] and [`simulate_sensitivity`]; `states`:
/// record the positions, velocities and accelerations too (else only the force).
#[allow(clippy::too_many_arguments)]
fn run<const N: usize, T: Tangent<N>>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
    states: bool,
    tangent: &mut T,
) -> Result<SimOutput> {
    let n = check_inputs(model, chi, controller, qr, u_ext, opts)?;

    let (lo, hi) = qr.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
        (a.min(x), b.max(x))
    });
    let bound = 10.0 * (hi - lo) + 1.0;

    let inv_mass = model.masses(chi).map(|m| 1.0 / m);
    let h = opts.dt / opts.substeps as f64;
    let quantize = |x: f64| {
        if opts.quantization > 0.0 {
            (x / opts.quantization).round() * opts.quantization
        } else {
            x
        }
    };
    let accel = |q: &SVector<f64, N>, qd: &SVector<f64, N>, tau: f64| {
        let mut u = SVector::<f64, N>::zeros();
        u[0] = tau;
        model.accel(chi, &inv_mass, q, qd, &u)
    };

    let mut q = SVector::<f64, N>::repeat(qr[0]);
    let mut qd = SVector::<f64, N>::zeros();
    let law = controller.law(opts.dt)?;
    let mut ctl = law.rest_state(qr[0], quantize(q[0]));
    let mut pending = vec![0.0; opts.delay]; // ring buffer of delayed commands

    let m = if states { n } else { 0 };
    let signals = |what| (0..N).map(|_| room(m, what)).collect::<Result<Vec<_>>>();
    let mut out = SimOutput {
        force: room(n, "the simulated force")?,
        q: signals("the simulated positions")?,
        qd: signals("the simulated velocities")?,
        qdd: signals("the simulated accelerations")?,
    };

    for k in 0..n {
        if k % crate::interrupt::EVERY == 0 {
            crate::interrupt::check()?;
        }
        let qm = quantize(q[0]);
        let (tau_cmd, active) = law.step(&mut ctl, qr[k], qm, u_ext.map_or(0.0, |u| u[k]));
        tangent.command(k, &law, active);
        let tau = if opts.delay == 0 {
            tau_cmd
        } else {
            std::mem::replace(&mut pending[k % opts.delay], tau_cmd)
        };

        let a = accel(&q, &qd, tau);
        out.force.push(tau_cmd);
        if states {
            for d in 0..N {
                out.q[d].push(q[d]);
                out.qd[d].push(qd[d]);
                out.qdd[d].push(a[d]);
            }
        }
        tangent.record(k);
        if k + 1 == n {
            break;
        }

        // RK4 over the sample period with the force held.
        let mut a1 = a;
        for s in 0..opts.substeps {
            if s > 0 {
                a1 = accel(&q, &qd, tau);
            }
            let (q2, v2) = (q + qd * (0.5 * h), qd + a1 * (0.5 * h));
            let a2 = accel(&q2, &v2, tau);
            let (q3, v3) = (q + v2 * (0.5 * h), qd + a2 * (0.5 * h));
            let a3 = accel(&q3, &v3, tau);
            let (q4, v4) = (q + v3 * h, qd + a3 * h);
            let a4 = accel(&q4, &v4, tau);
            tangent.substep(
                model,
                chi,
                &inv_mass,
                &[(q, qd, a1), (q2, v2, a2), (q3, v3, a3), (q4, v4, a4)],
                h,
            );
            q += (qd + (v2 + v3) * 2.0 + v4) * (h / 6.0);
            qd += (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0);
        }

        let err = (q[0] - qr[k + 1]).abs();
        if !(expint::finite(&q, &qd) && err <= bound) {
            return Err(Error::Simulation(format!(
                "closed-loop simulation diverged at sample {} (t = {:.6} s): motor tracking error {:.3e} m \
                 (bound {:.3e} m) with parameters {}; check the parameter values and units, the controller gains, \
                 and try more substeps",
                k + 1,
                (k + 1) as f64 * opts.dt,
                err,
                bound,
                describe(model, chi)
            )));
        }
    }
    Ok(out)
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
