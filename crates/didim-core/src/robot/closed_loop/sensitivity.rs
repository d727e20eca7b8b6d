//! The forward sensitivities of a robot's closed loop: the exact derivatives of the simulated
//! forces with respect to the plant's physical parameters along given directions, the tangent of
//! the very arithmetic [`super::simulate_robot`] does (RK4's stages, each drive's controller,
//! delay and force lag, the starting state), riding along it.
//!
//! The physical parameters, flattened ([`PhysLayout`]): each joint's rotor inertia, the bodies'
//! inertial parameters (10 per body, [`crate::robot::Robot::inertial_params`]' order), each joint's viscous and
//! Coulomb friction, offset, stiffness, damping, backlash width, load-dependent friction μ and
//! friction smoothing speed ε, then the joints' extra terms' values (joint by joint, each joint's
//! in [`Drives::terms`]' order). A direction is a column of `∂φ/∂χ`: the caller's parameters `χ`
//! (base parameters, logs, scales) map to these, and the sensitivities are `∂force/∂χ`.
//!
//! At each stage the link side's accelerations answer `RNEA(q, q̇, q̈) + A q̈ = τ`, so that
//!
//! ```text
//!   (M + A) dq̈ = dτ − ∂RNEA/∂q dq − ∂RNEA/∂q̇ dq̇ − Y(q, q̇, q̈) dπ − dA q̈
//! ```
//!
//! ([`crate::robot::Robot::rnea_derivatives`], [`crate::robot::Robot::regressor_into`]); τ's own derivatives are those of each
//! joint's friction and terms (rigid) or its spring (elastic), the rotors' equations are scalar,
//! and the load-dependent friction's fixed point is differentiated as a fixed point (the same
//! contraction of rate μ). The first state's links, settled on their springs, are differentiated
//! through their rest equation `K (θ − q) = g(q)`.

use nalgebra::{Cholesky, DMatrix};

use super::{sign, ArmTangent, Drives, Dynamics};
use crate::error::{filled, invalid, Error, Result};
use crate::model::dead_zone;
use crate::robot::BODY_PARAMS;
use crate::sim::drive::JointDrive;
use crate::sim::driver::CommandSens;

/// Where each physical parameter sits in the flattened vector the directions are columns of.
#[derive(Clone, Copy, Debug)]
pub struct PhysLayout {
    /// Joints.
    pub n: usize,
    /// Extra terms, all joints together.
    pub terms: usize,
}

impl PhysLayout {
    /// The layout of a robot of `n` joints whose drives carry `drives.terms`.
    pub fn of(n: usize, drives: &Drives) -> Self {
        Self {
            n,
            terms: drives.terms.iter().map(Vec::len).sum(),
        }
    }
    /// The number of physical parameters: `19 n + terms`.
    pub fn len(&self) -> usize {
        19 * self.n + self.terms
    }
    /// Whether there is none (a robot of no joint).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn armature(&self, j: usize) -> usize {
        j
    }
    /// Body `i`'s inertial parameter `k` (0–9).
    pub fn body(&self, i: usize, k: usize) -> usize {
        self.n + BODY_PARAMS * i + k
    }
    pub fn viscous(&self, j: usize) -> usize {
        11 * self.n + j
    }
    pub fn coulomb(&self, j: usize) -> usize {
        12 * self.n + j
    }
    pub fn offset(&self, j: usize) -> usize {
        13 * self.n + j
    }
    pub fn stiffness(&self, j: usize) -> usize {
        14 * self.n + j
    }
    pub fn damping(&self, j: usize) -> usize {
        15 * self.n + j
    }
    pub fn backlash(&self, j: usize) -> usize {
        16 * self.n + j
    }
    pub fn load_friction(&self, j: usize) -> usize {
        17 * self.n + j
    }
    pub fn eps(&self, j: usize) -> usize {
        18 * self.n + j
    }
    /// The `t`-th extra term, counting joint by joint.
    pub fn term(&self, t: usize) -> usize {
        19 * self.n + t
    }
}

/// The most fixed-point steps of the load-dependent friction's tangent (a contraction of rate μ,
/// as the simulation's own).
const LOAD_TANGENT_ITERATIONS: usize = 60;

