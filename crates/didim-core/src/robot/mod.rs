//! Serial manipulators: a chain of revolute and prismatic joints, each moving one rigid body with
//! the 10 standard inertial parameters, under gravity.
//!
//! - [`Robot`]: the chain, built from a URDF ([`Robot::from_urdf`], fixed joints merged) or by hand;
//! - [`Robot::rnea`]: inverse dynamics (recursive Newton–Euler) and [`Robot::regressor`], the
//!   same torques as a matrix linear in the inertial parameters;
//! - [`Robot::mass_matrix`], [`Robot::gravity`], [`Robot::aba`] (forward dynamics).
//!
//! Conventions are Pinocchio's, against which every function is tested: joint `i`'s frame is its
//! placement in the frame of joint `i − 1` (the world for the first) composed with the joint's own
//! motion (a rotation about, or a translation along, its unit axis); a body's parameters
//! `[m, m·cx, m·cy, m·cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]` are expressed in its joint's frame, the
//! inertia about that frame's origin. SI units: m, kg, rad, N, N·m.

mod aba;
pub mod closed_loop;
mod spatial;
mod urdf;

pub use aba::AbaWork;
pub use closed_loop::{
    simulate_robot, simulate_robot_sensitivity, Directions, Drives, PhysLayout, RobotLoopOptions,
    RobotLoopOutput,
};

use nalgebra::{Cholesky, DMatrix, DVector, Matrix3, Vector3};

use crate::error::{invalid, Result};
use spatial::{Force, Motion, Pose};

/// Number of standard inertial parameters of one body.
pub const BODY_PARAMS: usize = 10;

/// The names of a body's inertial parameters, in their order (suffixed by the joint's name).
pub const BODY_PARAM_NAMES: [&str; BODY_PARAMS] =
    ["m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"];

/// How a joint moves its body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// A rotation about the axis (rad).
    Revolute,
    /// A translation along the axis (m).
    Prismatic,
}

/// One actuated joint of the chain and the body it moves.
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    /// Unit axis in the joint's frame.
    pub axis: Vector3<f64>,
    /// Pose of the joint's frame at zero position in the previous joint's frame (the world's
    /// for the first joint).
    pub placement_rotation: Matrix3<f64>,
    pub placement_translation: Vector3<f64>,
    /// The moved body's inertial parameters ([`BODY_PARAM_NAMES`]), in the joint's frame.
    pub inertia: [f64; BODY_PARAMS],
    /// Position limits (rad or m; infinite when the URDF gives none), speed and effort limits.
    pub lower: f64,
    pub upper: f64,
    pub velocity_limit: f64,
    pub effort_limit: f64,
}

/// A serial chain of joints under gravity.
#[derive(Clone, Debug)]
pub struct Robot {
    pub name: String,
    pub joints: Vec<Joint>,
    /// Gravity's acceleration in the world frame (m/s²), (0, 0, −9.81) by default.
    pub gravity: Vector3<f64>,
    /// The URDF's movable joints that are not actuated (locked at zero, their bodies merged):
    /// the branches left out of a chain by default (a gripper's fingers).
    pub locked: Vec<String>,
}

/// Standard gravity's acceleration (m/s²): Pinocchio's default.
pub const STANDARD_GRAVITY: f64 = 9.81;

/// What Newton–Euler's passes leave behind ([`Robot::rnea_derivatives`] differentiates them).
struct NewtonEuler {
    poses: Vec<Pose>,
    vel: Vec<Motion>,
    acc: Vec<Motion>,
    /// The total force each joint transmits, in its body's frame.
    force: Vec<Force>,
    tau: Vec<f64>,
}

/// Inverse dynamics with its partial derivatives ([`Robot::rnea_derivatives`]).
#[derive(Clone, Debug, PartialEq)]
pub struct RneaDerivatives {
    /// The joint torques (forces on prismatic joints).
    pub tau: Vec<f64>,
    /// `∂τ/∂q`, n × n row-major.
    pub dtau_dq: Vec<f64>,
    /// `∂τ/∂q̇`, n × n row-major.
    pub dtau_dv: Vec<f64>,
}

