//! Property tests: the core's public functions never panic, whatever they are given (empty, NaN, infinite, huge,
//! subnormal values; mismatched lengths; absurd options). Each returns a result or an `Error`, and a result is
//! usable: the documented lengths, and finite values where the function promises them.
//!
//! Cases per property: `PROPTEST_CASES` when set (a local campaign runs tens of thousands), otherwise a default
//! sized for CI (the tests build in debug mode there).

use didim_core::controller::{Controller, TransferFunction};
use didim_core::filter::{self, Decimation, FilterForm, Sos, Tf};
use didim_core::lstsq::{lstsq, LstsqOptions, SigmaConvention};
use didim_core::model::{self, Basis, Model};
use didim_core::sim::{self, Integrator, SimOptions, DEFAULT_TOL};
use didim_core::Error;
use proptest::prelude::*;

fn config(default_cases: u32) -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default_cases);
    ProptestConfig {
        cases,
        max_shrink_iters: 2000,
        // failures found here are kept as named regression tests in `regressions.rs`
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// Any float, biased towards the values that break numerical code.
fn hostile() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => -10.0..10.0f64,
        2 => prop::sample::select(vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            5e-324,
            1e-300,
            1e300,
            -1e300,
            1e-12,
            1e12,
        ]),
        1 => any::<f64>(),
    ]
}

/// A float that is mostly sensible (positive, moderate) but sometimes hostile: lets the search reach deep code.
fn mostly(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    prop_oneof![4 => lo..hi, 1 => hostile()]
}

fn signal(max_len: usize) -> impl Strategy<Value = Vec<f64>> {
    prop_oneof![
        2 => prop::collection::vec(-1.0..1.0f64, 0..max_len),
        1 => prop::collection::vec(hostile(), 0..max_len),
    ]
}

fn whole() -> impl Strategy<Value = usize> {
    prop_oneof![
        4 => 0usize..12,
        1 => prop::sample::select(vec![usize::MAX, usize::MAX / 2, 1 << 32, 100_000, 100_001]),
    ]
}

fn controller() -> impl Strategy<Value = Controller> {
    prop_oneof![
        (
            mostly(1.0, 500.0),
            mostly(1.0, 500.0),
            mostly(1.0, 50.0),
            mostly(1.0, 20.0)
        )
            .prop_map(|(kp, kv, gtau, vsat)| Controller::EmpsCascade { kp, kv, gtau, vsat }),
        (mostly(1e2, 1e6), mostly(1.0, 1e4), mostly(1.0, 1e4)).prop_map(|(kp, kd, tau_max)| Controller::Pd {
            kp,
            kd,
            tau_max
        }),
    ]
}

fn sim_options() -> impl Strategy<Value = SimOptions> {
    (
        mostly(1e-4, 1e-2),
        prop_oneof![4 => 0usize..16, 1 => prop::sample::select(vec![100_001usize, usize::MAX])],
        prop_oneof![3 => Just(0.0), 1 => mostly(0.0, 1e-3)],
        prop_oneof![4 => 0usize..6, 1 => prop::sample::select(vec![200usize, usize::MAX, 1 << 40])],
        prop_oneof![Just(Integrator::Exponential), Just(Integrator::Rk4)],
        prop_oneof![4 => Just(DEFAULT_TOL), 1 => hostile()],
        prop_oneof![3 => Just(0.0), 1 => mostly(0.0, 2e-3)],
        prop_oneof![4 => Just(0usize), 1 => 0usize..40, 1 => prop::sample::select(vec![usize::MAX, 1 << 40])],
    )
        .prop_map(
            |(dt, substeps, quantization, delay, integrator, tol, force_lag, lead)| SimOptions {
                dt,
                substeps,
                quantization,
                delay,
                force_lag,
                integrator,
                tol,
                lead,
            },
        )
}

fn params(n: usize) -> impl Strategy<Value = Vec<f64>> {
    prop_oneof![
        4 => prop::collection::vec(mostly(0.1, 100.0), n..=n),
        1 => prop::collection::vec(hostile(), 0..n + 3),
    ]
}

fn stiffness_params() -> impl Strategy<Value = Vec<f64>> {
    prop_oneof![
        4 => (prop::collection::vec(mostly(0.1, 100.0), 6..=6), mostly(1e3, 1e6)).prop_map(|(mut v, k)| {
            v.push(k);
            v
        }),
        1 => prop::collection::vec(hostile(), 0..10),
    ]
}

