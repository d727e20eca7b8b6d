//! The closed loop of a robot: one drive per joint (`sim::drive::JointDrive`: its digital
//! controller run once per sample on the quantized position, its delay and force lag), its force
//! held over the sample while the rigid-body dynamics, the rotor inertias and the joint friction
//! move the arm (RK4 on fixed substeps). The arm is a `sim::closed_loop::Plant` under the same
//! loop as one axis's; only the dynamics and their integration are its own.

use crate::controller::TransferFunction;
use crate::error::{invalid, Error, Result};
use crate::model::FrictionLaw;
use crate::sim::closed_loop::{self, Plant};
use crate::sim::drive::{JointDrive, Start};

use super::{AbaWork, Robot};

/// The drive side of each joint, beside the rigid bodies: rotor inertia reflected to the joint
/// (kg·m² or kg), viscous (N·m·s/rad or N·s/m) and Coulomb (N·m or N) friction, and a constant
/// torque offset, and each joint's friction law through zero speed (its shape and smoothing
/// speed in the joint's own units: rad/s or m/s).
#[derive(Clone, Debug)]
pub struct Drives {
    pub armature: Vec<f64>,
    pub viscous: Vec<f64>,
    pub coulomb: Vec<f64>,
    pub offset: Vec<f64>,
    pub laws: Vec<FrictionLaw>,
}

impl Drives {
    /// Checks the lengths against `n` joints and the values.
    pub fn validate(&self, n: usize) -> Result<()> {
        for (name, x) in [
            ("armature", &self.armature),
            ("viscous friction", &self.viscous),
            ("Coulomb friction", &self.coulomb),
            ("offset", &self.offset),
        ] {
            if x.len() != n {
                return Err(invalid!(
                    "{name} has {} values; the robot has {n} joints",
                    x.len()
                ));
            }
            if x.iter().any(|v| !v.is_finite()) {
                return Err(invalid!("{name} holds a non-finite value"));
            }
        }
        if self.laws.len() != n {
            return Err(invalid!(
                "{} friction laws for a robot of {n} joints: give one per joint",
                self.laws.len()
            ));
        }
        if let Some(j) = self
            .laws
            .iter()
            .position(|l| !(l.eps >= 0.0 && l.eps.is_finite()))
        {
            return Err(invalid!(
                "the friction law of joint {} has the smoothing speed {}: it must be finite and >= 0",
                j + 1,
                self.laws[j].eps
            ));
        }
        // a negative rotor inertia is refused by the dynamics only where the arm's inertia does not make up for it
        // (a base parameter that regroups it with link inertias fixes only their sum)
        Ok(())
    }

    /// The friction and offset torque of each joint at speeds `v`.
    #[inline(always)]
    fn resist(&self, v: &[f64], out: &mut [f64]) {
        for i in 0..v.len() {
            out[i] = self.viscous[i] * v[i] + self.coulomb[i] * self.laws[i].sign(v[i]) + self.offset[i];
        }
    }
}

/// How the loop is simulated.
#[derive(Clone, Debug)]
pub struct RobotLoopOptions {
    /// Sample period of the controllers and of the record (s).
    pub dt: f64,
    /// RK4 steps per sample; 0 chooses them ([`auto_substeps`]).
    pub substeps: usize,
    /// Encoder step of each joint (rad or m; 0 for none).
    pub quantization: Vec<f64>,
    /// The controllers' output at the first sample, held by their integrators from before the
    /// record (the logged force of the first sample): each controller runs on the positions'
    /// departures from the first reference and adds this.
    pub force0: Vec<f64>,
    /// A known force added to each joint's command before its saturation (`samples × n`,
    /// row-major: a feedforward the drive adds, as one axis's `u_ext`); empty for none.
    pub u_ext: Vec<f64>,
    /// Each joint's actuation delay (samples) between its command and the force applied; empty
    /// for none. The drive held the first command before the record.
    pub delay: Vec<usize>,
    /// Each joint's first-order lag (s) from the held command to the applied force (a current
    /// loop's); empty for none.
    pub force_lag: Vec<f64>,
}

impl RobotLoopOptions {
    /// Options with no feedforward, delay nor lag.
    pub fn new(dt: f64, substeps: usize, quantization: Vec<f64>, force0: Vec<f64>) -> Self {
        Self {
            dt,
            substeps,
            quantization,
            force0,
            u_ext: Vec::new(),
            delay: Vec::new(),
            force_lag: Vec::new(),
        }
    }
}

