use super::*;
use crate::controller::TransferFunction;

/// A pendulum: one revolute joint about y, a point-like body of mass `m` at `l` along x with its own
/// inertia `iyy` about its centre.
fn pendulum(m: f64, l: f64, iyy: f64) -> Robot {
    let body = spatial::params_of(
        m,
        &Vector3::new(l, 0.0, 0.0),
        &Matrix3::from_diagonal(&Vector3::new(iyy, iyy, iyy)),
    );
    Robot::new(
        "pendulum",
        vec![Joint {
            name: "j".into(),
            kind: JointKind::Revolute,
            axis: Vector3::y(),
            placement_rotation: Matrix3::identity(),
            placement_translation: Vector3::zeros(),
            inertia: body,
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
            velocity_limit: f64::INFINITY,
            effort_limit: f64::INFINITY,
        }],
    )
    .unwrap()
}

const CHAIN: &str = r#"<robot name="chain">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0.02 0.3" rpy="0.1 0.2 0.3"/><mass value="3.0"/>
    <inertia ixx="0.05" ixy="0.001" ixz="0.002" iyy="0.04" iyz="0.003" izz="0.03"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.2 0.0 0.05" rpy="0 0.4 0"/><mass value="2.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.01"/></inertial></link>
  <link name="tool"><inertial><origin xyz="0 0 0.1"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0 0.1 0"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="100" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0.4" rpy="1.5707963 0 0"/>
    <axis xyz="0 0.6 0.8"/><limit lower="-2" upper="2" effort="50" velocity="2"/></joint>
  <joint name="fix" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0.3 0 0" rpy="0 0 0.5"/></joint>
  <joint name="j3" type="prismatic"><parent link="tool"/><child link="l3"/><origin xyz="0 0 0.2"/>
    <axis xyz="1 0 0"/><limit lower="-0.1" upper="0.5" effort="20" velocity="1"/></joint>
</robot>"#;

fn state(n: usize, seed: u64) -> Vec<f64> {
    // a small deterministic generator: values in [-1, 1)
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        })
        .collect()
}

#[test]
fn a_pendulum_has_its_textbook_dynamics() {
    let (m, l, iyy, g) = (2.0, 0.5, 0.01, STANDARD_GRAVITY);
    let r = pendulum(m, l, iyy);
    for &q in &[-1.0, 0.0, 0.3, 2.0] {
        // V = m g z = -m g l sin q: g(q) = dV/dq
        let grav = r.gravity_torque(&[q]).unwrap()[0];
        assert!((grav - (-m * g * l * q.cos())).abs() < 1e-12);
        let mm = r.mass_matrix(&[q]).unwrap()[(0, 0)];
        assert!((mm - (m * l * l + iyy)).abs() < 1e-12);
        let tau = r.rnea(&[q], &[0.7], &[1.3]).unwrap()[0];
        assert!((tau - ((m * l * l + iyy) * 1.3 - m * g * l * q.cos())).abs() < 1e-12);
    }
}

#[test]
fn the_regressor_times_the_parameters_is_newton_euler() {
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    assert_eq!(r.ndof(), 3);
    let pi = r.inertial_params();
    for seed in 0..20 {
        let (q, v, a) = (state(3, seed), state(3, seed + 100), state(3, seed + 200));
        let tau = r.rnea(&q, &v, &a).unwrap();
        let y = r.regressor(&q, &v, &a).unwrap();
        let scale = tau.iter().fold(1.0f64, |s, t| s.max(t.abs()));
        for i in 0..3 {
            let yt: f64 = (0..30).map(|k| y[i * 30 + k] * pi[k]).sum();
            assert!(
                (yt - tau[i]).abs() < 1e-12 * scale,
                "joint {i}: {yt} vs {}",
                tau[i]
            );
        }
    }
}

#[test]
fn the_regressor_of_many_states_keeps_the_columns_asked_for() {
    use RegressorLayout::{Rows, Series};
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    let (n, p) = (3, 30);
    let cols = [29, 0, 7, 7, 12];
    // fewer states than a block, and several blocks with a partial last one
    for rows in [7, 2 * 256 + 41] {
        let (q, v, a) = (state(n * rows, 1), state(n * rows, 2), state(n * rows, 3));
        let full = regressor_many(&r, &q, &v, &a, None, Rows).unwrap();
        assert_eq!(full.len(), rows * n * p);
        let some = regressor_many(&r, &q, &v, &a, Some(&cols), Rows).unwrap();
        assert_eq!(some.len(), rows * n * cols.len());
        for row in 0..rows {
            let one = r
                .regressor(&q[row * n..][..n], &v[row * n..][..n], &a[row * n..][..n])
                .unwrap();
            assert_eq!(&full[row * n * p..][..n * p], &one[..]);
            for j in 0..n {
                for (c, &col) in cols.iter().enumerate() {
                    assert_eq!(
                        some[(row * n + j) * cols.len() + c].to_bits(),
                        one[j * p + col].to_bits()
                    );
                }
            }
        }
        // series by series: the same values, joint j's column c at (j m + c) rows + row
        for (pick, m) in [(None, p), (Some(&cols[..]), cols.len())] {
            let series = regressor_many(&r, &q, &v, &a, pick, Series).unwrap();
            let rowwise = regressor_many(&r, &q, &v, &a, pick, Rows).unwrap();
            assert_eq!(series.len(), rows * n * m);
            for row in 0..rows {
                for jc in 0..n * m {
                    assert_eq!(
                        series[jc * rows + row].to_bits(),
                        rowwise[row * n * m + jc].to_bits()
                    );
                }
            }
        }
    }
    let (q, v, a) = (state(n * 7, 1), state(n * 7, 2), state(n * 7, 3));
    for layout in [Rows, Series] {
        assert!(regressor_many(&r, &q, &v, &a, Some(&[]), layout)
            .unwrap()
            .is_empty());
        let e = regressor_many(&r, &q, &v, &a, Some(&[3, 30]), layout).unwrap_err();
        assert!(format!("{e}").contains("column 30 is out of range"), "{e}");
        let e = regressor_many(&r, &q, &v, &a[1..], None, layout).unwrap_err();
        assert!(format!("{e}").contains("same number of rows"), "{e}");
    }
}

