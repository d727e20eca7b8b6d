//! Filter tests: designs, filters and decimation against scipy reference vectors and properties.

use super::*;
use std::collections::HashMap;
use std::sync::OnceLock;

/// scipy reference vectors, written by `tests/data/make_filter_refs.py`.
const REFS: &str = include_str!("../../tests/data/filter_refs.txt");

fn refs() -> &'static HashMap<String, Vec<f64>> {
    static REFS_MAP: OnceLock<HashMap<String, Vec<f64>>> = OnceLock::new();
    REFS_MAP.get_or_init(|| {
        let mut map = HashMap::new();
        for line in REFS.lines() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let mut it = line.split_whitespace();
            let name = it.next().expect("name").to_string();
            let count: usize = it.next().expect("count").parse().expect("count");
            let vals: Vec<f64> = it.map(|v| v.parse().expect("float")).collect();
            assert_eq!(vals.len(), count, "record {name}");
            map.insert(name, vals);
        }
        map
    })
}

fn get(name: &str) -> &'static [f64] {
    refs()
        .get(name)
        .unwrap_or_else(|| panic!("missing reference record {name}"))
}

fn cases(prefix: &str) -> Vec<usize> {
    (0..)
        .take_while(|i| refs().contains_key(&format!("{prefix}.{i}.params")))
        .collect()
}

/// max |got - want| / max |want|.
fn rel_err(got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len(), "length mismatch");
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let err = got
        .iter()
        .zip(want)
        .fold(0.0f64, |m, (g, w)| m.max((g - w).abs()));
    err / scale
}

/// Tolerance of an output against scipy's from the reference's measured
/// sensitivity (its relative change when the ba coefficients move by one ulp):
/// two correct implementations round differently inside the recursion and the
/// steady-state solve, and the filter amplifies that as it amplifies an ulp.
fn tol(sensitivity: f64) -> f64 {
    1e-10f64.max(100.0 * sensitivity)
}

/// How far two correct implementations of a ba filter may differ, relative to
/// the signal's scale: each step of the recursion rounds its sums, an error of
/// about eps·(Σ|b| + Σ|a|) of the signal, which the recursion 1/A(z) amplifies
/// by at most the ℓ1 norm of its impulse response; the two implementations may
/// err in opposite directions (and so may their steady-state solves).
fn iir_tolerance(tf: &Tf) -> f64 {
    let mut imp = vec![0.0; 200_000];
    imp[0] = 1.0;
    let h = lfilter(
        &Tf {
            b: vec![1.0],
            a: tf.a.clone(),
        },
        &imp,
        None,
    );
    let gain: f64 = h.iter().map(|v| v.abs()).sum();
    let coef: f64 = tf.b.iter().chain(&tf.a).map(|v| v.abs()).sum();
    4.0 * f64::EPSILON * coef * gain
}

fn x_ref() -> &'static [f64] {
    get("x")
}

fn design_ba(kind: f64, order: f64, rp: f64, wn: f64) -> Tf {
    if kind == 0.0 {
        butter(order as usize, wn).unwrap()
    } else {
        cheby1(order as usize, rp, wn).unwrap()
    }
}

fn design_sos(kind: f64, order: f64, rp: f64, wn: f64) -> Sos {
    if kind == 0.0 {
        butter_sos(order as usize, wn).unwrap()
    } else {
        cheby1_sos(order as usize, rp, wn).unwrap()
    }
}

fn flat(sos: &Sos) -> Vec<f64> {
    sos.0.iter().flatten().copied().collect()
}

fn msg(e: Error) -> String {
    match e {
        Error::InvalidInput(m) => m,
        other => panic!("expected InvalidInput, got {other:?}"),
    }
}

#[test]
fn reference_file_is_complete() {
    assert_eq!(x_ref().len(), 1237);
    assert_eq!(cases("butter").len(), 11);
    assert_eq!(cases("cheby1").len(), 9);
    assert_eq!(cases("lfilter").len(), 3);
    assert_eq!(cases("sosfilt").len(), 3);
    assert_eq!(cases("filtfilt").len(), 7);
    assert_eq!(cases("sosfiltfilt").len(), 6);
    assert_eq!(cases("dec_bw").len(), 6);
    assert_eq!(cases("dec_matlab").len(), 6);
}