/// Forward dynamics with its partial derivatives ([`Robot::aba_derivatives`]).
#[derive(Clone, Debug, PartialEq)]
pub struct AbaDerivatives {
    /// The accelerations.
    pub qdd: Vec<f64>,
    /// `∂q̈/∂q`, n × n row-major.
    pub dqdd_dq: Vec<f64>,
    /// `∂q̈/∂q̇`, n × n row-major.
    pub dqdd_dv: Vec<f64>,
    /// `∂q̈/∂τ`, the inverse of the mass matrix (with the armature), n × n row-major.
    pub dqdd_dtau: Vec<f64>,
}

impl Robot {
    /// The chain of `joints` (in order, each moving after the one before it), with standard gravity
    /// along −z.
    pub fn new(name: &str, joints: Vec<Joint>) -> Result<Self> {
        if joints.is_empty() {
            return Err(invalid!("a robot needs at least one actuated joint"));
        }
        for j in &joints {
            let n = j.axis.norm();
            if !(n > 0.0 && n.is_finite()) {
                return Err(invalid!(
                    "joint {}: its axis must be a non-zero finite vector",
                    j.name
                ));
            }
            if j.inertia.iter().any(|x| !x.is_finite()) {
                return Err(invalid!(
                    "joint {}: its body's inertial parameters must be finite",
                    j.name
                ));
            }
        }
        Ok(Robot {
            name: name.to_string(),
            joints,
            gravity: Vector3::new(0.0, 0.0, -STANDARD_GRAVITY),
            locked: Vec::new(),
        })
    }

    /// The chain of a URDF document: its actuated joints (revolute, continuous as revolute, or
    /// prismatic) from the root, fixed joints merged into the body before them. `joints` picks
    /// the actuated ones by name (the others are locked at zero and merged too); by default all.
    pub fn from_urdf(text: &str, joints: Option<&[String]>) -> Result<Self> {
        urdf::parse(text, joints)
    }

    /// Number of actuated joints.
    pub fn ndof(&self) -> usize {
        self.joints.len()
    }

    /// The names of the inertial parameters, `<param>_<joint>` body after body.
    pub fn param_names(&self) -> Vec<String> {
        self.joints
            .iter()
            .flat_map(|j| BODY_PARAM_NAMES.iter().map(move |p| format!("{p}_{}", j.name)))
            .collect()
    }

    /// Every body's inertial parameters, body after body (length 10·n).
    pub fn inertial_params(&self) -> Vec<f64> {
        self.joints.iter().flat_map(|j| j.inertia).collect()
    }

    /// This robot with other inertial parameters (length 10·n, as [`Robot::inertial_params`]).
    pub fn with_inertial_params(&self, pi: &[f64]) -> Result<Self> {
        if pi.len() != BODY_PARAMS * self.ndof() {
            return Err(invalid!(
                "expected {} inertial parameters (10 per joint), got {}",
                BODY_PARAMS * self.ndof(),
                pi.len()
            ));
        }
        let mut out = self.clone();
        for (j, chunk) in out.joints.iter_mut().zip(pi.chunks(BODY_PARAMS)) {
            j.inertia.copy_from_slice(chunk);
        }
        Ok(out)
    }

    fn check(&self, what: &str, x: &[f64]) -> Result<()> {
        if x.len() != self.ndof() {
            return Err(invalid!(
                "{what} has {} values; the robot has {} joints",
                x.len(),
                self.ndof()
            ));
        }
        if x.iter().any(|v| !v.is_finite()) {
            return Err(invalid!("{what} holds a non-finite value"));
        }
        Ok(())
    }