#[test]
fn forward_dynamics_inverts_inverse_dynamics() {
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    for seed in 0..20 {
        let (q, v, a) = (state(3, seed), state(3, seed + 100), state(3, seed + 200));
        let tau = r.rnea(&q, &v, &a).unwrap();
        let back = r.aba(&q, &v, &tau, None).unwrap();
        for i in 0..3 {
            assert!((back[i] - a[i]).abs() < 1e-10, "{back:?} vs {a:?}");
        }
        // the armature adds to the diagonal
        let ia = [0.1, 0.2, 0.3];
        let tau_ia: Vec<f64> = tau.iter().zip(&ia).zip(&a).map(|((t, i), x)| t + i * x).collect();
        let back = r.aba(&q, &v, &tau_ia, Some(&ia)).unwrap();
        let crba = r.forward_dynamics_crba(&q, &v, &tau_ia, Some(&ia)).unwrap();
        for i in 0..3 {
            assert!((back[i] - a[i]).abs() < 1e-10);
            assert!((crba[i] - a[i]).abs() < 1e-10);
        }
    }
}

/// Checks `jac` (∂f/∂q when `wrt_q`, else ∂f/∂q̇; n × n row-major) against central differences of
/// `f` at `(q, v)`, within `tol` (absolute).
fn assert_central_differences(
    f: impl Fn(&[f64], &[f64]) -> Vec<f64>,
    q: &[f64],
    v: &[f64],
    wrt_q: bool,
    jac: &[f64],
    tol: f64,
) {
    let n = q.len();
    let h = 1e-5;
    for j in 0..n {
        let shifted = |sign: f64| {
            let (mut q2, mut v2) = (q.to_vec(), v.to_vec());
            if wrt_q {
                q2[j] += sign * h;
            } else {
                v2[j] += sign * h;
            }
            f(&q2, &v2)
        };
        let (up, down) = (shifted(1.0), shifted(-1.0));
        for i in 0..n {
            let fd = (up[i] - down[i]) / (2.0 * h);
            assert!(
                (jac[i * n + j] - fd).abs() < tol,
                "d f_{i} / d {}_{j}: {} against {fd}",
                if wrt_q { "q" } else { "v" },
                jac[i * n + j]
            );
        }
    }
}

#[test]
fn rnea_derivatives_are_those_of_central_differences() {
    // the chain of revolute joints about skewed axes, a fixed joint and a prismatic one: each column
    // of ∂τ/∂q and ∂τ/∂q̇ against central differences of Newton–Euler (step h: their error is
    // O(h²)·τ‴ ≈ 1e-10 here, rounding ε·|τ|/h ≈ 1e-11), and τ bit for bit Newton–Euler's
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    let n = 3;
    for seed in 0..20 {
        let (q, v, a) = (state(n, seed), state(n, seed + 100), state(n, seed + 200));
        let d = r.rnea_derivatives(&q, &v, &a).unwrap();
        assert_eq!(d.tau, r.rnea(&q, &v, &a).unwrap());
        let scale = d.tau.iter().fold(1.0f64, |m, t| m.max(t.abs()));
        let f = |q: &[f64], v: &[f64]| r.rnea(q, v, &a).unwrap();
        assert_central_differences(f, &q, &v, true, &d.dtau_dq, 1e-7 * scale);
        assert_central_differences(f, &q, &v, false, &d.dtau_dv, 1e-7 * scale);
        // ∂τ/∂q̇ at rest is zero: the speeds enter the torques through products of two of them
        let zero = vec![0.0; n];
        let d0 = r.rnea_derivatives(&q, &zero, &a).unwrap();
        assert!(d0.dtau_dv.iter().all(|x| x.abs() < 1e-12 * scale));
    }
}

