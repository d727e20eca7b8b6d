//! Simulation throughput of both models on an EMPS-length reference (24,841 samples at 1 kHz),
//! one core. Fixed-step cost does not depend on the trajectory's shape, so a synthetic
//! EMPS-like reference (bang-bang acceleration of 0.83 m/s², speed plateaus at 0.042, 0.083
//! and 0.125 m/s, strokes within 0..0.246 m) stands in for the recorded one.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use didim_core::model::{flexible, rigid, DEFAULT_COULOMB_EPS};
use didim_core::{simulate, Controller, SimOptions};
use std::hint::black_box;

pub const EMPS_SAMPLES: usize = 24_841;

/// EMPS-like reference: back-and-forth moves with trapezoidal velocity profiles.
pub fn emps_like_reference(n: usize, dt: f64) -> Vec<f64> {
    let acc = 0.83;
    let mut moves = [0.125, -0.083, 0.042, -0.125, 0.083, -0.042].iter().cycle();
    let (mut q, mut v, mut target_v) = (0.0f64, 0.0f64, *moves.next().unwrap());
    let mut hold = 0usize;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        out.push(q);
        if hold > 0 {
            hold -= 1;
        } else {
            let dv = (target_v - v).clamp(-acc * dt, acc * dt);
            v += dv;
            if (q > 0.2 && target_v > 0.0) || (q < 0.01 && target_v < 0.0) {
                target_v = 0.0;
            }
            if target_v == 0.0 && v.abs() < 1e-12 {
                v = 0.0;
                hold = 300;
                target_v = *moves.next().unwrap();
                if (q > 0.1) == (target_v > 0.0) {
                    target_v = -target_v;
                }
            }
        }
        q += v * dt;
    }
    out
}

fn bench_simulation(c: &mut Criterion) {
    let dt = 1e-3;
    let qr = emps_like_reference(EMPS_SAMPLES, dt);
    let opts = SimOptions {
        quantization: 5e-8,
        ..SimOptions::new(dt)
    };
    let mut g = c.benchmark_group("simulate_emps_24841");
    g.throughput(Throughput::Elements(EMPS_SAMPLES as u64));
    g.sample_size(20);
    let r = rigid(true, DEFAULT_COULOMB_EPS).unwrap();
    let chi_r = [95.1089, 203.5034, 20.3935, -3.1648];
    g.bench_function("rigid_rk4_10substeps", |b| {
        b.iter(|| {
            simulate(
                &r,
                black_box(&chi_r),
                &Controller::EMPS,
                black_box(&qr),
                None,
                &opts,
            )
            .unwrap()
        })
    });
    let f = flexible(DEFAULT_COULOMB_EPS).unwrap();
    let chi_f = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5];
    g.bench_function("flexible_rk4_10substeps", |b| {
        b.iter(|| {
            simulate(
                &f,
                black_box(&chi_f),
                &Controller::EMPS,
                black_box(&qr),
                None,
                &opts,
            )
            .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench_simulation);
criterion_main!(benches);