/// The forward sensitivities riding along a robot's loop: the state's `dx` (`m × p`, the state's
/// index major), RK4's stage tangents, each joint's command tangent and the work buffers.
pub(super) struct Sensitivities<'d> {
    p: usize,
    n: usize,
    lay: PhysLayout,
    /// The directions, `lay.len() × p` row-major.
    dirs: &'d [f64],
    dx: Vec<f64>,
    dxs: Vec<f64>,
    dk: [Vec<f64>; 4],
    /// The applied forces' tangent over the period (`n × p`).
    du: Vec<f64>,
    cmd: Vec<CommandSens>,
    // work
    y: Vec<f64>,
    mass: Vec<f64>,
    scratch: Vec<f64>,
    /// The chain's right-hand side, with the load's tangent, and its solution (p × n each).
    base: DMatrix<f64>,
    rhs: DMatrix<f64>,
    sol: DMatrix<f64>,
    dtau: Vec<f64>,
    dload: Vec<f64>,
    coef_load: Vec<f64>,
    /// Each term's index in the layout, per joint: the first.
    term_start: Vec<usize>,
}

/// A row of the directions.
#[inline(always)]
fn row(dirs: &[f64], p: usize, i: usize) -> &[f64] {
    &dirs[i * p..(i + 1) * p]
}

/// `out += a · x`.
#[inline(always)]
fn axpy(out: &mut [f64], a: f64, x: &[f64]) {
    if a != 0.0 {
        for (o, v) in out.iter_mut().zip(x) {
            *o += a * v;
        }
    }
}