#[test]
fn aba_derivatives_are_those_of_central_differences() {
    // ∂q̈/∂q, ∂q̈/∂q̇ against central differences of the articulated-body algorithm, with an
    // armature; ∂q̈/∂τ is the inverse of the mass matrix with it (its product with M + A is I)
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    let n = 3;
    let ia = [0.1, 0.2, 0.3];
    for seed in 0..20 {
        let (q, v, tau) = (state(n, seed), state(n, seed + 100), state(n, seed + 200));
        let d = r.aba_derivatives(&q, &v, &tau, Some(&ia)).unwrap();
        assert_eq!(d.qdd, r.aba(&q, &v, &tau, Some(&ia)).unwrap());
        let scale = d.qdd.iter().fold(1.0f64, |m, t| m.max(t.abs()));
        let f = |q: &[f64], v: &[f64]| r.aba(q, v, &tau, Some(&ia)).unwrap();
        assert_central_differences(f, &q, &v, true, &d.dqdd_dq, 1e-7 * scale);
        assert_central_differences(f, &q, &v, false, &d.dqdd_dv, 1e-7 * scale);
        let mut m = r.mass_matrix(&q).unwrap();
        for (i, x) in ia.iter().enumerate() {
            m[(i, i)] += x;
        }
        for i in 0..n {
            for k in 0..n {
                let prod: f64 = (0..n).map(|j| d.dqdd_dtau[i * n + j] * m[(j, k)]).sum();
                assert!((prod - if i == k { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }
}

#[test]
fn fixed_joints_merge_and_picked_joints_lock_the_others() {
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    let names: Vec<&str> = r.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["j1", "j2", "j3"]);
    // l2 and the tool: 2.5 kg on joint 2
    assert!((r.joints[1].inertia[0] - 2.5).abs() < 1e-15);
    let two = Robot::from_urdf(CHAIN, Some(&["j1".to_string(), "j3".to_string()])).unwrap();
    assert_eq!(two.ndof(), 2);
    assert!((two.joints[0].inertia[0] - 5.5).abs() < 1e-15);
    // j2 locked at zero: the same torques as the full robot with q2 = v2 = a2 = 0
    let full = r
        .rnea(&[0.3, 0.0, 0.1], &[0.2, 0.0, -0.4], &[0.5, 0.0, 0.7])
        .unwrap();
    let locked = two.rnea(&[0.3, 0.1], &[0.2, -0.4], &[0.5, 0.7]).unwrap();
    assert!((full[0] - locked[0]).abs() < 1e-12 && (full[2] - locked[1]).abs() < 1e-12);
}

#[test]
fn bad_urdfs_and_inputs_are_refused_by_name() {
    let e = |r: Result<Robot>| r.unwrap_err().to_string();
    assert!(e(Robot::from_urdf("<robot", None)).contains("not a URDF"));
    assert!(e(Robot::from_urdf(CHAIN, Some(&["j9".to_string()]))).contains("no joint j9"));
    assert!(e(Robot::from_urdf(CHAIN, Some(&["fix".to_string()]))).contains("fixed"));
    assert!(e(Robot::from_urdf(
        CHAIN,
        Some(&["j3".to_string(), "j1".to_string()])
    ))
    .contains("chain's order"));
    let tree = CHAIN.replace(r#"<parent link="tool"/>"#, r#"<parent link="l1"/>"#);
    assert!(e(Robot::from_urdf(&tree, None)).contains("not a serial chain"));
    // a short branch at the end (a finger): the chain by default, the finger locked
    let finger = CHAIN.replace(
        "</robot>",
        r#"<link name="f"><inertial><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <joint name="finger" type="prismatic"><parent link="l2"/><child link="f"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.2"/></joint>
</robot>"#,
    );
    let r = Robot::from_urdf(&finger, None).unwrap();
    assert_eq!(
        r.joints.iter().map(|j| j.name.as_str()).collect::<Vec<_>>(),
        ["j1", "j2"]
    );
    assert_eq!(r.locked, ["j3", "finger"]);
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    assert!(r
        .rnea(&[0.0; 2], &[0.0; 3], &[0.0; 3])
        .unwrap_err()
        .to_string()
        .contains("3 joints"));
    assert!(r.gravity_torque(&[f64::NAN, 0.0, 0.0]).is_err());
    // other formats than URDF are named, not read as an empty robot
    let sdf = r#"<?xml version="1.0"?><!-- a Gazebo model --><sdf version="1.6"><model name="m"><link name="a"/></model></sdf>"#;
    assert!(e(Robot::from_urdf(sdf, None)).contains("an SDF model"));
    assert!(e(Robot::from_urdf("<mujoco model=\"m\"/>", None)).contains("root element is <mujoco>"));
    let xacro = CHAIN
        .replace(
            "<robot ",
            r#"<robot xmlns:xacro="http://www.ros.org/wiki/xacro" "#,
        )
        .replace("</robot>", r#"<xacro:property name="l" value="0.3"/></robot>"#);
    assert!(e(Robot::from_urdf(&xacro, None)).contains("a xacro file"));
    // a negative mass, an inertia with a negative principal moment
    assert!(e(Robot::from_urdf(
        &CHAIN.replace(r#"<mass value="3.0"/>"#, r#"<mass value="-3.0"/>"#),
        None
    ))
    .contains("link l1's <mass> is -3"));
    assert!(e(Robot::from_urdf(
        &CHAIN.replace(r#"ixx="0.05""#, r#"ixx="-0.05""#),
        None
    ))
    .contains("link l1's <inertia> has a negative principal moment"));
    // a tiny link whose rounded inertia is not quite positive (Tiago's antennas in example-robot-data) is read
    let tiny = CHAIN.replace(
        "</robot>",
        r#"<link name="antenna"><inertial><mass value="0.000001"/><inertia ixx="0.00000002371" ixy="0.00000006119" ixz="0.00000001179" iyy="0.00000002833" iyz="0.00000000774" izz="0.00000003849"/></inertial></link>
  <joint name="fix_antenna" type="fixed"><parent link="l1"/><child link="antenna"/></joint></robot>"#,
    );
    assert!(Robot::from_urdf(&tiny, None).is_ok());
    // a chain of 2,000 links (it overflowed the walk's stack: a segfault) is refused by its size
    let mut long = String::from(r#"<robot name="long"><link name="l0"/>"#);
    for i in 1..=2000 {
        long += &format!(
            r#"<joint name="j{i}" type="revolute"><parent link="l{}"/><child link="l{i}"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint><link name="l{i}"><inertial><mass value="0.1"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link>"#,
            i - 1
        );
    }
    long += "</robot>";
    assert!(e(Robot::from_urdf(&long, None)).contains("2001 links"));
    // the xacro namespace alone, as exported URDFs keep it, is a URDF
    let exported = CHAIN.replace(
        "<robot ",
        r#"<robot xmlns:xacro="http://www.ros.org/wiki/xacro" "#,
    );
    assert!(Robot::from_urdf(&exported, None).is_ok());
    // nor are xacro expressions left in comments (example-robot-data's xArm7 keeps `${prefix}` links commented out)
    let commented = CHAIN.replace("</robot>", r#"<!-- <link name="${prefix}eef"/> --></robot>"#);
    assert!(Robot::from_urdf(&commented, None).is_ok());
}

#[test]
fn a_urdf_that_is_not_one_tree_is_refused_naming_the_link_or_joint() {
    let e = |text: &str| Robot::from_urdf(text, None).unwrap_err().to_string();
    let add = |extra: &str| CHAIN.replace("</robot>", &format!("{extra}</robot>"));
    // a fixed joint back from l2 to l1: l1 hangs from two joints (the walk used to recurse forever)
    let back = add(r#"<joint name="back" type="fixed"><parent link="l2"/><child link="l1"/></joint>"#);
    let m = e(&back);
    assert!(
        m.contains("link l1 is the child of two joints (j1 and back)"),
        "{m}"
    );
    let own = add(r#"<joint name="own" type="fixed"><parent link="l2"/><child link="l2"/></joint>"#);
    assert!(e(&own).contains("joint own joins link l2 to itself"));
    // two links joined to each other only: a loop away from the root
    let island = add(r#"<link name="a"/><link name="b"/>
  <joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>
  <joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint>"#);
    assert!(e(&island).contains("links a, b form a loop"));
    assert!(
        e(&CHAIN.replace(r#"<child link="l3"/>"#, r#"<child link="l4"/>"#))
            .contains("joint j3's child link l4 is not defined")
    );
    assert!(e(&CHAIN.replace(r#"name="j2""#, r#"name="j1""#)).contains("joint j1 is defined twice"));
    assert!(
        e(&CHAIN.replace(r#"<link name="l3">"#, r#"<link name="l2">"#)).contains("link l2 is defined twice")
    );
    assert!(e(r#"<robot name="empty"></robot>"#).contains("defines no link"));
    assert!(
        e(&CHAIN.replace(r#"<origin xyz="0 0 0.2"/>"#, r#"<origin xyz="0 nan 0.2"/>"#))
            .contains("joint j3's <origin> holds NaN")
    );
    assert!(
        e(&CHAIN.replace(r#"<mass value="2.0"/>"#, r#"<mass value="inf"/>"#))
            .contains("link l2's <mass> holds inf")
    );
    // XML nested far deeper than a robot description: refused before the parser's recursion
    let deep = format!(
        "<robot name=\"d\">{}{}</robot>",
        "<a>".repeat(100_000),
        "</a>".repeat(100_000)
    );
    assert!(e(&deep).contains("nested 100001 elements deep"));
    assert_eq!(super::urdf::xml_depth(CHAIN), 3); // robot, link, inertial (the rest self-closing)
}

#[test]
fn each_unit_force_is_the_inertia_of_that_parameter_alone() {
    use super::spatial::{inertia_apply, unit_forces, Motion};
    use nalgebra::Vector3;
    for seed in 0..10 {
        let x = state(12, seed);
        let a = Motion::new(Vector3::new(x[0], x[1], x[2]), Vector3::new(x[3], x[4], x[5]));
        let v = Motion::new(Vector3::new(x[6], x[7], x[8]), Vector3::new(x[9], x[10], x[11]));
        let got = unit_forces(&a, &v);
        for (k, g) in got.iter().enumerate() {
            let mut e = [0.0; BODY_PARAMS];
            e[k] = 1.0;
            let want = inertia_apply(&e, &a) + v.cross_force(&inertia_apply(&e, &v));
            // both are a few products of the same entries, of order 1: rounding only
            assert!(
                (g.n - want.n).norm() + (g.f - want.f).norm() < 1e-14,
                "parameter {k}"
            );
        }
    }
}

/// A cart on a horizontal rail: one prismatic joint along x (gravity along −z does no work), a
/// point mass `m`.
fn cart(m: f64) -> Robot {
    let mut r = pendulum(m, 0.0, 0.0);
    r.joints[0].kind = JointKind::Prismatic;
    r.joints[0].axis = Vector3::x();
    r
}

/// The rigid axis's parameters as a one-joint robot's: mass, viscous and Coulomb friction, offset.
const AXIS: [f64; 4] = [95.1089, 203.5034, 20.3935, -3.1648];

fn cart_drives() -> Drives {
    Drives {
        armature: vec![0.0],
        viscous: vec![AXIS[1]],
        coulomb: vec![AXIS[2]],
        offset: vec![AXIS[3]],
        laws: vec![crate::model::FrictionLaw::algebraic(1e-4)],
        stiffness: Vec::new(),
        damping: Vec::new(),
        backlash: Vec::new(),
        terms: Vec::new(),
        load_friction: Vec::new(),
    }
}

/// The force that the recorded states answer: the inverse dynamics of the cart with its drive.
fn cart_idm(out: &RobotLoopOutput, k: usize) -> f64 {
    let sign = crate::model::FrictionLaw::algebraic(1e-4).sign(out.qd[k]);
    AXIS[0] * out.qdd[k] + AXIS[1] * out.qd[k] + AXIS[2] * sign + AXIS[3]
}

/// One axis's loop and a one-joint robot's are the same loop: the same commands (to 1e-7 of the
/// largest, `scale`) and positions (each pair: one axis's dof, the robot's signal) but for the
/// rounding of two plants' arithmetic.
fn assert_same_loop(axis_force: &[f64], arm_force: &[f64], positions: &[(&[f64], &[f64])], scale: f64) {
    for k in 0..axis_force.len() {
        assert!(
            (axis_force[k] - arm_force[k]).abs() < 1e-7 * scale,
            "sample {k}: {} vs {}",
            axis_force[k],
            arm_force[k]
        );
        for (i, (a, b)) in positions.iter().enumerate() {
            assert!((a[k] - b[k]).abs() < 1e-12, "position {i}, sample {k}");
        }
    }
}

#[test]
fn a_one_joint_robot_is_one_axis_under_the_same_drive_delay_and_force_lag() {
    use crate::model::rigid;
    use crate::sim::{applied_force, simulate, Integrator, SimOptions};
    use crate::Controller;
    let (dt, n, delay, lag) = (1e-3, 3000, 2, 1e-3);
    // from 0.1 m (the robot's controller works on departures from it, one axis's on positions)
    let qr: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * dt;
            0.1 + 0.1 * (1.0 - (2.0 * std::f64::consts::PI * t / (n as f64 * dt)).cos())
        })
        .collect();
    let law = Controller::EMPS.law(dt).unwrap();
    let axis_opts = SimOptions {
        integrator: Integrator::Rk4,
        substeps: 10,
        delay,
        force_lag: lag,
        ..SimOptions::new(dt)
    };
    let robot_opts = RobotLoopOptions {
        delay: vec![delay],
        force_lag: vec![lag],
        ..RobotLoopOptions::new(dt, 10, vec![0.0], vec![0.0])
    };
    let model = rigid(true, 1e-4).unwrap();
    let (r, drives) = (cart(AXIS[0]), cart_drives());
    let axis = simulate(&model, &AXIS, &Controller::EMPS, &qr, None, &axis_opts).unwrap();
    let arm = simulate_robot(&r, &drives, &[law], &qr, &robot_opts).unwrap();
    // the same loop: the same commands and states but for the rounding of two plants' arithmetic
    let scale = axis.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    assert!(scale > 50.0, "the move should need force: {scale}");
    assert_same_loop(&axis.force, &arm.force, &[(&axis.q[0], &arm.q)], scale);
    // and both plants receive the logged commands as `applied_force` replays them (the loop
    // from rest held 0 before the record, its first command here)
    assert_eq!(arm.force[0], 0.0);
    let want = applied_force(&arm.force, delay, lag, dt, arm.force[0]);
    let want_axis = applied_force(&axis.force, delay, lag, dt, 0.0);
    for k in 0..n {
        let got_axis = AXIS[0] * axis.qdd[0][k]
            + AXIS[1] * axis.qd[0][k]
            + AXIS[2] * crate::model::FrictionLaw::algebraic(1e-4).sign(axis.qd[0][k])
            + AXIS[3];
        assert!((cart_idm(&arm, k) - want[k]).abs() < 1e-9 * scale, "sample {k}");
        assert!((got_axis - want_axis[k]).abs() < 1e-9 * scale, "sample {k}");
    }
}

#[test]
fn a_joint_term_is_one_axis_term_on_a_one_joint_robot() {
    // a Stribeck hump, direction-dependent Coulomb friction and a force along the stroke: the
    // same basis functions on one axis's model and on the cart's joint give the same loop
    use crate::model::{rigid, Basis};
    use crate::sim::{simulate, Integrator, SimOptions};
    use crate::Controller;
    let (dt, n) = (1e-3, 3000);
    let qr: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * dt;
            0.1 + 0.1 * (1.0 - (2.0 * std::f64::consts::PI * t / (n as f64 * dt)).cos())
        })
        .collect();
    let terms = vec![
        (Basis::Stribeck { dof: 0, vs: 0.02 }, 12.0),
        (Basis::AbsCoulomb { dof: 0 }, 3.0),
        (
            Basis::Ripple {
                dof: 0,
                period: 0.05,
                phase: 0.3,
            },
            8.0,
        ),
    ];
    let model = rigid(true, 1e-4)
        .unwrap()
        .with_terms(
            terms
                .iter()
                .enumerate()
                .map(|(i, (b, _))| (format!("T{i}"), *b))
                .collect(),
        )
        .unwrap();
    let chi: Vec<f64> = AXIS.iter().copied().chain(terms.iter().map(|t| t.1)).collect();
    let axis_opts = SimOptions {
        integrator: Integrator::Rk4,
        substeps: 10,
        ..SimOptions::new(dt)
    };
    let mut drives = cart_drives();
    drives.terms = vec![terms.clone()];
    let r = cart(AXIS[0]);
    let law = Controller::EMPS.law(dt).unwrap();
    let axis = simulate(&model, &chi, &Controller::EMPS, &qr, None, &axis_opts).unwrap();
    let arm = simulate_robot(
        &r,
        &drives,
        &[law],
        &qr,
        &RobotLoopOptions::new(dt, 10, vec![0.0], vec![0.0]),
    )
    .unwrap();
    let scale = axis.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    assert_same_loop(&axis.force, &arm.force, &[(&axis.q[0], &arm.q)], scale);
    // the terms act: without them the loop is another
    let bare = simulate_robot(
        &r,
        &cart_drives(),
        &[law],
        &qr,
        &RobotLoopOptions::new(dt, 10, vec![0.0], vec![0.0]),
    )
    .unwrap();
    let moved = (0..n).fold(0.0f64, |m, k| m.max((bare.force[k] - arm.force[k]).abs()));
    assert!(moved > 1.0, "the terms should change the force: {moved}");
    // a coupling term has no place on one joint
    drives.terms = vec![vec![(Basis::Spring { a: 0, b: 1 }, 1.0)]];
    assert!(simulate_robot(
        &r,
        &drives,
        &[law],
        &qr,
        &RobotLoopOptions::new(dt, 10, vec![0.0], vec![0.0])
    )
    .is_err());
}

#[test]
fn a_robot_drive_holds_its_first_command_through_its_delay_and_lag() {
    // an external force from the first sample makes the first command non-zero: the robot's
    // drive applied it before the record, as `applied_force` with it held replays
    let (dt, n) = (1e-3, 800);
    let qr = vec![0.0; n];
    let u_ext: Vec<f64> = (0..n).map(|k| if k < 300 { 40.0 } else { -25.0 }).collect();
    let law = crate::Controller::EMPS.law(dt).unwrap();
    let (r, drives) = (cart(AXIS[0]), cart_drives());
    for (delay, lag) in [(0, 0.0), (3, 0.0), (0, 2e-3), (4, 1e-3)] {
        let opts = RobotLoopOptions {
            delay: vec![delay],
            force_lag: vec![lag],
            u_ext: u_ext.clone(),
            ..RobotLoopOptions::new(dt, 8, vec![0.0], vec![5.0])
        };
        let out = simulate_robot(&r, &drives, &[law], &qr, &opts).unwrap();
        assert!(
            (out.force[0] - 45.0).abs() < 1e-12,
            "force0 plus the external force: {}",
            out.force[0]
        );
        let want = crate::sim::applied_force(&out.force, delay, lag, dt, out.force[0]);
        for k in 0..n {
            assert!(
                (cart_idm(&out, k) - want[k]).abs() < 1e-9 * 50.0,
                "delay {delay}, lag {lag}, sample {k}: {} vs {}",
                cart_idm(&out, k),
                want[k]
            );
        }
    }
}

/// The paper's two masses (the motor side M1, Fv1, Fc1 and the load M2 on the cart, no load
/// friction, joined by K12: eqs. (2)-(4)) under the EMPS controller, following `cycles` cosine
/// moves of 0.1 m over 3 s, as one axis simulates them and as a cart with an elastic joint does
/// (with a dead zone of `gap` in K12 when given): one axis's output, the arm's, the arm's drives
/// and what its loop needs to run again.
#[allow(clippy::type_complexity)]
fn two_mass_loops(
    cycles: f64,
    gap: Option<f64>,
) -> (
    crate::sim::SimOutput,
    RobotLoopOutput,
    Drives,
    Vec<f64>,
    RobotLoopOptions,
) {
    use crate::model::{flexible, Basis};
    use crate::sim::{simulate, Integrator, SimOptions};
    use crate::Controller;
    let (m1, fv1, fc1, m2, k12) = (30.0, 150.0, 20.0, 65.0, 4.0e5);
    let (dt, n) = (1e-3, 3000);
    let qr: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * dt;
            0.1 * (1.0 - (2.0 * cycles * std::f64::consts::PI * t / (n as f64 * dt)).cos())
        })
        .collect();
    let axis_opts = SimOptions {
        integrator: Integrator::Rk4,
        substeps: 10,
        ..SimOptions::new(dt)
    };
    let mut model = flexible(1e-4).unwrap();
    if let Some(gap) = gap {
        model = model
            .with_basis("K12", Basis::Backlash { a: 0, b: 1, gap })
            .unwrap();
    }
    let axis = simulate(
        &model,
        &[m1, fv1, fc1, m2, 0.0, 0.0, k12],
        &Controller::EMPS,
        &qr,
        None,
        &axis_opts,
    )
    .unwrap();
    let drives = Drives {
        armature: vec![m1],
        viscous: vec![fv1],
        coulomb: vec![fc1],
        offset: vec![0.0],
        laws: vec![crate::model::FrictionLaw::algebraic(1e-4)],
        stiffness: vec![k12],
        damping: vec![0.0],
        backlash: gap.map(|g| vec![g]).unwrap_or_default(),
        terms: Vec::new(),
        load_friction: Vec::new(),
    };
    let law = Controller::EMPS.law(dt).unwrap();
    let opts = RobotLoopOptions::new(dt, 10, vec![0.0], vec![0.0]);
    let arm = simulate_robot(&cart(m2), &drives, &[law], &qr, &opts).unwrap();
    (axis, arm, drives, qr, opts)
}

#[test]
fn an_elastic_one_joint_robot_is_the_one_axis_two_mass_model() {
    let (axis, arm, _, _, _) = two_mass_loops(1.0, None);
    let scale = axis.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    assert!(scale > 50.0, "the move should need force: {scale}");
    // the load lags the motor by the spring's stretch: this is an elastic loop
    let stretch = (0..arm.q.len()).fold(0.0f64, |m, k| m.max((arm.theta[k] - arm.q[k]).abs()));
    assert!(stretch > 1e-5, "the spring should stretch: {stretch}");
    assert_same_loop(
        &axis.force,
        &arm.force,
        &[(&axis.q[0], &arm.theta), (&axis.q[1], &arm.q)],
        scale,
    );
}

#[test]
fn an_elastic_joint_with_backlash_is_the_one_axis_two_mass_model_with_backlash() {
    use crate::Controller;
    // as above, twice the moves, K12 replaced by one axis's spring with a dead zone of 0.4 mm (the
    // stretch of the move's force is about 0.05 mm: the load crosses the gap at each reversal)
    let gap = 4e-4;
    let (axis, arm, drives, qr, opts) = two_mass_loops(2.0, Some(gap));
    let scale = axis.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    // the load crosses the gap: the stretch exceeds half of it both ways
    let (lo, hi) = (0..arm.q.len()).fold((0.0f64, 0.0f64), |(l, h), k| {
        let x = arm.theta[k] - arm.q[k];
        (l.min(x), h.max(x))
    });
    assert!(
        hi > 0.5 * gap && lo < -0.5 * gap,
        "the load should cross the gap: {lo} .. {hi}"
    );
    assert_same_loop(
        &axis.force,
        &arm.force,
        &[(&axis.q[0], &arm.theta), (&axis.q[1], &arm.q)],
        scale,
    );
    // and the gap matters: without it, another loop
    let no_gap = Drives {
        backlash: Vec::new(),
        ..drives.clone()
    };
    let law = Controller::EMPS.law(opts.dt).unwrap();
    let other = simulate_robot(&cart(65.0), &no_gap, &[law], &qr, &opts).unwrap();
    let moved = (0..arm.q.len()).fold(0.0f64, |m, k| m.max((other.q[k] - arm.q[k]).abs()));
    assert!(moved > 0.25 * gap, "backlash should move the load: {moved}");
}

#[test]
fn backlash_on_a_rigid_joint_is_refused() {
    let mut drives = cart_drives();
    drives.backlash = vec![1e-3];
    let err = drives.validate(1).unwrap_err().to_string();
    assert!(err.contains("rigid") && err.contains("elastic"), "{err}");
}

#[test]
fn an_elastic_arm_at_rest_stays_at_rest_with_its_springs_holding_gravity() {
    // a pendulum whose joint is elastic, its controller holding gravity's torque from the start:
    // the link hangs where the spring holds it, and nothing moves
    let r = pendulum(2.0, 0.5, 0.01);
    let (q0, k) = (0.7, 3.0e3);
    // the link's rest: K (q0 − q) = g(q)
    let mut q = q0;
    for _ in 0..100 {
        q = q0 - r.rnea(&[q], &[0.0], &[0.0]).unwrap()[0] / k;
    }
    let g = r.rnea(&[q], &[0.0], &[0.0]).unwrap()[0];
    assert!(((q0 - q) * k).abs() > 1.0, "gravity should stretch the spring");
    let drives = Drives {
        armature: vec![0.05],
        viscous: vec![0.5],
        coulomb: vec![0.3],
        offset: vec![0.0],
        laws: vec![crate::model::FrictionLaw::algebraic(1e-3)],
        stiffness: vec![k],
        damping: vec![0.5],
        backlash: Vec::new(),
        terms: Vec::new(),
        load_friction: Vec::new(),
    };
    let law = crate::Controller::EMPS.law(1e-3).unwrap();
    let qr = vec![q0; 500];
    let opts = RobotLoopOptions::new(1e-3, 0, vec![0.0], vec![g]);
    let out = simulate_robot(&r, &drives, &[law], &qr, &opts).unwrap();
    for i in 0..qr.len() {
        assert!(
            (out.theta[i] - q0).abs() < 1e-12,
            "motor, sample {i}: {}",
            out.theta[i]
        );
        assert!(
            (out.q[i] - q).abs() < 1e-12,
            "link, sample {i}: {} vs {q}",
            out.q[i]
        );
        assert!((out.force[i] - g).abs() < 1e-9 * g.abs(), "force, sample {i}");
    }
}

#[test]
fn a_joints_load_dependent_friction_grows_with_the_torque_its_link_asks() {
    // a pendulum swinging under its controller, its friction μ s(v) |τ_L| with τ_L = M q̈ + g(q):
    // the recorded states answer the implicit inverse model (the friction a stage behind the
    // accelerations it slows, within RK4's error), and the friction changes the loop
    let r = pendulum(2.0, 0.5, 0.01);
    let (dt, n, mu) = (1e-3, 2000, 0.08);
    let qr: Vec<f64> = (0..n)
        .map(|k| 0.3 + 0.6 * (2.0 * std::f64::consts::PI * k as f64 * dt / (n as f64 * dt)).sin())
        .collect();
    let law = crate::Controller::EMPS.law(dt).unwrap();
    let mut drives = Drives {
        armature: vec![0.05],
        viscous: vec![0.5],
        coulomb: vec![0.3],
        offset: vec![0.0],
        laws: vec![crate::model::FrictionLaw::algebraic(1e-3)],
        stiffness: Vec::new(),
        damping: Vec::new(),
        backlash: Vec::new(),
        terms: Vec::new(),
        load_friction: vec![mu],
    };
    let g0 = r.rnea(&[qr[0]], &[0.0], &[0.0]).unwrap()[0];
    let opts = RobotLoopOptions::new(dt, 20, vec![0.0], vec![g0]);
    let out = simulate_robot(&r, &drives, &[law], &qr, &opts).unwrap();
    let applied = crate::sim::applied_force(&out.force, 0, 0.0, dt, out.force[0]);
    let scale = out.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    for k in 10..n {
        let (q, v, a) = (out.q[k], out.qd[k], out.qdd[k]);
        let link = r.rnea(&[q], &[v], &[a]).unwrap()[0];
        let s = drives.laws[0].sign(v);
        let idm = 0.05 * a + link + 0.5 * v + 0.3 * s + mu * s * link.abs();
        assert!(
            (idm - applied[k]).abs() < 1e-5 * scale,
            "sample {k}: {idm} vs {}",
            applied[k]
        );
    }
    drives.load_friction = Vec::new();
    let bare = simulate_robot(&r, &drives, &[law], &qr, &opts).unwrap();
    let moved = (0..n).fold(0.0f64, |m, k| m.max((bare.force[k] - out.force[k]).abs()));
    assert!(
        moved > 0.05 * scale * mu,
        "the load friction should change the force: {moved}"
    );
}

/// The chain of [`CHAIN`] in closed loop with every kind of physics the loop simulates: its second
/// joint elastic (spring, damping, backlash), load-dependent friction, a delay and a force lag, and
/// extra terms on each joint (a Stribeck hump, a ripple on the elastic joint's rotor, a profile
/// along the prismatic stroke).
fn loaded_chain() -> (Robot, Drives, Vec<TransferFunction>, Vec<f64>, RobotLoopOptions) {
    use crate::model::{Basis, FrictionLaw, LawShape};
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    let (dt, samples) = (1e-3, 700);
    let n = 3;
    let mut qr = vec![0.0; samples * n];
    for k in 0..samples {
        let t = k as f64 * dt / (samples as f64 * dt);
        let s = (std::f64::consts::PI * t).sin();
        qr[k * n] = 0.2 + 0.5 * s * s;
        qr[k * n + 1] = -0.3 + 0.4 * (2.0 * std::f64::consts::PI * t).sin();
        qr[k * n + 2] = 0.1 + 0.05 * s;
    }
    let drives = Drives {
        armature: vec![0.03, 0.2, 0.5],
        viscous: vec![0.4, 0.3, 5.0],
        coulomb: vec![0.5, 0.4, 2.0],
        offset: vec![0.1, -0.05, 0.3],
        laws: vec![
            FrictionLaw::algebraic(0.02),
            FrictionLaw {
                shape: LawShape::Tanh,
                eps: 0.03,
            },
            FrictionLaw {
                shape: LawShape::Exp,
                eps: 0.01,
            },
        ],
        stiffness: vec![f64::INFINITY, 400.0, f64::INFINITY],
        damping: vec![0.0, 0.4, 0.0],
        backlash: Vec::new(),
        terms: vec![
            vec![(Basis::Stribeck { dof: 0, vs: 0.05 }, 0.3)],
            vec![(
                Basis::CoulombRipple {
                    dof: 0,
                    period: 0.4,
                    phase: 0.3,
                },
                0.1,
            )],
            vec![(
                Basis::Spline {
                    dof: 0,
                    center: 0.12,
                    width: 0.05,
                    lo: 0.0,
                    hi: 0.0,
                },
                1.5,
            )],
        ],
        load_friction: vec![0.05, 0.0, 0.0],
    };
    let law = |kp: f64, kv: f64| {
        crate::Controller::EmpsCascade {
            kp,
            kv,
            gtau: 1.0,
            vsat: f64::INFINITY,
        }
        .law(dt)
        .unwrap()
    };
    let laws = vec![law(40.0, 60.0), law(20.0, 10.0), law(40.0, 200.0)];
    let g0 = r.rnea(&qr[..n], &[0.0; 3], &[0.0; 3]).unwrap();
    let force0: Vec<f64> = (0..n).map(|j| g0[j] + drives.offset[j]).collect();
    let opts = RobotLoopOptions {
        delay: vec![1, 0, 0],
        force_lag: vec![0.0, 0.0, 2e-3],
        ..RobotLoopOptions::new(dt, 6, vec![0.0; 3], force0)
    };
    (r, drives, laws, qr, opts)
}

/// The chain's robot and drives with physical parameter `i` ([`PhysLayout`]) moved by `h`.
fn moved(r: &Robot, d: &Drives, i: usize, h: f64) -> (Robot, Drives) {
    let n = r.ndof();
    let lay = PhysLayout::of(n, d);
    let (mut r, mut d) = (r.clone(), d.clone());
    if (n..11 * n).contains(&i) {
        let mut pi = r.inertial_params();
        pi[i - n] += h;
        r = r.with_inertial_params(&pi).unwrap();
    } else if i < n {
        d.armature[i] += h;
    } else if i >= lay.term(0) {
        let mut t = i - lay.term(0);
        for terms in d.terms.iter_mut() {
            if t < terms.len() {
                terms[t].1 += h;
                break;
            }
            t -= terms.len();
        }
    } else {
        let (group, j) = ((i - 11 * n) / n, (i - 11 * n) % n);
        let field = match group {
            0 => &mut d.viscous,
            1 => &mut d.coulomb,
            2 => &mut d.offset,
            3 => &mut d.stiffness,
            4 => &mut d.damping,
            5 => &mut d.backlash,
            6 => &mut d.load_friction,
            _ => {
                d.laws[j].eps += h;
                return (r, d);
            }
        };
        field[j] += h;
    }
    (r, d)
}

/// Checks the loop's sensitivities to each physical parameter it depends on and to each drive's
/// held first force against central differences of steps `hrel` of each parameter (of its body's
/// largest for a body's), within `tol` of the largest sensitivity of each (and the differences'
/// rounding of the forces); the simulation itself must be the plain one, bit for bit.
fn check_robot_sensitivities(
    r: &Robot,
    drives: &Drives,
    laws: &[TransferFunction],
    qr: &[f64],
    opts: &RobotLoopOptions,
    tol: f64,
) {
    use super::closed_loop::{simulate_robot_sensitivity, Directions};
    let hrel = 1e-4;
    let n = r.ndof();
    let lay = PhysLayout::of(n, drives);
    // every physical parameter the loop depends on (the rigid joints' stiffness, damping and backlash
    // are not), then each drive's first force
    let elastic = drives.elastic();
    let params: Vec<usize> = (0..lay.len())
        .filter(|&i| {
            let g = i.checked_sub(11 * n).map(|x| (x / n, x % n));
            !matches!(g, Some((3..=5, j)) if !elastic.contains(&j))
                && !matches!(g, Some((5, j)) if drives.backlash.get(j).copied().unwrap_or(0.0) == 0.0)
                && !matches!(g, Some((6, j)) if drives.load_friction[j] == 0.0)
        })
        .collect();
    let p = params.len() + n;
    let mut dirs = vec![0.0; lay.len() * p];
    for (c, &i) in params.iter().enumerate() {
        dirs[i * p + c] = 1.0;
    }
    let mut dforce0 = vec![0.0; n * p];
    for j in 0..n {
        dforce0[j * p + params.len() + j] = 1.0;
    }
    let (out, sens) = simulate_robot_sensitivity(
        r,
        drives,
        laws,
        qr,
        opts,
        Directions {
            count: p,
            physical: &dirs,
            force0: &dforce0,
        },
    )
    .unwrap();
    let plain = simulate_robot(r, drives, laws, qr, opts).unwrap();
    assert_eq!(
        out.force, plain.force,
        "the sensitivities must not change the simulation"
    );
    let samples = qr.len() / n;
    let fscale = out.force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    let value = |i: usize| -> f64 {
        let d = drives;
        match i {
            _ if i < n => d.armature[i],
            _ if i < 11 * n => r.inertial_params()[i - n],
            _ if i >= lay.term(0) => d.terms.iter().flatten().nth(i - lay.term(0)).unwrap().1,
            _ => {
                let (g, j) = ((i - 11 * n) / n, (i - 11 * n) % n);
                [
                    d.viscous[j],
                    d.coulomb[j],
                    d.offset[j],
                    d.stiffness[j],
                    d.damping[j],
                    d.backlash.get(j).copied().unwrap_or(0.0),
                    d.load_friction[j],
                    d.laws[j].eps,
                ][g]
            }
        }
    };
    let mut worst: f64 = 0.0;
    for c in 0..p {
        let (h, plus, minus) = if c < params.len() {
            let i = params[c];
            // a body's parameters each by the same share of its largest (a first moment may be 0)
            let h = hrel
                * if (n..11 * n).contains(&i) {
                    let b = (i - n) / 10 * 10;
                    r.inertial_params()[b..b + 10]
                        .iter()
                        .fold(0.0f64, |m, x| m.max(x.abs()))
                } else {
                    value(i).abs()
                };
            let (rp, dp) = moved(r, drives, i, h);
            let (rm, dm) = moved(r, drives, i, -h);
            (
                h,
                simulate_robot(&rp, &dp, laws, qr, opts).unwrap().force,
                simulate_robot(&rm, &dm, laws, qr, opts).unwrap().force,
            )
        } else {
            let j = c - params.len();
            let h = hrel * opts.force0[j].abs().max(1.0);
            let shift = |s: f64| {
                let mut o = opts.clone();
                o.force0[j] += s;
                simulate_robot(r, drives, laws, qr, &o).unwrap().force
            };
            (h, shift(h), shift(-h))
        };
        let col = |j: usize, k: usize| sens[(j * p + c) * samples + k];
        let cscale = (0..n)
            .flat_map(|j| (0..samples).map(move |k| (j, k)))
            .fold(0.0f64, |m, (j, k)| m.max(col(j, k).abs()));
        let mut err: f64 = 0.0;
        for j in 0..n {
            for k in 0..samples {
                let fd = (plus[k * n + j] - minus[k * n + j]) / (2.0 * h);
                err = err.max((fd - col(j, k)).abs());
            }
        }
        // central differences' own error: h² of the third derivative, and the rounding of the forces over h
        let rel = err / (cscale + 1e-9 * fscale / h);
        worst = worst.max(rel);
        assert!(
            rel < tol,
            "direction {c} (physical parameter {:?}): error {err:e} of {cscale:e}",
            params.get(c)
        );
    }
    assert!(worst > 0.0);
}

#[test]
fn the_robot_loops_sensitivities_are_those_of_central_differences() {
    // truncation of the central differences at steps of 1e-4: up to 5e-6 of each sensitivity
    let (r, drives, laws, qr, opts) = loaded_chain();
    check_robot_sensitivities(&r, &drives, &laws, &qr, &opts, 5e-5);
}

#[test]
fn an_elastic_joints_backlash_has_its_sensitivities_while_in_contact() {
    // a pendulum hanging on its spring across a dead zone, gravity keeping it on one side of its gap
    // as it swings (a contact made or lost within an RK4 step is a kink the differences straddle)
    let r = pendulum(2.0, 0.5, 0.01);
    let (dt, samples) = (1e-3, 600);
    let qr: Vec<f64> = (0..samples)
        .map(|k| 0.7 + 0.05 * (2.0 * std::f64::consts::PI * k as f64 / samples as f64).sin())
        .collect();
    let drives = Drives {
        armature: vec![0.05],
        viscous: vec![0.5],
        coulomb: vec![0.3],
        offset: vec![0.1],
        laws: vec![crate::model::FrictionLaw::algebraic(1e-2)],
        stiffness: vec![3.0e3],
        damping: vec![0.5],
        backlash: vec![1e-3],
        terms: vec![Vec::new()],
        load_friction: vec![0.04],
    };
    let law = crate::Controller::EmpsCascade {
        kp: 30.0,
        kv: 8.0,
        gtau: 1.0,
        vsat: f64::INFINITY,
    }
    .law(dt)
    .unwrap();
    let g0 = r.rnea(&qr[..1], &[0.0], &[0.0]).unwrap()[0];
    let opts = RobotLoopOptions {
        delay: vec![2],
        force_lag: vec![1e-3],
        ..RobotLoopOptions::new(dt, 8, vec![0.0], vec![g0 + 0.1])
    };
    let out = simulate_robot(&r, &drives, &[law], &qr, &opts).unwrap();
    let side = (out.theta[0] - out.q[0]).signum();
    let least = (0..samples).fold(f64::INFINITY, |m, k| m.min(side * (out.theta[k] - out.q[k])));
    assert!(least > 0.6e-3, "the link should stay in contact: {least:e}");
    check_robot_sensitivities(&r, &drives, &[law], &qr, &opts, 5e-5);
}

#[test]
fn the_mass_matrix_beside_the_derivatives_is_the_mass_matrix() {
    // the chain with skewed axes and a prismatic joint, at a few random states
    let r = Robot::from_urdf(CHAIN, None).unwrap();
    let n = r.ndof();
    for seed in 0..5 {
        let x = state(3 * n, seed);
        let (q, v, a) = (&x[..n], &x[n..2 * n], &x[2 * n..]);
        let mut m = vec![0.0; n * n];
        let d = r.rnea_derivatives_and_mass(q, v, a, Some(&mut m)).unwrap();
        assert_eq!(d, r.rnea_derivatives(q, v, a).unwrap());
        let want = r.mass_matrix(q).unwrap();
        let scale = want.iter().fold(0.0f64, |s, x| s.max(x.abs()));
        for i in 0..n {
            for j in 0..n {
                assert!((m[i * n + j] - want[(i, j)]).abs() <= 1e-13 * scale, "({i}, {j})");
            }
        }
    }
}

#[test]
fn the_sensitivities_do_not_depend_on_how_the_directions_are_split() {
    // OE-LM splits its directions in one chunk per core: each direction's values must be the same bit for
    // bit in any chunk, so that its result does not depend on the machine's cores
    use super::closed_loop::{simulate_robot_sensitivity, Directions};
    let (r, drives, laws, qr, opts) = loaded_chain();
    let n = r.ndof();
    let lay = PhysLayout::of(n, &drives);
    let samples = qr.len() / n;
    let rows: Vec<usize> = (0..lay.len()).step_by(3).collect();
    let run = |cols: &[usize]| {
        let p = cols.len();
        let mut physical = vec![0.0; lay.len() * p];
        for (c, &i) in cols.iter().enumerate() {
            physical[i * p + c] = 1.0 + 0.1 * i as f64;
        }
        let force0 = vec![0.0; n * p];
        let dirs = Directions {
            count: p,
            physical: &physical,
            force0: &force0,
        };
        simulate_robot_sensitivity(&r, &drives, &laws, &qr, &opts, dirs)
            .unwrap()
            .1
    };
    let all = run(&rows);
    let (a, b) = rows.split_at(5);
    let parts = [run(a), run(b)];
    let p = rows.len();
    for j in 0..n {
        for (c, _) in rows.iter().enumerate() {
            let (part, pc, cc) = if c < 5 {
                (&parts[0], 5, c)
            } else {
                (&parts[1], p - 5, c - 5)
            };
            for k in 0..samples {
                assert_eq!(
                    all[(j * p + c) * samples + k].to_bits(),
                    part[(j * pc + cc) * samples + k].to_bits(),
                    "joint {j}, direction {c}, sample {k}"
                );
            }
        }
    }
}
