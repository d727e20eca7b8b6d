//! One axis's closed loop: the plant of one joint (the motor, dof 0 of a [`Model`] of `N`
//! degrees of freedom, a load behind it for the flexible model), [`Axis`], under the loop of
//! [`closed_loop::run`] with its one [`JointDrive`]. This is the fast path of the [`Plant`]
//! interface, not a second loop: its state is const-generic, its one drive an array of one,
//! and the whole loop, inlined, is compiled into the processor's widest build ([`simd`]).
//! A [`Stepper`] integrates the plant over each period: the exponential integrator (exact for
//! the affine part) or RK4, once for every integrator. A [`Tangent`] rides along: nothing for a
//! plain simulation, the forward sensitivities for `simulate_sensitivity`.

use super::closed_loop::{self, Plant};
use super::drive::{Delay, ForceLag, JointDrive, Start};
use super::{describe, Signals, SimOptions, SimOutput};
use crate::controller::{Controller, FilterState, TransferFunction, MAX_TAPS};
use crate::error::{filled, Error, Result};
use crate::model::Model;
use nalgebra::SVector;

pub(super) type V<const N: usize> = SVector<f64, N>;

/// An integrator of the plant over one sample period with the force held constant.
pub(super) trait Stepper<const N: usize>: Sized {
    /// What a tangent reads beside each accepted step (the plant split, the model).
    type Ctx;
    /// One accepted (sub)step, as the tangent needs it to differentiate the step.
    type Step;
    /// Extra advice for a diverged simulation (e.g. "try more substeps").
    const DIVERGENCE_HINT: &'static str;

    /// The context of the tangent.
    fn ctx(&self) -> &Self::Ctx;
    /// Sets the initial state.
    fn start(&mut self, q: &V<N>, v: &V<N>);
    /// The accelerations of the direct model at the current state `(q, v)` under the
    /// motor force `tau` (N).
    fn accel(&self, q: &V<N>, v: &V<N>, tau: f64) -> V<N>;
    /// Advances `(q, v)` over one sample period under the held motor force `tau`;
    /// `tangent` sees every accepted step.
    fn advance<T: Tangent<N, Self>>(
        &mut self,
        q: &mut V<N>,
        v: &mut V<N>,
        tau: f64,
        tangent: &mut T,
    ) -> Result<()>;
}

/// What rides along the samples and the steps of a [`Stepper`] `S`.
pub(super) trait Tangent<const N: usize, S: Stepper<N>> {
    /// Sets up the tangent at the initial state.
    fn start(&mut self, ctx: &S::Ctx, q: &V<N>, v: &V<N>);
    /// The command of sample `k` has been computed by `law` (`active`: not saturated);
    /// `tau` is the force applied over the coming period (after the delay).
    fn command(&mut self, k: usize, law: &TransferFunction, active: bool, tau: f64);
    /// Records the outputs of sample `k`.
    fn record(&mut self, k: usize);
    /// Differentiates one accepted step.
    fn step(&mut self, ctx: &S::Ctx, step: &S::Step) -> Result<()>;
}

/// The command's part of the sensitivities, the same for every plant and integrator: the
/// controller's law run on `∂q1/∂χ_j` per parameter, plus the sensitivity of the force the drive
/// adds (a robot's held first force; none on one axis), zero while the command saturates; delayed
/// like the command (the same [`Delay`]: zero before the first command as one axis's 0, or the
/// first command's own for a drive that held it) and through the same force lag; recorded as
/// `∂force[k]/∂χ_j`.
pub(crate) struct CommandSens {
    n: usize,
    /// The controller's state on `∂q1/∂χ`, one per parameter.
    ctl: Vec<FilterState>,
    /// The command sensitivities on their way (one vector per sample of delay).
    pending: Delay<Vec<f64>>,
    /// The sensitivity of the force added to every command (one per parameter; empty: none).
    dext: Vec<f64>,
    /// Fill the delay with the first command's sensitivities ([`super::drive::Held::FirstCommand`]).
    hold_first: bool,
    /// The force lag and the sensitivities of its output at the start of the period.
    lag: Option<ForceLag>,
    lagged: Option<Vec<f64>>,
    /// Sensitivity of the force applied over the current period.
    pub dtau: Vec<f64>,
    /// `∂force[k]/∂χ_j`, layout `[j][k]`.
    pub dforce: Vec<f64>,
}

impl CommandSens {
    /// One axis's: `p` parameters, `n` samples, `delay` samples of delay holding 0 before the
    /// record, no force added, no lag.
    pub fn new(p: usize, n: usize, delay: usize) -> Result<Self> {
        Ok(Self {
            n,
            ctl: vec![[0.0; MAX_TAPS]; p],
            pending: Delay::new(vec![vec![0.0; p]; delay]),
            dext: Vec::new(),
            hold_first: false,
            lag: None,
            lagged: None,
            dtau: vec![0.0; p],
            dforce: filled(p * n, 0.0, "the force sensitivities")?,
        })
    }

