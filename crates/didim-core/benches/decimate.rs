//! Decimation of an EMPS-length record (24,841 samples), one core (`RAYON_NUM_THREADS=1`
//! for the one-core figure): one signal, and Y with a 7-column W (the flexible regressor's
//! width), with the paper's 60 Hz Butterworth (order 4, sos, factor 6) and with MATLAB's
//! `decimate` by 10 (Chebyshev I of order 8, ba).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use didim_core::filter::{Decimation, FilterForm};
use std::hint::black_box;

mod common;
use common::*;

fn bench_decimation(c: &mut Criterion) {
    let n = EMPS_SAMPLES;
    let y: Vec<f64> = emps_like_reference(n, 1e-3)
        .iter()
        .enumerate()
        .map(|(k, q)| 1e3 * q + (k as f64 * 0.37).sin())
        .collect();
    let w: Vec<f64> = (0..7)
        .flat_map(|j| y.iter().map(move |v| v * (1.0 + j as f64) + j as f64))
        .collect();
    let mut g = c.benchmark_group("decimate_emps_24841");
    g.throughput(Throughput::Elements(n as u64));
    g.sample_size(30);
    for (name, d) in [
        (
            "butter4_60Hz_sos_r6",
            Decimation::butterworth(4, 60.0, 1000.0, 6, FilterForm::Sos).unwrap(),
        ),
        ("matlab_r10", Decimation::matlab(10).unwrap()),
    ] {
        g.bench_function(format!("{name}/y"), |b| {
            b.iter(|| d.apply(black_box(&y)).unwrap())
        });
        g.bench_function(format!("{name}/y_and_7_columns"), |b| {
            b.iter(|| d.apply_parallel(black_box(&y), black_box(&w), 7).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench_decimation);
criterion_main!(benches);