    /// Each joint's pose in the previous joint's frame at positions `q`.
    fn poses(&self, q: &[f64]) -> Vec<Pose> {
        self.joints
            .iter()
            .zip(q)
            .map(|(j, &qi)| match j.kind {
                JointKind::Revolute => Pose {
                    rotation: j.placement_rotation * spatial::rotation_about(&j.axis, qi),
                    translation: j.placement_translation,
                },
                JointKind::Prismatic => Pose {
                    rotation: j.placement_rotation,
                    translation: j.placement_translation + j.placement_rotation * (j.axis * qi),
                },
            })
            .collect()
    }

    /// The joint's motion subspace: its unit axis as a spatial motion.
    fn subspace(j: &Joint) -> Motion {
        let a = j.axis.normalize();
        match j.kind {
            JointKind::Revolute => Motion::new(a, Vector3::zeros()),
            JointKind::Prismatic => Motion::new(Vector3::zeros(), a),
        }
    }

    /// The forward pass of Newton–Euler: each body's pose, velocity and acceleration (gravity as
    /// an acceleration of the base when `with_gravity`).
    fn forward(
        &self,
        q: &[f64],
        v: &[f64],
        a: &[f64],
        with_gravity: bool,
    ) -> (Vec<Pose>, Vec<Motion>, Vec<Motion>) {
        let poses = self.poses(q);
        let n = self.ndof();
        let (mut vel, mut acc) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut vp = Motion::zero();
        let mut ap = if with_gravity {
            Motion::new(Vector3::zeros(), -self.gravity)
        } else {
            Motion::zero()
        };
        for i in 0..n {
            let s = Self::subspace(&self.joints[i]);
            let vi = poses[i].motion_to_child(&vp) + s.scale(v[i]);
            let ai = poses[i].motion_to_child(&ap) + s.scale(a[i]) + vi.cross(&s.scale(v[i]));
            vel.push(vi);
            acc.push(ai);
            vp = vi;
            ap = ai;
        }
        (poses, vel, acc)
    }

    /// Inverse dynamics (recursive Newton–Euler): the joint torques (N·m) or forces (N) that give
    /// accelerations `a` at positions `q` and speeds `v`, gravity included.
    pub fn rnea(&self, q: &[f64], v: &[f64], a: &[f64]) -> Result<Vec<f64>> {
        self.check("q", q)?;
        self.check("v", v)?;
        self.check("a", a)?;
        Ok(self.rnea_unchecked(q, v, a, true))
    }

    fn rnea_unchecked(&self, q: &[f64], v: &[f64], a: &[f64], with_gravity: bool) -> Vec<f64> {
        self.newton_euler(q, v, a, with_gravity).tau
    }

    /// Newton–Euler's passes, with what they leave behind: each body's pose, velocity, the total
    /// force its joint transmits (its own and its descendants'), and the joint torques.
    fn newton_euler(&self, q: &[f64], v: &[f64], a: &[f64], with_gravity: bool) -> NewtonEuler {
        let (poses, vel, acc) = self.forward(q, v, a, with_gravity);
        let n = self.ndof();
        let mut f: Vec<Force> = (0..n)
            .map(|i| {
                let pi = &self.joints[i].inertia;
                spatial::inertia_apply(pi, &acc[i]) + vel[i].cross_force(&spatial::inertia_apply(pi, &vel[i]))
            })
            .collect();
        let mut tau = vec![0.0; n];
        for i in (0..n).rev() {
            tau[i] = Self::subspace(&self.joints[i]).dot(&f[i]);
            if i > 0 {
                let fp = poses[i].force_to_parent(&f[i]);
                f[i - 1] = f[i - 1] + fp;
            }
        }
        NewtonEuler {
            poses,
            vel,
            acc,
            force: f,
            tau,
        }
    }

