//! Shared inputs of the benches: an EMPS-length reference and the parameter sets.

#![allow(dead_code)]

pub const EMPS_SAMPLES: usize = 24_841;

/// The EMPS benchmark's rigid IDIM-LS values (M, Fv, Fc, OF).
pub const RIGID: [f64; 4] = [95.1089, 203.5034, 20.3935, -3.1648];
/// The paper's Table 3 (M1, Fv1, Fc1, M2, Fv2, Fc2, K12).
pub const FLEXIBLE: [f64; 7] = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5];

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
