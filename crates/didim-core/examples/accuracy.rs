//! Scratch experiment: accuracy and speed of the integrators on the EMPS reference.
use didim_core::model::{flexible, rigid, DEFAULT_COULOMB_EPS};
use didim_core::sim::{simulate_sensitivity, simulate_with_stats, Integrator, SimOptions};
use didim_core::Controller;
use std::time::Instant;

fn rel(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt();
    let den: f64 = b.iter().map(|y| y * y).sum::<f64>().sqrt();
    num / den
}
fn maxabs(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

fn main() {
    let qr: Vec<f64> = std::fs::read_to_string("/tmp/emps_qr.txt")
        .unwrap()
        .lines()
        .map(|l| l.trim().parse().unwrap())
        .collect();
    let args: Vec<String> = std::env::args().collect();
    let quant: f64 = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(0.0);
    let tol: f64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(1e-9);
    let dt = 1e-3;
    let eps: f64 = args
        .get(3)
        .map(|s| s.parse().unwrap())
        .unwrap_or(DEFAULT_COULOMB_EPS);
    let f = flexible(eps).unwrap();
    let chi = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5];
    let base = SimOptions {
        quantization: quant,
        ..SimOptions::new(dt)
    };
    let rk = |s: usize| SimOptions {
        integrator: Integrator::Rk4,
        substeps: s,
        ..base
    };
    let t = Instant::now();
    let (reference, _) = simulate_with_stats(&f, &chi, &Controller::EMPS, &qr, None, &rk(100)).unwrap();
    println!("ref rk4x100 {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    for s in [10, 20, 1000] {
        let t = Instant::now();
        let (o, _) = simulate_with_stats(&f, &chi, &Controller::EMPS, &qr, None, &rk(s)).unwrap();
        let el = t.elapsed().as_secs_f64() * 1e3;
        println!(
            "rk4x{s}: {el:.1} ms force rel {:.3e} q1 max {:.3e} q12 max {:.3e}",
            rel(&o.force, &reference.force),
            maxabs(&o.q[0], &reference.q[0]),
            maxabs(&o.q[1], &reference.q[1])
        );
    }
    for tol in [tol * 100.0, tol * 10.0, tol, tol / 10.0] {
        let o = SimOptions { tol, ..base };
        let mut best = f64::INFINITY;
        let mut res = None;
        for _ in 0..5 {
            let t = Instant::now();
            let r = simulate_with_stats(&f, &chi, &Controller::EMPS, &qr, None, &o).unwrap();
            best = best.min(t.elapsed().as_secs_f64() * 1e3);
            res = Some(r);
        }
        let (o, st) = res.unwrap();
        println!("exp tol {tol:e}: {best:.2} ms steps {} rejected {} implicit {} force rel {:.3e} q1 max {:.3e} q12 max {:.3e}", st.steps, st.rejected, st.implicit, rel(&o.force, &reference.force), maxabs(&o.q[0], &reference.q[0]), maxabs(&o.q[1], &reference.q[1]));
    }
    let r = rigid(true, eps).unwrap();
    let chir = [95.1089, 203.5034, 20.3935, -3.1648];
    let ropt = |s| SimOptions {
        integrator: Integrator::Rk4,
        substeps: s,
        ..base
    };
    let (rref, _) = simulate_with_stats(&r, &chir, &Controller::EMPS, &qr, None, &ropt(100)).unwrap();
    let (r10, _) = simulate_with_stats(&r, &chir, &Controller::EMPS, &qr, None, &ropt(10)).unwrap();
    println!("rigid rk4x10 force rel {:.3e}", rel(&r10.force, &rref.force));
    let t = Instant::now();
    let (re, st) = simulate_with_stats(&r, &chir, &Controller::EMPS, &qr, None, &base).unwrap();
    println!(
        "rigid exp {:.2} ms steps {} rej {} force rel {:.3e}",
        t.elapsed().as_secs_f64() * 1e3,
        st.steps,
        st.rejected,
        rel(&re.force, &rref.force)
    );
    for integ in [Integrator::Exponential, Integrator::Rk4] {
        let o = SimOptions {
            integrator: integ,
            ..base
        };
        let t = Instant::now();
        let _ = simulate_sensitivity(&f, &chi, &Controller::EMPS, &qr, None, &o).unwrap();
        println!(
            "sensitivity flexible {integ:?}: {:.2} ms",
            t.elapsed().as_secs_f64() * 1e3
        );
    }
}