    /// Inverse dynamics and its exact partial derivatives at `q`, `v`, `a` (gravity included):
    /// the torques, `∂τ/∂q` and `∂τ/∂q̇` (n × n each, row-major: entry `(i, j)` is `∂τ_i/∂x_j`;
    /// `∂τ/∂q̈` is the mass matrix). Each column is Newton–Euler's passes differentiated along one
    /// coordinate (forward mode), on the values of one pass: a joint's transform `X_j` moves with
    /// its angle or stroke as `∂(X_j m)/∂q_j = −s_j × (X_j m)` for a motion and
    /// `∂(X_jᵀ f)/∂q_j = X_jᵀ (s_j ×* f)` for a force carried to the parent (`s_j` its motion
    /// subspace), and everything else by the product rule. The closed loop's sensitivities need
    /// these (`∂q̈/∂x = −M⁻¹ ∂τ/∂x`); checked against Pinocchio's `computeRNEADerivatives` and
    /// against central differences in the tests.
    pub fn rnea_derivatives(&self, q: &[f64], v: &[f64], a: &[f64]) -> Result<RneaDerivatives> {
        self.rnea_derivatives_and_mass(q, v, a, None)
    }

    /// [`Robot::rnea_derivatives`], and with `mass` (n × n) the mass matrix `∂τ/∂q̈` from the same
    /// pass's poses: each column Newton–Euler's passes on a unit acceleration of one joint, without
    /// speed nor gravity (the closed loop's sensitivities need both at every stage; the mass matrix
    /// by [`Robot::mass_matrix`] makes n passes of its own, each computing the poses again).
    pub(crate) fn rnea_derivatives_and_mass(
        &self,
        q: &[f64],
        v: &[f64],
        a: &[f64],
        mass: Option<&mut [f64]>,
    ) -> Result<RneaDerivatives> {
        self.check("q", q)?;
        self.check("v", v)?;
        self.check("a", a)?;
        let n = self.ndof();
        let ne = self.newton_euler(q, v, a, true);
        if let Some(m) = mass {
            if m.len() != n * n {
                return Err(invalid!(
                    "the mass matrix of {n} joints has {} values, got room for {}",
                    n * n,
                    m.len()
                ));
            }
            let mut force = vec![Force::zero(); n];
            for j in 0..n {
                let mut ta = Motion::zero();
                for i in 0..n {
                    if i < j {
                        force[i] = Force::zero();
                        continue;
                    }
                    ta = if i == j {
                        Self::subspace(&self.joints[i])
                    } else {
                        ne.poses[i].motion_to_child(&ta)
                    };
                    force[i] = spatial::inertia_apply(&self.joints[i].inertia, &ta);
                }
                for i in (0..n).rev() {
                    m[i * n + j] = Self::subspace(&self.joints[i]).dot(&force[i]);
                    if i > 0 {
                        let fp = ne.poses[i].force_to_parent(&force[i]);
                        force[i - 1] = force[i - 1] + fp;
                    }
                }
            }
            // exact symmetry (each column's rounding differs), as `mass_matrix`
            for i in 0..n {
                for j in 0..i {
                    let x = 0.5 * (m[i * n + j] + m[j * n + i]);
                    m[i * n + j] = x;
                    m[j * n + i] = x;
                }
            }
        }
        let sub: Vec<Motion> = self.joints.iter().map(Self::subspace).collect();
        let mut dq = vec![0.0; n * n];
        let mut dv = vec![0.0; n * n];
        let (mut dvel, mut dacc, mut dforce) = (
            vec![Motion::zero(); n],
            vec![Motion::zero(); n],
            vec![Force::zero(); n],
        );
        // what every direction reads: each body's parent's velocity and acceleration in its frame,
        // and its momentum
        let gravity = Motion::new(Vector3::zeros(), -self.gravity);
        let parent = |i: usize, m: &[Motion], root: Motion| if i == 0 { root } else { m[i - 1] };
        let xv: Vec<Motion> = (0..n)
            .map(|i| ne.poses[i].motion_to_child(&parent(i, &ne.vel, Motion::zero())))
            .collect();
        let xa: Vec<Motion> = (0..n)
            .map(|i| ne.poses[i].motion_to_child(&parent(i, &ne.acc, gravity)))
            .collect();
        let momentum: Vec<Force> = (0..n)
            .map(|i| spatial::inertia_apply(&self.joints[i].inertia, &ne.vel[i]))
            .collect();
        for (wrt_q, out) in [(true, &mut dq), (false, &mut dv)] {
            for j in 0..n {
                // forward: the tangents of the bodies' velocities and accelerations (zero before j)
                let (mut tvp, mut tap) = (Motion::zero(), Motion::zero());
                for i in 0..n {
                    let s = &sub[i];
                    let mut tv = ne.poses[i].motion_to_child(&tvp);
                    let mut ta = ne.poses[i].motion_to_child(&tap);
                    if i == j {
                        if wrt_q {
                            tv = tv + s.cross(&xv[i]).scale(-1.0);
                            ta = ta + s.cross(&xa[i]).scale(-1.0);
                        } else {
                            tv = tv + *s;
                        }
                    }
                    // a_i = X a_p + s a_i + v_i × (s q̇_i): the last term's tangent
                    ta = ta + tv.cross(&s.scale(v[i]));
                    if !wrt_q && i == j {
                        ta = ta + ne.vel[i].cross(s);
                    }
                    dvel[i] = tv;
                    dacc[i] = ta;
                    tvp = tv;
                    tap = ta;
                }
                // each body's own force's tangent, then the totals carried to the root
                for i in 0..n {
                    let pi = &self.joints[i].inertia;
                    dforce[i] = spatial::inertia_apply(pi, &dacc[i])
                        + dvel[i].cross_force(&momentum[i])
                        + ne.vel[i].cross_force(&spatial::inertia_apply(pi, &dvel[i]));
                }
                for i in (0..n).rev() {
                    out[i * n + j] = sub[i].dot(&dforce[i]);
                    if i > 0 {
                        let mut carried = dforce[i];
                        if wrt_q && i == j {
                            carried = carried + sub[i].cross_force(&ne.force[i]);
                        }
                        let fp = ne.poses[i].force_to_parent(&carried);
                        dforce[i - 1] = dforce[i - 1] + fp;
                    }
                }
            }
        }
        Ok(RneaDerivatives {
            tau: ne.tau,
            dtau_dq: dq,
            dtau_dv: dv,
        })
    }

