//! Fixed-step closed-loop simulation of a model under a digital controller.
//!
//! Every sample period `T` the controller reads the (optionally quantized)
//! motor position and computes a force held constant over the period
//! (zero-order hold), optionally delayed by a whole number of samples. The
//! continuous plant is integrated with classical RK4 over `substeps` equal
//! substeps per period. The simulation starts at rest at the first reference
//! position (spring unloaded).
//!
//! Per sample `k` (time `t_k = k·T`) it outputs the commanded force (what the
//! drive logs, after saturation) and the noise-free states at `t_k`: positions,
//! velocities and the accelerations of the direct model under the force applied
//! over `[t_k, t_{k+1})`. Without delay the IDM of these states reproduces the
//! commanded force exactly.

use crate::controller::Controller;
use crate::error::{invalid, Error, Result};
use crate::model::Model;
use nalgebra::SVector;

/// Options of the simulator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimOptions {
    /// Sample period of the controller and of the outputs (s).
    pub dt: f64,
    /// RK4 substeps per sample period (default 10).
    pub substeps: usize,
    /// Resolution of the measured motor position (m); 0 for none. EMPS: 5e-8 m.
    pub quantization: f64,
    /// Extra actuation delay in samples: the force applied over `[t_k, t_{k+1})`
    /// is the command of sample `k − delay` (0 before the first command).
    pub delay: usize,
}

impl SimOptions {
    /// Options with sample period `dt` and the defaults (10 substeps, no quantization, no delay).
    pub fn new(dt: f64) -> Self {
        Self {
            dt,
            substeps: 10,
            quantization: 0.0,
            delay: 0,
        }
    }

    fn validate(&self) -> Result<()> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(invalid!("sample period dt must be finite and > 0 s, got {}", self.dt));
        }
        if self.substeps == 0 {
            return Err(invalid!("substeps must be at least 1 (default 10)"));
        }
        if self.substeps > 100_000 {
            return Err(invalid!("substeps = {} is unreasonably large (at most 100000)", self.substeps));
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
    model.check_params(chi)?;
    controller.validate()?;
    opts.validate()?;
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

    let (lo, hi) = qr.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
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
    let q0m = quantize(q[0]);
    let (mut qm1, mut qm2) = (q0m, q0m); // measurements at k-1 and k-2
    let mut pending = vec![0.0; opts.delay]; // ring buffer of delayed commands

    let mut out = SimOutput {
        force: Vec::with_capacity(n),
        q: vec![Vec::with_capacity(n); N],
        qd: vec![Vec::with_capacity(n); N],
        qdd: vec![Vec::with_capacity(n); N],
    };

    for k in 0..n {
        let qm = quantize(q[0]);
        let tau_cmd = controller.command(qr[k], qm, qm2, opts.dt, u_ext.map_or(0.0, |u| u[k]));
        qm2 = qm1;
        qm1 = qm;
        let tau = if opts.delay == 0 {
            tau_cmd
        } else {
            std::mem::replace(&mut pending[k % opts.delay], tau_cmd)
        };

        let a = accel(&q, &qd, tau);
        out.force.push(tau_cmd);
        for d in 0..N {
            out.q[d].push(q[d]);
            out.qd[d].push(qd[d]);
            out.qdd[d].push(a[d]);
        }
        if k + 1 == n {
            break;
        }

        // RK4 over the sample period with the force held.
        let mut a1 = a;
        for s in 0..opts.substeps {
            if s > 0 {
                a1 = accel(&q, &qd, tau);
            }
            let (v1, q2, v2) = (qd, q + qd * (0.5 * h), qd + a1 * (0.5 * h));
            let a2 = accel(&q2, &v2, tau);
            let (q3, v3) = (q + v2 * (0.5 * h), qd + a2 * (0.5 * h));
            let a3 = accel(&q3, &v3, tau);
            let (q4, v4) = (q + v3 * h, qd + a3 * h);
            let a4 = accel(&q4, &v4, tau);
            q += (v1 + (v2 + v3) * 2.0 + v4) * (h / 6.0);
            qd += (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0);
        }

        let err = (q[0] - qr[k + 1]).abs();
        if !(q.iter().chain(qd.iter()).all(|x| x.is_finite()) && err <= bound) {
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
