//! The closed loop of a robot: one drive per joint (`sim::drive::JointDrive`: its digital
//! controller run once per sample on the quantized position, its delay and force lag), its force
//! held over the sample while the rigid-body dynamics, the rotor inertias and the joint friction
//! move the arm (RK4 on fixed substeps). The arm is a `sim::closed_loop::Plant` under the same
//! loop as one axis's; only the dynamics and their integration are its own.
//!
//! A joint is rigid or elastic. An elastic joint's rotor is a body of its own (Spong's model): the
//! drive's force, the rotor inertia and the friction act on the motor side, whose position the
//! encoder reads, and a spring K with damping D carries the torque to the link side, which moves
//! in the rigid-body chain:
//!
//! ```text
//!   Ia θ̈ = u − Fv θ̇ − Fc s(θ̇) − OF − K (θ − q) − D (θ̇ − q̇)       (motor side)
//!   M(q) q̈ + c(q, q̇) + g(q) = τ,  τ_j = K (θ − q) + D (θ̇ − q̇)      (link side)
//! ```
//!
//! An elastic joint may have backlash: a dead zone of total width b between rotor and link, across
//! which they move apart; the spring and its damping act only in contact,
//! `τ_j = K dz(θ − q) + D (θ̇ − q̇)·[|θ − q| > b/2]`, `dz(x) = sign(x)·max(|x| − b/2, 0)` (one axis's
//! backlash, [`crate::model::dead_zone`]).
//!
//! A rigid joint has θ = q, its rotor inertia added to the chain's (armature) and its friction
//! at the link speed, as the one-axis rigid model. The one-axis two-mass model (eqs. (1)–(3)) is
//! this plant's elastic joint on a chain of one body.

use crate::controller::TransferFunction;
use crate::error::{invalid, Error, Result};
use crate::model::{dead_zone, Basis, FrictionLaw};
use crate::sim::closed_loop::{self, Plant};
use crate::sim::drive::{JointDrive, Start};

use super::{AbaWork, Robot};

pub mod sensitivity;
pub use sensitivity::PhysLayout;