#[test]
fn designs_match_scipy_coefficients() {
    let mut worst = [0.0f64; 3];
    for i in cases("butter") {
        let p = get(&format!("butter.{i}.params"));
        let (order, wn) = (p[0] as usize, p[1]);
        let tf = butter(order, wn).unwrap();
        let sos = butter_sos(order, wn).unwrap();
        let eb = rel_err(&tf.b, get(&format!("butter.{i}.b")));
        let ea = rel_err(&tf.a, get(&format!("butter.{i}.a")));
        let es = rel_err(&flat(&sos), get(&format!("butter.{i}.sos")));
        assert!(
            eb <= 1e-12 && ea <= 1e-12,
            "butter({order}, {wn}): b {eb:e}, a {ea:e}"
        );
        assert!(es <= 1e-12, "butter_sos({order}, {wn}): {es:e}");
        worst = [worst[0].max(eb), worst[1].max(ea), worst[2].max(es)];
    }
    for i in cases("cheby1") {
        let p = get(&format!("cheby1.{i}.params"));
        let (order, rp, wn) = (p[0] as usize, p[1], p[2]);
        let tf = cheby1(order, rp, wn).unwrap();
        let sos = cheby1_sos(order, rp, wn).unwrap();
        let eb = rel_err(&tf.b, get(&format!("cheby1.{i}.b")));
        let ea = rel_err(&tf.a, get(&format!("cheby1.{i}.a")));
        let es = rel_err(&flat(&sos), get(&format!("cheby1.{i}.sos")));
        assert!(
            eb <= 1e-12 && ea <= 1e-12,
            "cheby1({order}, {rp}, {wn}): b {eb:e}, a {ea:e}"
        );
        assert!(es <= 1e-12, "cheby1_sos({order}, {rp}, {wn}): {es:e}");
        worst = [worst[0].max(eb), worst[1].max(ea), worst[2].max(es)];
    }
    eprintln!(
        "design max rel err: b {:e}, a {:e}, sos {:e}",
        worst[0], worst[1], worst[2]
    );
}

#[test]
fn steady_states_match_scipy() {
    let mut worst = (0.0f64, 0.0f64);
    for (kind, n) in [("butter", cases("butter")), ("cheby1", cases("cheby1"))] {
        for i in n {
            let tf = Tf {
                b: get(&format!("{kind}.{i}.b")).to_vec(),
                a: get(&format!("{kind}.{i}.a")).to_vec(),
            };
            let zi = lfilter_zi(&tf);
            let e = rel_err(&zi, get(&format!("{kind}.{i}.zi")));
            let rows: Vec<[f64; 6]> = get(&format!("{kind}.{i}.sos"))
                .chunks(6)
                .map(|c| [c[0], c[1], c[2], c[3], c[4], c[5]])
                .collect();
            let szi: Vec<f64> = sosfilt_zi(&Sos(rows)).into_iter().flatten().collect();
            let es = rel_err(&szi, get(&format!("{kind}.{i}.sos_zi")));
            // lfilter_zi solves an ill-conditioned system for high orders at
            // low cutoffs (butter(9, 0.02): 1 ulp in `a` moves zi by 3e-3), so
            // its agreement with numpy's LAPACK solve follows that sensitivity.
            let order = tf.a.len() - 1;
            let sens = get(&format!("{kind}.{i}.zi_sensitivity"))[0];
            let t = 1e-12f64.max(100.0 * sens);
            assert!(e <= t, "{kind}.{i} lfilter_zi: {e:e}");
            assert!(es <= 1e-12, "{kind}.{i} sosfilt_zi: {es:e}");
            eprintln!("{kind}.{i} (order {order}) lfilter_zi rel err {e:e}, sosfilt_zi {es:e}");
            worst = (worst.0.max(e), worst.1.max(es));
        }
    }
    eprintln!(
        "steady state max rel err: lfilter_zi {:e}, sosfilt_zi {:e}",
        worst.0, worst.1
    );
}

#[test]
fn causal_filters_match_scipy() {
    let x = x_ref();
    for i in cases("lfilter") {
        let p = get(&format!("lfilter.{i}.params"));
        let tf = design_ba(p[0], p[1], p[2], p[3]);
        let xs = &x[..p[4] as usize];
        let zi: Option<Vec<f64>> = (p[5] != 0.0).then(|| lfilter_zi(&tf).iter().map(|v| v * xs[0]).collect());
        let y = lfilter(&tf, xs, zi.as_deref());
        let e = rel_err(&y, get(&format!("lfilter.{i}.y")));
        let t = 1e-10f64.max(iir_tolerance(&tf));
        eprintln!("lfilter.{i}: rel err {e:e} (tolerance {t:e})");
        assert!(e <= t, "lfilter.{i}: {e:e} > {t:e}");
    }
    for i in cases("sosfilt") {
        let p = get(&format!("sosfilt.{i}.params"));
        let sos = design_sos(p[0], p[1], p[2], p[3]);
        let xs = &x[..p[4] as usize];
        let zi: Option<Vec<[f64; 2]>> = (p[5] != 0.0).then(|| {
            sosfilt_zi(&sos)
                .iter()
                .map(|z| [z[0] * xs[0], z[1] * xs[0]])
                .collect()
        });
        let y = sosfilt(&sos, xs, zi.as_deref());
        let e = rel_err(&y, get(&format!("sosfilt.{i}.y")));
        eprintln!("sosfilt.{i}: rel err {e:e}");
        assert!(e <= 1e-10, "sosfilt.{i}: {e:e}");
    }
}

