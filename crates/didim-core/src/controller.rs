//! Digital position controllers, run once per sample period on the measured
//! motor position, output held over the period (zero-order hold).
//!
//! Every controller is, for the simulator, one linear two-degree-of-freedom law
//! `u = C_r(z)·qr − C_y(z)·qm` ([`TransferFunction`]), followed by the known external
//! input, a saturation of `u` and a gain from `u` to force. The EMPS cascade and the PD
//! are named constructors of that law; both use the velocity estimate of the EMPS drive,
//! a two-sample backward difference `v̂[k] = (q̂[k] − q̂[k−2]) / (2T)`.

use crate::error::{invalid, Result};

/// Most coefficients of one polynomial of a [`TransferFunction`] (order 15), after
/// `C_r` and `C_y` are brought to a common denominator.
pub const MAX_TAPS: usize = 16;

/// The state of a [`TransferFunction`] (transposed direct form II) between samples.
pub type FilterState = [f64; MAX_TAPS];

/// A position controller. Forces are in N on the load side.
///
/// `Copy` and free of heap data, so a closed-loop problem can be copied to every worker
/// thread; the transfer-function variant is larger than the named ones by design.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Controller {
    /// The cascade of the EMPS as logged:
    /// `vir[k] = kv·(kp·(qr[k] − q̂[k]) − v̂[k])` in V, plus the known external
    /// input (converted to V), saturated at `±vsat`, force `τ = gtau·vir`.
    /// EMPS: `kp = 160.18 1/s`, `kv = 243.45 V/(m/s)`, `gtau = 35.15065188248547 N/V`, `vsat = 10 V`.
    EmpsCascade {
        /// Position-loop gain (1/s).
        kp: f64,
        /// Velocity-loop gain (V/(m/s)).
        kv: f64,
        /// Drive gain (N/V).
        gtau: f64,
        /// Saturation of the command (V); `f64::INFINITY` for none.
        vsat: f64,
    },
    /// A PD in force units: `τ[k] = kp·(qr[k] − q̂[k]) − kd·v̂[k]` plus the
    /// external input, saturated at `±tau_max`.
    Pd {
        /// Stiffness gain (N/m).
        kp: f64,
        /// Damping gain (N/(m/s)).
        kd: f64,
        /// Saturation (N); `f64::INFINITY` for none.
        tau_max: f64,
    },
    /// Any linear two-degree-of-freedom digital controller.
    TransferFunction(TransferFunction),
}

impl Controller {
    /// The EMPS gains.
    pub const EMPS: Controller = Controller::EmpsCascade {
        kp: 160.18,
        kv: 243.45,
        gtau: 35.15065188248547,
        vsat: 10.0,
    };

    /// Checks that gains are finite and positive and saturations positive.
    pub fn validate(&self) -> Result<()> {
        let (gains, sat, sat_name): (Vec<(&str, f64)>, f64, &str) = match *self {
            Controller::EmpsCascade { kp, kv, gtau, vsat } => {
                (vec![("kp", kp), ("kv", kv), ("gtau", gtau)], vsat, "vsat")
            }
            Controller::Pd { kp, kd, tau_max } => (vec![("kp", kp), ("kd", kd)], tau_max, "tau_max"),
            Controller::TransferFunction(ref tf) => (vec![("gain", tf.gain)], tf.saturation, "saturation"),
        };
        for (name, g) in gains {
            if !(g.is_finite() && g > 0.0) {
                return Err(invalid!("controller gain {name} must be finite and > 0, got {g}"));
            }
        }
        if sat.is_nan() || sat <= 0.0 {
            return Err(invalid!(
                "controller saturation {sat_name} must be > 0 (or infinite for none), got {sat}"
            ));
        }
        Ok(())
    }

    /// The controller as the linear law the simulator runs, at sample period `dt` (s).
    pub fn law(&self, dt: f64) -> Result<TransferFunction> {
        self.validate()?;
        let h = 0.5 / dt;
        match *self {
            Controller::EmpsCascade { kp, kv, gtau, vsat } => TransferFunction::new(
                &[kv * kp],
                &[1.0],
                &[kv * (kp + h), 0.0, -kv * h],
                &[1.0],
                vsat,
                gtau,
            ),
            Controller::Pd { kp, kd, tau_max } => {
                TransferFunction::new(&[kp], &[1.0], &[kp + kd * h, 0.0, -kd * h], &[1.0], tau_max, 1.0)
            }
            Controller::TransferFunction(tf) => Ok(tf),
        }
    }
}