    /// The joint torques of gravity alone at positions `q`.
    pub fn gravity_torque(&self, q: &[f64]) -> Result<Vec<f64>> {
        self.check("q", q)?;
        let z = vec![0.0; self.ndof()];
        Ok(self.rnea_unchecked(q, &z, &z, true))
    }

    /// Coriolis, centrifugal and gravity torques at positions `q` and speeds `v`.
    pub fn nonlinear_effects(&self, q: &[f64], v: &[f64]) -> Result<Vec<f64>> {
        self.check("q", q)?;
        self.check("v", v)?;
        Ok(self.rnea_unchecked(q, v, &vec![0.0; self.ndof()], true))
    }

    /// The joint-space mass matrix at positions `q` (n × n, symmetric positive definite for a
    /// physical robot), column by column from Newton–Euler without speed nor gravity.
    pub fn mass_matrix(&self, q: &[f64]) -> Result<DMatrix<f64>> {
        self.check("q", q)?;
        let n = self.ndof();
        let z = vec![0.0; n];
        let mut m = DMatrix::zeros(n, n);
        let mut e = vec![0.0; n];
        for k in 0..n {
            e[k] = 1.0;
            let col = self.rnea_unchecked(q, &z, &e, false);
            for (r, c) in col.iter().enumerate() {
                m[(r, k)] = *c;
            }
            e[k] = 0.0;
        }
        // exact symmetry (each column's rounding differs)
        let mt = m.transpose();
        Ok((m + mt) * 0.5)
    }