/// One simulation's inputs: parameters, controller, reference, external input, options.
type SimCase = (Vec<f64>, Controller, Vec<f64>, Option<Vec<f64>>, SimOptions);

/// Valid inputs for a model with `n_params` parameters (flexible when 7): the simulation runs to its end or
/// diverges (a `Simulation` error), so these cases exercise the loop itself.
fn valid_case(n_params: usize, max_len: usize) -> impl Strategy<Value = SimCase> {
    let chi = if n_params == 7 {
        (prop::collection::vec(0.1..200.0f64, 6..=6), 1e3..1e7f64)
            .prop_map(|(v, k)| vec![v[0], v[1], v[2] / 4.0, v[3], v[4], v[5] / 4.0, k])
            .boxed()
    } else {
        (0.1..200.0f64, 0.0..300.0f64, 0.0..50.0f64, -10.0..10.0f64)
            .prop_map(move |(m, fv, fc, of)| [m, fv, fc, of][..n_params].to_vec())
            .boxed()
    };
    let ctrl = prop_oneof![
        (
            1.0..500.0f64,
            1.0..500.0f64,
            0.1..100.0f64,
            prop_oneof![0.1..20.0f64, Just(f64::INFINITY)]
        )
            .prop_map(|(kp, kv, gtau, vsat)| Controller::EmpsCascade { kp, kv, gtau, vsat }),
        (
            1e2..1e6f64,
            1.0..1e4f64,
            prop_oneof![1.0..1e4f64, Just(f64::INFINITY)]
        )
            .prop_map(|(kp, kd, tau_max)| Controller::Pd { kp, kd, tau_max }),
    ];
    let qr = prop::collection::vec(-1e-3..1e-3f64, 4..max_len).prop_map(|steps| {
        steps
            .iter()
            .scan(0.0, |q, d| {
                *q += d;
                Some(*q)
            })
            .collect::<Vec<f64>>()
    });
    (
        chi,
        ctrl,
        qr,
        any::<bool>(),
        1e-4..1e-2f64,
        1usize..16,
        any::<bool>(),
        0usize..4,
    )
        .prop_map(|(chi, c, qr, with_u, dt, substeps, quantized, delay)| {
            let u = with_u.then(|| qr.iter().map(|q| 1e4 * q).collect());
            let quantization = if quantized { 1e-7 } else { 0.0 };
            (
                chi,
                c,
                qr,
                u,
                SimOptions {
                    dt,
                    substeps,
                    quantization,
                    delay,
                    force_lag: if delay == 1 { 3e-4 } else { 0.0 },
                    // valid cases alternate the integrators
                    integrator: if substeps % 2 == 0 {
                        Integrator::Exponential
                    } else {
                        Integrator::Rk4
                    },
                    tol: DEFAULT_TOL,
                    // a lead-in shorter than every valid reference
                    lead: delay % 3,
                },
            )
        })
}

/// Half valid cases, half hostile ones (any of the inputs may be absurd).
fn sim_case(n_params: usize, max_len: usize) -> impl Strategy<Value = SimCase> {
    let chi = if n_params == 7 {
        stiffness_params().boxed()
    } else {
        params(n_params).boxed()
    };
    prop_oneof![
        valid_case(n_params, max_len),
        (
            chi,
            controller(),
            signal(max_len),
            prop::option::of(signal(max_len)),
            sim_options()
        ),
    ]
}

fn check_sim(out: &sim::SimOutput, ndof: usize, n: usize) {
    assert_eq!(out.force.len(), n);
    for rows in [&out.q, &out.qd, &out.qdd] {
        assert_eq!(rows.len(), ndof);
        for r in rows.iter() {
            assert_eq!(r.len(), n);
            assert!(
                r.iter().all(|v| v.is_finite()),
                "non-finite state in an Ok simulation"
            );
        }
    }
    assert!(
        out.force.iter().all(|v| v.is_finite()),
        "non-finite force in an Ok simulation"
    );
}

fn is_documented(e: &Error) -> bool {
    !e.to_string().is_empty()
}

