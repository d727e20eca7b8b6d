//! Inputs that crashed or misbehaved before, found by the property tests of `proptest_no_panic.rs`; each is now an
//! error or a correct value.

use didim_core::controller::{Controller, TransferFunction};
use didim_core::filter::{self, Sos, Tf};
use didim_core::model::{self, coulomb_sign, coulomb_sign_derivative};
use didim_core::sim::{self, SimOptions};
use didim_core::Error;

fn ramp(n: usize) -> Vec<f64> {
    (0..n).map(|k| 1e-4 * k as f64).collect()
}

/// A delay of 2^40 samples made the simulator allocate 8 TB for its command buffer and abort the process (an abort
/// cannot be caught, so it would have killed the Python interpreter); `usize::MAX` overflowed the capacity (a panic).
#[test]
fn a_delay_not_shorter_than_the_record_is_an_error_before_any_allocation() {
    let m = model::flexible(1e-4).unwrap();
    let chi = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5];
    for delay in [10, 1 << 40, usize::MAX] {
        let o = SimOptions {
            delay,
            ..SimOptions::new(1e-3)
        };
        let e = sim::simulate(&m, &chi, &Controller::EMPS, &ramp(10), None, &o).unwrap_err();
        assert!(
            matches!(&e, Error::InvalidInput(m) if m.contains("delay") && m.contains("not shorter than the record"))
        );
        let e = sim::simulate_sensitivity(&m, &chi, &Controller::EMPS, &ramp(10), None, &o).unwrap_err();
        assert!(matches!(e, Error::InvalidInput(_)));
    }
    let o = SimOptions {
        delay: 9,
        ..SimOptions::new(1e-3)
    };
    assert!(sim::simulate(&m, &chi, &Controller::EMPS, &ramp(10), None, &o).is_ok());
}

/// `f64::clamp` panics when the limit is NaN or negative; the controller's command used it and is public.
#[test]
fn the_controller_command_does_not_panic_on_a_bad_saturation() {
    for vsat in [f64::NAN, -10.0, 0.0] {
        let c = Controller::EmpsCascade {
            kp: 160.18,
            kv: 243.45,
            gtau: 35.15,
            vsat,
        };
        assert!(c.validate().is_err());
        assert!(c.law(1e-3).is_err());
        assert!(TransferFunction::new(&[1.0], &[1.0], &[1.0], &[1.0], vsat, 1.0).is_err());
    }
    let law = Controller::Pd {
        kp: 1e4,
        kd: 100.0,
        tau_max: 5.0,
    }
    .law(1e-3)
    .unwrap();
    let mut z = law.rest_state(0.0, 0.0);
    assert_eq!(law.step(&mut z, 1.0, 0.0, 0.0), (5.0, false));
    let mut z = law.rest_state(0.0, 0.0);
    assert_eq!(law.step(&mut z, -1.0, 0.0, 0.0), (-5.0, false));
}