#[test]
fn filtfilt_matches_scipy() {
    let x = x_ref();
    for i in cases("filtfilt") {
        let p = get(&format!("filtfilt.{i}.params"));
        let tf = design_ba(p[0], p[1], p[2], p[3]);
        let padlen = (p[5] >= 0.0).then_some(p[5] as usize);
        let y = filtfilt(&tf, &x[..p[4] as usize], padlen).unwrap();
        let e = rel_err(&y, get(&format!("filtfilt.{i}.y")));
        eprintln!("filtfilt.{i} {p:?}: rel err {e:e} (sensitivity {:e})", p[6]);
        assert!(e <= tol(p[6]), "filtfilt.{i}: {e:e}");
    }
}

#[test]
fn sosfiltfilt_matches_scipy_on_its_own_sos() {
    let x = x_ref();
    for i in cases("sosfiltfilt") {
        let p = get(&format!("sosfiltfilt.{i}.params"));
        let sos = design_sos(p[0], p[1], p[2], p[3]);
        let padlen = (p[5] >= 0.0).then_some(p[5] as usize);
        let y = sosfiltfilt(&sos, &x[..p[4] as usize], padlen).unwrap();
        let e = rel_err(&y, get(&format!("sosfiltfilt.{i}.y")));
        eprintln!("sosfiltfilt.{i} {p:?}: rel err {e:e}");
        assert!(e <= 1e-10, "sosfiltfilt.{i}: {e:e}");
    }
}

#[test]
fn butterworth_decimation_matches_scipy() {
    let x = x_ref();
    for i in cases("dec_bw") {
        let p = get(&format!("dec_bw.{i}.params"));
        let form = if p[4] == 0.0 {
            FilterForm::Ba
        } else {
            FilterForm::Sos
        };
        let d = Decimation::butterworth(p[0] as usize, p[1], p[2], p[3] as usize, form).unwrap();
        let xs = &x[..p[5] as usize];
        let y = d.apply(xs).unwrap();
        assert_eq!(y.len(), d.output_len(xs.len()));
        let e = rel_err(&y, get(&format!("dec_bw.{i}.y")));
        eprintln!("dec_bw.{i} {p:?}: rel err {e:e}");
        assert!(e <= tol(p[6]), "dec_bw.{i}: {e:e}");
    }
}

#[test]
fn matlab_decimation_matches_scipy_model() {
    let x = x_ref();
    for i in cases("dec_matlab") {
        let p = get(&format!("dec_matlab.{i}.params"));
        let d = Decimation::matlab(p[0] as usize).unwrap();
        assert_eq!(d.order(), p[2] as usize, "order for r = {}", p[0]);
        assert_eq!(d.padlen(), 3 * d.order());
        let xs = &x[..p[1] as usize];
        let y = d.apply(xs).unwrap();
        assert_eq!(y.len(), d.output_len(xs.len()));
        let e = rel_err(&y, get(&format!("dec_matlab.{i}.y")));
        eprintln!("dec_matlab.{i} {p:?}: rel err {e:e}");
        assert!(e <= tol(p[3]), "dec_matlab.{i}: {e:e}");
    }
}

#[test]
fn matlab_order_safeguard_matches_reference() {
    let rs = get("matlab_order.r");
    let orders = get("matlab_order.order");
    for (&r, &o) in rs.iter().zip(orders) {
        let d = Decimation::matlab(r as usize).unwrap();
        assert_eq!(d.order(), o as usize, "r = {r}");
    }
}

#[test]
fn matlab_alignment_keeps_the_last_sample() {
    let d = Decimation::matlab(10).unwrap();
    let x = x_ref();
    let full = filtfilt(&cheby1(8, 0.05, 0.08).unwrap(), x, Some(24)).unwrap();
    // n = 1237: nout = 124, nbeg = 10 - (1240 - 1237) = 7 (1-based).
    let y = d.apply(x).unwrap();
    assert_eq!(y.len(), 124);
    for (k, v) in y.iter().enumerate() {
        assert_eq!(v.to_bits(), full[6 + 10 * k].to_bits(), "k = {k}");
    }
    // n divisible by r: the first kept sample is x[r - 1].
    let y = d.apply(&x[..1230]).unwrap();
    let full = filtfilt(&cheby1(8, 0.05, 0.08).unwrap(), &x[..1230], Some(24)).unwrap();
    assert_eq!((y.len(), y[0], y[122]), (123, full[9], full[1229]));
    let x: Vec<f64> = x.to_vec();
    let one = Decimation::matlab(1).unwrap();
    assert_eq!(one.apply(&x).unwrap(), x);
    assert!(one.filter().is_none());
    assert_eq!(one.min_input_len(), 1);
}