use sensitivity::Sensitivities;

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
    /// Each joint's spring from its rotor to its link (N·m/rad or N/m): `f64::INFINITY` for a
    /// rigid joint; empty: every joint rigid.
    pub stiffness: Vec<f64>,
    /// The springs' damping (N·m·s/rad or N·s/m; ignored on rigid joints); empty: none.
    pub damping: Vec<f64>,
    /// Each elastic joint's backlash: the total width (rad or m) of a dead zone between its rotor
    /// and its link, 0 for none (and on every rigid joint); empty: none on any joint.
    pub backlash: Vec<f64>,
    /// Each joint's extra terms beside its viscous and Coulomb friction and offset: one axis's basis
    /// functions ([`Basis`], of dof 0: a Stribeck hump, direction-dependent friction, a torque
    /// along the stroke such as a counterbalance's `A sin(q + φ)`) and their values, acting where
    /// the joint's friction acts (the rotor of an elastic joint) at its position and speed under
    /// its friction law; empty: none on any joint.
    pub terms: Vec<Vec<(Basis, f64)>>,
    /// Each joint's friction that grows with the torque it carries (dimensionless μ): `μ s(v) |τ_L|`,
    /// τ_L the torque the chain's bodies ask of the joint (the spring's on an elastic joint), at the
    /// joint's friction speed under its law (gear-mesh and bearing friction under load); empty:
    /// none on any joint.
    pub load_friction: Vec<f64>,
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
        for (name, x) in [("stiffness", &self.stiffness), ("damping", &self.damping)] {
            if !x.is_empty() && x.len() != n {
                return Err(invalid!(
                    "{name} has {} values; the robot has {n} joints (give none for a rigid robot)",
                    x.len()
                ));
            }
        }
        for j in self.elastic() {
            let (k, d) = (self.stiffness[j], self.damping.get(j).copied().unwrap_or(0.0));
            if !(k > 0.0 && k.is_finite()) {
                return Err(invalid!(
                    "joint {}'s stiffness must be > 0 and finite (INFINITY for a rigid joint), got {k}",
                    j + 1
                ));
            }
            if !(d >= 0.0 && d.is_finite()) {
                return Err(invalid!(
                    "joint {}'s spring damping must be finite and >= 0, got {d}",
                    j + 1
                ));
            }
            // the rotor is a body of its own: without inertia its acceleration has no equation
            if self.armature[j].is_nan() || self.armature[j] <= 0.0 {
                return Err(invalid!(
                    "joint {} is elastic: its rotor inertia must be > 0, got {}",
                    j + 1,
                    self.armature[j]
                ));
            }
        }
        if !self.backlash.is_empty() && self.backlash.len() != n {
            return Err(invalid!(
                "backlash has {} values; the robot has {n} joints (give none for no backlash)",
                self.backlash.len()
            ));
        }
        let elastic = self.elastic();
        for (j, &b) in self.backlash.iter().enumerate() {
            if !(b.is_finite() && b >= 0.0) {
                return Err(invalid!(
                    "joint {}'s backlash is {b}: it must be finite and >= 0 (rad or m)",
                    j + 1
                ));
            }
            if b > 0.0 && !elastic.contains(&j) {
                return Err(invalid!(
                    "joint {} has backlash ({b}) but is rigid: backlash is a dead zone between an elastic joint's rotor and link (make the joint elastic)",
                    j + 1
                ));
            }
        }
        if !self.load_friction.is_empty() && self.load_friction.len() != n {
            return Err(invalid!(
                "load-dependent friction has {} values; the robot has {n} joints (give none for no such friction)",
                self.load_friction.len()
            ));
        }
        if let Some(j) = self.load_friction.iter().position(|m| !m.is_finite()) {
            return Err(invalid!(
                "joint {}'s load-dependent friction is {}: it must be finite",
                j + 1,
                self.load_friction[j]
            ));
        }
        if !self.terms.is_empty() && self.terms.len() != n {
            return Err(invalid!(
                "terms are given for {} joints; the robot has {n} (give each joint its list, or none at all)",
                self.terms.len()
            ));
        }
        for (j, terms) in self.terms.iter().enumerate() {
            for (b, v) in terms {
                if b.is_inertia() || b.couples() || b.dofs().0 != 0 {
                    return Err(invalid!(
                        "joint {}: a {:?} term acts on a joint's own position and speed only if it is no inertia nor coupling",
                        j + 1,
                        b
                    ));
                }
                if !v.is_finite() {
                    return Err(invalid!("joint {}'s term {:?} has the value {v}", j + 1, b));
                }
            }
        }
        // a negative rotor inertia is refused by the dynamics only where the arm's inertia does not make up for it
        // (a base parameter that regroups it with link inertias fixes only their sum)
        Ok(())
    }

    /// The elastic joints' indices, in order.
    pub fn elastic(&self) -> Vec<usize> {
        (0..self.stiffness.len())
            .filter(|&j| self.stiffness[j] != f64::INFINITY)
            .collect()
    }

    /// The rotor inertia each joint adds to the chain: its own on a rigid joint, none on an
    /// elastic one (its rotor moves on its own).
    fn link_armature(&self) -> Vec<f64> {
        let mut out = self.armature.clone();
        for j in self.elastic() {
            out[j] = 0.0;
        }
        out
    }

    /// Joint `j`'s backlash (total width of its dead zone; 0 for none).
    #[inline(always)]
    fn gap(&self, j: usize) -> f64 {
        self.backlash.get(j).copied().unwrap_or(0.0)
    }

    /// The torque elastic joint `j`'s spring and damping carry at the rotor-minus-link stretch `x`
    /// and its rate `r`: in contact only, with backlash.
    #[inline(always)]
    pub fn spring(&self, j: usize, x: f64, r: f64) -> f64 {
        let d = self.damping.get(j).copied().unwrap_or(0.0);
        let b = self.gap(j);
        if b == 0.0 {
            return self.stiffness[j] * x + d * r;
        }
        let s = dead_zone(x, b);
        if s == 0.0 {
            0.0
        } else {
            self.stiffness[j] * s + d * r
        }
    }

    /// The friction, offset and extra terms' torque of joint `j` at position `x` and speed `v`.
    #[inline(always)]
    fn resist_one(&self, j: usize, x: f64, v: f64) -> f64 {
        let law = self.laws[j];
        let mut f = self.viscous[j] * v + self.coulomb[j] * law.sign(v) + self.offset[j];
        if let Some(terms) = self.terms.get(j) {
            for (b, value) in terms {
                f += value * b.local(x, v, law).0;
            }
        }
        f
    }

    /// The friction, offset and extra terms' torque of each joint at positions `q`, speeds `v`,
    /// with the load-dependent friction of the link torques `load`.
    #[inline(always)]
    fn resist(&self, q: &[f64], v: &[f64], load: &[f64], out: &mut [f64]) {
        for i in 0..v.len() {
            out[i] = self.resist_one(i, q[i], v[i]) + self.load_part(i, v[i], load[i]);
        }
    }

    /// Joint `j`'s load-dependent friction at speed `v` under the link torque `load`.
    #[inline(always)]
    fn load_part(&self, j: usize, v: f64, load: f64) -> f64 {
        match self.load_friction.get(j) {
            Some(&mu) if mu != 0.0 => mu * self.laws[j].sign(v) * load.abs(),
            _ => 0.0,
        }
    }

    /// The slope through zero speed of joint `j`'s resisting torque at position `x` (its decay
    /// rate times the inertia it moves).
    fn slope_at_rest(&self, j: usize, x: f64) -> f64 {
        let law = self.laws[j];
        let (_, s) = law.sign_and_derivative(0.0);
        let mut slope = self.viscous[j].abs() + self.coulomb[j].abs() * s;
        if let Some(terms) = self.terms.get(j) {
            for (b, value) in terms {
                slope += (value * b.local(x, 0.0, law).2).abs();
            }
        }
        slope
    }
}