/// The linear two-degree-of-freedom controller `u = C_r(z)·qr − C_y(z)·qm`, with
/// `v = u + u_ext/gain` limited to `±saturation` and the force `τ = gain·v` (N).
///
/// Held as one filter with two inputs over the common denominator of `C_r` and `C_y`
/// (transposed direct form II), so that a shared integrator (a PI velocity loop acting on
/// both paths) cancels between them instead of growing in each.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransferFunction {
    taps: usize,
    num_r: [f64; MAX_TAPS],
    num_y: [f64; MAX_TAPS],
    den: [f64; MAX_TAPS],
    saturation: f64,
    gain: f64,
}

fn poly_mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// `a` without its trailing zeros (at least one coefficient).
fn trim(a: &[f64]) -> &[f64] {
    let end = a.iter().rposition(|&x| x != 0.0).map_or(1, |i| i + 1);
    &a[..end.min(a.len())]
}

impl TransferFunction {
    /// `C_r = b_r/a_r`, `C_y = b_y/a_y` in ascending powers of `1/z` (the convention of
    /// `scipy.signal.lfilter`), the saturation of `u` (`f64::INFINITY` for none) and the
    /// gain from `u` to force (N per unit of `u`).
    pub fn new(
        b_r: &[f64],
        a_r: &[f64],
        b_y: &[f64],
        a_y: &[f64],
        saturation: f64,
        gain: f64,
    ) -> Result<Self> {
        for (name, c) in [("b_r", b_r), ("a_r", a_r), ("b_y", b_y), ("a_y", a_y)] {
            if c.is_empty() {
                return Err(invalid!("controller coefficients {name} are empty"));
            }
            if let Some(i) = c.iter().position(|x| !x.is_finite()) {
                return Err(invalid!(
                    "controller coefficient {name}[{i}] is not finite ({})",
                    c[i]
                ));
            }
        }
        for (name, a) in [("a_r", a_r), ("a_y", a_y)] {
            if a[0] == 0.0 {
                return Err(invalid!(
                    "controller denominator {name} starts with 0: its first coefficient (of z^0) must be non-zero"
                ));
            }
        }
        if !(gain.is_finite() && gain > 0.0) {
            return Err(invalid!("controller gain must be finite and > 0, got {gain}"));
        }
        if saturation.is_nan() || saturation <= 0.0 {
            return Err(invalid!(
                "controller saturation must be > 0 (or infinite for none), got {saturation}"
            ));
        }
        let (b_r, a_r, b_y, a_y) = (trim(b_r), trim(a_r), trim(b_y), trim(a_y));
        let (num_r, num_y, den) = if a_r == a_y {
            (b_r.to_vec(), b_y.to_vec(), a_r.to_vec())
        } else {
            (poly_mul(b_r, a_y), poly_mul(b_y, a_r), poly_mul(a_r, a_y))
        };
        let taps = num_r.len().max(num_y.len()).max(den.len());
        if taps > MAX_TAPS {
            return Err(invalid!(
                "controller of order {} over the common denominator of C_r and C_y: at most {} is supported",
                taps - 1,
                MAX_TAPS - 1
            ));
        }
        let a0 = den[0];
        let pad = |c: &[f64]| {
            let mut out = [0.0; MAX_TAPS];
            for (o, x) in out.iter_mut().zip(c) {
                *o = x / a0;
            }
            out
        };
        Ok(Self {
            taps,
            num_r: pad(&num_r),
            num_y: pad(&num_y),
            den: pad(&den),
            saturation,
            gain,
        })
    }

    /// Gain from `u` to force (N per unit of `u`).
    pub fn gain(&self) -> f64 {
        self.gain
    }

