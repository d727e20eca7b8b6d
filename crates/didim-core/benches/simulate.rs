//! Simulation throughput of both models with both integrators on an EMPS-length reference
//! (24,841 samples at 1 kHz), one core, and the accuracy of each against a reference RK4
//! integration with a ten times smaller step than the default (100 substeps, 10 µs), printed
//! before the timings. Fixed-step cost does not depend on the trajectory's shape; the
//! exponential integrator's does a little (it halves steps where the Coulomb sign bends), so
//! a synthetic EMPS-like reference (bang-bang acceleration of 0.83 m/s², speed plateaus at
//! 0.042, 0.083 and 0.125 m/s, strokes within 0..0.246 m, rests) stands in for the recorded one.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use didim_core::model::{flexible, rigid, Model, DEFAULT_COULOMB_EPS};
use didim_core::sim::{simulate_sensitivity, simulate_with_stats, Integrator};
use didim_core::{simulate, Controller, SimOptions};
use std::hint::black_box;

mod common;
use common::*;

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt();
    num / b.iter().map(|y| y * y).sum::<f64>().sqrt()
}

fn max_err(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

/// Prints the accuracy of both integrators against RK4 with 100 substeps (no quantizer: a
/// quantized loop amplifies any difference into whole encoder counts).
fn report_accuracy<const N: usize>(name: &str, model: &Model<N>, chi: &[f64], qr: &[f64], dt: f64) {
    let reference = simulate(
        model,
        chi,
        &Controller::EMPS,
        qr,
        None,
        &SimOptions {
            integrator: Integrator::Rk4,
            substeps: 100,
            ..SimOptions::new(dt)
        },
    )
    .unwrap();
    for (label, opts) in [
        ("exponential", SimOptions::new(dt)),
        (
            "rk4_10substeps",
            SimOptions {
                integrator: Integrator::Rk4,
                ..SimOptions::new(dt)
            },
        ),
    ] {
        let (o, st) = simulate_with_stats(model, chi, &Controller::EMPS, qr, None, &opts).unwrap();
        println!(
            "accuracy {name}/{label}: force ‖Δ‖/‖ref‖ = {:.2e}, max |Δforce| = {:.2e} N, max |Δq| = {:.2e} m \
             (vs RK4 x100 substeps; {} steps, {} halved)",
            rel_err(&o.force, &reference.force),
            max_err(&o.force, &reference.force),
            (0..N).map(|d| max_err(&o.q[d], &reference.q[d])).fold(0.0, f64::max),
            st.steps,
            st.rejected
        );
    }
}

fn bench_simulation(c: &mut Criterion) {
    let dt = 1e-3;
    let qr = emps_like_reference(EMPS_SAMPLES, dt);
    let r = rigid(true, DEFAULT_COULOMB_EPS).unwrap();
    let f = flexible(DEFAULT_COULOMB_EPS).unwrap();
    report_accuracy("rigid", &r, &RIGID, &qr, dt);
    report_accuracy("flexible", &f, &FLEXIBLE, &qr, dt);

    let exp = SimOptions::new(dt);
    let rk4 = SimOptions {
        integrator: Integrator::Rk4,
        ..exp
    };
    let quantized = SimOptions {
        quantization: 5e-8,
        ..exp
    };
    let mut g = c.benchmark_group("simulate_emps_24841");
    g.throughput(Throughput::Elements(EMPS_SAMPLES as u64));
    g.sample_size(20);
    for (name, opts) in [
        ("exponential", exp),
        ("rk4_10substeps", rk4),
        ("exponential_quantized", quantized),
    ] {
        g.bench_function(format!("rigid_{name}"), |b| {
            b.iter(|| {
                simulate(
                    &r,
                    black_box(&RIGID),
                    &Controller::EMPS,
                    black_box(&qr),
                    None,
                    &opts,
                )
                .unwrap()
            })
        });
        g.bench_function(format!("flexible_{name}"), |b| {
            b.iter(|| {
                simulate(
                    &f,
                    black_box(&FLEXIBLE),
                    &Controller::EMPS,
                    black_box(&qr),
                    None,
                    &opts,
                )
                .unwrap()
            })
        });
    }
    g.finish();

    let mut g = c.benchmark_group("sensitivity_emps_24841");
    g.throughput(Throughput::Elements(EMPS_SAMPLES as u64));
    g.sample_size(10);
    for (name, opts) in [("exponential", exp), ("rk4_10substeps", rk4)] {
        g.bench_function(format!("flexible_{name}"), |b| {
            b.iter(|| {
                simulate_sensitivity(
                    &f,
                    black_box(&FLEXIBLE),
                    &Controller::EMPS,
                    black_box(&qr),
                    None,
                    &opts,
                )
                .unwrap()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_simulation);
criterion_main!(benches);