/// The simulated record: positions, speeds, accelerations and the controllers' forces, each
/// `samples × n` row-major, at the sample instants.
#[derive(Clone, Debug, Default)]
pub struct RobotLoopOutput {
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    pub qdd: Vec<f64>,
    pub force: Vec<f64>,
}

/// The arm's dynamics: the chain and its drives' inertia and friction, and their work buffers.
struct Dynamics<'a> {
    robot: &'a Robot,
    drives: &'a Drives,
    ws: AbaWork,
    /// The joint torques of the last acceleration.
    tau: Vec<f64>,
}

impl Dynamics<'_> {
    /// The accelerations at `(q, v)` under the drives' forces `u`, into `out`.
    #[inline(always)]
    fn accel(&mut self, q: &[f64], v: &[f64], u: &[f64], out: &mut [f64]) -> Result<()> {
        self.drives.resist(v, &mut self.tau);
        for i in 0..u.len() {
            self.tau[i] = u[i] - self.tau[i];
        }
        self.robot
            .aba_into(q, v, &self.tau, Some(&self.drives.armature), &mut self.ws, out)
    }
}

/// The arm as the loop's [`Plant`]: its dynamics, the state `(q, v)`, the acceleration at the last
/// recorded state (the first RK4 stage of the next period), RK4's work buffers and the recorded
/// positions, speeds and accelerations (`samples × n`, row-major).
struct Arm<'a, 'b> {
    /// Borrowed, not held: the dynamics go out of line (ABA), and a pointer into the arm would
    /// keep the state and the stages' buffers out of registers.
    dynamics: &'b mut Dynamics<'a>,
    q: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    /// RK4's stages and the state at a stage.
    k1q: Vec<f64>,
    k1v: Vec<f64>,
    k2q: Vec<f64>,
    k2v: Vec<f64>,
    k3q: Vec<f64>,
    k3v: Vec<f64>,
    k4q: Vec<f64>,
    k4v: Vec<f64>,
    qs: Vec<f64>,
    vs: Vec<f64>,
    /// The RK4 step (s) and the steps per sample.
    h: f64,
    substeps: usize,
    dt: f64,
    out_q: Vec<f64>,
    out_qd: Vec<f64>,
    out_qdd: Vec<f64>,
}

impl Plant for Arm<'_, '_> {
    type Joints = Vec<f64>;

    fn joints(&self) -> Vec<f64> {
        vec![0.0; self.q.len()]
    }

    #[inline(always)]
    fn position(&self, j: usize) -> f64 {
        self.q[j]
    }

    #[inline(always)]
    fn record(&mut self, k: usize, applied: &[f64]) -> Result<()> {
        let n = self.q.len();
        self.dynamics.accel(&self.q, &self.v, applied, &mut self.a)?;
        let row = k * n;
        self.out_q[row..row + n].copy_from_slice(&self.q);
        self.out_qd[row..row + n].copy_from_slice(&self.v);
        self.out_qdd[row..row + n].copy_from_slice(&self.a);
        Ok(())
    }

    /// `substeps` RK4 steps with the forces held.
    #[inline(always)]
    fn advance(&mut self, applied: &[f64]) -> Result<()> {
        let n = self.q.len();
        let h = self.h;
        let Self {
            dynamics,
            q,
            v,
            a,
            k1q,
            k1v,
            k2q,
            k2v,
            k3q,
            k3v,
            k4q,
            k4v,
            qs,
            vs,
            ..
        } = self;
        let mut accel = |q: &[f64], v: &[f64], out: &mut [f64]| dynamics.accel(q, v, applied, out);
        for s in 0..self.substeps {
            // the first stage of the first substep is the acceleration just recorded
            if s == 0 {
                k1v.copy_from_slice(a);
            } else {
                accel(q, v, k1v)?;
            }
            k1q.copy_from_slice(v);
            for j in 0..n {
                qs[j] = q[j] + 0.5 * h * k1q[j];
                vs[j] = v[j] + 0.5 * h * k1v[j];
            }
            k2q.copy_from_slice(vs);
            accel(qs, vs, k2v)?;
            for j in 0..n {
                qs[j] = q[j] + 0.5 * h * k2q[j];
                vs[j] = v[j] + 0.5 * h * k2v[j];
            }
            k3q.copy_from_slice(vs);
            accel(qs, vs, k3v)?;
            for j in 0..n {
                qs[j] = q[j] + h * k3q[j];
                vs[j] = v[j] + h * k3v[j];
            }
            k4q.copy_from_slice(vs);
            accel(qs, vs, k4v)?;
            for j in 0..n {
                q[j] += h / 6.0 * (k1q[j] + 2.0 * k2q[j] + 2.0 * k3q[j] + k4q[j]);
                v[j] += h / 6.0 * (k1v[j] + 2.0 * k2v[j] + 2.0 * k3v[j] + k4v[j]);
            }
        }
        Ok(())
    }

