//! A joint's drive, once for every plant: what stands between a joint's reference and the force
//! its motor applies. Each sample the encoder quantizes the joint's position, the digital
//! controller computes the command (what the drive logs, with the known external force added
//! before its saturation), and the actuator applies it: `delay` samples late, held over the
//! period, through the first-order force lag, whose mean over the period the plant receives.
//!
//! One axis's loop (`sim::driver`) and a robot's (`robot::closed_loop`) each run one
//! [`JointDrive`] per joint; [`applied_force`] replays the same [`Actuator`] on a logged command.
//! The two loops differ only in how the drive starts ([`Start`]): one axis from rest with its
//! controller at rest on absolute positions and nothing applied before the record; a robot's joint
//! with its controller on departures from the first reference, its integrators holding the
//! logged first force, which its actuator held before the record.

use crate::controller::{FilterState, TransferFunction};

/// The nearest multiple of `step` (ties away from zero, like [`f64::round`]) without the
/// libm call `round` compiles to on baseline x86-64: adding and removing 1.5·2⁵² rounds to
/// the nearest integer (ties to even), exact ties are then moved away from zero, and the
/// sign of zero is kept.
#[inline(always)]
pub(crate) fn round_to(x: f64, step: f64) -> f64 {
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
/// bit the result of [`round_to`], hence of `(x / step).round() * step`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Quantizer {
    step: f64,
    inv: f64,
}

impl Quantizer {
    /// `step` (m or rad): the resolution, 0 for none.
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
/// (see [`super::SimOptions::force_lag`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ForceLag {
    /// `e^{−T_s/T}`: what remains of the gap `f − τ` after one period.
    decay: f64,
    /// `(T/T_s)(1 − e^{−T_s/T})`: the share of the initial gap in the period's mean force.
    mean: f64,
}

impl ForceLag {
    /// The lag of time constant `lag` (s) sampled every `dt` (s); `None` for none (`lag` 0).
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

/// A delay of a whole number of samples: a ring buffer of the values on their way. The value
/// that comes out at sample `k` went in at sample `k − d` (before the first: what the buffer was
/// filled with). Used for the commands and for their sensitivities (one vector per sample).
#[derive(Clone, Debug)]
pub(crate) struct Delay<T> {
    slots: Vec<T>,
    /// The slot of the current sample: it holds the value of `d` samples earlier.
    at: usize,
}

impl<T> Delay<T> {
    /// A delay of `slots.len()` samples, holding `slots` before the first value.
    pub fn new(slots: Vec<T>) -> Self {
        Self { slots, at: 0 }
    }

    /// Puts in this sample's value `x` and takes out, in its place, the value of `d` samples
    /// earlier (nothing happens with no delay). Called once per sample.
    #[inline(always)]
    pub fn pass(&mut self, x: &mut T) {
        if let Some(slot) = self.slots.get_mut(self.at) {
            std::mem::swap(x, slot);
            self.at += 1;
            if self.at == self.slots.len() {
                self.at = 0;
            }
        }
    }

    /// Fills every slot with `x` (what the drive held before the record).
    pub fn fill(&mut self, x: &T)
    where
        T: Clone,
    {
        self.slots.iter_mut().for_each(|s| s.clone_from(x));
    }
}

/// What a drive applied before the record: what comes out of its delay in the first `delay`
/// samples, and where its force lag starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Held {
    /// A given force: 0 for one axis's loop from rest.
    Value(f64),
    /// The first command: a robot's drive, its integrators holding the logged first force.
    FirstCommand,
}

/// From the command to the force the plant receives over each period: the command of `delay`
/// samples earlier ([`Delay`]), held over the period, through the first-order [`ForceLag`]
/// started at the first value that reaches it; the plant receives the lag's mean over the period.
#[derive(Clone, Debug)]
pub(crate) struct Actuator {
    delay: Delay<f64>,
    lag: Option<ForceLag>,
    /// The lag's output at the start of the period (`None` before the first).
    lagged: Option<f64>,
    /// Fill the delay with the first command ([`Held::FirstCommand`]), not yet done.
    hold_first: bool,
}