/// The most fixed-point steps between the load-dependent friction and the link torques it grows
/// with, per derivative (each divides their error by 1/μ, μ of order 0.01–0.1).
const LOAD_ITERATIONS: usize = 8;

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
/// `samples × n` row-major, at the sample instants. `q`, `qd`, `qdd` are the link side's; on a
/// robot with an elastic joint, `theta`, `thetad`, `thetadd` are the motor side's (equal to the
/// link side's on rigid joints), empty otherwise.
#[derive(Clone, Debug, Default)]
pub struct RobotLoopOutput {
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    pub qdd: Vec<f64>,
    pub force: Vec<f64>,
    pub theta: Vec<f64>,
    pub thetad: Vec<f64>,
    pub thetadd: Vec<f64>,
}

/// The arm's dynamics: the chain and its drives' inertia, friction and springs, and their work
/// buffers. The state is `x = [q, q̇, θ, θ̇]`: the link side's `n` positions and speeds, then the
/// elastic joints' rotors' (in [`Drives::elastic`]'s order).
struct Dynamics<'a> {
    robot: &'a Robot,
    drives: &'a Drives,
    ws: AbaWork,
    /// The joint torques of the last acceleration.
    tau: Vec<f64>,
    /// The elastic joints and the inertia each joint adds to the chain.
    elastic: Vec<usize>,
    link_armature: Vec<f64>,
    /// The torque the chain's bodies asked of each joint at the last derivative (the spring's on an
    /// elastic joint): what the load-dependent friction of the next one acts with (a stage behind:
    /// the friction and the accelerations it slows are one algebraic loop of gain μ < 1).
    load: Vec<f64>,
    load_before: Vec<f64>,
    has_load: bool,
}