/// `v / sqrt(v² + eps²)` returned +inf when v² + eps² underflowed to 0 (v = eps = 2.2e-308) and 0 when it
/// overflowed (v = 1e200): the sign must stay within [-1, 1] with the sign of v.
#[test]
fn the_coulomb_sign_is_right_where_its_square_under_or_overflows() {
    let tiny = f64::MIN_POSITIVE;
    assert!((coulomb_sign(tiny, tiny) - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15);
    assert_eq!(coulomb_sign(1e200, 1e-4), 1.0);
    assert_eq!(coulomb_sign(-1e200, 1e-4), -1.0);
    assert_eq!(coulomb_sign(f64::INFINITY, 1e-4), 1.0);
    assert_eq!(coulomb_sign(-1e-200, 1e-200), -std::f64::consts::FRAC_1_SQRT_2);
    assert!((coulomb_sign_derivative(1e-200, 1e-200) * 1e-200 - 0.5f64.powf(1.5)).abs() < 1e-12);
    assert_eq!(coulomb_sign_derivative(1e200, 1e-4), 0.0);
    // unchanged where it was right
    let (v, eps) = (3e-4f64, 1e-4f64);
    assert_eq!(coulomb_sign(v, eps), v / (v * v + eps * eps).sqrt());
}

/// A tiny `a[0]` (4.2e-199) scales the normalised numerator to 1e198: the two passes overflowed and `filtfilt`
/// returned all NaN without an error.
#[test]
fn filtering_that_overflows_is_an_error_not_nan() {
    let b = filter::butter(1, 0.5).unwrap().b;
    let tf = Tf {
        b,
        a: vec![4.204551453322078e-199],
    };
    let x = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let e = filter::filtfilt(&tf, &x, None).unwrap_err();
    assert!(e.to_string().contains("overflowed"), "{e}");
    let sos = Sos(vec![[1e300, 0.0, 0.0, 1.0, 0.5, 0.0]]);
    let e = filter::sosfiltfilt(&sos, &x, Some(2)).unwrap_err();
    assert!(e.to_string().contains("overflowed"), "{e}");
}

/// Fc2 = 1.8e308 N leaves the axis at rest (finite states) but its sensitivity, 1.8e308/eps, overflowed: the
/// Jacobian came back full of NaN without an error.
#[test]
fn sensitivities_that_overflow_are_a_simulation_error() {
    let m = model::flexible(1e-4).unwrap();
    let chi = [0.1, 0.1, 0.1, 0.1, 0.1, f64::MAX, 1000.0];
    let c = Controller::EmpsCascade {
        kp: 1.0,
        kv: 1.0,
        gtau: 1.0,
        vsat: 1.0,
    };
    // the exponential integrator's discrete sensitivities stay finite here; whatever they are, never NaN
    let ex = SimOptions::new(1e-4);
    if let Ok(s) = sim::simulate_sensitivity(&m, &chi, &c, &[0.0, 0.0], None, &ex) {
        assert!(s.dforce.iter().chain(&s.dq).all(|v| v.is_finite()));
    }
    let o = SimOptions {
        substeps: 1,
        integrator: sim::Integrator::Rk4,
        ..SimOptions::new(1e-4)
    };
    assert!(sim::simulate(&m, &chi, &c, &[0.0, 0.0], None, &o).is_ok());
    let e = sim::simulate_sensitivity(&m, &chi, &c, &[0.0, 0.0], None, &o).unwrap_err();
    assert!(
        matches!(&e, Error::Simulation(s) if s.contains("sensitivities") && s.contains("Fc2=")),
        "{e}"
    );
}

/// gtau = 1.8e308 makes the saturated command gtau·vsat infinite; with a delay the infinite commands of the last
/// samples never reached the states, so the simulation returned an infinite force without an error.
#[test]
fn an_infinite_command_is_a_simulation_error() {
    let m = model::rigid(true, 1e-4).unwrap();
    let c = Controller::EmpsCascade {
        kp: 1.0,
        kv: 1.0,
        gtau: f64::MAX,
        vsat: 12.395229657568873,
    };
    let o = SimOptions {
        substeps: 1,
        delay: 2,
        ..SimOptions::new(1e-4)
    };
    let qr = [0.7362795948266236, 0.0, -0.512781346536688, 0.0];
    let e = sim::simulate(&m, &[0.1; 4], &c, &qr, None, &o).unwrap_err();
    assert!(
        matches!(&e, Error::Simulation(s) if s.contains("commanded force is not finite at sample")),
        "{e}"
    );
    assert!(sim::simulate_sensitivity(&m, &[0.1; 4], &c, &qr, None, &o).is_err());
}

/// M = 2.1e-308 kg: the acceleration of the last sample (where the loop stops before checking the state) was
/// infinite in an Ok result.
#[test]
fn an_infinite_acceleration_at_the_last_sample_is_a_simulation_error() {
    let m = model::rigid(false, 1e-4).unwrap();
    let c = Controller::EmpsCascade {
        kp: 1.0,
        kv: 278.80050037214704,
        gtau: 1.0,
        vsat: 10.496181331336428,
    };
    let qr = [0.0, -0.5193288921026687, 0.0, 0.0, 0.0, 0.0, 0.0];
    let chi = [2.1458939827553693e-308, 0.1, 0.1];
    // the exponential integrator refuses the mass earlier (its matrix exponential is not finite)
    let ex = SimOptions {
        delay: 5,
        ..SimOptions::new(1e-4)
    };
    assert!(sim::simulate(&m, &chi, &c, &qr, None, &ex).is_err());
    let o = SimOptions {
        substeps: 1,
        delay: 5,
        integrator: sim::Integrator::Rk4,
        ..SimOptions::new(1e-4)
    };
    let e = sim::simulate(&m, &chi, &c, &qr, None, &o).unwrap_err();
    assert!(
        matches!(&e, Error::Simulation(s) if s.contains("acceleration is not finite at sample 6")),
        "{e}"
    );
}

/// A linear part whose entries over a sample period exceed f64 (a sample period of 1e300 s, or a stiffness over a
/// mass beyond f64) made nalgebra's matrix exponential take log2 of an infinite norm and square its Padé approximant
/// 2^64 times: the simulation never returned (found by `simulate_flexible_never_panics`). Now an error, promptly.
#[test]
fn a_linear_part_beyond_f64_is_an_error_not_an_endless_exponential() {
    let m = model::flexible(1e-4).unwrap();
    for (chi, dt) in [
        ([68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5], 1e300),
        ([68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5], 1e60),
        ([68.0, 104.0, 10.0, 1e-300, 96.5, 9.5, 1e300], 1e-3),
    ] {
        let o = SimOptions::new(dt);
        let e = sim::simulate(&m, &chi, &Controller::EMPS, &ramp(10), None, &o).unwrap_err();
        assert!(
            matches!(&e, Error::InvalidInput(msg) if msg.contains("not finite")),
            "{e:?}"
        );
        let e = sim::simulate_sensitivity(&m, &chi, &Controller::EMPS, &ramp(10), None, &o).unwrap_err();
        assert!(matches!(e, Error::InvalidInput(_)), "{e:?}");
    }
}
