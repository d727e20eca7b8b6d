//! A robot's closed loop and dynamics, one core: a 6-joint arm (the UR5's kinematics, written
//! here so that the bench needs no file) under a PI velocity loop per joint, 20 s at 1 kHz with
//! RK4 on 4 substeps, its exact sensitivities to OE-LM's 78 parameters of a rigid arm (every
//! body's 10, each joint's rotor, Fv and Fc) over its first 2 s beside the plain loop over the same
//! 2 s, and the articulated-body algorithm, Newton–Euler and its regressor alone.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use didim_core::controller::TransferFunction;
use didim_core::model::FrictionLaw;
use didim_core::robot::{
    simulate_robot, simulate_robot_sensitivity, AbaWork, Directions, Drives, PhysLayout, Robot,
    RobotLoopOptions,
};
use std::hint::black_box;

const UR5: &str = r#"<robot name="ur5">
  <link name="base_link"/>
  <link name="shoulder_link"><inertial><mass value="3.7"/><origin xyz="0 0 0"/>
    <inertia ixx="0.0102675" ixy="0" ixz="0" iyy="0.0102675" iyz="0" izz="0.00666"/></inertial></link>
  <link name="upper_arm_link"><inertial><mass value="8.393"/><origin xyz="0 0 0.28"/>
    <inertia ixx="0.2269" ixy="0" ixz="0" iyy="0.2269" iyz="0" izz="0.0151"/></inertial></link>
  <link name="forearm_link"><inertial><mass value="2.275"/><origin xyz="0 0 0.25"/>
    <inertia ixx="0.0494" ixy="0" ixz="0" iyy="0.0494" iyz="0" izz="0.004095"/></inertial></link>
  <link name="wrist_1_link"><inertial><mass value="1.219"/><origin xyz="0 0 0"/>
    <inertia ixx="0.1111" ixy="0" ixz="0" iyy="0.1111" iyz="0" izz="0.21942"/></inertial></link>
  <link name="wrist_2_link"><inertial><mass value="1.219"/><origin xyz="0 0 0"/>
    <inertia ixx="0.1111" ixy="0" ixz="0" iyy="0.1111" iyz="0" izz="0.21942"/></inertial></link>
  <link name="wrist_3_link"><inertial><mass value="0.1879"/><origin xyz="0 0 0"/>
    <inertia ixx="0.0171" ixy="0" ixz="0" iyy="0.0171" iyz="0" izz="0.0338"/></inertial></link>
  <joint name="shoulder_pan_joint" type="revolute"><parent link="base_link"/><child link="shoulder_link"/>
    <origin xyz="0 0 0.089159"/><axis xyz="0 0 1"/><limit lower="-6.28" upper="6.28" effort="150" velocity="3.15"/></joint>
  <joint name="shoulder_lift_joint" type="revolute"><parent link="shoulder_link"/><child link="upper_arm_link"/>
    <origin xyz="0 0.13585 0" rpy="0 1.5707963267949 0"/><axis xyz="0 1 0"/><limit lower="-6.28" upper="6.28" effort="150" velocity="3.15"/></joint>
  <joint name="elbow_joint" type="revolute"><parent link="upper_arm_link"/><child link="forearm_link"/>
    <origin xyz="0 -0.1197 0.425"/><axis xyz="0 1 0"/><limit lower="-3.14" upper="3.14" effort="150" velocity="3.15"/></joint>
  <joint name="wrist_1_joint" type="revolute"><parent link="forearm_link"/><child link="wrist_1_link"/>
    <origin xyz="0 0 0.39225" rpy="0 1.5707963267949 0"/><axis xyz="0 1 0"/><limit lower="-6.28" upper="6.28" effort="28" velocity="3.2"/></joint>
  <joint name="wrist_2_joint" type="revolute"><parent link="wrist_1_link"/><child link="wrist_2_link"/>
    <origin xyz="0 0.093 0"/><axis xyz="0 0 1"/><limit lower="-6.28" upper="6.28" effort="28" velocity="3.2"/></joint>
  <joint name="wrist_3_joint" type="revolute"><parent link="wrist_2_link"/><child link="wrist_3_link"/>
    <origin xyz="0 0 0.09465"/><axis xyz="0 1 0"/><limit lower="-6.28" upper="6.28" effort="28" velocity="3.2"/></joint>
</robot>"#;