    /// A robot joint's (`sim::drive::Start::Holding`): the first command held through the delay,
    /// the force lag `lag` (s, 0 for none) at the sample period `dt`, and `dext` (one per
    /// parameter) the sensitivity of the force the drive adds to every command.
    pub fn holding(n: usize, delay: usize, lag: f64, dt: f64, dext: Vec<f64>) -> Result<Self> {
        let mut out = Self::new(dext.len(), n, delay)?;
        out.hold_first = delay > 0;
        out.set_lag(lag, dt);
        out.dext = dext;
        Ok(out)
    }

    /// The force lag `lag` (s, 0 for none) at the sample period `dt` between the delayed command
    /// and the force applied ([`super::drive::Actuator`]'s).
    pub fn set_lag(&mut self, lag: f64, dt: f64) {
        self.lag = ForceLag::new(lag, dt);
    }

    /// The command of sample `k` (by `law`, `active`: not saturated) with `dq1(j)` the
    /// sensitivity of the measured motor position to parameter `j`.
    pub fn command(&mut self, k: usize, law: &TransferFunction, active: bool, dq1: impl Fn(usize) -> f64) {
        let gain = if active { law.gain() } else { 0.0 };
        for (j, c) in self.dtau.iter_mut().enumerate() {
            *c = gain * law.sensitivity_step(&mut self.ctl[j], dq1(j));
            if active && !self.dext.is_empty() {
                *c += self.dext[j];
            }
            self.dforce[j * self.n + k] = *c;
        }
        if self.hold_first {
            self.pending.fill(&self.dtau);
            self.hold_first = false;
        }
        // this sample's sensitivities in, those of `delay` samples earlier out to be applied
        self.pending.pass(&mut self.dtau);
        if let Some(lag) = self.lag {
            // the lag is linear: its sensitivities follow it (`ForceLag::period`), from the first
            let start = self.lagged.get_or_insert_with(|| self.dtau.clone());
            for (c, f0) in self.dtau.iter_mut().zip(start.iter_mut()) {
                let (mean, end) = lag.period(*f0, *c);
                *f0 = end;
                *c = mean;
            }
        }
    }
}

/// The tangent of a plain simulation.
pub(super) struct NoTangent;

impl<const N: usize, S: Stepper<N>> Tangent<N, S> for NoTangent {
    #[inline(always)]
    fn start(&mut self, _: &S::Ctx, _: &V<N>, _: &V<N>) {}
    #[inline(always)]
    fn command(&mut self, _: usize, _: &TransferFunction, _: bool, _: f64) {}
    #[inline(always)]
    fn record(&mut self, _: usize) {}
    #[inline(always)]
    fn step(&mut self, _: &S::Ctx, _: &S::Step) -> Result<()> {
        Ok(())
    }
}

/// Whether every entry of `q` and `v` is finite: their sum is then finite too unless it
/// overflows, which for a state is divergence as well (one test instead of `2N`).
#[inline(always)]
fn finite<const N: usize>(q: &V<N>, v: &V<N>) -> bool {
    (q.sum() + v.sum()).is_finite()
}

/// One axis as a [`Plant`] of one joint (its motor, dof 0): the state `(q, v)` of a model of `N`
/// degrees of freedom, integrated by the [`Stepper`] `S` with the [`Tangent`] `T` riding along,
/// and, when `states`, the recorded positions, velocities and accelerations.
struct Axis<'a, const N: usize, S: Stepper<N>, T: Tangent<N, S>> {
    model: &'a Model<N>,
    chi: &'a [f64],
    opts: &'a SimOptions,
    stepper: S,
    tangent: &'a mut T,
    q: V<N>,
    v: V<N>,
    /// Samples recorded per signal: all of them when the states are kept, else 0.
    m: usize,
    out_q: Signals,
    out_qd: Signals,
    out_qdd: Signals,
}

impl<const N: usize, S: Stepper<N>, T: Tangent<N, S>> Plant for Axis<'_, N, S, T> {
    type Joints = [f64; 1];

    #[inline(always)]
    fn joints(&self) -> [f64; 1] {
        [0.0]
    }

    #[inline(always)]
    fn position(&self, _: usize) -> f64 {
        self.q[0]
    }

    #[inline(always)]
    fn commanded(&mut self, k: usize, _: usize, drive: &JointDrive, active: bool, applied: f64) {
        self.tangent.command(k, drive.law(), active, applied);
    }

    #[inline(always)]
    fn record(&mut self, k: usize, applied: &[f64]) -> Result<()> {
        if self.m > 0 {
            // the direct model's acceleration at the recorded state: the IDM of the
            // outputs reproduces the applied force to rounding
            let a = self.stepper.accel(&self.q, &self.v, applied[0]);
            for d in 0..N {
                let at = d * self.m + k; // dof d's row, sample k (the layout of Signals)
                self.out_q.data[at] = self.q[d];
                self.out_qd.data[at] = self.v[d];
                self.out_qdd.data[at] = a[d];
            }
        }
        self.tangent.record(k);
        Ok(())
    }

    #[inline(always)]
    fn advance(&mut self, applied: &[f64]) -> Result<()> {
        self.stepper
            .advance(&mut self.q, &mut self.v, applied[0], &mut *self.tangent)
    }

    #[inline(always)]
    fn finite(&self) -> bool {
        finite(&self.q, &self.v)
    }

    /// Out of line with the values it reports, not the plant: a pointer to the plant would keep
    /// its state out of registers throughout the loop.
    #[inline(always)]
    fn diverged(&self, k: usize, qr: &[f64], bound: &[f64]) -> Error {
        diverged(
            self.model,
            self.chi,
            self.opts,
            k,
            (self.q[0] - qr[0]).abs(),
            bound[0],
            S::DIVERGENCE_HINT,
        )
    }
}

