//! Profiling harness (not a benchmark): simulates an axis on a reference read from a raw little-endian f64
//! file many times and prints the step statistics, for `perf record`.
//! `cargo run --release --example profile_sim -- qr.bin 5e-8 200 [rk4]`
//!
//! Environment: `DIDIM_CHI="M1,Fv1,Fc1,M2,Fv2,Fc2,K12[,OF]"` (or the rigid model's `M,Fv,Fc[,OF]`),
//! `DIDIM_MODEL=rigid|flexible`, `DIDIM_OFFSET=1`, `DIDIM_EPS` (the algebraic law's ε, m/s),
//! `DIDIM_LAG` (force lag, s), `DIDIM_TOL`.
use didim_core::model::{flexible_with, rigid, DEFAULT_COULOMB_EPS};
use didim_core::sim::{simulate_with_stats, Integrator};
use didim_core::{Controller, SimOptions};
use std::time::Instant;

fn env<T: std::str::FromStr>(name: &str) -> Option<T> {
    std::env::var(name).ok().map(|s| s.parse().ok().expect(name))
}

/// Writes the force to the file `DIDIM_DUMP` names (raw little-endian f64), if any.
fn dump(force: &[f64]) {
    if let Ok(path) = std::env::var("DIDIM_DUMP") {
        let bytes: Vec<u8> = force.iter().flat_map(|x| x.to_le_bytes()).collect();
        std::fs::write(path, bytes).unwrap();
    }
}

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
    if let Some(t) = env("DIDIM_TOL") {
        opts.tol = t;
    }
    if let Some(lag) = env("DIDIM_LAG") {
        opts.force_lag = lag;
    }
    let eps = env("DIDIM_EPS").unwrap_or(DEFAULT_COULOMB_EPS);
    let offset = env::<u8>("DIDIM_OFFSET").unwrap_or(0) == 1;
    let chi = |default: &[f64]| -> Vec<f64> {
        std::env::var("DIDIM_CHI").map_or_else(
            |_| default.to_vec(),
            |s| s.split(',').map(|x| x.parse().unwrap()).collect(),
        )
    };
    let t0 = Instant::now();
    let mut stats = None;
    if std::env::var("DIDIM_MODEL").as_deref() == Ok("rigid") {
        let model = rigid(offset, eps).unwrap();
        let chi = chi(&[95.0, 200.0, 20.0, 0.0][..3 + offset as usize]);
        for _ in 0..reps {
            let (o, s) = simulate_with_stats(&model, &chi, &Controller::EMPS, &qr, None, &opts).unwrap();
            stats = Some(s);
            dump(&o.force);
        }
    } else {
        let model = flexible_with(offset, eps).unwrap();
        let chi = chi(&[68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5, 0.0][..7 + offset as usize]);
        for _ in 0..reps {
            let (o, s) = simulate_with_stats(&model, &chi, &Controller::EMPS, &qr, None, &opts).unwrap();
            stats = Some(s);
            dump(&o.force);
        }
    }
    let per = t0.elapsed().as_secs_f64() / reps as f64;
    println!(
        "{} samples: {:.3} ms per simulation, {:?}",
        qr.len(),
        1e3 * per,
        stats.unwrap()
    );
}
