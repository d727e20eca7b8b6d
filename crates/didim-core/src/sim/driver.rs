//! The closed loop, once for every integrator: each sample the controller reads the
//! (quantized) motor position and computes the force held over the coming period
//! (optionally delayed), the outputs of the sample are recorded, and a [`Stepper`]
//! integrates the plant over the period. A [`Tangent`] rides along: nothing for a plain
//! simulation, the forward sensitivities for `simulate_sensitivity`.

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

/// The command's part of the sensitivities, the same for every integrator: the
/// controller's law run on `∂q1/∂χ_j` per parameter (zero while the command saturates),
/// delayed like the command, and recorded as `∂force[k]/∂χ_j`.
pub(super) struct CommandSens {
    n: usize,
    /// The controller's state on `∂q1/∂χ`, one per parameter.
    ctl: Vec<FilterState>,
    /// Delayed command sensitivities (ring buffer, like the commands).
    pending: Vec<Vec<f64>>,
    /// Sensitivity of the force applied over the current period.
    pub dtau: Vec<f64>,
    /// `∂force[k]/∂χ_j`, layout `[j][k]`.
    pub dforce: Vec<f64>,
}

impl CommandSens {
    pub fn new(p: usize, n: usize, delay: usize) -> Result<Self> {
        Ok(Self {
            n,
            ctl: vec![[0.0; MAX_TAPS]; p],
            pending: vec![vec![0.0; p]; delay],
            dtau: vec![0.0; p],
            dforce: filled(p * n, 0.0, "the force sensitivities")?,
        })
    }

    /// The command of sample `k` (by `law`, `active`: not saturated) with `dq1(j)` the
    /// sensitivity of the measured motor position to parameter `j`.
    pub fn command(&mut self, k: usize, law: &TransferFunction, active: bool, dq1: impl Fn(usize) -> f64) {
        let d = self.pending.len();
        let cmd = if d == 0 {
            &mut self.dtau
        } else {
            // the slot of sample k held the command of sample k − d: apply it now
            let slot = &mut self.pending[k % d];
            std::mem::swap(&mut self.dtau, slot);
            slot
        };
        let gain = if active { law.gain() } else { 0.0 };
        for (j, c) in cmd.iter_mut().enumerate() {
            *c = gain * law.sensitivity_step(&mut self.ctl[j], dq1(j));
            self.dforce[j * self.n + k] = *c;
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

/// The nearest multiple of `step` (ties away from zero, like [`f64::round`]) without the
/// libm call `round` compiles to on baseline x86-64: adding and removing 1.5·2⁵² rounds to
/// the nearest integer (ties to even), exact ties are then moved away from zero, and the
/// sign of zero is kept.
#[inline(always)]
pub(super) fn round_to(x: f64, step: f64) -> f64 {
    let y = x / step;
    if y.abs() >= TWO_52 {
        return y.round() * step; // beyond 2^52 every double is an integer already
    }
    let mut r = (y + MAGIC) - MAGIC;
    if (r - y).abs() == 0.5 {
        r = y + 0.5 * y.signum();
    }
    r.copysign(y) * step
}

const MAGIC: f64 = 6_755_399_441_055_744.0; // 1.5 · 2^52
const TWO_52: f64 = 4_503_599_627_370_496.0;

/// The encoder: [`round_to`] its resolution, with the division (whose latency lies on the
/// loop's critical path, sample after sample) replaced by a product with the inverse. The
/// product is within 2 ulps of the quotient, so both round to the same multiple unless the
/// quotient is that close to a tie (or beyond 2⁵²): there the division decides. Bit for
/// bit the result of [`round_to`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Quantizer {
    step: f64,
    inv: f64,
}

impl Quantizer {
    /// `step` (m): the resolution, 0 for none.
    pub fn new(step: f64) -> Self {
        Self {
            step,
            inv: if step > 0.0 { 1.0 / step } else { 0.0 },
        }
    }

    #[inline(always)]
    pub fn apply(&self, x: f64) -> f64 {
        if self.step <= 0.0 {
            return x;
        }
        let y = x * self.inv;
        let r = (y + MAGIC) - MAGIC;
        let margin = 8.0 * f64::EPSILON * y.abs();
        if y.abs() < 0.25 * TWO_52 && ((r - y).abs() - 0.5).abs() > margin {
            r.copysign(y) * self.step
        } else {
            round_to(x, self.step)
        }
    }
}

/// A first-order lag `T ḟ = τ − f` between the held command `τ` and the applied force `f`
/// (see [`SimOptions::force_lag`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ForceLag {
    /// `e^{−T_s/T}`: what remains of the gap `f − τ` after one period.
    decay: f64,
    /// `(T/T_s)(1 − e^{−T_s/T})`: the share of the initial gap in the period's mean force.
    mean: f64,
}

impl ForceLag {
    pub(crate) fn new(lag: f64, dt: f64) -> Option<Self> {
        (lag > 0.0).then(|| {
            let decay = (-dt / lag).exp();
            Self {
                decay,
                mean: lag / dt * (1.0 - decay),
            }
        })
    }