    /// The state of the loop at rest: constant inputs `qr0`, `qm0` since forever and, when
    /// the denominator has a root at 1 (integral action), `u = 0`.
    pub fn rest_state(&self, qr0: f64, qm0: f64) -> FilterState {
        let n = self.taps;
        let a_sum: f64 = self.den[..n].iter().sum();
        let drive: f64 = (0..n).map(|m| self.num_r[m] * qr0 - self.num_y[m] * qm0).sum();
        let scale = self.den[..n].iter().map(|x| x.abs()).sum::<f64>();
        let u = if a_sum.abs() > 1e-12 * scale {
            drive / a_sum
        } else {
            0.0
        };
        let mut z = [0.0; MAX_TAPS];
        for i in 0..n.saturating_sub(1) {
            z[i] = (i + 1..n)
                .map(|m| self.num_r[m] * qr0 - self.num_y[m] * qm0 - self.den[m] * u)
                .sum();
        }
        z
    }

    /// The force command (N) of one sample from the reference `qr`, the measurement `qm`
    /// and the known external force `u_ext` (N), and whether the loop is linear there
    /// (not saturated). Advances the state `z`.
    #[inline(always)]
    pub fn step(&self, z: &mut FilterState, qr: f64, qm: f64, u_ext: f64) -> (f64, bool) {
        let n = self.taps;
        let u = self.num_r[0] * qr - self.num_y[0] * qm + z[0];
        for i in 0..n - 1 {
            z[i] = self.num_r[i + 1] * qr - self.num_y[i + 1] * qm - self.den[i + 1] * u + z[i + 1];
        }
        let v = if u_ext != 0.0 { u + u_ext / self.gain } else { u };
        let active = v.abs() < self.saturation;
        (self.gain * saturate(v, self.saturation), active)
    }

    /// The same law on the sensitivity `s` of the measurement to one parameter: returns
    /// the sensitivity of `u` and advances that parameter's state `z`.
    #[inline]
    pub fn sensitivity_step(&self, z: &mut FilterState, s: f64) -> f64 {
        let n = self.taps;
        let u = -self.num_y[0] * s + z[0];
        for i in 0..n - 1 {
            z[i] = -self.num_y[i + 1] * s - self.den[i + 1] * u + z[i + 1];
        }
        u
    }
}