impl Dynamics<'_> {
    /// Whether joint `j` is elastic.
    #[inline(always)]
    fn is_elastic(&self, j: usize) -> bool {
        self.drives.stiffness.get(j).is_some_and(|k| *k != f64::INFINITY)
    }

    /// The state's derivative `[q̇, q̈, θ̇, θ̈]` at `x` under the drives' forces `u`, into `out`;
    /// with load-dependent friction, the friction and the link torques it grows with solved
    /// together by fixed-point steps (a contraction of rate μ < 1), from the last derivative's.
    #[inline(always)]
    fn deriv(&mut self, x: &[f64], u: &[f64], out: &mut [f64]) -> Result<()> {
        self.deriv_once(x, u, out)?;
        if self.has_load {
            let n = u.len();
            for _ in 0..LOAD_ITERATIONS {
                self.load_before.copy_from_slice(&self.load);
                self.deriv_once(x, u, out)?;
                let before = &self.load_before;
                let scale = before.iter().fold(1e-300f64, |m, t| m.max(t.abs()));
                if (0..n).all(|i| (self.load[i] - before[i]).abs() <= 1e-13 * scale) {
                    break;
                }
            }
        }
        Ok(())
    }

    /// One evaluation of the derivative with the load-dependent friction of the link torques of
    /// the last one (which it updates).
    #[inline(always)]
    fn deriv_once(&mut self, x: &[f64], u: &[f64], out: &mut [f64]) -> Result<()> {
        let n = u.len();
        let ne = self.elastic.len();
        let (q, rest) = x.split_at(n);
        let (v, rest) = rest.split_at(n);
        let (theta, omega) = rest.split_at(ne);
        let (dq, rest) = out.split_at_mut(n);
        let (dv, rest) = rest.split_at_mut(n);
        let (dtheta, domega) = rest.split_at_mut(ne);
        dq.copy_from_slice(v);
        self.drives.resist(q, v, &self.load, &mut self.tau);
        for i in 0..n {
            self.tau[i] = u[i] - self.tau[i];
        }
        let d = self.drives;
        for (e, &j) in self.elastic.iter().enumerate() {
            // the spring's torque drives the link; the drive's force, less the motor side's friction and
            // the spring's reaction, the rotor
            let spring = d.spring(j, theta[e] - q[j], omega[e] - v[j]);
            let w = omega[e];
            let friction = d.resist_one(j, theta[e], w) + d.load_part(j, w, spring);
            dtheta[e] = w;
            domega[e] = (u[j] - friction - spring) / d.armature[j];
            self.tau[j] = spring;
        }
        self.robot
            .aba_into(q, v, &self.tau, Some(&self.link_armature), &mut self.ws, dv)?;
        if self.has_load {
            // what the bodies took of each joint's torque: all of it but what moved the rotor (its
            // spring's on an elastic joint, whose rotor is apart)
            for i in 0..n {
                self.load[i] = self.tau[i] - self.link_armature[i] * dv[i];
            }
        }
        Ok(())
    }
}

/// The arm as the loop's [`Plant`]: its dynamics, the state `x` ([`Dynamics`]), its derivative
/// at the last recorded state (the first RK4 stage of the next period), RK4's work buffers and the
/// recorded link and motor sides (`samples × n`, row-major).
struct Arm<'a, 'b, T: ArmTangent> {
    /// Borrowed, not held: the dynamics go out of line (ABA), and a pointer into the arm would
    /// keep the state and the stages' buffers out of registers.
    dynamics: &'b mut Dynamics<'a>,
    /// What rides along the stages: nothing, or the forward sensitivities.
    tangent: T,
    n: usize,
    x: Vec<f64>,
    dx: Vec<f64>,
    /// RK4's stages and the state at a stage.
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    xs: Vec<f64>,
    /// Each joint's encoder: its index in `x` (the rotor's position on an elastic joint).
    encoder: Vec<usize>,
    /// The RK4 step (s) and the steps per sample.
    h: f64,
    substeps: usize,
    dt: f64,
    out: RobotLoopOutput,
}