    /// Forward dynamics through the mass matrix and its Cholesky factor (the reference that
    /// [`Robot::aba`] is tested against).
    pub fn forward_dynamics_crba(
        &self,
        q: &[f64],
        v: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
    ) -> Result<Vec<f64>> {
        self.check("tau", tau)?;
        let nle = self.nonlinear_effects(q, v)?;
        let mut m = self.mass_matrix(q)?;
        if let Some(ia) = armature {
            self.check("armature", ia)?;
            for (i, x) in ia.iter().enumerate() {
                m[(i, i)] += x;
            }
        }
        let rhs = DVector::from_iterator(tau.len(), tau.iter().zip(&nle).map(|(t, c)| t - c));
        let chol = Cholesky::new(m).ok_or_else(|| {
            invalid!("the mass matrix is not positive definite at this configuration: the inertial parameters are not those of physical bodies")
        })?;
        Ok(chol.solve(&rhs).iter().copied().collect())
    }

    /// Forward dynamics and its exact partial derivatives at `q`, `v`, `tau` (with `armature` on
    /// the mass matrix's diagonal): the accelerations, `∂q̈/∂q`, `∂q̈/∂q̇` and `∂q̈/∂τ = (M + A)⁻¹`
    /// (n × n each, row-major). Differentiating `(M(q) + A) q̈ + h(q, q̇) = τ` at fixed `τ` gives
    /// `∂q̈/∂x = −(M + A)⁻¹ ∂τ_ID/∂x`, the inverse dynamics' derivatives at the accelerations
    /// themselves ([`Robot::rnea_derivatives`]); as Pinocchio's `computeABADerivatives`.
    pub fn aba_derivatives(
        &self,
        q: &[f64],
        v: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
    ) -> Result<AbaDerivatives> {
        let qdd = self.aba(q, v, tau, armature)?;
        let d = self.rnea_derivatives(q, v, &qdd)?;
        let n = self.ndof();
        let mut m = self.mass_matrix(q)?;
        if let Some(ia) = armature {
            for (i, x) in ia.iter().enumerate() {
                m[(i, i)] += x;
            }
        }
        let chol = Cholesky::new(m).ok_or_else(|| {
            invalid!("the mass matrix is not positive definite at this configuration: the inertial parameters are not those of physical bodies")
        })?;
        let minv = chol.inverse();
        let times = |jac: &[f64]| -> Vec<f64> {
            // −M⁻¹ J, row-major
            let j = DMatrix::from_row_slice(n, n, jac);
            let out = -(&minv * j);
            out.transpose().as_slice().to_vec()
        };
        Ok(AbaDerivatives {
            dqdd_dq: times(&d.dtau_dq),
            dqdd_dv: times(&d.dtau_dv),
            dqdd_dtau: minv.transpose().as_slice().to_vec(),
            qdd,
        })
    }

    /// The inverse-dynamics regressor at one state: `Y` (n × 10n, row-major) with
    /// `rnea(q, v, a) = Y · inertial_params()`, gravity included.
    pub fn regressor(&self, q: &[f64], v: &[f64], a: &[f64]) -> Result<Vec<f64>> {
        let n = self.ndof();
        let mut y = vec![0.0; n * BODY_PARAMS * n];
        self.regressor_into(q, v, a, &mut y)?;
        Ok(y)
    }

    /// [`Robot::regressor`] written into `y` (`n × 10n` values, row-major), without allocating
    /// it: for many states in a row ([`map_rows_into`]).
    pub fn regressor_into(&self, q: &[f64], v: &[f64], a: &[f64], y: &mut [f64]) -> Result<()> {
        self.check("q", q)?;
        self.check("v", v)?;
        self.check("a", a)?;
        let n = self.ndof();
        let p = BODY_PARAMS * n;
        if y.len() != n * p {
            return Err(invalid!(
                "the regressor of a {n}-joint robot has {} values, got room for {}",
                n * p,
                y.len()
            ));
        }
        let (poses, vel, acc) = self.forward(q, v, a, true);
        y.fill(0.0);
        // joint j's torque from body i's force f is s_j · X*_{j<-i} f = (X_{i<-j} s_j) · f: the
        // ancestors' axes carried out to each body (one motion transform per pair), rather than
        // each body's ten unit forces carried in to every ancestor (ten force transforms per pair)
        let mut axes: Vec<Motion> = Vec::with_capacity(n);
        for i in 0..n {
            if i > 0 {
                for m in axes.iter_mut() {
                    *m = poses[i].motion_to_child(m);
                }
            }
            axes.push(Self::subspace(&self.joints[i]));
            // the body's spatial force is linear in its parameters: one column per unit parameter
            for (k, c) in spatial::unit_forces(&acc[i], &vel[i]).iter().enumerate() {
                for (j, s) in axes.iter().enumerate() {
                    y[j * p + BODY_PARAMS * i + k] = s.dot(c);
                }
            }
        }
        Ok(())
    }
}

