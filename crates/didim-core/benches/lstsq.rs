//! QR least squares with covariance (eqs. (11)-(15)) on the size of a DIDIM system: the
//! flexible model's two rows of an EMPS-length record decimated by 6 (2 × 4,141 rows,
//! 7 columns), the rigid model's record decimated by 10 (2,485 rows, 4 columns), and a 7-joint
//! arm's (7 × 1,500 rows, 63 columns: base parameters, rotors, friction, offsets).

use criterion::{criterion_group, criterion_main, Criterion};
use didim_core::lstsq::{lstsq, LstsqOptions};
use std::hint::black_box;

fn system(rows: usize, cols: usize) -> (Vec<f64>, Vec<f64>) {
    let w: Vec<f64> = (0..cols)
        .flat_map(|j| (0..rows).map(move |i| ((i * (j + 3)) as f64 * 0.013).sin() + 0.1 * j as f64))
        .collect();
    let y: Vec<f64> = (0..rows)
        .map(|i| (0..cols).map(|j| w[j * rows + i] * (j + 1) as f64).sum::<f64>() + (i as f64).cos() * 1e-2)
        .collect();
    (w, y)
}

fn bench_lstsq(c: &mut Criterion) {
    let mut g = c.benchmark_group("lstsq");
    g.sample_size(30);
    for (name, rows, cols) in [
        ("flexible_8282x7", 8282, 7),
        ("rigid_2485x4", 2485, 4),
        ("robot_10500x63", 10500, 63),
    ] {
        let (w, y) = system(rows, cols);
        let opts = LstsqOptions::default();
        g.bench_function(name, |b| {
            b.iter(|| lstsq(black_box(&w), rows, cols, black_box(&y), &opts).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench_lstsq);
criterion_main!(benches);