/// The error of one axis's loop found diverged at sample `k` (of the simulation, the lead-in's
/// included), its motor `err` from its reference beyond `bound`; `hint` the integrator's advice.
#[cold]
#[inline(never)]
fn diverged<const N: usize>(
    model: &Model<N>,
    chi: &[f64],
    opts: &SimOptions,
    k: usize,
    err: f64,
    bound: f64,
    hint: &str,
) -> Error {
    Error::Simulation(format!(
        "closed-loop simulation diverged at {}: motor tracking error {:.3e} m \
         (bound {:.3e} m) with parameters {}; check the parameter values and units and the controller \
         gains{}{}",
        {
            // samples of the record from 0; a lead-in's are negative
            let j = k as f64 - opts.lead as f64;
            format!(
                "sample {j} (t = {:.6} s{})",
                j * opts.dt,
                if j < 0.0 {
                    ", in the lead-in before the record"
                } else {
                    ""
                }
            )
        },
        err,
        bound,
        describe(model, chi),
        if opts.force_lag > 0.0 {
            format!(
                ", and the force lag of {} s (a current loop's is a fraction of a millisecond)",
                opts.force_lag
            )
        } else {
            String::new()
        },
        hint,
    ))
}

/// The closed-loop simulation of `model` with parameters `chi` (already checked, with
/// the signals and options) integrated by `stepper`: the loop of [`closed_loop::run`] over the
/// [`Axis`] plant and its one [`JointDrive`], started at rest at the first reference (the
/// controller at rest, nothing applied before the record); `states`: record the positions,
/// velocities and accelerations too (else only the force). Returns the stepper for its
/// statistics.
///
/// The loop is compiled twice (see [`simd`]): for the baseline x86-64 and with AVX2 and FMA.
#[allow(clippy::too_many_arguments)]
pub(super) fn run<const N: usize, S: Stepper<N>, T: Tangent<N, S>>(
    model: &Model<N>,
    chi: &[f64],
    controller: &Controller,
    qr: &[f64],
    u_ext: Option<&[f64]>,
    opts: &SimOptions,
    states: bool,
    stepper: S,
    tangent: &mut T,
) -> Result<(SimOutput, S)> {
    simd(
        #[inline(always)]
        move || {
            let n = qr.len();
            let (lo, hi) = qr.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
            let bound = [10.0 * (hi - lo) + 1.0];
            let law = controller.law(opts.dt)?;
            let mut drive = [JointDrive::new(
                law,
                opts.quantization,
                opts.delay,
                opts.force_lag,
                opts.dt,
                Start::Rest { qr0: qr[0] },
            )];
            let m = if states { n } else { 0 };
            let mut force = filled(n, 0.0, "the simulated force")?;
            let mut axis = Axis {
                model,
                chi,
                opts,
                stepper,
                tangent,
                q: V::<N>::repeat(qr[0]),
                v: V::<N>::zeros(),
                m,
                out_q: Signals::zeros(N, m, "the simulated positions")?,
                out_qd: Signals::zeros(N, m, "the simulated velocities")?,
                out_qdd: Signals::zeros(N, m, "the simulated accelerations")?,
            };
            axis.stepper.start(&axis.q, &axis.v);
            axis.tangent.start(axis.stepper.ctx(), &axis.q, &axis.v);
            closed_loop::run(&mut axis, &mut drive, qr, u_ext, &bound, &mut force)?;
            let out = SimOutput {
                force,
                q: axis.out_q,
                qd: axis.out_qd,
                qdd: axis.out_qdd,
            };
            Ok((out, axis.stepper))
        },
    )
}

/// Runs `f` compiled for the processor: with AVX2 and FMA enabled where it has both
/// ([`crate::cpu::wide_simd`]), else for the baseline x86-64 (SSE2). `f` is inlined into each build
/// with whatever `#[inline(always)]` code it calls (the closed loop, the steppers' steps,
/// the controller): three-operand instructions and wider registers, about 4 % of a
/// simulation on the quantized EMPS record. Rust never fuses a multiply and an add by
/// itself (only `mul_add` does), so both builds compute the same IEEE operations in the
/// same order and give the same results. Out of line: the callers' fast paths stay compact.
#[inline(never)]
pub(crate) fn simd<R>(f: impl FnOnce() -> R) -> R {
    /// # Safety
    /// The processor must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn wide<R>(f: impl FnOnce() -> R) -> R {
        f()
    }
    #[cfg(target_arch = "x86_64")]
    let _flush = crate::filter::FlushSubnormals::on();
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::wide_simd() {
        // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
        return unsafe { wide(f) };
    }
    f()
}