#[test]
fn parallel_decimation_equals_sequential_bit_for_bit() {
    let x = x_ref();
    let n = 1000;
    let ncols = 7;
    let y = &x[..n];
    let w: Vec<f64> = (0..ncols)
        .flat_map(|j| (0..n).map(move |i| x[(i * (j + 1) + 3 * j) % x.len()] * (j as f64 + 0.5)))
        .collect();
    for d in [
        Decimation::butterworth(4, 40.0, 1000.0, 5, FilterForm::Sos).unwrap(),
        Decimation::butterworth(4, 40.0, 1000.0, 5, FilterForm::Ba).unwrap(),
        Decimation::matlab(10).unwrap(),
    ] {
        let (yd, wd) = d.apply_parallel(y, &w, ncols).unwrap();
        let nout = d.output_len(n);
        assert_eq!(yd.len(), nout);
        assert_eq!(wd.len(), nout * ncols);
        let ys = d.apply(y).unwrap();
        assert!(yd.iter().zip(&ys).all(|(a, b)| a.to_bits() == b.to_bits()));
        for j in 0..ncols {
            let col = d.apply(&w[j * n..(j + 1) * n]).unwrap();
            let got = &wd[j * nout..(j + 1) * nout];
            assert!(
                got.iter().zip(&col).all(|(a, b)| a.to_bits() == b.to_bits()),
                "column {j}"
            );
        }
    }
    // No columns.
    let d = Decimation::matlab(4).unwrap();
    let (yd, wd) = d.apply_parallel(y, &[], 0).unwrap();
    assert_eq!(yd.len(), d.output_len(n));
    assert!(wd.is_empty());
}

#[test]
fn too_short_records_are_rejected() {
    let tf = butter(4, 0.2).unwrap();
    // Default padlen 3 * 5 = 15: 15 samples are too few, 16 are enough.
    let m = msg(filtfilt(&tf, &[1.0; 15], None).unwrap_err());
    assert!(
        m.contains("too short") && m.contains("15") && m.contains("len(a) = 5"),
        "{m}"
    );
    assert!(filtfilt(&tf, &[1.0; 16], None).is_ok());
    // MATLAB padlen 3 * 4 = 12.
    assert!(filtfilt(&tf, &[1.0; 12], Some(12)).is_err());
    assert!(filtfilt(&tf, &[1.0; 13], Some(12)).is_ok());
    let m = msg(filtfilt(&tf, &[], Some(0)).unwrap_err());
    assert!(m.contains("x has 0 samples"), "{m}");
    let sos = butter_sos(4, 0.2).unwrap();
    let m = msg(sosfiltfilt(&sos, &[1.0; 15], None).unwrap_err());
    assert!(
        m.contains("too short") && m.contains("2 second-order sections"),
        "{m}"
    );
    assert!(sosfiltfilt(&sos, &[1.0; 16], None).is_ok());
    let d = Decimation::matlab(10).unwrap();
    assert_eq!(d.min_input_len(), 25);
    let m = msg(d.apply(&[0.0; 24]).unwrap_err());
    assert!(m.contains("x has 24 samples") && m.contains("too short"), "{m}");
    assert!(d.apply(&[0.0; 25]).is_ok());
    let d = Decimation::butterworth(3, 10.0, 100.0, 2, FilterForm::Sos).unwrap();
    assert_eq!(d.padlen(), 12);
    assert!(d.apply(&[0.0; 12]).is_err());
    let m = msg(d.apply_parallel(&[0.0; 12], &[0.0; 24], 2).unwrap_err());
    assert!(m.starts_with("y has 12 samples"), "{m}");
}

#[test]
fn bad_design_arguments_are_rejected() {
    for wn in [0.0, 1.0, -0.1, 1.5, f64::NAN, f64::INFINITY] {
        let m = msg(butter(4, wn).unwrap_err());
        assert!(m.contains("wn"), "{m}");
        assert!(cheby1_sos(4, 0.5, wn).is_err());
    }
    for order in [0, 21] {
        let m = msg(butter_sos(order, 0.2).unwrap_err());
        assert!(m.contains("order") && m.contains(&order.to_string()), "{m}");
    }
    for rp in [0.0, -1.0, f64::NAN] {
        let m = msg(cheby1(4, rp, 0.2).unwrap_err());
        assert!(m.contains("rp_db"), "{m}");
    }
    for cutoff in [0.0, -5.0, 50.0, 60.0, f64::NAN] {
        let m = msg(Decimation::butterworth(4, cutoff, 100.0, 2, FilterForm::Sos).unwrap_err());
        assert!(m.contains("cutoff_hz"), "{m}");
    }
    for fs in [0.0, -100.0, f64::NAN] {
        let m = msg(Decimation::butterworth(4, 10.0, fs, 2, FilterForm::Ba).unwrap_err());
        assert!(m.contains("fs_hz"), "{m}");
    }
    let m = msg(Decimation::butterworth(0, 10.0, 100.0, 2, FilterForm::Ba).unwrap_err());
    assert!(m.contains("order"), "{m}");
}