impl Actuator {
    /// `delay` in samples, `lag` the force lag's time constant (s, 0 for none), `dt` the sample
    /// period (s), `held` what the drive applied before the record.
    pub fn new(delay: usize, lag: f64, dt: f64, held: Held) -> Self {
        let before = match held {
            Held::Value(x) => x,
            Held::FirstCommand => 0.0,
        };
        Self {
            delay: Delay::new(vec![before; delay]),
            lag: ForceLag::new(lag, dt),
            lagged: None,
            hold_first: held == Held::FirstCommand && delay > 0,
        }
    }

    /// The force applied over this sample's period (its mean) when the command is `command`.
    /// Called once per sample, from the first.
    #[inline(always)]
    pub fn apply(&mut self, command: f64) -> f64 {
        if self.hold_first {
            self.delay.fill(&command);
            self.hold_first = false;
        }
        let mut tau = command;
        self.delay.pass(&mut tau);
        match self.lag {
            None => tau,
            Some(lag) => {
                let (mean, end) = lag.period(*self.lagged.get_or_insert(tau), tau);
                self.lagged = Some(end);
                mean
            }
        }
    }
}

/// How a [`JointDrive`] starts, before its first sample.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Start {
    /// One axis's loop: at rest on the first reference `qr0`, the controller on absolute
    /// positions with its state at rest on `qr0` and the encoder's reading of it (integral action
    /// at zero), nothing applied before the record ([`Held::Value`] 0).
    Rest { qr0: f64 },
    /// A robot's joint: the controller on the departures from the first reference `qr0` from a
    /// zero state, adding `force0` (what its integrators held before the record, the logged first
    /// force) to its external force; the actuator held the first command ([`Held::FirstCommand`]).
    Holding { qr0: f64, force0: f64 },
}

/// One joint's drive: encoder, controller and actuator, and the state of each. [`JointDrive::step`]
/// runs one sample of it.
#[derive(Clone, Debug)]
pub(crate) struct JointDrive {
    law: TransferFunction,
    encoder: Quantizer,
    /// The controller's inputs are the positions' departures from this (0: absolute positions).
    origin: f64,
    /// Added to the external force of every sample.
    force0: f64,
    /// The controller's state.
    ctl: FilterState,
    actuator: Actuator,
}

impl JointDrive {
    /// The drive of controller `law`, encoder step `quantization` (0 for none), `delay` samples
    /// and a force lag `force_lag` (s, 0 for none) at the sample period `dt` (s), started as `start`.
    pub fn new(
        law: TransferFunction,
        quantization: f64,
        delay: usize,
        force_lag: f64,
        dt: f64,
        start: Start,
    ) -> Self {
        let encoder = Quantizer::new(quantization);
        let (origin, force0, ctl, held) = match start {
            Start::Rest { qr0 } => (
                0.0,
                0.0,
                law.rest_state(qr0, encoder.apply(qr0)),
                Held::Value(0.0),
            ),
            Start::Holding { qr0, force0 } => (qr0, force0, law.rest_state(0.0, 0.0), Held::FirstCommand),
        };
        Self {
            law,
            encoder,
            origin,
            force0,
            ctl,
            actuator: Actuator::new(delay, force_lag, dt, held),
        }
    }

    /// The controller's law.
    #[inline(always)]
    pub fn law(&self) -> &TransferFunction {
        &self.law
    }