    /// The mean applied force over a period from `f0` under the command `tau`, and the
    /// applied force at its end.
    #[inline(always)]
    pub(crate) fn period(&self, f0: f64, tau: f64) -> (f64, f64) {
        (tau + (f0 - tau) * self.mean, tau + (f0 - tau) * self.decay)
    }
}

/// The force the plant receives, as the mean over each sample period, when the drive logs the
/// commands `force`: the command of `delay` samples earlier (`held` before the first: 0 for one
/// axis's loop from rest, the first command for a robot's, whose drive held it), held over the
/// period, through the first-order [`SimOptions::force_lag`] `lag` (s) started at its first
/// value, as the simulators apply it; `dt` the sample period (s). With no delay and no lag, the
/// commands themselves. DIDIM's regression target: the simulated states answer this force, not
/// the logged command.
pub fn applied_force(force: &[f64], delay: usize, lag: f64, dt: f64, held: f64) -> Vec<f64> {
    let n = force.len();
    let delayed = (0..n).map(|k| if k < delay { held } else { force[k - delay] });
    match ForceLag::new(lag, dt) {
        None => delayed.collect(),
        Some(fl) => {
            let mut f: Option<f64> = None;
            delayed
                .map(|tau| {
                    let (mean, end) = fl.period(*f.get_or_insert(tau), tau);
                    f = Some(end);
                    mean
                })
                .collect()
        }
    }
}

/// The closed-loop simulation of `model` with parameters `chi` (already checked, with
/// the signals and options) integrated by `stepper`; `states`: record the positions,
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
            let mut stepper = stepper;
            let n = qr.len();
            let (lo, hi) = qr.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
            let bound = 10.0 * (hi - lo) + 1.0;
            let encoder = Quantizer::new(opts.quantization);
            let quantize = |x: f64| encoder.apply(x);

            let mut q = V::<N>::repeat(qr[0]);
            let mut v = V::<N>::zeros();
            stepper.start(&q, &v);
            tangent.start(stepper.ctx(), &q, &v);
            let law = controller.law(opts.dt)?;
            let mut ctl = law.rest_state(qr[0], quantize(q[0]));
            let mut pending = vec![0.0; opts.delay]; // ring buffer of delayed commands
            let lag = ForceLag::new(opts.force_lag, opts.dt);
            let mut applied: Option<f64> = None; // the lagged force at the start of the period

            let m = if states { n } else { 0 };
            let mut out = SimOutput {
                force: filled(n, 0.0, "the simulated force")?,
                q: Signals::zeros(N, m, "the simulated positions")?,
                qd: Signals::zeros(N, m, "the simulated velocities")?,
                qdd: Signals::zeros(N, m, "the simulated accelerations")?,
            };