#[test]
fn zero_factor_is_rejected() {
    let m = msg(Decimation::butterworth(4, 10.0, 100.0, 0, FilterForm::Sos).unwrap_err());
    assert!(m.contains("factor") && m.contains('0'), "{m}");
    let m = msg(Decimation::matlab(0).unwrap_err());
    assert!(m.contains("factor"), "{m}");
}

#[test]
fn non_finite_input_is_rejected() {
    let mut x = x_ref()[..200].to_vec();
    x[57] = f64::NAN;
    let m = msg(filtfilt(&butter(2, 0.3).unwrap(), &x, None).unwrap_err());
    assert!(m.contains("x has a non-finite value at index 57 (NaN)"), "{m}");
    let m = msg(sosfiltfilt(&butter_sos(2, 0.3).unwrap(), &x, None).unwrap_err());
    assert!(m.contains("x has a non-finite value at index 57"), "{m}");
    let d = Decimation::butterworth(2, 100.0, 1000.0, 2, FilterForm::Sos).unwrap();
    let m = msg(d.apply(&x).unwrap_err());
    assert!(m.contains("x has a non-finite value at index 57"), "{m}");
    let y = x_ref()[..200].to_vec();
    let mut w = [y.clone(), y.clone(), y.clone()].concat();
    w[2 * 200 + 9] = f64::INFINITY;
    let m = msg(d.apply_parallel(&y, &w, 3).unwrap_err());
    assert!(
        m.contains("w column 2 has a non-finite value at index 9 (inf)"),
        "{m}"
    );
    let m = msg(d.apply_parallel(&x, &w[..400], 2).unwrap_err());
    assert!(m.contains("y has a non-finite value at index 57"), "{m}");
    let bad = Tf {
        b: vec![1.0, f64::NAN],
        a: vec![1.0, 0.5],
    };
    let m = msg(filtfilt(&bad, &y, None).unwrap_err());
    assert!(m.contains("tf.b[1]"), "{m}");
}

#[test]
fn mismatched_lengths_are_rejected() {
    let d = Decimation::matlab(2).unwrap();
    let y = vec![0.0; 100];
    let m = msg(d.apply_parallel(&y, &[0.0; 299], 3).unwrap_err());
    assert!(
        m.contains("w has 299 values") && m.contains("ncols = 3") && m.contains("300"),
        "{m}"
    );
    let m = msg(d.apply_parallel(&y, &[0.0; 100], usize::MAX).unwrap_err());
    assert!(m.contains("overflows"), "{m}");
    assert!(d.apply_parallel(&y, &[0.0; 200], 2).is_ok());
}