/// What rides along the arm's loop: nothing for a plain simulation ([`NoTangent`]), the forward
/// sensitivities for [`simulate_robot_sensitivity`] (`sensitivity::Sensitivities`).
trait ArmTangent {
    /// Joint `j`'s drive computed its command of sample `k` (`active`: not saturated); its encoder
    /// reads the state's entry `encoder`.
    fn commanded(&mut self, k: usize, j: usize, drive: &JointDrive, active: bool, encoder: usize);
    /// Stage `i` (0–3) of an RK4 step of length `h`: the dynamics just computed the derivative
    /// `f` at the stage's state `x` under the period's forces.
    fn stage(&mut self, dynamics: &Dynamics, i: usize, h: f64, x: &[f64], f: &[f64]) -> Result<()>;
    /// The RK4 step of length `h` is complete.
    fn end(&mut self, h: f64);
}

/// A plain simulation's tangent: nothing.
struct NoTangent;

impl ArmTangent for NoTangent {
    #[inline(always)]
    fn commanded(&mut self, _: usize, _: usize, _: &JointDrive, _: bool, _: usize) {}
    #[inline(always)]
    fn stage(&mut self, _: &Dynamics, _: usize, _: f64, _: &[f64], _: &[f64]) -> Result<()> {
        Ok(())
    }
    #[inline(always)]
    fn end(&mut self, _: f64) {}
}

impl<T: ArmTangent> Plant for Arm<'_, '_, T> {
    type Joints = Vec<f64>;

    fn joints(&self) -> Vec<f64> {
        vec![0.0; self.n]
    }

    #[inline(always)]
    fn commanded(&mut self, k: usize, j: usize, drive: &JointDrive, active: bool, _applied: f64) {
        self.tangent.commanded(k, j, drive, active, self.encoder[j]);
    }

    #[inline(always)]
    fn position(&self, j: usize) -> f64 {
        self.x[self.encoder[j]]
    }

    #[inline(always)]
    fn record(&mut self, k: usize, applied: &[f64]) -> Result<()> {
        let n = self.n;
        self.dynamics.deriv(&self.x, applied, &mut self.dx)?;
        let row = k * n;
        self.out.q[row..row + n].copy_from_slice(&self.x[..n]);
        self.out.qd[row..row + n].copy_from_slice(&self.x[n..2 * n]);
        self.out.qdd[row..row + n].copy_from_slice(&self.dx[n..2 * n]);
        let ne = self.dynamics.elastic.len();
        if ne > 0 {
            self.out.theta[row..row + n].copy_from_slice(&self.x[..n]);
            self.out.thetad[row..row + n].copy_from_slice(&self.x[n..2 * n]);
            self.out.thetadd[row..row + n].copy_from_slice(&self.dx[n..2 * n]);
            for (e, &j) in self.dynamics.elastic.iter().enumerate() {
                self.out.theta[row + j] = self.x[2 * n + e];
                self.out.thetad[row + j] = self.x[2 * n + ne + e];
                self.out.thetadd[row + j] = self.dx[2 * n + ne + e];
            }
        }
        Ok(())
    }

