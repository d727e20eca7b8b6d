//! Digital position controllers, run once per sample period on the measured
//! motor position, output held over the period (zero-order hold).
//!
//! Both use the velocity estimate of the EMPS drive, a two-sample backward
//! difference `v̂[k] = (q̂[k] − q̂[k−2]) / (2T)`.

use crate::error::{invalid, Result};

/// A position controller. Forces are in N on the load side.
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

    /// The force command of sample `k` (N), from the reference `qr`, the measured
    /// position `qm` and the measurement two samples earlier `qm2`, the sample
    /// period `dt` (s) and the known external force `u_ext` (N) added to the command.
    #[inline]
    pub fn command(&self, qr: f64, qm: f64, qm2: f64, dt: f64, u_ext: f64) -> f64 {
        let v_hat = (qm - qm2) / (2.0 * dt);
        match *self {
            Controller::EmpsCascade { kp, kv, gtau, vsat } => {
                let vir = kv * (kp * (qr - qm) - v_hat) + u_ext / gtau;
                gtau * saturate(vir, vsat)
            }
            Controller::Pd { kp, kd, tau_max } => saturate(kp * (qr - qm) - kd * v_hat + u_ext, tau_max),
        }
    }

    /// The command (N) and its derivatives with respect to `qm` and `qm2`
    /// (zero while the output saturates), for the sensitivity equations.
    #[inline]
    pub fn command_with_partials(&self, qr: f64, qm: f64, qm2: f64, dt: f64, u_ext: f64) -> (f64, f64, f64) {
        let tau = self.command(qr, qm, qm2, dt, u_ext);
        let (d_qm, d_qm2, limit) = match *self {
            Controller::EmpsCascade { kp, kv, gtau, vsat } => {
                (-gtau * kv * (kp + 0.5 / dt), gtau * kv * 0.5 / dt, gtau * vsat)
            }
            Controller::Pd { kp, kd, tau_max } => (-(kp + 0.5 * kd / dt), 0.5 * kd / dt, tau_max),
        };
        if tau.abs() >= limit {
            (tau, 0.0, 0.0)
        } else {
            (tau, d_qm, d_qm2)
        }
    }

    /// Force per metre of position error at low frequency (N/m), used to scale
    /// checks (`kv·kp·gtau` or `kp`).
    pub fn stiffness(&self) -> f64 {
        match *self {
            Controller::EmpsCascade { kp, kv, gtau, .. } => kp * kv * gtau,
            Controller::Pd { kp, .. } => kp,
        }
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

    #[test]
    fn emps_command_matches_the_logged_law_and_saturates() {
        let c = Controller::EMPS;
        let (qr, qm, qm2, dt) = (0.01, 0.0099, 0.00989, 1e-3);
        let vir = 243.45 * (160.18 * (qr - qm) - (qm - qm2) / (2.0 * dt));
        assert!((c.command(qr, qm, qm2, dt, 0.0) - 35.15065188248547 * vir).abs() < 1e-9);
        // external input in N enters as volts before the saturation
        let with = c.command(qr, qm, qm2, dt, 35.15065188248547 * 5.0);
        assert!((with - 35.15065188248547 * (vir + 5.0)).abs() < 1e-9);
        assert!((c.command(1.0, 0.0, 0.0, dt, 0.0) - 351.5065188248547).abs() < 1e-9);
        assert!(Controller::Pd {
            kp: 0.0,
            kd: 1.0,
            tau_max: 1.0
        }
        .validate()
        .is_err());
        assert!(Controller::Pd {
            kp: 1.0,
            kd: 1.0,
            tau_max: f64::INFINITY
        }
        .validate()
        .is_ok());
        assert!(Controller::Pd {
            kp: 1.0,
            kd: 1.0,
            tau_max: f64::NAN
        }
        .validate()
        .is_err());
    }
}