proptest! {
    #![proptest_config(config(96))]

    #[test]
    fn simulate_rigid_never_panics(
        (chi, c, qr, u, o) in sim_case(4, 120), offset in any::<bool>(),
        eps in prop_oneof![3 => Just(1e-4), 1 => Just(0.0), 1 => hostile()],
    ) {
        let chi = if offset { chi } else { chi[..chi.len().min(3)].to_vec() };
        if let Ok(m) = model::rigid(offset, eps) {
            match sim::simulate(&m, &chi, &c, &qr, u.as_deref(), &o) {
                Ok(out) => check_sim(&out, 1, o.outputs(qr.len())),
                Err(e) => prop_assert!(is_documented(&e)),
            }
        }
    }

    #[test]
    fn simulate_flexible_never_panics((chi, c, qr, u, o) in sim_case(7, 120)) {
        let m = model::flexible(1e-4).unwrap();
        match sim::simulate(&m, &chi, &c, &qr, u.as_deref(), &o) {
            Ok(out) => check_sim(&out, 2, o.outputs(qr.len())),
            Err(e) => prop_assert!(is_documented(&e)),
        }
    }

    #[test]
    fn simulate_sensitivity_never_panics(flexible in any::<bool>(), (chi, c, qr, u, o) in sim_case(7, 80)) {
        let n = o.outputs(qr.len());
        if flexible {
            let m = model::flexible(1e-4).unwrap();
            if let Ok(out) = sim::simulate_sensitivity(&m, &chi, &c, &qr, u.as_deref(), &o) {
                check_sim(&out.sim, 2, n);
                prop_assert_eq!(out.dforce.len(), 7 * n);
                prop_assert_eq!(out.dq.len(), 2 * 7 * n);
                prop_assert!(out.dforce.iter().chain(&out.dq).all(|v| v.is_finite()), "non-finite sensitivity");
            }
        } else {
            let m = model::rigid(false, 1e-4).unwrap();
            let chi = &chi[..chi.len().min(3)];
            if let Ok(out) = sim::simulate_sensitivity(&m, chi, &c, &qr, u.as_deref(), &o) {
                check_sim(&out.sim, 1, n);
                prop_assert_eq!(out.dforce.len(), 3 * n);
                prop_assert_eq!(out.dq.len(), 3 * n);
                prop_assert!(out.dforce.iter().chain(&out.dq).all(|v| v.is_finite()), "non-finite sensitivity");
            }
        }
    }

    #[test]
    fn custom_models_never_panic(
        terms in prop::collection::vec((0usize..4, 0usize..3, 0usize..3), 0..6), eps in hostile(),
        chi in prop::collection::vec(mostly(0.1, 10.0), 0..7), qr in signal(40),
    ) {
        let terms: Vec<(String, Basis)> = terms
            .into_iter()
            .enumerate()
            .map(|(i, (kind, a, b))| {
                let basis = match kind {
                    0 => Basis::Inertia { dof: a },
                    1 => Basis::Viscous { dof: a },
                    2 => Basis::Coulomb { dof: a },
                    _ => Basis::Spring { a, b },
                };
                (format!("p{i}"), basis)
            })
            .collect();
        if let Ok(m) = Model::<2>::new(terms, eps) {
            let _ = m.check_params(&chi);
            let _ = sim::simulate(&m, &chi, &Controller::EMPS, &qr, None, &SimOptions::new(1e-3));
        }
    }

    #[test]
    fn regressor_never_panics(
        flexible in any::<bool>(), offset in any::<bool>(), eps in hostile(),
        q in prop::collection::vec(signal(30), 0..3), qd in prop::collection::vec(signal(30), 0..3),
        qdd in prop::collection::vec(signal(30), 0..3),
    ) {
        if flexible {
            if let Ok(m) = model::flexible_with(offset, eps) {
                if let Ok(w) = m.regressor(&q, &qd, &qdd) {
                    prop_assert_eq!(w.len(), 2 * m.n_params() * q[0].len());
                }
            }
        } else if let Ok(m) = model::rigid(offset, eps) {
            if let Ok(w) = m.regressor(&q, &qd, &qdd) {
                prop_assert_eq!(w.len(), m.n_params() * q[0].len());
                prop_assert!(w.iter().all(|v| v.is_finite()));
            }
        }
    }

    #[test]
    fn controller_command_never_panics(c in controller(), x in prop::collection::vec(hostile(), 5..=5)) {
        let _ = c.validate();
        if let Ok(law) = c.law(x[3]) {
            let mut z = law.rest_state(x[0], x[1]);
            let _ = law.step(&mut z, x[0], x[1], x[4]);
            let _ = law.sensitivity_step(&mut z, x[2]);
        }
        if let Ok(law) = TransferFunction::new(&x[..3], &x[1..4], &x[2..], &x[..2], x[4].abs(), x[3]) {
            let mut z = law.rest_state(x[0], x[1]);
            let _ = law.step(&mut z, x[0], x[1], x[4]);
        }
    }
}