    #[inline(always)]
    fn finite(&self) -> bool {
        self.q.iter().chain(&self.v).all(|x| x.is_finite())
    }

    #[cold]
    fn diverged(&self, k: usize, qr: &[f64], bound: &[f64]) -> Error {
        // the first joint off its reference or not finite
        let j = (0..self.q.len())
            .find(|&j| !((self.q[j] - qr[j]).abs() <= bound[j] && self.v[j].is_finite()))
            .unwrap_or(0);
        Error::Simulation(format!(
            "the robot's closed loop diverged at sample {k} (t = {:.6} s): joint {} ({}) is {:.3e} away from its reference",
            k as f64 * self.dt,
            j + 1,
            self.dynamics.robot.joints[j].name,
            self.q[j] - qr[j]
        ))
    }
}

/// The stiffest friction mode's λ·h that RK4's substeps keep within. RK4's amplification on the
/// real axis, 1 − z + z²/2 − z³/6 + z⁴/24 at z = λh, stays in (0, 1) up to z = 2.785: below this the
/// mode decays without changing sign (0.65 per step at 2.5). It lives within a smoothing speed of
/// zero speed and decays within a sample either way (λ·dt > 2.5), so its rate there does not reach
/// the force: on the UR5's records (tanh and exp laws, ε = 0.01 and 0.005 rad/s) the closed-loop
/// force error moves by at most 0.4 % of itself from 1.5 to 2.5, where the substeps, and the
/// simulation's time, fall by 40 %.
pub const STIFF_STEP: f64 = 2.5;

/// RK4's steps per sample for this robot: the fastest decay rate of its joints at `q0`, friction's
/// slope through zero speed over the joint's inertia, `λ = (Fv + Fc·s'(0)) / (Ia + M_jj)`, times
/// the step within [`STIFF_STEP`], and at least 2 steps. A sharp friction law (a small smoothing
/// speed) is stiff: on the UR5 with ε = 0.01 rad/s the wrist's λ is about 4·10³/s.
pub fn auto_substeps(robot: &Robot, drives: &Drives, q0: &[f64], dt: f64) -> Result<usize> {
    let m = robot.mass_matrix(q0)?;
    let mut lambda: f64 = 0.0;
    for j in 0..robot.ndof() {
        let (_, slope) = drives.laws[j].sign_and_derivative(0.0);
        let inertia = drives.armature[j] + m[(j, j)];
        if inertia > 0.0 {
            lambda = lambda.max((drives.viscous[j].abs() + drives.coulomb[j].abs() * slope) / inertia);
        }
    }
    let steps = (lambda * dt / STIFF_STEP).ceil();
    if !steps.is_finite() || steps > 1e4 {
        return Err(invalid!(
            "the joints' friction is too stiff to integrate ({lambda:.3e}/s at a sample period of {dt} s): a Coulomb smoothing speed this small needs a finer law or the friction parameters are off"
        ));
    }
    Ok((steps as usize).max(2))
}