    /// `substeps` RK4 steps with the forces held.
    #[inline(always)]
    fn advance(&mut self, applied: &[f64]) -> Result<()> {
        let h = self.h;
        let Self {
            dynamics,
            tangent,
            x,
            dx,
            k1,
            k2,
            k3,
            k4,
            xs,
            ..
        } = self;
        let m = x.len();
        for s in 0..self.substeps {
            // the first stage of the first substep is the derivative just recorded
            if s == 0 {
                k1.copy_from_slice(dx);
            } else {
                dynamics.deriv(x, applied, k1)?;
            }
            tangent.stage(dynamics, 0, h, x, k1)?;
            for i in 0..m {
                xs[i] = x[i] + 0.5 * h * k1[i];
            }
            dynamics.deriv(xs, applied, k2)?;
            tangent.stage(dynamics, 1, h, xs, k2)?;
            for i in 0..m {
                xs[i] = x[i] + 0.5 * h * k2[i];
            }
            dynamics.deriv(xs, applied, k3)?;
            tangent.stage(dynamics, 2, h, xs, k3)?;
            for i in 0..m {
                xs[i] = x[i] + h * k3[i];
            }
            dynamics.deriv(xs, applied, k4)?;
            tangent.stage(dynamics, 3, h, xs, k4)?;
            for i in 0..m {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            tangent.end(h);
        }
        Ok(())
    }

    #[inline(always)]
    fn finite(&self) -> bool {
        self.x.iter().all(|x| x.is_finite())
    }

    #[cold]
    fn diverged(&self, k: usize, qr: &[f64], bound: &[f64]) -> Error {
        // the first joint off its reference or not finite
        let n = self.n;
        let j = (0..n)
            .find(|&j| !((self.position(j) - qr[j]).abs() <= bound[j] && self.x[n + j].is_finite()))
            .unwrap_or(0);
        Error::Simulation(format!(
            "the robot's closed loop diverged at sample {k} (t = {:.6} s): joint {} ({}) is {:.3e} away from its reference",
            k as f64 * self.dt,
            j + 1,
            self.dynamics.robot.joints[j].name,
            self.position(j) - qr[j]
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

/// The poses along the references (besides the first) whose inertias choose the RK4 steps.
pub const SUBSTEP_POSES: usize = 8;

/// The largest ω·h of an elastic joint's oscillation that RK4's substeps keep within: RK4 damps
/// a mode of ω·h = 0.5 by (ωh)⁶/144 ≈ 1e-4 per step, a damping ratio of 3e-5, far below a
/// transmission's own (1–5 %), and shifts its frequency by (ωh)⁴/120 ≈ 5e-4.
pub const SPRING_STEP: f64 = 0.5;

/// RK4's steps per sample for this robot: the fastest decay rate of its joints at `q0`, friction's
/// slope through zero speed over the inertia it moves, `λ = (Fv + Fc·s'(0)) / (Ia + M_jj)` on a
/// rigid joint and `/ Ia` on an elastic joint's rotor, times the step within [`STIFF_STEP`]; an
/// elastic joint's free-motor mode `ω² = K (1/Ia + 1/M_jj)` and its damping's rate
/// `D (1/Ia + 1/M_jj)` within [`SPRING_STEP`] and [`STIFF_STEP`]; and at least 2 steps. A sharp
/// friction law (a small smoothing speed) is stiff: on the UR5 with ε = 0.01 rad/s the wrist's λ
/// is about 4·10³/s.
pub fn auto_substeps(robot: &Robot, drives: &Drives, q0: &[f64], dt: f64) -> Result<usize> {
    let m = robot.mass_matrix(q0)?;
    let link = drives.link_armature();
    let mut lambda: f64 = 0.0;
    let mut omega: f64 = 0.0;
    let elastic = drives.elastic();
    for j in 0..robot.ndof() {
        let friction = drives.slope_at_rest(j, q0[j]);
        let link_inertia = link[j] + m[(j, j)];
        if elastic.contains(&j) {
            let ia = drives.armature[j];
            let both = 1.0 / ia
                + if link_inertia > 0.0 {
                    1.0 / link_inertia
                } else {
                    0.0
                };
            lambda = lambda
                .max(friction / ia)
                .max(drives.damping.get(j).copied().unwrap_or(0.0) * both);
            omega = omega.max((drives.stiffness[j] * both).sqrt());
        } else if link_inertia > 0.0 {
            lambda = lambda.max(friction / link_inertia);
        }
    }
    let steps = (lambda * dt / STIFF_STEP)
        .ceil()
        .max((omega * dt / SPRING_STEP).ceil());
    if !steps.is_finite() || steps > 1e4 {
        return Err(invalid!(
            "the joints' friction or springs are too stiff to integrate (decay {lambda:.3e}/s, mode {omega:.3e} rad/s at a sample period of {dt} s): a Coulomb smoothing speed this small needs a finer law or the parameters are off"
        ));
    }
    Ok((steps as usize).max(2))
}

/// The directions of [`simulate_robot_sensitivity`]: `count` columns `∂φ/∂χ` of the physical
/// parameters over the caller's parameters χ (`physical`: [`PhysLayout::len`] × `count`,
/// row-major; [`sensitivity`]), and `force0` (`n × count`) the derivatives of each drive's held
/// first force ([`RobotLoopOptions::force0`]), which may depend on χ too (a lead-in's static torque).
#[derive(Clone, Copy, Debug)]
pub struct Directions<'a> {
    pub count: usize,
    pub physical: &'a [f64],
    pub force0: &'a [f64],
}

/// [`simulate_robot`] with its forward sensitivities along `directions`. Returns the simulation
/// and `∂force/∂χ`, `[joint][direction][sample]`. The encoders should read the exact positions
/// (no quantization): a quantized loop is not differentiable.
pub fn simulate_robot_sensitivity(
    robot: &Robot,
    drives: &Drives,
    controllers: &[TransferFunction],
    qr: &[f64],
    opts: &RobotLoopOptions,
    directions: Directions,
) -> Result<(RobotLoopOutput, Vec<f64>)> {
    let Directions {
        count: p,
        physical: directions,
        force0: dforce0,
    } = directions;
    let n = robot.ndof();
    drives.validate(n)?;
    let lay = PhysLayout::of(n, drives);
    if directions.len() != lay.len() * p {
        return Err(invalid!(
            "the directions must be {} physical parameters × {p} directions, got {} values",
            lay.len(),
            directions.len()
        ));
    }
    if dforce0.len() != n * p {
        return Err(invalid!(
            "the first forces' sensitivities must be {n} joints × {p} directions, got {} values",
            dforce0.len()
        ));
    }
    if directions.iter().chain(dforce0).any(|x| !x.is_finite()) {
        return Err(invalid!("the directions hold a non-finite value"));
    }
    let (out, sens) = run_arm(robot, drives, controllers, qr, opts, |dynamics, x0, samples| {
        Sensitivities::new(
            dynamics,
            x0,
            samples,
            directions,
            p,
            dforce0,
            &opts.delay,
            &opts.force_lag,
            opts.dt,
        )
    })?;
    let forces = sens.forces();
    if let Some(i) = forces.iter().position(|x| !x.is_finite()) {
        let samples = qr.len() / n;
        return Err(Error::Simulation(format!(
            "the sensitivities of the robot's closed loop are not finite (joint {}, direction {}, sample {}): the loop is too stiff or the parameters are off",
            i / (p * samples) + 1,
            i / samples % p,
            i % samples
        )));
    }
    Ok((out, forces))
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
    run_arm(robot, drives, controllers, qr, opts, |_, _, _| Ok(NoTangent)).map(|(out, _)| out)
}

/// [`simulate_robot`] with the tangent `tangent(dynamics, x0, samples)` makes at the initial state
/// `x0` riding along; returns it with the simulation.
fn run_arm<T: ArmTangent>(
    robot: &Robot,
    drives: &Drives,
    controllers: &[TransferFunction],
    qr: &[f64],
    opts: &RobotLoopOptions,
    tangent: impl FnOnce(&Dynamics, &[f64], usize) -> Result<T>,
) -> Result<(RobotLoopOutput, T)> {
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
        // the joints' inertias change along the motion, and with them their modes and decay rates: the
        // steps the stiffest of some poses along the references asks (a UR10's shoulder under PID at
        // 500 Hz: 2 steps from its first pose, and the loop diverged where the arm folds)
        let mut steps = 0;
        for i in 0..=SUBSTEP_POSES {
            let k = i * (samples - 1) / SUBSTEP_POSES;
            steps = steps.max(auto_substeps(robot, drives, &qr[k * n..(k + 1) * n], opts.dt)?);
        }
        steps
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
            let elastic = drives.elastic();
            let ne = elastic.len();
            let mut dynamics = Dynamics {
                robot,
                drives,
                ws: AbaWork::new(robot),
                tau: vec![0.0; n],
                link_armature: drives.link_armature(),
                elastic,
                load: vec![0.0; n],
                load_before: vec![0.0; n],
                has_load: drives.load_friction.iter().any(|&m| m != 0.0),
            };
            // from rest at the first reference: an elastic joint's rotor there, its link where the spring
            // holds the link side's static torque (gravity), found by a few fixed-point steps
            let mut x = vec![0.0; 2 * n + 2 * ne];
            x[..n].copy_from_slice(&qr[..n]);
            for (e, &j) in dynamics.elastic.iter().enumerate() {
                x[2 * n + e] = qr[j];
            }
            settle_links(robot, drives, &dynamics.elastic, &mut x)?;
            if dynamics.has_load {
                // at rest the bodies ask of each joint their weight's torque
                let rest = vec![0.0; n];
                dynamics.load = robot.rnea(&x[..n], &rest, &rest)?;
            }
            let mut encoder: Vec<usize> = (0..n).collect();
            for (e, &j) in dynamics.elastic.iter().enumerate() {
                encoder[j] = 2 * n + e;
            }
            let m = x.len();
            let motor = |what| if ne > 0 { zeros(what) } else { Ok(Vec::new()) };
            let tangent = tangent(&dynamics, &x, samples)?;
            let mut arm = Arm {
                dynamics: &mut dynamics,
                tangent,
                n,
                x,
                dx: vec![0.0; m],
                k1: vec![0.0; m],
                k2: vec![0.0; m],
                k3: vec![0.0; m],
                k4: vec![0.0; m],
                xs: vec![0.0; m],
                encoder,
                h: opts.dt / substeps as f64,
                substeps,
                dt: opts.dt,
                out: RobotLoopOutput {
                    q: zeros("the simulated positions")?,
                    qd: zeros("the simulated speeds")?,
                    qdd: zeros("the simulated accelerations")?,
                    force: Vec::new(),
                    theta: motor("the simulated motor positions")?,
                    thetad: motor("the simulated motor speeds")?,
                    thetadd: motor("the simulated motor accelerations")?,
                },
            };
            let mut force = zeros("the simulated forces")?;
            let u_ext = (!opts.u_ext.is_empty()).then_some(&opts.u_ext[..]);
            closed_loop::run(&mut arm, &mut joint_drives, qr, u_ext, &span, &mut force)?;
            arm.out.force = force;
            Ok((arm.out, arm.tangent))
        },
    )
}

/// Each elastic joint's link position at rest with its rotor at `x`'s: where the spring holds the
/// link side's static torque, `K (θ − q) = g(q)`, by fixed-point steps `q ← θ − g(q)/K` (a
/// contraction while the springs are stiffer than gravity's slope, as a transmission's are by
/// orders of magnitude), to rounding; with backlash, the link hangs on the far side of its gap,
/// `q ← θ − g(q)/K − sign(g)·b/2`.
/// The sign of `x`, 0 at 0 (a link that no torque holds sits in the middle of its gap).
fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

fn settle_links(robot: &Robot, drives: &Drives, elastic: &[usize], x: &mut [f64]) -> Result<()> {
    if elastic.is_empty() {
        return Ok(());
    }
    let n = robot.ndof();
    let rest = vec![0.0; n];
    for _ in 0..50 {
        let g = robot.rnea(&x[..n], &rest, &rest)?;
        let mut moved: f64 = 0.0;
        for (e, &j) in elastic.iter().enumerate() {
            let q = x[2 * n + e] - g[j] / drives.stiffness[j] - 0.5 * drives.gap(j) * sign(g[j]);
            moved = moved.max((q - x[j]).abs());
            x[j] = q;
        }
        if moved <= 1e-15 * (1.0 + x[..n].iter().fold(0.0f64, |a, b| a.max(b.abs()))) {
            return Ok(());
        }
    }
    Ok(())
}