proptest! {
    #![proptest_config(config(256))]

    #[test]
    fn filter_designs_never_panic(order in whole(), wn in mostly(0.0, 1.0), rp in mostly(0.01, 3.0)) {
        if let Ok(tf) = filter::butter(order, wn) {
            prop_assert!(tf.b.iter().chain(&tf.a).all(|v| v.is_finite()));
        }
        let _ = filter::cheby1(order, rp, wn);
        if let Ok(sos) = filter::butter_sos(order, wn) {
            prop_assert!(sos.sections().iter().flatten().all(|v| v.is_finite()));
        }
        let _ = filter::cheby1_sos(order, rp, wn);
    }

    #[test]
    fn causal_filters_never_panic(
        b in prop::collection::vec(hostile(), 0..6), a in prop::collection::vec(hostile(), 0..6),
        x in signal(60), zi in prop::option::of(prop::collection::vec(hostile(), 0..8)),
        secs in prop::collection::vec(prop::collection::vec(hostile(), 6..=6), 0..4),
    ) {
        let tf = Tf { b, a };
        prop_assert_eq!(filter::lfilter(&tf, &x, zi.as_deref()).len(), x.len());
        let _ = filter::lfilter_zi(&tf);
        let sos = Sos(secs.iter().map(|s| [s[0], s[1], s[2], s[3], s[4], s[5]]).collect());
        let zis: Option<Vec<[f64; 2]>> = zi.map(|z| z.chunks(2).map(|c| [c[0], *c.get(1).unwrap_or(&0.0)]).collect());
        prop_assert_eq!(filter::sosfilt(&sos, &x, zis.as_deref()).len(), x.len());
        let _ = filter::sosfilt_zi(&sos);
    }

    #[test]
    fn zero_phase_filters_never_panic(
        order in 0usize..9, wn in mostly(0.01, 0.99), x in signal(80), padlen in prop::option::of(whole()),
        b in prop::collection::vec(hostile(), 0..5), a in prop::collection::vec(hostile(), 0..5),
    ) {
        for tf in [filter::butter(order, wn).ok(), Some(Tf { b: b.clone(), a: a.clone() })].into_iter().flatten() {
            if let Ok(y) = filter::filtfilt(&tf, &x, padlen) {
                prop_assert_eq!(y.len(), x.len());
                prop_assert!(y.iter().all(|v| v.is_finite()), "non-finite filtfilt output");
            }
        }
        if let Ok(sos) = filter::butter_sos(order, wn) {
            if let Ok(y) = filter::sosfiltfilt(&sos, &x, padlen) {
                prop_assert_eq!(y.len(), x.len());
                prop_assert!(y.iter().all(|v| v.is_finite()), "non-finite sosfiltfilt output");
            }
        }
        let hostile_sos = Sos(vec![[b.first().copied().unwrap_or(1.0), 0.0, 0.0, a.first().copied().unwrap_or(1.0), 0.5, 0.0]]);
        if let Ok(y) = filter::sosfiltfilt(&hostile_sos, &x, padlen) {
            prop_assert!(y.iter().all(|v| v.is_finite()), "non-finite sosfiltfilt output");
        }
    }

    #[test]
    fn decimators_never_panic(
        order in whole(), cutoff in mostly(1.0, 200.0), fs in mostly(100.0, 2000.0), factor in whole(),
        sos in any::<bool>(), y in signal(300), ncols in 0usize..4, extra in 0usize..3,
        wvals in prop::collection::vec(hostile(), 0..8),
    ) {
        let form = if sos { FilterForm::Sos } else { FilterForm::Ba };
        let decs = [Decimation::butterworth(order, cutoff, fs, factor, form), Decimation::matlab(factor)];
        let n = y.len();
        // a regressor with the right shape (columns copied from y with hostile values mixed in), or a wrong length
        let mut w: Vec<f64> = (0..ncols).flat_map(|_| y.iter().copied()).collect();
        for (i, v) in wvals.iter().enumerate() {
            if !w.is_empty() {
                let k = (i * 7919) % w.len();
                w[k] = *v;
            }
        }
        w.extend(std::iter::repeat_n(0.5, extra));
        for d in decs.into_iter().flatten() {
            let _ = (d.factor(), d.order(), d.padlen(), d.min_input_len(), d.output_len(n), d.filter());
            if let Ok(out) = d.apply(&y) {
                prop_assert_eq!(out.len(), d.output_len(n));
                prop_assert!(out.iter().all(|v| v.is_finite()));
            }
            if let Ok((yd, wd)) = d.apply_parallel(&y, &w, ncols) {
                prop_assert_eq!(yd.len(), d.output_len(n));
                prop_assert_eq!(wd.len(), if n == 0 { 0 } else { d.output_len(n) * ncols });
                prop_assert!(yd.iter().chain(&wd).all(|v| v.is_finite()));
            }
        }
        let _ = filter::default_factor(fs, cutoff);
    }

    #[test]
    fn lstsq_never_panics(
        rows in 0usize..24, cols in 0usize..6, w in prop::collection::vec(hostile(), 0..150),
        y in prop::collection::vec(hostile(), 0..30), tol in prop::option::of(hostile()), sample_std in any::<bool>(),
        dup in any::<bool>(),
    ) {
        let opts = LstsqOptions {
            rank_tol: tol,
            sigma: if sample_std { SigmaConvention::SampleStd } else { SigmaConvention::Paper },
        };
        let _ = lstsq(&w, rows, cols, &y, &opts);
        // shaped inputs, so that the factorisation itself runs (with duplicated columns when `dup`)
        let mut ws: Vec<f64> = (0..rows * cols).map(|i| w.get(i % w.len().max(1)).copied().unwrap_or(1.0)).collect();
        if dup && cols >= 2 && rows > 0 {
            let (first, second) = ws.split_at_mut(rows);
            second[..rows].copy_from_slice(first);
        }
        let ys: Vec<f64> = (0..rows).map(|i| y.get(i % y.len().max(1)).copied().unwrap_or(1.0)).collect();
        if let Ok(sol) = lstsq(&ws, rows, cols, &ys, &opts) {
            prop_assert_eq!(sol.params.len(), cols);
            prop_assert_eq!(sol.covariance.len(), cols * cols);
            prop_assert!(sol.params.iter().all(|v| v.is_finite()));
            prop_assert!(sol.rank <= cols && sol.rank >= 1);
        }
    }

    #[test]
    fn coulomb_sign_is_bounded(v in hostile(), eps in hostile()) {
        let s = model::coulomb_sign(v, eps);
        prop_assert!(s.is_nan() || s.abs() <= 1.0 + 1e-12);
        let _ = model::coulomb_sign_derivative(v, eps);
    }
}

