//! Decimation of an EMPS-length record (24,841 samples), one core (`RAYON_NUM_THREADS=1`
//! for the one-core figure): one signal, and Y with a 7-column W (the flexible regressor's
//! width), with the paper's 60 Hz Butterworth (order 4, sos, factor 6) and with MATLAB's
//! `decimate` by 10 (Chebyshev I of order 8, ba). Then the robot DIDIM's case: a UR5 record
//! (20,001 samples) decimated by 80 after a 5 Hz Butterworth (order 4, sos), one column
//! alone and groups of columns as the inverse model's rows ask for them.

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

fn bench_robot_decimation(c: &mut Criterion) {
    let n = 20_001;
    let y: Vec<f64> = emps_like_reference(n, 1e-3)
        .iter()
        .enumerate()
        .map(|(k, q)| 1e3 * q + (k as f64 * 0.37).sin())
        .collect();
    let cols: Vec<Vec<f64>> = (0..38)
        .map(|j| y.iter().map(|v| v * (1.0 + j as f64) + j as f64).collect())
        .collect();
    let d = Decimation::butterworth(4, 5.0, 1000.0, 80, FilterForm::Sos).unwrap();
    let mut g = c.benchmark_group("decimate_ur5_20001");
    g.sample_size(30);
    g.bench_function("butter4_5Hz_sos_r80/apply_1", |b| {
        b.iter(|| d.apply(black_box(&y)).unwrap())
    });
    for k in [1, 4, 12, 38] {
        let refs: Vec<&[f64]> = cols[..k].iter().map(Vec::as_slice).collect();
        g.throughput(Throughput::Elements((n * k) as u64));
        g.bench_function(format!("butter4_5Hz_sos_r80/columns_{k}"), |b| {
            b.iter(|| d.apply_columns(black_box(&refs), |j| format!("c{j}")).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench_decimation, bench_robot_decimation);
criterion_main!(benches);