fn setup() -> (Robot, Drives, Vec<TransferFunction>, Vec<f64>) {
    let robot = Robot::from_urdf(UR5, None).unwrap();
    let n = robot.ndof();
    let drives = Drives {
        armature: vec![0.3, 0.1, 0.1, 0.03, 0.03, 0.03],
        viscous: vec![3.6, 1.3, 4.2, 0.4, 1.0, 0.8],
        coulomb: vec![9.5, 3.3, 3.0, 0.8, 1.7, 1.5],
        offset: vec![0.0; n],
        laws: vec![FrictionLaw::algebraic(0.015); n],
        stiffness: Vec::new(),
        damping: Vec::new(),
        backlash: Vec::new(),
        terms: Vec::new(),
        load_friction: Vec::new(),
    };
    // a PI velocity loop (kv·(1 + T/(ti (1 − z⁻¹)))) on kp·(qr − qm) − D(z) qm, as the data folder's
    let (dt, kp, ti) = (1e-3, 50.0, 0.0265);
    let ctl = [400.0, 490.0, 150.0, 43.0, 40.0, 8.0]
        .iter()
        .map(|&kv| {
            let pi = [kv * (1.0 + dt / ti), -kv];
            let b_r = [pi[0] * kp, pi[1] * kp];
            let b_y = [
                pi[0] * (kp + 1.0 / dt),
                pi[1] * (kp + 1.0 / dt) - pi[0] / dt,
                -pi[1] / dt,
            ];
            TransferFunction::new(&b_r, &[1.0, -1.0], &b_y, &[1.0, -1.0], f64::INFINITY, 1.0).unwrap()
        })
        .collect();
    let samples = 20_000;
    let mut qr = Vec::with_capacity(samples * n);
    for k in 0..samples {
        let t = k as f64 * dt;
        for j in 0..n {
            let w = 2.0 * std::f64::consts::PI * 0.1 * (j as f64 + 1.0);
            qr.push(0.5 * (w * t).sin() * (1.0 - (-t).exp()));
        }
    }
    (robot, drives, ctl, qr)
}

fn bench(c: &mut Criterion) {
    let (robot, drives, ctl, qr) = setup();
    let n = robot.ndof();
    let opts = RobotLoopOptions::new(
        1e-3,
        4,
        vec![2.0 * std::f64::consts::PI / 1_048_576.0; n],
        vec![0.0; n],
    );
    let mut g = c.benchmark_group("robot");
    g.sample_size(10);
    g.throughput(Throughput::Elements((qr.len() / n) as u64));
    g.bench_function("closed_loop_ur5_20s_rk4x4", |b| {
        b.iter(|| black_box(simulate_robot(&robot, &drives, &ctl, &qr, &opts).unwrap()))
    });
    // the sensitivities along the 78 directions against the plain loop, both without quantization
    let short = &qr[..2000 * n];
    let exact = RobotLoopOptions::new(1e-3, 4, vec![0.0; n], vec![0.0; n]);
    let lay = PhysLayout::of(n, &drives);
    let rows: Vec<usize> = (0..11 * n)
        .chain((0..n).map(|j| lay.viscous(j)))
        .chain((0..n).map(|j| lay.coulomb(j)))
        .collect();
    let p = rows.len();
    let mut physical = vec![0.0; lay.len() * p];
    for (c, &i) in rows.iter().enumerate() {
        physical[i * p + c] = 1.0;
    }
    let force0 = vec![0.0; n * p];
    let dirs = Directions {
        count: p,
        physical: &physical,
        force0: &force0,
    };
    g.throughput(Throughput::Elements(2000));
    g.bench_function("closed_loop_ur5_2s_rk4x4", |b| {
        b.iter(|| black_box(simulate_robot(&robot, &drives, &ctl, short, &exact).unwrap()))
    });
    g.bench_function("closed_loop_ur5_2s_rk4x4_sensitivities_78", |b| {
        b.iter(|| black_box(simulate_robot_sensitivity(&robot, &drives, &ctl, short, &exact, dirs).unwrap()))
    });
    g.finish();
    let (q, v, tau) = ([0.3, -1.0, 1.2, -1.6, -1.57, 0.2], [0.5; 6], [1.0; 6]);
    let mut ws = AbaWork::new(&robot);
    let mut out = [0.0; 6];
    c.bench_function("aba_ur5", |b| {
        b.iter(|| {
            robot
                .aba_into(
                    black_box(&q),
                    black_box(&v),
                    black_box(&tau),
                    Some(&drives.armature),
                    &mut ws,
                    &mut out,
                )
                .unwrap();
            black_box(out[0])
        })
    });
    c.bench_function("rnea_ur5", |b| {
        b.iter(|| black_box(robot.rnea(black_box(&q), &v, &tau).unwrap()))
    });
    c.bench_function("regressor_ur5", |b| {
        b.iter(|| black_box(robot.regressor(black_box(&q), &v, &tau).unwrap()))
    });
    c.bench_function("rnea_derivatives_ur5", |b| {
        b.iter(|| black_box(robot.rnea_derivatives(black_box(&q), &v, &tau).unwrap()))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