/// How deep the generated cases reach: the share of results (not errors) per function, printed for a campaign
/// report (`cargo test -p didim-core --test proptest_no_panic -- --ignored --nocapture`).
#[test]
#[ignore]
fn outcome_mix() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::TestRunner;
    let cases = config(2000).cases;
    let mut runner = TestRunner::new(config(cases));
    let strat = (sim_case(4, 120), any::<bool>());
    let (mut ok, mut total) = (0, 0);
    for _ in 0..cases {
        let ((chi, c, qr, u, o), offset) = strat.new_tree(&mut runner).unwrap().current();
        let chi = if offset {
            chi
        } else {
            chi[..chi.len().min(3)].to_vec()
        };
        let m = model::rigid(offset, 1e-4).unwrap();
        total += 1;
        ok += sim::simulate(&m, &chi, &c, &qr, u.as_deref(), &o).is_ok() as usize;
    }
    eprintln!("simulate (rigid): {ok} results in {total} cases");
    let strat = sim_case(7, 80);
    let (mut ok, mut total) = (0, 0);
    for _ in 0..cases {
        let (chi, c, qr, u, o) = strat.new_tree(&mut runner).unwrap().current();
        let m = model::flexible(1e-4).unwrap();
        total += 1;
        ok += sim::simulate_sensitivity(&m, &chi, &c, &qr, u.as_deref(), &o).is_ok() as usize;
    }
    eprintln!("simulate_sensitivity (flexible): {ok} results in {total} cases");
    let strat = (
        whole(),
        mostly(1.0, 200.0),
        mostly(100.0, 2000.0),
        whole(),
        signal(300),
    );
    let (mut ok, mut total) = (0, 0);
    for _ in 0..cases {
        let (order, cutoff, fs, factor, y) = strat.new_tree(&mut runner).unwrap().current();
        if let Ok(d) = Decimation::butterworth(order, cutoff, fs, factor, FilterForm::Sos) {
            total += 1;
            ok += d.apply(&y).is_ok() as usize;
        }
    }
    eprintln!("Decimation::apply (valid decimators): {ok} results in {total} cases");
}