            for k in 0..n {
                if k % crate::interrupt::EVERY == 0 {
                    crate::interrupt::check()?;
                }
                let (tau_cmd, active) =
                    law.step(&mut ctl, qr[k], quantize(q[0]), u_ext.map_or(0.0, |u| u[k]));
                let tau = if opts.delay == 0 {
                    tau_cmd
                } else {
                    std::mem::replace(&mut pending[k % opts.delay], tau_cmd)
                };
                let tau = match lag {
                    None => tau,
                    Some(lag) => {
                        let (mean, end) = lag.period(*applied.get_or_insert(tau), tau);
                        applied = Some(end);
                        mean
                    }
                };
                tangent.command(k, &law, active, tau);
                out.force[k] = tau_cmd;
                if states {
                    // the direct model's acceleration at the recorded state: the IDM of the
                    // outputs reproduces the applied force to rounding
                    let a = stepper.accel(&q, &v, tau);
                    for d in 0..N {
                        let at = d * m + k; // dof d's row, sample k (the layout of Signals)
                        out.q.data[at] = q[d];
                        out.qd.data[at] = v[d];
                        out.qdd.data[at] = a[d];
                    }
                }
                tangent.record(k);
                if k + 1 == n {
                    break;
                }
                stepper.advance(&mut q, &mut v, tau, tangent)?;

                let err = (q[0] - qr[k + 1]).abs();
                if !(finite(&q, &v) && err <= bound) {
                    return Err(Error::Simulation(format!(
                    "closed-loop simulation diverged at {}: motor tracking error {:.3e} m \
                     (bound {:.3e} m) with parameters {}; check the parameter values and units and the controller \
                     gains{}{}",
                    {
                        // samples of the record from 0; a lead-in's are negative
                        let j = (k + 1) as f64 - opts.lead as f64;
                        format!(
                            "sample {j} (t = {:.6} s{})",
                            j * opts.dt,
                            if j < 0.0 { ", in the lead-in before the record" } else { "" }
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
                    S::DIVERGENCE_HINT,
                )));
                }
            }
            Ok((out, stepper))
        },
    )
}

/// Runs `f` compiled for the processor: with AVX2 and FMA enabled where it has both
/// ([`wide_simd`]), else for the baseline x86-64 (SSE2). `f` is inlined into each build
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
    if wide_simd() {
        // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
        return unsafe { wide(f) };
    }
    f()
}

/// Whether [`simd`] runs the AVX2 and FMA build: the processor has both, and the
/// environment variable `DIDIM_BASELINE_SIMD` is not set (to compare the two builds).
#[cfg(target_arch = "x86_64")]
pub(crate) fn wide_simd() -> bool {
    static WIDE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *WIDE.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::env::var_os("DIDIM_BASELINE_SIMD").is_none()
    })
}

#[cfg(test)]
mod tests {
    use super::{round_to, Quantizer};

    #[test]
    fn the_quantizer_is_round_to_bit_for_bit_near_ties_too() {
        for &step in &[5e-8, 1.0, 0.1, 3e-3, 1e-9, 7.3e-6] {
            let qz = Quantizer::new(step);
            for i in -20_000i64..20_000 {
                // exact ties, their neighbours one ulp away, and generic values
                let k = i as f64 * 37.0;
                for x in [
                    (k + 0.5) * step,
                    f64::from_bits(((k + 0.5) * step).to_bits() + 1),
                    f64::from_bits(((k + 0.5) * step).to_bits().saturating_sub(1)),
                    k * step + 0.123 * step * (i as f64).sin(),
                ] {
                    assert_eq!(qz.apply(x).to_bits(), round_to(x, step).to_bits(), "{x} {step}");
                }
            }
            for x in [0.0, -0.0, 1e300, -1e300, 4.6e15 * step, f64::MIN_POSITIVE] {
                assert_eq!(qz.apply(x).to_bits(), round_to(x, step).to_bits(), "{x} {step}");
            }
        }
        assert_eq!(Quantizer::new(0.0).apply(0.123), 0.123);
    }

    #[test]
    fn round_to_matches_f64_round_including_ties() {
        for &step in &[5e-8, 1.0, 0.1, 3e-3] {
            for i in -2000..2000 {
                let x = i as f64 * 0.37e-3 * step / 5e-8 + 1e-3 * (i as f64).sin();
                assert_eq!(round_to(x, step), (x / step).round() * step, "{x} {step}");
            }
        }
        for x in [
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.0,
            0.0,
            4.6e15,
            -9.1e15,
        ] {
            assert_eq!(round_to(x, 1.0).to_bits(), x.round().to_bits(), "{x}");
        }
    }
}