    /// One sample, from the first: the reference `qr`, the joint's true position `q` (which the
    /// encoder reads) and the known external force `u_ext` (added before the saturation). Returns
    /// the command (what the drive logs), the force applied over the coming period (its mean), and
    /// whether the controller is linear there (not saturated).
    ///
    /// With [`Start::Rest`] the departures are from 0 and nothing is added to `u_ext`: `x − 0`
    /// is `x` and `0 + u_ext` is `u_ext` (or +0 for −0, which the law treats alike), so one axis's
    /// loop computes exactly what it did on absolute positions.
    #[inline(always)]
    pub fn step(&mut self, qr: f64, q: f64, u_ext: f64) -> (f64, f64, bool) {
        let qm = self.encoder.apply(q);
        let (command, active) = self.law.step(
            &mut self.ctl,
            qr - self.origin,
            qm - self.origin,
            self.force0 + u_ext,
        );
        (command, self.actuator.apply(command), active)
    }
}

/// The force the plant receives, as the mean over each sample period, when the drive logs the
/// commands `force`: the command of `delay` samples earlier (`held` before the first: 0 for one
/// axis's loop from rest, the first command for a robot's, whose drive held it), held over the
/// period, through the first-order [`super::SimOptions::force_lag`] `lag` (s) started at its first
/// value, as the simulators apply it (the same [`Actuator`]); `dt` the sample period (s). With no
/// delay and no lag, the commands themselves. DIDIM's regression target: the simulated states
/// answer this force, not the logged command.
pub fn applied_force(force: &[f64], delay: usize, lag: f64, dt: f64, held: f64) -> Vec<f64> {
    // a delay as long as the record holds `held` throughout, as any longer one
    let mut actuator = Actuator::new(delay.min(force.len()), lag, dt, Held::Value(held));
    force.iter().map(|&c| actuator.apply(c)).collect()
}

#[cfg(test)]
mod tests {
    use super::{applied_force, round_to, Actuator, Held, Quantizer};

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
                    // what a robot's loop computed before it shared the encoder
                    assert_eq!(
                        qz.apply(x).to_bits(),
                        ((x / step).round() * step).to_bits(),
                        "{x} {step}"
                    );
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

    #[test]
    fn the_actuator_delays_by_whole_samples_holding_its_value_before_the_record() {
        let cmd: Vec<f64> = (1..=7).map(f64::from).collect();
        assert_eq!(applied_force(&cmd, 0, 0.0, 1e-3, 9.0), cmd);
        assert_eq!(
            applied_force(&cmd, 3, 0.0, 1e-3, 0.0),
            [0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0]
        );
        assert_eq!(
            applied_force(&cmd, 2, 0.0, 1e-3, -1.0),
            [-1.0, -1.0, 1.0, 2.0, 3.0, 4.0, 5.0]
        );
        // a delay as long as the record or longer: the held value throughout
        assert_eq!(applied_force(&cmd, 7, 0.0, 1e-3, 0.5), [0.5; 7]);
        assert_eq!(applied_force(&cmd, 1_000_000_000, 0.0, 1e-3, 0.5), [0.5; 7]);
        // a robot's drive holds its first command
        let mut a = Actuator::new(2, 0.0, 1e-3, Held::FirstCommand);
        let got: Vec<f64> = cmd.iter().map(|&c| a.apply(c)).collect();
        assert_eq!(got, [1.0, 1.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(got, applied_force(&cmd, 2, 0.0, 1e-3, cmd[0]));
    }

    #[test]
    fn the_force_lag_applies_the_mean_of_its_exponential_response_over_each_period() {
        // a step of the command from 0 to 1 at sample 1, lag T = dt: the mean over the period
        // from f0 is 1 + (f0 − 1)(1 − e^{−1}), and f falls towards 1 by e^{−1} per period
        let (dt, lag) = (1e-3, 1e-3);
        let got = applied_force(&[0.0, 1.0, 1.0, 1.0], 0, lag, dt, 0.0);
        let e = (-1.0f64).exp();
        let mut f0 = 0.0;
        let mut want = vec![0.0];
        for _ in 1..4 {
            want.push(1.0 + (f0 - 1.0) * (1.0 - e));
            f0 = 1.0 + (f0 - 1.0) * e;
        }
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-15, "{got:?} vs {want:?}");
        }
    }
}
