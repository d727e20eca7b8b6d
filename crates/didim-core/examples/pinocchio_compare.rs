//! didim's half of `benches/pinocchio_compare.py` (not a test): the articulated-body algorithm,
//! Newton–Euler and the joint-torque regressor on the states the driver wrote, their results
//! written for the driver's check against Pinocchio's, then each timed in ns per call, the same
//! protocol as `benches/pinocchio/bench.cpp`.
//!
//! `cargo run --release --example pinocchio_compare -- URDF STATES OUT ROUNDS [JOINT,JOINT,...]`
//!
//! - STATES: `n K`, then K rows of q, K of v, K of a, K of τ (n values each), then the armature (n);
//! - OUT: per state, aba's n values, rnea's n, the regressor's n × 10n (row-major), one per line;
//! - prints `<algorithm> <best ns per call> <median ns per call>` for aba, rnea, regressor.
use didim_core::robot::{AbaWork, Robot, BODY_PARAMS};
use std::fmt::Write as _;
use std::hint::black_box;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 5 {
        eprintln!("usage: pinocchio_compare URDF STATES OUT ROUNDS [JOINT,JOINT,...]");
        std::process::exit(2);
    }
    let text = std::fs::read_to_string(&args[1]).expect("the URDF");
    let joints: Option<Vec<String>> = args.get(5).map(|s| s.split(',').map(String::from).collect());
    let robot = Robot::from_urdf(&text, joints.as_deref()).expect("a robot");
    let words = std::fs::read_to_string(&args[2]).expect("the states");
    let mut x = words.split_whitespace();
    let (n, k): (usize, usize) = (
        x.next().unwrap().parse().unwrap(),
        x.next().unwrap().parse().unwrap(),
    );
    assert_eq!(n, robot.ndof(), "the states are another robot's");
    let vals: Vec<f64> = x.map(|w| w.parse().unwrap()).collect();
    assert_eq!(vals.len(), 4 * k * n + n, "the states file is short or long");
    let rows = |b: usize| -> Vec<&[f64]> { (0..k).map(|s| &vals[(b * k + s) * n..][..n]).collect() };
    let (q, v, a, tau) = (rows(0), rows(1), rows(2), rows(3));
    let armature = &vals[4 * k * n..];
    let rounds: usize = args[4].parse().unwrap();

    let mut ws = AbaWork::new(&robot);
    let mut ddq = vec![0.0; n];
    let mut y = vec![0.0; n * BODY_PARAMS * n];

    // the results, for the driver's check against Pinocchio's
    let mut out = String::new();
    for s in 0..k {
        robot
            .aba_into(q[s], v[s], tau[s], Some(armature), &mut ws, &mut ddq)
            .unwrap();
        let t = robot.rnea(q[s], v[s], a[s]).unwrap();
        robot.regressor_into(q[s], v[s], a[s], &mut y).unwrap();
        for z in ddq.iter().chain(&t).chain(&y) {
            write!(out, "{z:e} ").unwrap();
        }
        out.push('\n');
    }
    std::fs::write(&args[3], out).expect("the results file");

    // each round times each algorithm once over the K states (ns per call), alternating them
    let mut sink = 0.0;
    let mut time = |f: &mut dyn FnMut(usize) -> f64| {
        let t0 = Instant::now();
        for s in 0..k {
            sink += f(black_box(s));
        }
        t0.elapsed().as_secs_f64() * 1e9 / k as f64
    };
    let (mut t_aba, mut t_rnea, mut t_reg) = (vec![], vec![], vec![]);
    for _ in 0..rounds {
        t_aba.push(time(&mut |s| {
            robot
                .aba_into(q[s], v[s], tau[s], Some(armature), &mut ws, &mut ddq)
                .unwrap();
            ddq[0]
        }));
        t_rnea.push(time(&mut |s| robot.rnea(q[s], v[s], a[s]).unwrap()[0]));
        t_reg.push(time(&mut |s| {
            robot.regressor_into(q[s], v[s], a[s], &mut y).unwrap();
            y[0]
        }));
    }
    for (name, mut t) in [("aba", t_aba), ("rnea", t_rnea), ("regressor", t_reg)] {
        t.sort_by(f64::total_cmp);
        println!("{name} {:.2} {:.2}", t[0], t[t.len() / 2]);
    }
    eprintln!("checksum {sink}");
}