/// One function of a robot evaluated on many states: `inputs` are row-major arrays of `rows × n`
/// values (n = the robot's joints), `f` maps one row of each to `width` outputs; the rows are
/// computed in parallel and returned concatenated (`rows × width`).
pub fn map_rows(
    robot: &Robot,
    inputs: &[&[f64]],
    width: usize,
    f: impl Fn(&[&[f64]]) -> Result<Vec<f64>> + Sync,
) -> Result<Vec<f64>> {
    map_rows_into(robot, inputs, width, |row, dst| {
        let got = f(row)?;
        if got.len() != dst.len() {
            return Err(invalid!(
                "the function gave {} outputs per row, {} expected",
                got.len(),
                dst.len()
            ));
        }
        dst.copy_from_slice(&got);
        Ok(())
    })
}

/// [`map_rows`] with `f` writing each row's `width` outputs in place (`f(row, dst)`): no
/// allocation per row.
pub fn map_rows_into(
    robot: &Robot,
    inputs: &[&[f64]],
    width: usize,
    f: impl Fn(&[&[f64]], &mut [f64]) -> Result<()> + Sync,
) -> Result<Vec<f64>> {
    map_rows_with(robot, inputs, width, || (), |_, row, dst| f(row, dst))
}

/// How [`regressor_many`] lays out the regressor of many states.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RegressorLayout {
    /// `rows × n × m` values, row-major: state `r`'s joint `j`, column `c` at `(r * n + j) * m + c`.
    Rows,
    /// `n × m × rows` values: joint `j`'s column `c` over the states at `[(j * m + c) * rows..][..rows]`.
    /// Each joint's columns are then a column-major matrix of its own (what a decimation filters
    /// and a least squares takes), with no gather through a `rows × n × m` array (on a 4 kHz
    /// record of a 6-joint arm, 65 MB read back with a stride of a row).
    Series,
}

/// Samples per task of [`regressor_many`]: a block's rows are computed together and then written
/// to its piece of the output (one piece per series in [`RegressorLayout::Series`]), whose cache
/// lines they fill in turn.
const REGRESSOR_BLOCK: usize = 256;