impl<'d> Sensitivities<'d> {
    /// The sensitivities along `dirs` (`PhysLayout::len() × p`) of the loop of `dynamics` from its
    /// first state `x0` over `samples` samples; `dext` (`n × p`) the tangent of the force each
    /// drive adds to its commands; each joint's delay (samples) and force lag (s) at period `dt`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        dynamics: &Dynamics,
        x0: &[f64],
        samples: usize,
        dirs: &'d [f64],
        p: usize,
        dext: &[f64],
        delay: &[usize],
        lag: &[f64],
        dt: f64,
    ) -> Result<Self> {
        let robot = dynamics.robot;
        let n = robot.ndof();
        let m = x0.len();
        let lay = PhysLayout::of(n, dynamics.drives);
        let cmd = (0..n)
            .map(|j| {
                CommandSens::holding(
                    samples,
                    delay.get(j).copied().unwrap_or(0),
                    lag.get(j).copied().unwrap_or(0.0),
                    dt,
                    dext[j * p..(j + 1) * p].to_vec(),
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let mut term_start = Vec::with_capacity(n);
        let mut t = 0;
        for j in 0..n {
            term_start.push(lay.term(t));
            t += dynamics.drives.terms.get(j).map_or(0, Vec::len);
        }
        let mut out = Self {
            p,
            n,
            lay,
            dirs,
            dx: filled(m * p, 0.0, "the state's sensitivities")?,
            dxs: vec![0.0; m * p],
            dk: [
                vec![0.0; m * p],
                vec![0.0; m * p],
                vec![0.0; m * p],
                vec![0.0; m * p],
            ],
            du: vec![0.0; n * p],
            cmd,
            y: vec![0.0; n * BODY_PARAMS * n],
            mass: vec![0.0; n * n],
            scratch: vec![0.0; p],
            base: DMatrix::zeros(p, n),
            rhs: DMatrix::zeros(p, n),
            sol: DMatrix::zeros(p, n),
            dtau: vec![0.0; n * p],
            dload: vec![0.0; n * p],
            coef_load: vec![0.0; n],
            term_start,
        };
        out.settled(dynamics, x0)?;
        Ok(out)
    }

    /// The first state's tangent: the elastic joints' links at rest on their springs,
    /// `q_j = θ_j − g_j(q)/K_j − sign(g_j) b_j/2` (rotors on their references, speeds 0, rigid
    /// joints on their references: none moves with the parameters).
    fn settled(&mut self, dynamics: &Dynamics, x0: &[f64]) -> Result<()> {
        let (n, p) = (self.n, self.p);
        let elastic = &dynamics.elastic;
        if elastic.is_empty() {
            return Ok(());
        }
        let (robot, drives) = (dynamics.robot, dynamics.drives);
        let q = &x0[..n];
        let rest = vec![0.0; n];
        let gd = robot.rnea_derivatives(q, &rest, &rest)?;
        robot.regressor_into(q, &rest, &rest, &mut self.y)?;
        let ne = elastic.len();
        let mut a = DMatrix::<f64>::zeros(ne, ne);
        let mut b = DMatrix::<f64>::zeros(ne, p);
        for (e, &j) in elastic.iter().enumerate() {
            let k = drives.stiffness[j];
            for (f, &i) in elastic.iter().enumerate() {
                a[(e, f)] = gd.dtau_dq[j * n + i] / k + if e == f { 1.0 } else { 0.0 };
            }
            let g = gd.tau[j];
            let mut r = vec![0.0; p];
            self.body_part(j, &mut r, -1.0 / k);
            axpy(&mut r, g / (k * k), row(self.dirs, p, self.lay.stiffness(j)));
            axpy(&mut r, -0.5 * sign(g), row(self.dirs, p, self.lay.backlash(j)));
            for c in 0..p {
                b[(e, c)] = r[c];
            }
        }
        let sol = a
            .lu()
            .solve(&b)
            .ok_or_else(|| Error::Simulation("the links' rest on their springs is singular".into()))?;
        for (e, &j) in elastic.iter().enumerate() {
            for c in 0..p {
                self.dx[j * p + c] = sol[(e, c)];
            }
        }
        Ok(())
    }

    /// `out += scale · (Y dπ)_j`, the regressor `self.y`'s row `j` on the bodies' directions.
    #[inline(always)]
    fn body_part(&self, j: usize, out: &mut [f64], scale: f64) {
        let (n, p) = (self.n, self.p);
        let width = BODY_PARAMS * n;
        for k in 0..width {
            let yk = self.y[j * width + k];
            if yk != 0.0 {
                axpy(
                    out,
                    scale * yk,
                    row(self.dirs, p, self.lay.body(k / BODY_PARAMS, k % BODY_PARAMS)),
                );
            }
        }
    }

    /// The sensitivities of the simulated forces, `[joint][direction][sample]`.
    pub fn forces(self) -> Vec<f64> {
        self.cmd.into_iter().flat_map(|c| c.dforce).collect()
    }

    /// Adds to `out` (one per direction) the tangent of joint `j`'s friction, offset and terms at
    /// position `x` and speed `v` (of tangents `dx`, `dv`), with its load-dependent friction under
    /// the load `load`; returns the coefficient of the load's own tangent in it.
    #[allow(clippy::too_many_arguments)]
    fn resist_tangent(
        &self,
        drives: &Drives,
        j: usize,
        x: f64,
        v: f64,
        dx: &[f64],
        dv: &[f64],
        load: f64,
        out: &mut [f64],
    ) -> f64 {
        let (lay, p, dirs) = (self.lay, self.p, self.dirs);
        let law = drives.laws[j];
        let (s, ds) = law.sign_and_derivative(v);
        let s_eps = law.eps_derivative(v);
        let (mut r_x, mut r_v, mut r_eps) = (
            0.0,
            drives.viscous[j] + drives.coulomb[j] * ds,
            drives.coulomb[j] * s_eps,
        );
        axpy(out, v, row(dirs, p, lay.viscous(j)));
        axpy(out, s, row(dirs, p, lay.coulomb(j)));
        axpy(out, 1.0, row(dirs, p, lay.offset(j)));
        if let Some(terms) = drives.terms.get(j) {
            for (t, (b, value)) in terms.iter().enumerate() {
                let (phi, dphi_x, dphi_v) = b.local(x, v, law);
                r_x += value * dphi_x;
                r_v += value * dphi_v;
                r_eps += value * b.local_eps(x, v, law);
                axpy(out, phi, row(dirs, p, self.term_start[j] + t));
            }
        }
        let mut coef_load = 0.0;
        if let Some(&mu) = drives.load_friction.get(j) {
            if mu != 0.0 {
                let a = load.abs();
                axpy(out, s * a, row(dirs, p, lay.load_friction(j)));
                r_v += mu * ds * a;
                r_eps += mu * s_eps * a;
                coef_load = mu * s * sign(load);
            }
        }
        for c in 0..p {
            out[c] += r_x * dx[c] + r_v * dv[c];
        }
        axpy(out, r_eps, row(dirs, p, lay.eps(j)));
        coef_load
    }

    /// The tangent of the state's derivative at stage `i`: `dk[i] = J(x) · dxs`.
    fn derivative(&mut self, d: &Dynamics, i: usize, x: &[f64], f: &[f64]) -> Result<()> {
        let (n, p, lay) = (self.n, self.p, self.lay);
        let (robot, drives) = (d.robot, d.drives);
        let ne = d.elastic.len();
        let (q, v) = (&x[..n], &x[n..2 * n]);
        let qdd = &f[n..2 * n];
        let dxs = std::mem::take(&mut self.dxs);
        let mut out = std::mem::take(&mut self.dk[i]);
        let dq = |j: usize| &dxs[j * p..(j + 1) * p];
        let dv = |j: usize| &dxs[(n + j) * p..(n + j + 1) * p];
        // q̇' = q̇, θ̇' = ω
        out[..n * p].copy_from_slice(&dxs[n * p..2 * n * p]);
        out[2 * n * p..(2 * n + ne) * p].copy_from_slice(&dxs[(2 * n + ne) * p..]);
        // each joint's torque's tangent, less the load-dependent friction's load term
        let mut dtau = std::mem::take(&mut self.dtau);
        let mut scratch = std::mem::take(&mut self.scratch);
        for j in 0..n {
            let dt = &mut dtau[j * p..(j + 1) * p];
            dt.copy_from_slice(&self.du[j * p..(j + 1) * p]);
            self.coef_load[j] = 0.0;
            if d.is_elastic(j) {
                continue;
            }
            scratch.fill(0.0);
            let c = self.resist_tangent(drives, j, q[j], v[j], dq(j), dv(j), d.load[j], &mut scratch);
            for (t, s) in dt.iter_mut().zip(&scratch) {
                *t -= s;
            }
            self.coef_load[j] = -c;
        }
        for (e, &j) in d.elastic.iter().enumerate() {
            let (th, om) = (x[2 * n + e], x[2 * n + ne + e]);
            let dth = &dxs[(2 * n + e) * p..(2 * n + e + 1) * p];
            let dom = &dxs[(2 * n + ne + e) * p..(2 * n + ne + e + 1) * p];
            let (stretch, rate) = (th - q[j], om - v[j]);
            let k = drives.stiffness[j];
            let damping = drives.damping.get(j).copied().unwrap_or(0.0);
            let gap = drives.backlash.get(j).copied().unwrap_or(0.0);
            let s = if gap == 0.0 {
                stretch
            } else {
                dead_zone(stretch, gap)
            };
            let dspring = &mut dtau[j * p..(j + 1) * p];
            dspring.fill(0.0);
            if gap == 0.0 || s != 0.0 {
                for c in 0..p {
                    dspring[c] = k * (dth[c] - dq(j)[c]) + damping * (dom[c] - dv(j)[c]);
                }
                axpy(dspring, s, row(self.dirs, p, lay.stiffness(j)));
                axpy(dspring, rate, row(self.dirs, p, lay.damping(j)));
                if gap != 0.0 {
                    axpy(
                        dspring,
                        -0.5 * k * sign(stretch),
                        row(self.dirs, p, lay.backlash(j)),
                    );
                }
            }
            // the rotor: Ia ω̇ = u − friction(θ, ω; spring) − spring
            let spring = d.drives.spring(j, stretch, rate);
            scratch.fill(0.0);
            let c = self.resist_tangent(drives, j, th, om, dth, dom, spring, &mut scratch);
            let ia = drives.armature[j];
            let wdot = f[2 * n + ne + e];
            let dia = row(self.dirs, p, lay.armature(j));
            let du = &self.du[j * p..(j + 1) * p];
            let row_out = &mut out[(2 * n + ne + e) * p..(2 * n + ne + e + 1) * p];
            for cc in 0..p {
                let dspring_c = dtau[j * p + cc];
                row_out[cc] = (du[cc] - scratch[cc] - c * dspring_c - dspring_c) / ia - wdot / ia * dia[cc];
            }
        }
        // the chain: (M + A) dq̈ = dτ − ∂RNEA/∂q dq − ∂RNEA/∂q̇ dq̇ − Y dπ − dA q̈
        let rd = robot.rnea_derivatives_and_mass(q, v, qdd, Some(&mut self.mass))?;
        robot.regressor_into(q, v, qdd, &mut self.y)?;
        // symmetric: its row-major values are its column-major ones
        let mut mm = DMatrix::from_column_slice(n, n, &self.mass);
        for j in 0..n {
            mm[(j, j)] += d.link_armature[j];
        }
        let chol = Cholesky::new(mm).ok_or_else(|| {
            invalid!("the mass matrix is not positive definite along the loop: the inertial parameters are not those of physical bodies")
        })?;
        // each joint's p directions contiguous (column j of the p × n buffers). Every direction's value is
        // the same sequence of operations whatever the other directions are (elementwise over the directions, in
        // a fixed order over the joints and the bodies' parameters): the sensitivities do not depend on how the
        // directions are split between calls, nor on the processor (no kernel chosen at run time)
        let mut base = std::mem::replace(&mut self.base, DMatrix::zeros(0, 0));
        base.copy_from_slice(&dtau);
        for j in 0..n {
            let mut col = base.column_mut(j);
            let b = col.as_mut_slice();
            for i in 0..n {
                axpy(b, -rd.dtau_dq[j * n + i], dq(i));
                axpy(b, -rd.dtau_dv[j * n + i], dv(i));
            }
            self.body_part(j, b, -1.0);
            if !d.is_elastic(j) {
                axpy(b, -qdd[j], row(self.dirs, p, lay.armature(j)));
            }
        }
        // dq̈_j = Σ_i (M + A)⁻¹_ji rhs_i
        let minv = chol.inverse();
        let loaded = d.has_load && (0..n).any(|j| self.coef_load[j] != 0.0);
        self.dload.fill(0.0);
        let mut rhs = std::mem::replace(&mut self.rhs, DMatrix::zeros(0, 0));
        rhs.copy_from(&base);
        let mut sol = std::mem::replace(&mut self.sol, DMatrix::zeros(0, 0));
        for it in 0..=LOAD_TANGENT_ITERATIONS {
            if it > 0 {
                rhs.copy_from(&base);
                for j in 0..n {
                    axpy(
                        rhs.column_mut(j).as_mut_slice(),
                        self.coef_load[j],
                        &self.dload[j * p..(j + 1) * p],
                    );
                }
            }
            sol.fill(0.0);
            for j in 0..n {
                let mut col = sol.column_mut(j);
                let out = col.as_mut_slice();
                for i in 0..n {
                    axpy(out, minv[(j, i)], rhs.column(i).as_slice());
                }
            }
            if !loaded {
                break;
            }
            // the load the rigid joints' friction grows with: τ_j − A_j q̈_j
            let mut change: f64 = 0.0;
            let mut scale: f64 = 1e-300;
            for j in 0..n {
                if self.coef_load[j] == 0.0 {
                    continue;
                }
                let dia = row(self.dirs, p, lay.armature(j));
                for c in 0..p {
                    let new = dtau[j * p + c] + self.coef_load[j] * self.dload[j * p + c]
                        - dia[c] * qdd[j]
                        - d.link_armature[j] * sol[(c, j)];
                    change = change.max((new - self.dload[j * p + c]).abs());
                    scale = scale.max(new.abs());
                    self.dload[j * p + c] = new;
                }
            }
            if change <= 1e-14 * scale || it == LOAD_TANGENT_ITERATIONS {
                break;
            }
        }
        out[n * p..2 * n * p].copy_from_slice(sol.as_slice());
        self.dtau = dtau;
        self.dxs = dxs;
        self.dk[i] = out;
        (self.scratch, self.base, self.rhs, self.sol) = (scratch, base, rhs, sol);
        Ok(())
    }
}

impl ArmTangent for Sensitivities<'_> {
    fn commanded(&mut self, k: usize, j: usize, drive: &JointDrive, active: bool, encoder: usize) {
        let p = self.p;
        let dx = &self.dx[encoder * p..(encoder + 1) * p];
        self.cmd[j].command(k, drive.law(), active, |c| dx[c]);
        self.du[j * p..(j + 1) * p].copy_from_slice(&self.cmd[j].dtau);
    }

    fn stage(&mut self, dynamics: &Dynamics, i: usize, h: f64, x: &[f64], f: &[f64]) -> Result<()> {
        let w = [0.0, 0.5, 0.5, 1.0][i] * h;
        if i == 0 {
            self.dxs.copy_from_slice(&self.dx);
        } else {
            for ((s, x), k) in self.dxs.iter_mut().zip(&self.dx).zip(&self.dk[i - 1]) {
                *s = x + w * k;
            }
        }
        self.derivative(dynamics, i, x, f)
    }

    fn end(&mut self, h: f64) {
        let w = h / 6.0;
        let [k1, k2, k3, k4] = &self.dk;
        for (i, x) in self.dx.iter_mut().enumerate() {
            *x += w * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
}