/// `x` limited to `[-limit, limit]`; unlike `f64::clamp` it cannot panic (a NaN or
/// negative limit, which [`Controller::validate`] refuses, leaves `x` or gives `±limit`).
#[inline(always)]
fn saturate(x: f64, limit: f64) -> f64 {
    if x > limit {
        limit
    } else if x < -limit {
        -limit
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `lfilter(b, a, x)` with zero initial state, written out by its difference equation.
    fn lfilter(b: &[f64], a: &[f64], x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        for k in 0..x.len() {
            let mut s = 0.0;
            for (i, bi) in b.iter().enumerate() {
                if k >= i {
                    s += bi * x[k - i];
                }
            }
            for (j, aj) in a.iter().enumerate().skip(1) {
                if k >= j {
                    s -= aj * y[k - j];
                }
            }
            y[k] = s / a[0];
        }
        y
    }

    #[test]
    fn emps_law_matches_the_logged_formula_and_saturates() {
        let dt = 1e-3;
        let law = Controller::EMPS.law(dt).unwrap();
        let (qr, qm1, qm2) = (0.01, 0.0099, 0.00989);
        // history: qm2 at k-2, an arbitrary qm at k-1, then qm1 at k (the FIR sees three samples)
        let mut z = law.rest_state(qr, qm2);
        law.step(&mut z, qr, qm2, 0.0);
        law.step(&mut z, qr, 0.5 * (qm1 + qm2), 0.0);
        let mut z2 = z;
        let (tau, active) = law.step(&mut z, qr, qm1, 0.0);
        let vir = 243.45 * (160.18 * (qr - qm1) - (qm1 - qm2) / (2.0 * dt));
        assert!(active);
        assert!((tau - 35.15065188248547 * vir).abs() < 1e-9 * tau.abs().max(1.0));
        // the external input in N enters as volts before the saturation
        let (with, _) = law.step(&mut z2, qr, qm1, 35.15065188248547 * 5.0);
        assert!((with - 35.15065188248547 * (vir + 5.0)).abs() < 1e-9 * with.abs());
        let mut z = law.rest_state(0.0, 0.0);
        let (sat, active) = law.step(&mut z, 1.0, 0.0, 0.0);
        assert!(!active);
        assert!((sat - 351.5065188248547).abs() < 1e-9);
    }

    #[test]
    fn validation_names_the_problem() {
        let bad = |c: Controller| c.validate().is_err();
        assert!(bad(Controller::Pd {
            kp: 0.0,
            kd: 1.0,
            tau_max: 1.0
        }));
        assert!(bad(Controller::Pd {
            kp: 1.0,
            kd: 1.0,
            tau_max: f64::NAN
        }));
        assert!(!bad(Controller::Pd {
            kp: 1.0,
            kd: 1.0,
            tau_max: f64::INFINITY
        }));
        let e = TransferFunction::new(&[1.0], &[0.0, 1.0], &[1.0], &[1.0], 1.0, 1.0).unwrap_err();
        assert!(e.to_string().contains("a_r starts with 0"), "{e}");
        let e = TransferFunction::new(&[1.0], &[1.0], &[f64::NAN], &[1.0], 1.0, 1.0).unwrap_err();
        assert!(e.to_string().contains("b_y[0]"), "{e}");
        let long = [1.0; MAX_TAPS + 1];
        assert!(TransferFunction::new(&long, &[1.0], &[1.0], &[1.0], 1.0, 1.0).is_err());
    }

    /// Different denominators are brought to a common one: the law equals the two filters
    /// run apart, `lfilter(b_r, a_r, qr) − lfilter(b_y, a_y, qm)`, from rest at zero.
    #[test]
    fn two_denominators_equal_the_filters_run_apart() {
        let (b_r, a_r) = ([0.3, 0.2, -0.1], [2.0, -1.2, 0.35]);
        let (b_y, a_y) = ([1.5, -1.0], [1.0, -0.5]);
        let law = TransferFunction::new(&b_r, &a_r, &b_y, &a_y, f64::INFINITY, 2.0).unwrap();
        let qr: Vec<f64> = (0..200).map(|k| (0.05 * k as f64).sin()).collect();
        let qm: Vec<f64> = (0..200).map(|k| (0.07 * k as f64).cos() - 1.0).collect();
        let (ur, uy) = (lfilter(&b_r, &a_r, &qr), lfilter(&b_y, &a_y, &qm));
        let mut z = law.rest_state(0.0, 0.0);
        for k in 0..200 {
            let (tau, active) = law.step(&mut z, qr[k], qm[k], 0.0);
            assert!(active);
            let want = 2.0 * (ur[k] - uy[k]);
            assert!(
                (tau - want).abs() < 1e-12 * (1.0 + want.abs()),
                "sample {k}: {tau} vs {want}"
            );
        }
        // the sensitivity path is C_y alone, with the sign of the feedback
        let mut zs = [0.0; MAX_TAPS];
        for k in 0..200 {
            let s = law.sensitivity_step(&mut zs, qm[k]);
            assert!((s + uy[k]).abs() < 1e-12 * (1.0 + uy[k].abs()), "sample {k}");
        }
    }

    /// A PI velocity loop integrates the position error: at rest on the reference the
    /// state must hold zero force, not grow with the position.
    #[test]
    fn integral_action_rests_at_zero_force() {
        let (b, a) = ([5.0, -4.0], [1.0, -1.0]);
        let law = TransferFunction::new(&b, &a, &b, &a, f64::INFINITY, 1.0).unwrap();
        let mut z = law.rest_state(0.3, 0.3);
        for _ in 0..1000 {
            assert!(law.step(&mut z, 0.3, 0.3, 0.0).0.abs() < 1e-12);
        }
        // without integral action the rest state is the static response
        let law =
            TransferFunction::new(&[2.0], &[1.0], &[3.0, -1.0], &[1.0, -0.5], f64::INFINITY, 1.0).unwrap();
        let mut z = law.rest_state(1.0, 0.5);
        let tau0 = 2.0 * 1.0 - 4.0 * 0.5;
        for _ in 0..10 {
            assert!((law.step(&mut z, 1.0, 0.5, 0.0).0 - tau0).abs() < 1e-12);
        }
    }
}