/// The closed loop of `robot` with `drives` under `controllers` (one per joint) following the
/// references `qr` (`samples × n`, row-major), from rest at the first reference.
pub fn simulate_robot(
    robot: &Robot,
    drives: &Drives,
    controllers: &[TransferFunction],
    qr: &[f64],
    opts: &RobotLoopOptions,
) -> Result<RobotLoopOutput> {
    let n = robot.ndof();
    drives.validate(n)?;
    if controllers.len() != n {
        return Err(invalid!(
            "{} controllers for a robot of {n} joints: give one per joint",
            controllers.len()
        ));
    }
    if qr.is_empty() || qr.len() % n != 0 {
        return Err(invalid!(
            "the references must be samples × {n} values, got {}",
            qr.len()
        ));
    }
    if let Some(i) = qr.iter().position(|x| !x.is_finite()) {
        return Err(invalid!(
            "reference sample {} of joint {} is not finite",
            i / n,
            i % n + 1
        ));
    }
    if !(opts.dt.is_finite() && opts.dt > 0.0) {
        return Err(invalid!(
            "the sample period must be finite and > 0, got {}",
            opts.dt
        ));
    }
    if opts.quantization.len() != n || opts.force0.len() != n {
        return Err(invalid!("quantization and force0 need one value per joint ({n})"));
    }
    let samples = qr.len() / n;
    if !opts.u_ext.is_empty() && opts.u_ext.len() != qr.len() {
        return Err(invalid!(
            "the external force must be samples × {n} values like the references ({} samples), got {}",
            samples,
            opts.u_ext.len()
        ));
    }
    if let Some(i) = opts.u_ext.iter().position(|x| !x.is_finite()) {
        return Err(invalid!(
            "the external force of joint {} is not finite at sample {}",
            i % n + 1,
            i / n
        ));
    }
    if !opts.delay.is_empty() && opts.delay.len() != n {
        return Err(invalid!(
            "give one delay per joint ({n}), got {}",
            opts.delay.len()
        ));
    }
    if let Some(j) = opts.delay.iter().position(|&d| d >= samples.max(1)) {
        return Err(invalid!(
            "joint {}'s delay of {} samples is not shorter than the record ({samples} samples)",
            j + 1,
            opts.delay[j]
        ));
    }
    if !opts.force_lag.is_empty() && opts.force_lag.len() != n {
        return Err(invalid!(
            "give one force lag per joint ({n}), got {}",
            opts.force_lag.len()
        ));
    }
    if let Some(j) = opts.force_lag.iter().position(|l| !(l.is_finite() && *l >= 0.0)) {
        return Err(invalid!(
            "joint {}'s force lag must be finite and >= 0 s, got {}",
            j + 1,
            opts.force_lag[j]
        ));
    }
    let substeps = if opts.substeps == 0 {
        auto_substeps(robot, drives, &qr[..n], opts.dt)?
    } else {
        opts.substeps
    };
    // a loop that left the references by more than their whole range (and a radian or metre) diverged
    let mut span = vec![0.0f64; n];
    for j in 0..n {
        let (lo, hi) = (0..samples).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), k| {
            (l.min(qr[k * n + j]), h.max(qr[k * n + j]))
        });
        span[j] = (hi - lo) + 1.0;
    }
    // the loop in the processor's widest build (as one axis's: the same operations, the same
    // results), its state built inside it: locals there, not memory behind a pointer
    crate::sim::driver::simd(
        #[inline(always)]
        move || {
            // each joint's drive: its controller on the departures from its first reference, holding the
            // first force, which its actuator held before the record
            let mut joint_drives: Vec<JointDrive> = (0..n)
                .map(|j| {
                    JointDrive::new(
                        controllers[j],
                        opts.quantization[j],
                        opts.delay.get(j).copied().unwrap_or(0),
                        opts.force_lag.get(j).copied().unwrap_or(0.0),
                        opts.dt,
                        Start::Holding {
                            qr0: qr[j],
                            force0: opts.force0[j],
                        },
                    )
                })
                .collect();
            let zeros = |what| crate::error::filled(samples * n, 0.0, what);
            let mut dynamics = Dynamics {
                robot,
                drives,
                ws: AbaWork::new(robot),
                tau: vec![0.0; n],
            };
            let mut arm = Arm {
                dynamics: &mut dynamics,
                q: qr[..n].to_vec(),
                v: vec![0.0; n],
                a: vec![0.0; n],
                k1q: vec![0.0; n],
                k1v: vec![0.0; n],
                k2q: vec![0.0; n],
                k2v: vec![0.0; n],
                k3q: vec![0.0; n],
                k3v: vec![0.0; n],
                k4q: vec![0.0; n],
                k4v: vec![0.0; n],
                qs: vec![0.0; n],
                vs: vec![0.0; n],
                h: opts.dt / substeps as f64,
                substeps,
                dt: opts.dt,
                out_q: zeros("the simulated positions")?,
                out_qd: zeros("the simulated speeds")?,
                out_qdd: zeros("the simulated accelerations")?,
            };
            let mut force = zeros("the simulated forces")?;
            let u_ext = (!opts.u_ext.is_empty()).then_some(&opts.u_ext[..]);
            closed_loop::run(&mut arm, &mut joint_drives, qr, u_ext, &span, &mut force)?;
            Ok(RobotLoopOutput {
                q: arm.out_q,
                qd: arm.out_qd,
                qdd: arm.out_qdd,
                force,
            })
        },
    )
}