#[test]
fn malformed_filters_never_panic() {
    let x = [1.0, 2.0, 3.0];
    assert!(lfilter(
        &Tf {
            b: vec![],
            a: vec![1.0]
        },
        &x,
        None
    )
    .iter()
    .all(|v| v.is_nan()));
    assert!(lfilter(
        &Tf {
            b: vec![1.0],
            a: vec![0.0, 1.0]
        },
        &x,
        None
    )
    .iter()
    .all(|v| v.is_nan()));
    assert!(lfilter(
        &Tf {
            b: vec![1.0],
            a: vec![]
        },
        &x,
        None
    )
    .iter()
    .all(|v| v.is_nan()));
    // Gain-only filter and a0 normalisation.
    assert_eq!(
        lfilter(
            &Tf {
                b: vec![2.0],
                a: vec![4.0]
            },
            &x,
            None
        ),
        vec![0.5, 1.0, 1.5]
    );
    // Wrong zi lengths are tolerated.
    let tf = butter(3, 0.3).unwrap();
    assert_eq!(lfilter(&tf, &x, Some(&[])), lfilter(&tf, &x, None));
    let long = lfilter(&tf, &x, Some(&[0.0; 10]));
    assert_eq!(long, lfilter(&tf, &x, None));
    // Pole at z = 1: no steady state.
    let integ = Tf {
        b: vec![1.0],
        a: vec![1.0, -1.0],
    };
    assert!(lfilter_zi(&integ).iter().all(|v| v.is_nan()));
    assert!(filtfilt(&integ, &[1.0; 10], None).is_err());
    assert!(lfilter_zi(&Tf { b: vec![], a: vec![] }).is_empty());
    assert_eq!(
        lfilter_zi(&Tf {
            b: vec![1.0],
            a: vec![1.0]
        }),
        Vec::<f64>::new()
    );
    // Leading zeros of a are dropped by lfilter_zi, as in scipy.
    let z1 = lfilter_zi(&Tf {
        b: vec![0.5, 0.5],
        a: vec![1.0, -0.2],
    });
    let z2 = lfilter_zi(&Tf {
        b: vec![0.5, 0.5],
        a: vec![0.0, 1.0, -0.2],
    });
    assert_eq!(z1, z2[..1].to_vec());
    // Sos edge cases.
    assert_eq!(sosfilt(&Sos(vec![]), &x, None), x.to_vec());
    assert!(sosfilt(&Sos(vec![[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]), &x, None)
        .iter()
        .all(|v| v.is_nan()));
    assert!(sosfiltfilt(&Sos(vec![]), &[1.0; 50], None).is_err());
    assert!(sosfiltfilt(&Sos(vec![[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]), &[1.0; 50], None).is_err());
    assert!(sosfilt_zi(&Sos(vec![[1.0, 0.0, 0.0, 1.0, -1.0, 0.0]]))[0][0].is_nan());
    let sos = butter_sos(2, 0.3).unwrap();
    assert_eq!(sosfilt(&sos, &x, Some(&[])), sosfilt(&sos, &x, None));
    assert!(filtfilt(
        &Tf {
            b: vec![1.0],
            a: vec![0.0, 1.0]
        },
        &[1.0; 10],
        None
    )
    .is_err());
    assert!(filtfilt(
        &Tf {
            b: vec![],
            a: vec![1.0]
        },
        &[1.0; 10],
        None
    )
    .is_err());
    // padlen 0 leaves the record unextended; huge padlen is just "too short".
    assert!(filtfilt(&tf, &x, Some(0)).is_ok());
    assert!(filtfilt(&tf, &x, Some(usize::MAX)).is_err());
    // Extreme factors do not panic.
    let d = Decimation::matlab(usize::MAX);
    assert!(d.is_err() || d.unwrap().apply(&[0.0; 30]).is_ok());
    let d = Decimation::butterworth(2, 10.0, 100.0, usize::MAX, FilterForm::Sos).unwrap();
    assert_eq!(d.apply(&[1.0; 20]).unwrap().len(), 1);
    assert_eq!(d.output_len(0), 0);
}

#[test]
fn default_factor_follows_matlab_relation() {
    assert_eq!(default_factor(1000.0, 40.0), 10);
    assert_eq!(default_factor(1000.0, 45.0), 8);
    assert_eq!(default_factor(100.0, 4.0), 10);
    assert_eq!(default_factor(100.0, 40.0), 1);
    assert_eq!(default_factor(100.0, 400.0), 1);
    assert_eq!(default_factor(5000.0, 20.0), 100);
    for (fs, fc) in [
        (f64::NAN, 1.0),
        (1.0, 0.0),
        (-1.0, 1.0),
        (1.0, f64::INFINITY),
        (f64::INFINITY, 1.0),
    ] {
        assert_eq!(default_factor(fs, fc), 1);
    }
    // The MATLAB cutoff 0.8 fs / (2 r) maps back to r.
    for r in 1..200usize {
        let fs = 1234.5;
        assert_eq!(default_factor(fs, 0.8 * fs / (2.0 * r as f64)), r, "r = {r}");
    }
}

#[test]
fn accessors_describe_the_decimator() {
    let d = Decimation::butterworth(5, 30.0, 1000.0, 4, FilterForm::Sos).unwrap();
    assert_eq!(d.factor(), 4);
    assert_eq!(d.order(), 5);
    assert_eq!(d.padlen(), 18); // scipy: 3 * (2*3 + 1 - 1)
    assert_eq!(d.min_input_len(), 19);
    assert_eq!(d.output_len(10), 3);
    match d.filter() {
        Some(ZeroPhase::Sos(s)) => assert_eq!(s.n_sections(), 3),
        other => panic!("{other:?}"),
    }
    let d = Decimation::butterworth(5, 30.0, 1000.0, 4, FilterForm::Ba).unwrap();
    assert_eq!(d.padlen(), 18); // scipy: 3 * max(len(a), len(b))
    let d = Decimation::matlab(10).unwrap();
    assert_eq!((d.order(), d.padlen(), d.factor()), (8, 24, 10));
    match d.filter() {
        Some(ZeroPhase::Ba(tf)) => assert_eq!(tf.a.len(), 9),
        other => panic!("{other:?}"),
    }
}

#[test]
fn zero_phase_output_has_no_lag_and_unit_dc_gain() {
    // A constant goes through unchanged; a slow sine is not delayed.
    let n = 2000;
    let c = vec![3.25; n];
    let y = sosfiltfilt(&butter_sos(6, 0.05).unwrap(), &c, None).unwrap();
    assert!(y.iter().all(|v| (v - 3.25).abs() < 1e-12));
    let s: Vec<f64> = (0..n).map(|i| (2.0 * PI * 0.002 * i as f64).sin()).collect();
    let y = filtfilt(&butter(4, 0.1).unwrap(), &s, None).unwrap();
    let err = y[200..1800]
        .iter()
        .zip(&s[200..1800])
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(err < 1e-6, "{err}");
}

/// Bitwise equality of two results, or the same error.
fn same_bits(got: &Result<Vec<f64>>, want: &Result<Vec<f64>>) -> bool {
    match (got, want) {
        (Ok(g), Ok(w)) => g.len() == w.len() && g.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()),
        (Err(g), Err(w)) => format!("{g}") == format!("{w}"),
        _ => false,
    }
}

#[test]
fn zero_phase_kernels_equal_the_one_column_reference_bit_for_bit() {
    // every number of sections and of states, unrolled kernels and the general loops alike
    let x = &x_ref()[..400];
    for order in 1..=20 {
        for (kind, wn) in [(0.0, 0.3), (0.0, 0.05), (1.0, 0.2)] {
            let sos = design_sos(kind, order as f64, 0.5, wn);
            let norm = validate_sos(&sos).unwrap();
            let zi = sosfilt_zi_checked(&sos).unwrap();
            for padlen in [None, Some(0), Some(7)] {
                let edge = padlen.unwrap_or_else(|| sos_default_padlen(&norm));
                let want = finite_output(sosfiltfilt_core(&norm, &zi, x, edge), "x");
                let got = sosfiltfilt(&sos, x, padlen);
                assert!(
                    same_bits(&got, &want),
                    "sos order {order} kind {kind} wn {wn} padlen {padlen:?}"
                );
            }
            if order <= 12 {
                let tf = design_ba(kind, order as f64, 0.5, wn);
                let zi = lfilter_zi_checked(&tf.b, &tf.a).unwrap();
                let (b, a) = normalized_ba(&tf.b, &tf.a).unwrap();
                for padlen in [None, Some(0), Some(5)] {
                    let edge = padlen.unwrap_or(3 * tf.a.len().max(tf.b.len()));
                    let want = finite_output(filtfilt_core(&b, &a, &zi, x, edge), "x");
                    let got = filtfilt(&tf, x, padlen);
                    assert!(
                        same_bits(&got, &want),
                        "ba order {order} kind {kind} wn {wn} padlen {padlen:?}"
                    );
                }
            }
        }
    }
    // a gain alone (one coefficient each): y = x · b0 · b0
    let tf = Tf {
        b: vec![0.5],
        a: vec![2.0],
    };
    let want: Vec<f64> = x.iter().map(|v| v * 0.25 * 0.25).collect();
    assert!(same_bits(&filtfilt(&tf, x, None), &Ok(want)));
}

#[test]
fn decimated_groups_of_any_size_equal_the_one_column_reference() {
    let x = x_ref();
    let n = 700;
    let cols: Vec<Vec<f64>> = (0..9)
        .map(|j| {
            (0..n)
                .map(|i| x[(i * (j + 2) + 5 * j) % x.len()] * (j as f64 - 3.5))
                .collect()
        })
        .collect();
    for d in [
        Decimation::butterworth(4, 40.0, 1000.0, 5, FilterForm::Sos).unwrap(),
        Decimation::butterworth(11, 90.0, 1000.0, 3, FilterForm::Sos).unwrap(),
        Decimation::butterworth(4, 40.0, 1000.0, 5, FilterForm::Ba).unwrap(),
        Decimation::matlab(10).unwrap(),
        Decimation::matlab(1).unwrap(),
    ] {
        let reference = |c: &[f64]| -> Vec<f64> {
            let full = match &d.prepared {
                Prepared::Identity => c.to_vec(),
                Prepared::Ba { b, a, zi } => filtfilt_core(b, a, zi, c, d.padlen()),
                Prepared::Sos { sos, zi } => sosfiltfilt_core(sos, zi, c, d.padlen()),
            };
            full.iter()
                .skip(d.start_index(n))
                .step_by(d.factor())
                .copied()
                .collect()
        };
        for k in 1..=cols.len() {
            let refs: Vec<&[f64]> = cols[..k].iter().map(Vec::as_slice).collect();
            let got = d.apply_columns(&refs, |j| format!("c{j}")).unwrap();
            for (j, g) in got.into_iter().enumerate() {
                assert!(
                    same_bits(&Ok(g), &Ok(reference(&cols[j]))),
                    "{d:?}: {k} columns, column {j}"
                );
            }
        }
        assert!(same_bits(&d.apply(&cols[3]), &Ok(reference(&cols[3]))));
    }
}

#[test]
fn row_major_parallel_decimation_equals_column_major() {
    let x = x_ref();
    let n = 500;
    let y = &x[..n];
    for d in [
        Decimation::butterworth(4, 40.0, 1000.0, 5, FilterForm::Sos).unwrap(),
        Decimation::butterworth(4, 40.0, 1000.0, 5, FilterForm::Ba).unwrap(),
        Decimation::matlab(10).unwrap(),
        Decimation::matlab(1).unwrap(),
    ] {
        for ncols in 0..=7 {
            let colmajor: Vec<f64> = (0..ncols)
                .flat_map(|j| (0..n).map(move |i| x[(i * (j + 1) + 3 * j) % x.len()] * (j as f64 + 0.5)))
                .collect();
            let rowmajor: Vec<f64> = (0..n)
                .flat_map(|i| (0..ncols).map(move |j| (i, j)))
                .map(|(i, j)| colmajor[j * n + i])
                .collect();
            let (yc, wc) = d.apply_parallel(y, &colmajor, ncols).unwrap();
            let (yr, wr) = d.apply_parallel_rows(y, &rowmajor, ncols).unwrap();
            assert!(same_bits(&Ok(yr), &Ok(yc)), "{d:?} {ncols}");
            assert!(same_bits(&Ok(wr), &Ok(wc)), "{d:?} {ncols}");
            if ncols >= 3 {
                // the same errors: the first column (in column order) with a non-finite value
                let (mut c2, mut r2) = (colmajor.clone(), rowmajor.clone());
                for (i, j) in [(40, 2), (9, 1)] {
                    c2[j * n + i] = f64::INFINITY;
                    r2[i * ncols + j] = f64::INFINITY;
                }
                let ec = msg(d.apply_parallel(y, &c2, ncols).unwrap_err());
                let er = msg(d.apply_parallel_rows(y, &r2, ncols).unwrap_err());
                assert_eq!(ec, er);
                assert!(
                    ec.contains("w column 1 has a non-finite value at index 9 (inf)"),
                    "{ec}"
                );
                let mut ybad = y.to_vec();
                ybad[3] = f64::NAN;
                assert_eq!(
                    msg(d.apply_parallel(&ybad, &c2, ncols).unwrap_err()),
                    msg(d.apply_parallel_rows(&ybad, &r2, ncols).unwrap_err())
                );
            }
        }
    }
    let d = Decimation::matlab(10).unwrap();
    let m = msg(d.apply_parallel_rows(&y[..20], &[0.0; 40], 2).unwrap_err());
    assert!(m.contains("too short"), "{m}");
    let m = msg(d.apply_parallel_rows(y, &[0.0; 999], 2).unwrap_err());
    assert!(m.contains("row-major") && m.contains("999"), "{m}");
}

#[test]
fn columns_of_local_support_equal_the_reference_above_the_subnormals() {
    // a pulse, then zeros: the filter's state decays through subnormal numbers, which the
    // passes flush to zero (x86-64) instead of computing at their cost; the outputs change by
    // a few smallest normal numbers at most, so every output above 1e-250 is the same, bit
    // for bit
    let n = 12_000;
    let cols: Vec<Vec<f64>> = (0..5)
        .map(|j| {
            (0..n)
                .map(|i| {
                    if (300 * j..300 * j + 200).contains(&i) {
                        1.0 + 0.1 * j as f64
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let d = Decimation::butterworth(4, 40.0, 1000.0, 10, FilterForm::Sos).unwrap();
    let Prepared::Sos { sos, zi } = &d.prepared else {
        panic!("an sos decimation")
    };
    let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
    let got = d.apply_columns(&refs, |j| format!("c{j}")).unwrap();
    let mut subnormal = 0;
    for (j, g) in got.iter().enumerate() {
        let full = sosfiltfilt_core(sos, zi, &cols[j], d.padlen());
        subnormal += full
            .iter()
            .filter(|v| **v != 0.0 && v.abs() < f64::MIN_POSITIVE)
            .count();
        let want: Vec<f64> = full
            .iter()
            .skip(d.start_index(n))
            .step_by(d.factor())
            .copied()
            .collect();
        assert_eq!(g.len(), want.len());
        for (i, (a, b)) in g.iter().zip(&want).enumerate() {
            if b.abs() >= 1e-250 {
                assert_eq!(a.to_bits(), b.to_bits(), "column {j}, row {i}: {a} against {b}");
            } else {
                assert!((a - b).abs() < 1e-300, "column {j}, row {i}: {a} against {b}");
            }
        }
    }
    // the case is one: the reference passes through subnormal numbers
    assert!(subnormal > 0);
    #[cfg(target_arch = "x86_64")]
    {
        // the thread's floating-point mode is back: a subnormal product is not flushed
        let tiny = std::hint::black_box(f64::MIN_POSITIVE);
        assert!(std::hint::black_box(tiny * 0.5) > 0.0);
    }
}