/// The regressor ([`Robot::regressor`]) of many states, `q`, `v`, `a` row-major (`rows × n`
/// values each), keeping only the standard parameters `columns` (indices into the `10 n`, in any
/// order; all of them for `None`), laid out as `layout` says: `rows × n × m` values in all (m the
/// columns kept). The columns left out are never stored: a fit on a robot's base parameters
/// keeps about half of them, and the full array of a long record is tens of megabytes written
/// afresh. The blocks of states are computed in parallel.
pub fn regressor_many(
    robot: &Robot,
    q: &[f64],
    v: &[f64],
    a: &[f64],
    columns: Option<&[usize]>,
    layout: RegressorLayout,
) -> Result<Vec<f64>> {
    use rayon::prelude::*;
    let n = robot.ndof();
    let p = BODY_PARAMS * n;
    let all: Vec<usize>;
    let cols = match columns {
        Some(c) => {
            check_columns(c, n)?;
            c
        }
        None => {
            all = (0..p).collect();
            &all
        }
    };
    let rows = q.len() / n.max(1);
    for x in [q, v, a] {
        if x.len() != rows * n {
            return Err(invalid!(
                "every state array must have {n} columns (the robot's joints) and the same number of rows"
            ));
        }
    }
    let m = cols.len();
    let mut out = crate::error::filled(n * m * rows, 0.0, "the robot's regressor")?;
    if rows == 0 || m == 0 {
        return Ok(out);
    }
    // each block of states gets its disjoint pieces of `out`: one (its rows) or one per series
    let blocks = rows.div_ceil(REGRESSOR_BLOCK);
    let mut pieces: Vec<Vec<&mut [f64]>> = match layout {
        RegressorLayout::Rows => out
            .chunks_mut(REGRESSOR_BLOCK * n * m)
            .map(|piece| vec![piece])
            .collect(),
        RegressorLayout::Series => {
            let mut pieces: Vec<Vec<&mut [f64]>> = (0..blocks).map(|_| Vec::with_capacity(n * m)).collect();
            for series in out.chunks_mut(rows) {
                for (b, piece) in series.chunks_mut(REGRESSOR_BLOCK).enumerate() {
                    pieces[b].push(piece);
                }
            }
            pieces
        }
    };
    debug_assert_eq!(pieces.len(), blocks);
    pieces.par_iter_mut().enumerate().try_for_each_init(
        || vec![0.0; n * p],
        |full, (b, dst)| {
            let count = REGRESSOR_BLOCK.min(rows - b * REGRESSOR_BLOCK);
            for i in 0..count {
                let r = b * REGRESSOR_BLOCK + i;
                let s = r * n..(r + 1) * n;
                robot
                    .regressor_into(&q[s.clone()], &v[s.clone()], &a[s], full)
                    .map_err(|e| match e {
                        crate::Error::InvalidInput(msg) => invalid!("row {r}: {msg}"),
                        other => other,
                    })?;
                for j in 0..n {
                    let src = &full[j * p..(j + 1) * p];
                    match layout {
                        RegressorLayout::Rows => {
                            let row = &mut dst[0][(i * n + j) * m..(i * n + j + 1) * m];
                            for (o, &col) in row.iter_mut().zip(cols) {
                                *o = src[col];
                            }
                        }
                        RegressorLayout::Series => {
                            for (c, &col) in cols.iter().enumerate() {
                                dst[j * m + c][i] = src[col];
                            }
                        }
                    }
                }
            }
            Ok(())
        },
    )?;
    Ok(out)
}

fn check_columns(cols: &[usize], n: usize) -> Result<()> {
    let p = BODY_PARAMS * n;
    match cols.iter().find(|&&c| c >= p) {
        Some(&c) => Err(invalid!(
            "regressor column {c} is out of range: a {n}-joint robot has {p} standard parameters"
        )),
        None => Ok(()),
    }
}

/// [`map_rows_into`] with a scratch value per task (`init()`), passed to `f` with each row.
fn map_rows_with<S>(
    robot: &Robot,
    inputs: &[&[f64]],
    width: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, &[&[f64]], &mut [f64]) -> Result<()> + Sync,
) -> Result<Vec<f64>> {
    use rayon::prelude::*;
    let n = robot.ndof();
    let rows = inputs.first().map_or(0, |x| x.len() / n);
    for x in inputs {
        if x.len() != rows * n {
            return Err(invalid!(
                "every state array must have {n} columns (the robot's joints) and the same number of rows"
            ));
        }
    }
    let mut out = crate::error::filled(rows * width, 0.0, "the robot's outputs")?;
    out.par_chunks_mut(width.max(1)).enumerate().try_for_each_init(
        || (Vec::with_capacity(inputs.len()), init()),
        |(row, scratch): &mut (Vec<&[f64]>, S), (r, dst)| {
            row.clear();
            row.extend(inputs.iter().map(|x| &x[r * n..(r + 1) * n]));
            f(scratch, row, dst).map_err(|e| match e {
                crate::Error::InvalidInput(m) => invalid!("row {r}: {m}"),
                other => other,
            })
        },
    )?;
    Ok(out)
}

#[cfg(test)]
mod tests;
