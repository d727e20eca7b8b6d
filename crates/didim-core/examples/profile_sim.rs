//! Profiling harness (not a benchmark): simulates a flexible axis on a reference read from a raw little-endian f64
//! file many times and prints the step statistics, for `perf record`.
//! `cargo run --release --example profile_sim -- qr.bin 5e-8 200 [rk4]`
use didim_core::model::{flexible, DEFAULT_COULOMB_EPS};
use didim_core::sim::{simulate_with_stats, Integrator};
use didim_core::{Controller, SimOptions};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let bytes = std::fs::read(&args[1]).expect("reference file");
    let qr: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let quant: f64 = args.get(2).map_or(0.0, |s| s.parse().unwrap());
    let reps: usize = args.get(3).map_or(100, |s| s.parse().unwrap());
    let mut opts = SimOptions::new(1e-3);
    opts.quantization = quant;
    if args.get(4).map(String::as_str) == Some("rk4") {
        opts.integrator = Integrator::Rk4;
    }
    let model = flexible(DEFAULT_COULOMB_EPS).unwrap();
    // DIDIM_CHI="M1,Fv1,Fc1,M2,Fv2,Fc2,K12" and DIDIM_TOL override the defaults.
    let chi: Vec<f64> = std::env::var("DIDIM_CHI").map_or_else(
        |_| vec![68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5],
        |s| s.split(',').map(|x| x.parse().unwrap()).collect(),
    );
    if let Ok(t) = std::env::var("DIDIM_TOL") {
        opts.tol = t.parse().unwrap();
    }
    let t0 = Instant::now();
    let mut stats = None;
    for _ in 0..reps {
        let (_, s) = simulate_with_stats(&model, &chi, &Controller::EMPS, &qr, None, &opts).unwrap();
        stats = Some(s);
    }
    let per = t0.elapsed().as_secs_f64() / reps as f64;
    println!(
        "{} samples: {:.3} ms per simulation, {:?}",
        qr.len(),
        1e3 * per,
        stats.unwrap()
    );
}
