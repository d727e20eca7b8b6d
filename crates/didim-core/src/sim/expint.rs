//! The exponential integrator of the closed loop ([`Integrator::Exponential`], the default).
//!
//! With `x = (q, q̇)` the direct model (eqs. (5), (9)) splits into an affine part and
//! the rest:
//!
//! `ẋ = A x + b(τ) + (0, g(x))`, `g(q, q̇) = −M⁻¹ Σ_{non-affine j} χ_j φ_j(q, q̇)`,
//!
//! where `A` and `b` hold every [`Basis::is_affine`] term (viscous friction, springs,
//! offsets) and the held command `τ`, and `g` every other non-inertial term (the smooth
//! Coulomb sign, and any nonlinear term a model adds). Over a step `h` the affine part is
//! propagated exactly by `E = e^{Ah}` and the held force by `h φ1(Ah)` (the exact
//! zero-order-hold discretization), and `g` enters through the variation-of-constants
//! formula with `g` interpolated linearly in time between the ends of the step (the
//! second-order exponential time-differencing scheme, implicit in the end value):
//!
//! `x_{n+1} = E x_n + h φ1(Ah) (b + g_n) + h φ2(Ah) (g_{n+1} − g_n)`, `g_{n+1} = g(x_{n+1})`,
//!
//! solved by Newton on `g_{n+1}` with the partial derivatives of the same basis functions
//! ([`Basis::accumulate_partials`]). The matrices `E`, `h φ1(Ah)`, `h φ2(Ah)` come from one
//! matrix exponential per parameter set and step length. Being implicit, the scheme is not
//! limited by the stiff slope of the Coulomb sign at rest (`Fc / (ε M)`, about 2000 1/s on
//! the EMPS); being exact for the affine part, it is exact for a model without nonlinear
//! term, whatever the step.
//!
//! Step control: a sample period is integrated in one step when `g` is close to linear in
//! time over it, judged by `g` at the midpoint of the step against the mean of its end
//! values (defect `d`); the quadratic part of `g` that the scheme ignores moves the state by
//! about `h²/3·|d|` (positions) and `2h/3·|d|` (velocities). When `2h/3·|d|·T` exceeds
//! `tol` times the reference stroke, the step is halved, recursively down to `T / 2^12`.
//! The steps depend only on the inputs, so a simulation is deterministic.

use super::driver::{CommandSens, Stepper, Tangent, V};
use super::SimOptions;
use crate::controller::TransferFunction;
use crate::error::{filled, invalid, Error, Result};
use crate::model::{Basis, FrictionLaw, Law, Model};
use nalgebra::{DMatrix, SMatrix};

type Mat<const N: usize> = SMatrix<f64, N, N>;

/// Deepest halving of the sample period (`T / 4096`).
pub(super) const MAX_LEVEL: usize = 12;
const MAX_NEWTON: usize = 8;
/// A quick step whose predicted change of `g` missed by more than this many times the
/// step's `g` scale (300 × the quick step's own threshold) is halved at once, without the
/// implicit solve and the midpoint test: `g` bends so much over such a step (a Coulomb sign
/// reversing) that the midpoint test rejects it anyway (on the EMPS record 731 of 742 such
/// steps were rejected after the solve, which cost 4 evaluations of `g` each). Halving
/// only makes the step smaller; stiff steps, which the solve must stabilise, and the
/// deepest level still take the implicit path.
const EARLY_HALVING: f64 = 30.0;

/// The propagators of one step length `h`, split in `N × N` blocks:
/// `E = [[eqq, eqv], [evq, evv]]`, `h φ1(Ah) B = [p1q; p1v]`, `h φ2(Ah) B = [p2q; p2v]`
/// with `B = (0, I)` (the inputs act on the accelerations).
#[derive(Clone, Copy, Debug)]
pub(super) struct Level<const N: usize> {
    pub h: f64,
    /// `1 / h`.
    pub inv_h: f64,
    /// `atol / (h T)`: the change of `g` (an acceleration) over the step that moves the
    /// velocity by about the tolerance over a sample period (see [`Plant::try_step`]).
    pub g_scale: f64,
    pub eqq: Mat<N>,
    pub eqv: Mat<N>,
    pub evq: Mat<N>,
    pub evv: Mat<N>,
    pub p1q: Mat<N>,
    pub p1v: Mat<N>,
    pub p2q: Mat<N>,
    pub p2v: Mat<N>,
}

/// A non-affine term of `g`: it adds `φ(x, ẋ) · dir` to the force sum and `∂φ · outer`
/// to its partials, with `d` the term's direction ([`Basis::direction`]), `dir = −χ d` and
/// `outer = dir dᵀ`; `g` is that sum divided by the masses (after the sum, so that a huge
/// parameter times a zero basis function stays zero).
#[derive(Clone, Copy, Debug)]
struct GTerm<const N: usize> {
    basis: Basis,
    dir: V<N>,
    outer: Mat<N>,
}

/// The plant of one parameter set, split for the exponential integrator; `L` its friction
/// law, a [`FrictionLaw`] or a [`crate::model::Shaped`] one whose shape is a type (a
/// simulation's loop is compiled per shape, see [`FrictionLaw::dispatch`]).
pub(super) struct Plant<const N: usize, L: Law = FrictionLaw> {
    pub inv_mass: V<N>,
    /// `q̈_affine = aq q + av q̇ + a0` (without the command).
    pub aq: Mat<N>,
    pub av: Mat<N>,
    pub a0: V<N>,
    /// The non-affine, non-inertial terms, each ready to add its acceleration.
    terms: Vec<GTerm<N>>,
    /// `Some(c)` when every term of `terms` is a plain Coulomb term, at most one per dof
    /// (the rigid and flexible models): `c[d] = −Fc_d` (0 where dof `d` has none), and `g`
    /// and its partials are read off the friction law per dof, without a loop over the terms
    /// and a branch on each term's kind. The same operations as the loop's (see
    /// [`Plant::g_and_partials`]).
    coulomb: Option<V<N>>,
    pub law: L,
    pub dt: f64,
    /// Absolute position tolerance of one step (m).
    pub atol: f64,
    levels: Vec<Option<Level<N>>>,
    /// Steps taken and steps rejected (halved), for diagnostics.
    pub steps: usize,
    pub rejected: usize,
    /// Steps that needed the implicit solve.
    pub implicit: std::cell::Cell<usize>,
    /// The change of `g` over the last accepted step and the inverse of that step's length.
    last_dg: std::cell::Cell<V<N>>,
    last_inv_h: std::cell::Cell<f64>,
}

impl<const N: usize, L: Law> Plant<N, L> {
    /// The plant of `model` with parameters `chi` and the friction law `law` (the model's,
    /// with its shape static or not).
    pub fn new(model: &Model<N>, chi: &[f64], law: L, dt: f64, atol: f64) -> Result<Self> {
        debug_assert_eq!(law.law(), model.law());
        let inv_mass = model.masses(chi).map(|m| 1.0 / m);
        let zero = V::<N>::zeros();
        let affine: Vec<(Basis, f64)> = model
            .basis()
            .iter()
            .zip(chi)
            .filter(|(b, _)| b.is_affine())
            .map(|(b, &x)| (*b, x))
            .collect();
        let terms: Vec<GTerm<N>> = model
            .basis()
            .iter()
            .zip(chi)
            .filter(|(b, _)| !b.is_affine() && !b.is_inertia())
            .map(|(b, &x)| {
                let d = b.direction::<N>();
                let dir = -(d * x);
                GTerm {
                    basis: *b,
                    dir,
                    outer: dir * d.transpose(),
                }
            })
            .collect();
        // The affine forces F(q, q̇) = Kq q + Kv q̇ + c, read off the basis functions.
        let force = |q: &V<N>, v: &V<N>| {
            let mut f = V::<N>::zeros();
            for (b, x) in &affine {
                b.accumulate(*x, q, v, &zero, law, &mut f);
            }
            f
        };
        let c = force(&zero, &zero);
        let mut aq = Mat::<N>::zeros();
        let mut av = Mat::<N>::zeros();
        for e in 0..N {
            let mut unit = zero;
            unit[e] = 1.0;
            let fq = force(&unit, &zero) - c;
            let fv = force(&zero, &unit) - c;
            for d in 0..N {
                aq[(d, e)] = -inv_mass[d] * fq[d];
                av[(d, e)] = -inv_mass[d] * fv[d];
            }
        }
        let a0 = -c.component_mul(&inv_mass);
        let coulomb = {
            let mut c = V::<N>::zeros();
            let mut seen = [false; N];
            let plain = terms.iter().all(|t| match t.basis {
                Basis::Coulomb { dof } if !seen[dof] => {
                    seen[dof] = true;
                    c[dof] = t.dir[dof];
                    true
                }
                _ => false,
            });
            plain.then_some(c)
        };
        let plant = Self {
            inv_mass,
            aq,
            av,
            a0,
            terms,
            coulomb,
            law,
            dt,
            atol,
            levels: vec![None; MAX_LEVEL + 2],
            steps: 0,
            rejected: 0,
            implicit: std::cell::Cell::new(0),
            last_dg: std::cell::Cell::new(V::<N>::zeros()),
            last_inv_h: std::cell::Cell::new(1.0 / dt),
        };
        Ok(plant)
    }

    /// Computes the propagators of level `l` (step `dt / 2^l`) if not done yet.
    pub fn ensure(&mut self, l: usize) -> Result<()> {
        if self.levels[l].is_none() {
            self.levels[l] = Some(self.propagators(self.dt / (1u64 << l) as f64)?);
        }
        Ok(())
    }

    #[inline(always)]
    pub fn level(&self, l: usize) -> &Level<N> {
        self.levels[l].as_ref().expect("level computed by ensure")
    }

    /// The block matrix `Z = [[Ah, B, 0], [0, 0, I], [0, 0, 0]]` (size `4N`), whose
    /// exponential has the first block row `[e^{Ah}, φ1(Ah) B, φ2(Ah) B]`.
    fn augmented(aq: &Mat<N>, av: &Mat<N>, h: f64, with_inputs: bool) -> DMatrix<f64> {
        let n2 = 2 * N;
        let mut m = DMatrix::<f64>::zeros(4 * N, 4 * N);
        for d in 0..N {
            if with_inputs {
                m[(d, N + d)] = h; // q̇ row block of A h
                m[(N + d, n2 + d)] = 1.0; // B
                m[(n2 + d, n2 + N + d)] = 1.0; // I
            }
            for e in 0..N {
                m[(N + d, e)] = h * aq[(d, e)];
                m[(N + d, N + e)] = h * av[(d, e)];
            }
        }
        m
    }

    /// Reads `E`, `h φ1 B`, `h φ2 B` from the first `2N` rows of `x` starting at column `c0`.
    fn blocks(x: &DMatrix<f64>, c0: usize, h: f64) -> Level<N> {
        let n2 = 2 * N;
        let block =
            |r0: usize, c: usize, scale: f64| Mat::<N>::from_fn(|i, j| scale * x[(r0 + i, c0 + c + j)]);
        Level {
            h,
            inv_h: 1.0 / h,
            g_scale: f64::NAN,
            eqq: block(0, 0, 1.0),
            eqv: block(0, N, 1.0),
            evq: block(N, 0, 1.0),
            evv: block(N, N, 1.0),
            p1q: block(0, n2, h),
            p1v: block(N, n2, h),
            p2q: block(0, n2 + N, h),
            p2v: block(N, n2 + N, h),
        }
    }

    /// `E`, `h φ1(Ah) B`, `h φ2(Ah) B` for a step `h`.
    fn propagators(&self, h: f64) -> Result<Level<N>> {
        let z = Self::augmented(&self.aq, &self.av, h, true);
        let x = if exp_safe(&z) {
            z.exp()
        } else {
            z.map(|_| f64::NAN)
        };
        if x.iter().any(|v| !v.is_finite()) {
            return Err(invalid!(
                "the exponential of the linear part of the model is not finite for a step of {h} s; \
                 check the parameter values and units"
            ));
        }
        Ok(Level {
            g_scale: self.atol / (h * self.dt),
            ..Self::blocks(&x, 0, h)
        })
    }

    /// Derivatives of the propagators of a step `h` along a change `(daq, dav)` of the
    /// linear part: the upper right block of `exp([[Z, dZ], [0, Z]])` (Fréchet derivative
    /// of the exponential).
    fn propagator_derivatives(&self, h: f64, daq: &Mat<N>, dav: &Mat<N>) -> Level<N> {
        let z = Self::augmented(&self.aq, &self.av, h, true);
        let dz = Self::augmented(daq, dav, h, false);
        let s = 4 * N;
        let mut big = DMatrix::<f64>::zeros(2 * s, 2 * s);
        big.view_mut((0, 0), (s, s)).copy_from(&z);
        big.view_mut((s, s), (s, s)).copy_from(&z);
        big.view_mut((0, s), (s, s)).copy_from(&dz);
        // NaN propagators make the sensitivities non-finite, which the caller reports
        let x = if exp_safe(&big) {
            big.exp()
        } else {
            big.map(|_| f64::NAN)
        };
        Self::blocks(&x, s, h)
    }

    /// `g(q, q̇)`: accelerations of the non-affine terms.
    #[inline(always)]
    pub fn g(&self, q: &V<N>, v: &V<N>) -> V<N> {
        let mut g = V::<N>::zeros();
        if let Some(c) = &self.coulomb {
            for d in 0..N {
                // the loop's `0 + c_d·s` without the `0 +` (one addition less on the loop's
                // critical path): the same value but for the sign of an exact zero
                g[d] = c[d] * self.law.sign_and_derivative(v[d]).0;
            }
            return g.component_mul(&self.inv_mass);
        }
        for t in &self.terms {
            let (x, xd) = t.basis.coordinates(q, v);
            g += t.dir * t.basis.local(x, xd, self.law).0;
        }
        g.component_mul(&self.inv_mass)
    }

    /// `(g, ∂g/∂q, ∂g/∂q̇)` in one pass over the terms.
    #[inline(always)]
    pub fn g_and_partials(&self, q: &V<N>, v: &V<N>) -> (V<N>, Mat<N>, Mat<N>) {
        let mut g = V::<N>::zeros();
        let mut dq = Mat::<N>::zeros();
        let mut dv = Mat::<N>::zeros();
        if let Some(c) = &self.coulomb {
            // a Coulomb term of dof d adds `c_d·s(v_d)` to g_d and `c_d·s'(v_d)` to ∂g_d/∂q̇_d;
            // the loop below adds the same to zeros, and ±0 everywhere else (its position
            // partials are 0): the same values, up to the sign of an exact zero
            for d in 0..N {
                let (s, ds) = self.law.sign_and_derivative(v[d]);
                g[d] = c[d] * s;
                dv[(d, d)] = c[d] * ds;
            }
        } else {
            self.accumulate_terms(q, v, &mut g, &mut dq, &mut dv);
        }
        for d in 0..N {
            for e in 0..N {
                dq[(d, e)] *= self.inv_mass[d];
                dv[(d, e)] *= self.inv_mass[d];
            }
        }
        (g.component_mul(&self.inv_mass), dq, dv)
    }

    /// The general case of [`Plant::g_and_partials`]: the sums over the terms.
    #[inline(always)]
    fn accumulate_terms(&self, q: &V<N>, v: &V<N>, g: &mut V<N>, dq: &mut Mat<N>, dv: &mut Mat<N>) {
        for t in &self.terms {
            let (x, xd) = t.basis.coordinates(q, v);
            let (phi, px, pv) = t.basis.local(x, xd, self.law);
            *g += t.dir * phi;
            *dq += t.outer * px;
            *dv += t.outer * pv;
        }
    }

    /// Whether `g`, with partials `(gq, gv)` at the end of a quick step of length `h`, is
    /// too stiff for that step. The quick step extrapolates the change of `g` from the
    /// previous step, a recurrence whose perturbations grow by about `h·|∂g/∂q̇|/2` per
    /// step: near rest the Coulomb sign's slope `Fc/(εM)` makes that factor exceed 1 for a
    /// sample period, and while the prediction can still pass the defect test, the computed
    /// trajectory then chatters and its derivatives (the sensitivities) grow without bound.
    /// There the implicit solve, stable for any slope, is used instead.
    #[inline(always)]
    fn stiff(gq: &Mat<N>, gv: &Mat<N>, h: f64) -> bool {
        h * (amax(gv.as_slice()) + h * amax(gq.as_slice())) >= 1.0
    }

    /// The input accelerations `b = M⁻¹ u` of the motor force `tau` (N).
    #[inline(always)]
    pub fn input(&self, tau: f64) -> V<N> {
        let mut b = V::<N>::zeros();
        b[0] = tau * self.inv_mass[0];
        b
    }

    /// Accelerations of the full direct model for the input accelerations `b` (= M⁻¹ u).
    #[inline(always)]
    pub fn accel(&self, q: &V<N>, v: &V<N>, b: &V<N>, g: &V<N>) -> V<N> {
        self.aq * q + self.av * v + self.a0 + b + g
    }

    /// One step of level `l` from `(q, v)` with `g_n = gn`, input accelerations `b`.
    ///
    /// Quick path: the change of `g` over the step is predicted from the previous step's
    /// (`c · Δg_prev`, `c` the ratio of the step lengths), the state follows from it,
    /// `x_1 = E x + h φ1 (b + a0 + g_n) + h φ2 Δg_pred`, and `g_1 = g(x_1)` is evaluated
    /// there. When the prediction was right to a tenth of the tolerance (`g` nearly linear in
    /// time over the two steps), the step is taken; it is then the second-order scheme with
    /// the end value extrapolated, and costs one evaluation of `g`. Otherwise the implicit
    /// equation is solved by Newton and the midpoint defect decides. Either way the step ends
    /// with `g_1 = g(x_1)` exactly, so the next step and the output accelerations use the
    /// direct model at the state itself.
    #[inline(always)]
    pub fn try_step(&self, l: usize, q: &V<N>, v: &V<N>, gn: &V<N>, b: &V<N>) -> Step<N> {
        let lv = self.level(l);
        let h = lv.h;
        let c = h * self.last_inv_h.get();
        let f = b + self.a0 + gn;
        let qp = lv.eqq * q + lv.eqv * v + lv.p1q * f;
        let vp = lv.evq * q + lv.evv * v + lv.p1v * f;
        let pred = self.last_dg.get() * c;
        let q1 = qp + lv.p2q * pred;
        let v1 = vp + lv.p2v * pred;
        let (g1, gq, gv) = self.g_and_partials(&q1, &v1);
        let scale = lv.g_scale;
        let missed = amax((g1 - gn - pred).as_slice());
        if missed <= 0.1 * scale || missed > EARLY_HALVING * scale {
            let stiff = Self::stiff(&gq, &gv, h);
            let step = Step {
                q1,
                v1,
                g1,
                gq,
                gv,
                dw: pred,
                err: 0.0,
                quick: true,
                c,
                f,
            };
            if missed <= 0.1 * scale && !stiff {
                return step;
            }
            if missed > EARLY_HALVING * scale && !stiff && l < MAX_LEVEL {
                return Step {
                    err: f64::INFINITY,
                    quick: false,
                    ..step
                };
            }
        }
        self.implicit_step(l, q, v, gn, f, qp, vp, g1 - gn, scale)
    }

    /// The Newton solve and the midpoint test of [`Plant::try_step`], from the fixed-point
    /// iterate `dw = g(x(Δg_pred)) − g_n`: out of line (the quick path stays compact), in
    /// the build the closed loop runs in (see [`super::driver::simd`]). Called from inside
    /// the loop's AVX2 build, it calls its AVX2 twin directly: going through `simd` (a
    /// baseline function) would cost a call and two AVX/SSE transitions per solve (3 % of a
    /// simulation, measured), hence the pair of wrappers here and in `subdivide`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn implicit_step(
        &self,
        l: usize,
        q: &V<N>,
        v: &V<N>,
        gn: &V<N>,
        f: V<N>,
        qp: V<N>,
        vp: V<N>,
        dw: V<N>,
        scale: f64,
    ) -> Step<N> {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::wide_simd() {
            // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
            return unsafe { self.implicit_avx2(l, q, v, gn, f, qp, vp, dw, scale) };
        }
        self.implicit_base(l, q, v, gn, f, qp, vp, dw, scale)
    }

    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn implicit_base(
        &self,
        l: usize,
        q: &V<N>,
        v: &V<N>,
        gn: &V<N>,
        f: V<N>,
        qp: V<N>,
        vp: V<N>,
        dw: V<N>,
        scale: f64,
    ) -> Step<N> {
        self.implicit_body(l, q, v, gn, f, qp, vp, dw, scale)
    }

    /// # Safety
    /// The processor must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn implicit_avx2(
        &self,
        l: usize,
        q: &V<N>,
        v: &V<N>,
        gn: &V<N>,
        f: V<N>,
        qp: V<N>,
        vp: V<N>,
        dw: V<N>,
        scale: f64,
    ) -> Step<N> {
        self.implicit_body(l, q, v, gn, f, qp, vp, dw, scale)
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn implicit_body(
        &self,
        l: usize,
        q: &V<N>,
        v: &V<N>,
        gn: &V<N>,
        f: V<N>,
        qp: V<N>,
        vp: V<N>,
        mut dw: V<N>,
        scale: f64,
    ) -> Step<N> {
        let lv = self.level(l);
        self.implicit.set(self.implicit.get() + 1);
        let small = 1e-2 * scale;
        let mut step = Step {
            q1: qp,
            v1: vp,
            g1: *gn,
            gq: Mat::<N>::zeros(),
            gv: Mat::<N>::zeros(),
            dw,
            err: f64::INFINITY,
            quick: false,
            c: 0.0,
            f,
        };
        let mut converged = false;
        for _ in 0..MAX_NEWTON {
            let q1 = qp + lv.p2q * dw;
            let v1 = vp + lv.p2v * dw;
            let (g1, gq, gv) = self.g_and_partials(&q1, &v1);
            let r = g1 - gn - dw;
            (step.q1, step.v1, step.g1, step.gq, step.gv, step.dw) = (q1, v1, g1, gq, gv, dw);
            if amax(r.as_slice()) <= small {
                converged = true;
                break;
            }
            let jac = gq * lv.p2q + gv * lv.p2v - Mat::<N>::identity();
            match jac.try_inverse() {
                Some(ji) => dw -= ji * r,
                None => break,
            }
        }
        if converged {
            // Midpoint defect of the linear interpolation of g.
            let lm = self.level(l + 1);
            let half = dw * 0.5;
            let qm = lm.eqq * q + lm.eqv * v + lm.p1q * f + lm.p2q * half;
            let vm = lm.evq * q + lm.evv * v + lm.p1v * f + lm.p2v * half;
            let d = self.g(&qm, &vm) - gn - half;
            step.err = amax(d.as_slice()) * (2.0 / 3.0) / scale;
        }
        step
    }

    /// Advances `(q, v, g)` over one step of level `l`, halving it while the error is too
    /// large; `hook` sees every accepted step.
    ///
    /// `target`: the level a Coulomb sign reversing ahead needs (see [`Plant::kink_level`]),
    /// 0 for none. A step of a coarser level that the reversal falls inside is halved at
    /// once, without the attempt the step control would reject: the sign jumps by `2 Fc/M`
    /// within a few microseconds, which a step's linear interpolation of `g` misses by half
    /// the jump whatever its length, so the rejected step's error ratio says how many
    /// halvings the step around the reversal takes.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn advance<H: FnMut(&Self, &Accepted<N>) -> Result<()>>(
        &mut self,
        l: usize,
        q: &mut V<N>,
        v: &mut V<N>,
        g: &mut V<N>,
        b: &V<N>,
        target: usize,
        hook: &mut H,
    ) -> Result<()> {
        if target > l && self.reversal_ahead(l, q, v, g, b) {
            return self.subdivide(l, q, v, g, b, target, hook);
        }
        let step = self.try_step(l, q, v, g, b);
        if step.err <= 1.0 || l == MAX_LEVEL {
            let accepted = Accepted {
                l,
                q: *q,
                v: *v,
                step,
            };
            hook(self, &accepted)?;
            self.last_dg.set(step.g1 - *g);
            self.last_inv_h.set(self.level(l).inv_h);
            *q = step.q1;
            *v = step.v1;
            *g = step.g1;
            self.steps += 1;
            return Ok(());
        }
        let target = self.kink_level(l, q, v, g, b, &step);
        self.subdivide(l, q, v, g, b, target, hook)
    }

    /// Whether the velocity of a dof with Coulomb friction, moving (beyond 2 ε) and
    /// slowing down, reaches zero within the first nine tenths of a step of level `l` from
    /// `(q, v)` at its present acceleration: a reversal of the sign inside the step.
    #[inline(always)]
    fn reversal_ahead(&self, l: usize, q: &V<N>, v: &V<N>, g: &V<N>, b: &V<N>) -> bool {
        let reach = 0.9 * self.level(l).h;
        let moving = 2.0 * self.law.law().eps;
        let a = self.accel(q, v, b, g);
        (0..N).any(|d| {
            let friction = self.coulomb.as_ref().is_none_or(|c| c[d] != 0.0);
            friction && v[d] * a[d] < 0.0 && v[d].abs() > moving && v[d].abs() < reach * a[d].abs()
        })
    }

    /// The level the rejected `step` of level `l` from `(q, v)` asks for when a Coulomb sign
    /// reverses inside it ([`Plant::reversal_ahead`]), else 0. There the defect of `g`'s
    /// linear interpolation is half the sign's jump at any step length, so the error ratio
    /// falls as `h`: `l + ⌈log2 err⌉` is the level of the step that passes. A step halved
    /// early ([`EARLY_HALVING`]) has no error ratio: the midpoint defect is then about half
    /// the missed prediction, `err ≈ missed / (3 g_scale)`, and one level less is asked.
    #[inline(always)]
    fn kink_level(&self, l: usize, q: &V<N>, v: &V<N>, g: &V<N>, b: &V<N>, step: &Step<N>) -> usize {
        let (err, short) = if step.err.is_finite() {
            (step.err, 0)
        } else {
            let missed = amax((step.g1 - g - step.dw).as_slice());
            (missed / (3.0 * self.level(l).g_scale), 1)
        };
        if err.is_nan() || err < 4.0 || !self.reversal_ahead(l, q, v, g, b) {
            return 0;
        }
        (l + err.log2().ceil().min(MAX_LEVEL as f64) as usize - short).min(MAX_LEVEL)
    }

    /// A rejected step's two halves: out of line, in the build the closed loop runs in.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn subdivide<H: FnMut(&Self, &Accepted<N>) -> Result<()>>(
        &mut self,
        l: usize,
        q: &mut V<N>,
        v: &mut V<N>,
        g: &mut V<N>,
        b: &V<N>,
        target: usize,
        hook: &mut H,
    ) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::wide_simd() {
            // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
            return unsafe { self.subdivide_avx2(l, q, v, g, b, target, hook) };
        }
        self.subdivide_base(l, q, v, g, b, target, hook)
    }

    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn subdivide_base<H: FnMut(&Self, &Accepted<N>) -> Result<()>>(
        &mut self,
        l: usize,
        q: &mut V<N>,
        v: &mut V<N>,
        g: &mut V<N>,
        b: &V<N>,
        target: usize,
        hook: &mut H,
    ) -> Result<()> {
        self.subdivide_body(l, q, v, g, b, target, hook)
    }

    /// # Safety
    /// The processor must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn subdivide_avx2<H: FnMut(&Self, &Accepted<N>) -> Result<()>>(
        &mut self,
        l: usize,
        q: &mut V<N>,
        v: &mut V<N>,
        g: &mut V<N>,
        b: &V<N>,
        target: usize,
        hook: &mut H,
    ) -> Result<()> {
        self.subdivide_body(l, q, v, g, b, target, hook)
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn subdivide_body<H: FnMut(&Self, &Accepted<N>) -> Result<()>>(
        &mut self,
        l: usize,
        q: &mut V<N>,
        v: &mut V<N>,
        g: &mut V<N>,
        b: &V<N>,
        target: usize,
        hook: &mut H,
    ) -> Result<()> {
        self.rejected += 1;
        self.ensure(l + 2)?;
        self.advance(l + 1, q, v, g, b, target, hook)?;
        self.advance(l + 1, q, v, g, b, target, hook)
    }
}

/// One attempted step: the end state and `g` there, the change of `g` the state was
/// computed with, the error ratio (≤ 1: accept), and what the tangent needs to
/// differentiate it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Step<const N: usize> {
    pub q1: V<N>,
    pub v1: V<N>,
    /// `g(q1, v1)` and its partials `(∂g/∂q, ∂g/∂q̇)` there.
    pub g1: V<N>,
    pub gq: Mat<N>,
    pub gv: Mat<N>,
    /// The change of `g` in the state formula: the prediction (quick step) or the Newton
    /// iterate (implicit step).
    pub dw: V<N>,
    pub err: f64,
    /// Quick step (`dw = c · Δg_prev`) rather than the implicit solve.
    pub quick: bool,
    /// Ratio of this step's length to the previous one's (quick step).
    pub c: f64,
    /// `b + a0 + g_n`.
    pub f: V<N>,
}

/// An accepted step of level `l` from `(q, v)`, as the sensitivities differentiate it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Accepted<const N: usize> {
    pub l: usize,
    pub q: V<N>,
    pub v: V<N>,
    pub step: Step<N>,
}

/// The exponential integrator as a [`Stepper`]: the plant and `g` at the current state.
pub(super) struct Exponential<const N: usize, L: Law = FrictionLaw> {
    plant: Plant<N, L>,
    g: V<N>,
}

impl<const N: usize, L: Law> Exponential<N, L> {
    /// The integrator of `model` with parameters `chi` and the model's friction law `law`.
    pub fn new(model: &Model<N>, chi: &[f64], law: L, qr: &[f64], opts: &SimOptions) -> Result<Self> {
        let mut plant = Plant::new(model, chi, law, opts.dt, step_tolerance(qr, opts.tol))?;
        plant.ensure(0)?;
        plant.ensure(1)?;
        Ok(Self {
            plant,
            g: V::<N>::zeros(),
        })
    }

    pub fn stats(&self) -> StepStats {
        StepStats {
            steps: self.plant.steps,
            rejected: self.plant.rejected,
            implicit: self.plant.implicit.get(),
        }
    }
}

impl<const N: usize, L: Law> Stepper<N> for Exponential<N, L> {
    type Ctx = Plant<N, L>;
    type Step = Accepted<N>;
    const DIVERGENCE_HINT: &'static str = "";

    fn ctx(&self) -> &Plant<N, L> {
        &self.plant
    }

    fn start(&mut self, q: &V<N>, v: &V<N>) {
        self.g = self.plant.g(q, v);
    }

    /// Every step ends with `g` evaluated at its end state, so this is the direct model
    /// at the state itself.
    #[inline(always)]
    fn accel(&self, q: &V<N>, v: &V<N>, tau: f64) -> V<N> {
        self.plant.accel(q, v, &self.plant.input(tau), &self.g)
    }

    #[inline(always)]
    fn advance<T: Tangent<N, Self>>(
        &mut self,
        q: &mut V<N>,
        v: &mut V<N>,
        tau: f64,
        tangent: &mut T,
    ) -> Result<()> {
        let b = self.plant.input(tau);
        self.plant
            .advance(0, q, v, &mut self.g, &b, 0, &mut |plant, step| {
                tangent.step(plant, step)
            })
    }
}

/// Whether nalgebra's `exp` can be trusted with `z`: its scaling and squaring takes
/// `log2` of norms of powers of `z` up to the tenth, and an infinite one (a non-finite
/// entry, or entries beyond 1e30, e.g. a stiffness over a mass beyond f64) asks for
/// 2^64 squarings, a loop without end. Such a matrix has no useful exponential anyway.
fn exp_safe(z: &DMatrix<f64>) -> bool {
    let norm1 = z
        .column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    norm1.is_finite() && norm1 <= 1e30 && z.iter().all(|v| v.is_finite())
}

/// The largest absolute value of `x` (0 for none; NaN entries are skipped, as by
/// nalgebra's `amax`): a plain loop, which the compiler unrolls for the small static
/// sizes here (nalgebra's generic reduction does not).
#[inline(always)]
fn amax(x: &[f64]) -> f64 {
    let mut m = 0.0;
    for v in x {
        let a = v.abs();
        if a > m {
            m = a;
        }
    }
    m
}

/// Position tolerance of one step (m): `tol` times the reference stroke (1 m if flat).
pub(super) fn step_tolerance(qr: &[f64], tol: f64) -> f64 {
    let (lo, hi) = qr.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
        (a.min(x), b.max(x))
    });
    let stroke = hi - lo;
    tol * if stroke > 0.0 { stroke } else { 1.0 }
}

/// Diagnostics of an exponential-integrator run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Steps taken.
    pub steps: usize,
    /// Steps rejected and halved.
    pub rejected: usize,
    /// Steps (taken or rejected) that needed the implicit solve.
    pub implicit: usize,
}

/// How a parameter enters the split model.
#[derive(Clone, Copy, Debug)]
enum Role {
    /// A mass of dof `dof`: scales the whole row `dof` of the direct model.
    Inertia { dof: usize },
    /// An affine term: enters `A` and `a0`.
    Affine(Basis),
    /// Any other term: enters `g`.
    Nonlinear(Basis),
}

/// Forward sensitivities of the exponential integrator: the exact derivatives of the
/// computed discrete trajectory with respect to the parameters (every accepted step
/// differentiated, the propagators by the Fréchet derivative of the matrix exponential,
/// the implicit solve by the implicit function theorem). The quantizer is treated as the
/// identity and the step sequence as fixed.
pub(super) struct Sens<const N: usize> {
    p: usize,
    n: usize,
    role: Vec<Role>,
    /// `∂(M⁻¹)/∂χ_j` (diagonal).
    dinv: Vec<V<N>>,
    /// `∂a0/∂χ_j`.
    da0: Vec<V<N>>,
    /// `∂(aq, av)/∂χ_j`, `None` where zero.
    da: Vec<Option<(Mat<N>, Mat<N>)>>,
    /// Propagator derivatives per level and parameter, computed on first use.
    dlevels: Vec<Option<Vec<Option<Level<N>>>>>,
    sq: Vec<V<N>>,
    sv: Vec<V<N>>,
    /// `∂g_n/∂χ_j`.
    dg: Vec<V<N>>,
    /// Tangent of the change of `g` over the last accepted step.
    dlast: Vec<V<N>>,
    gchi: Vec<V<N>>,
    tau: f64,
    /// The command's sensitivities.
    pub cmd: CommandSens,
    pub dq: Vec<f64>,
}

impl<const N: usize> Sens<N> {
    pub fn new(model: &Model<N>, n: usize, delay: usize) -> Result<Self> {
        let p = model.n_params();
        let role = model
            .basis()
            .iter()
            .map(|b| match *b {
                Basis::Inertia { dof } => Role::Inertia { dof },
                b if b.is_affine() => Role::Affine(b),
                b => Role::Nonlinear(b),
            })
            .collect();
        Ok(Self {
            p,
            n,
            role,
            dinv: vec![V::<N>::zeros(); p],
            da0: vec![V::<N>::zeros(); p],
            da: vec![None; p],
            dlevels: vec![None; MAX_LEVEL + 2],
            sq: vec![V::<N>::zeros(); p],
            sv: vec![V::<N>::zeros(); p],
            dg: vec![V::<N>::zeros(); p],
            dlast: vec![V::<N>::zeros(); p],
            gchi: vec![V::<N>::zeros(); p],
            tau: 0.0,
            cmd: CommandSens::new(p, n, delay)?,
            dq: filled(N * p * n, 0.0, "the position sensitivities")?,
        })
    }

    /// `∂g/∂χ_j` at `(q, v)` where `g = ge`, into `self.gchi`.
    fn g_chi<L: Law>(&mut self, plant: &Plant<N, L>, q: &V<N>, v: &V<N>, ge: &V<N>) {
        let zero = V::<N>::zeros();
        for j in 0..self.p {
            self.gchi[j] = match self.role[j] {
                Role::Inertia { dof } => {
                    let mut x = V::<N>::zeros();
                    x[dof] = -ge[dof] * plant.inv_mass[dof];
                    x
                }
                Role::Affine(_) => zero,
                Role::Nonlinear(b) => {
                    let mut f = V::<N>::zeros();
                    b.accumulate(1.0, q, v, &zero, plant.law, &mut f);
                    -f.component_mul(&plant.inv_mass)
                }
            };
        }
    }

    fn dlevel<L: Law>(&mut self, plant: &Plant<N, L>, l: usize) {
        if self.dlevels[l].is_none() {
            let h = plant.level(l).h;
            let d = self
                .da
                .iter()
                .map(|x| {
                    x.as_ref()
                        .map(|(daq, dav)| plant.propagator_derivatives(h, daq, dav))
                })
                .collect();
            self.dlevels[l] = Some(d);
        }
    }
}

impl<const N: usize, L: Law> Tangent<N, Exponential<N, L>> for Sens<N> {
    fn start(&mut self, plant: &Plant<N, L>, q: &V<N>, v: &V<N>) {
        let g0 = &plant.g(q, v);
        let zero = V::<N>::zeros();
        for j in 0..self.p {
            match self.role[j] {
                Role::Inertia { dof } => {
                    let m = 1.0 / plant.inv_mass[dof];
                    self.dinv[j][dof] = -1.0 / (m * m);
                    self.da0[j][dof] = -plant.a0[dof] / m;
                    let mut daq = Mat::<N>::zeros();
                    let mut dav = Mat::<N>::zeros();
                    for e in 0..N {
                        daq[(dof, e)] = -plant.aq[(dof, e)] / m;
                        dav[(dof, e)] = -plant.av[(dof, e)] / m;
                    }
                    self.da[j] = Some((daq, dav));
                }
                Role::Affine(b) => {
                    let force = |q: &V<N>, v: &V<N>| {
                        let mut f = V::<N>::zeros();
                        b.accumulate(1.0, q, v, &zero, plant.law, &mut f);
                        f
                    };
                    let c = force(&zero, &zero);
                    self.da0[j] = -c.component_mul(&plant.inv_mass);
                    let mut daq = Mat::<N>::zeros();
                    let mut dav = Mat::<N>::zeros();
                    for e in 0..N {
                        let mut unit = zero;
                        unit[e] = 1.0;
                        let fq = force(&unit, &zero) - c;
                        let fv = force(&zero, &unit) - c;
                        for d in 0..N {
                            daq[(d, e)] = -plant.inv_mass[d] * fq[d];
                            dav[(d, e)] = -plant.inv_mass[d] * fv[d];
                        }
                    }
                    if daq.amax() > 0.0 || dav.amax() > 0.0 {
                        self.da[j] = Some((daq, dav));
                    }
                }
                Role::Nonlinear(_) => {}
            }
        }
        self.g_chi(plant, q, v, g0);
        self.dg.copy_from_slice(&self.gchi);
    }

    fn command(&mut self, k: usize, law: &TransferFunction, active: bool, tau: f64) {
        self.tau = tau;
        let sq = &self.sq;
        self.cmd.command(k, law, active, |j| sq[j][0]);
    }

    fn record(&mut self, k: usize) {
        let (p, n) = (self.p, self.n);
        for d in 0..N {
            for j in 0..p {
                self.dq[(d * p + j) * n + k] = self.sq[j][d];
            }
        }
    }

    fn step(&mut self, plant: &Plant<N, L>, acc: &Accepted<N>) -> Result<()> {
        let (l, q, v, st) = (acc.l, &acc.q, &acc.v, &acc.step);
        self.dlevel(plant, l);
        let lv = *plant.level(l);
        let (gq, gv) = (st.gq, st.gv);
        let jinv = if st.quick {
            Mat::<N>::identity()
        } else {
            (Mat::<N>::identity() - gq * lv.p2q - gv * lv.p2v)
                .try_inverse()
                .ok_or_else(|| {
                    Error::Simulation("singular implicit step in the sensitivity equations".into())
                })?
        };
        self.g_chi(plant, &st.q1, &st.v1, &st.g1);
        let dl = self.dlevels[l].as_ref().expect("computed above");
        for j in 0..self.p {
            let mut df = self.da0[j] + self.dg[j];
            df[0] += self.dinv[j][0] * self.tau + plant.inv_mass[0] * self.cmd.dtau[j];
            let (sq, sv) = (self.sq[j], self.sv[j]);
            // tangent of x_p = E x + h φ1 f, plus that of h φ2 along the step's Δg
            let mut yq = lv.eqq * sq + lv.eqv * sv + lv.p1q * df;
            let mut yv = lv.evq * sq + lv.evv * sv + lv.p1v * df;
            if let Some(d) = &dl[j] {
                yq += d.eqq * q + d.eqv * v + d.p1q * st.f + d.p2q * st.dw;
                yv += d.evq * q + d.evv * v + d.p1v * st.f + d.p2v * st.dw;
            }
            let (q1, v1, dg1) = if st.quick {
                // x1 = x_p + h φ2 c Δg_prev, g1 = g(x1)
                let dpred = self.dlast[j] * st.c;
                let q1 = yq + lv.p2q * dpred;
                let v1 = yv + lv.p2v * dpred;
                (q1, v1, gq * q1 + gv * v1 + self.gchi[j])
            } else {
                // x1 = x_p + h φ2 (g1 − g_n), g1 = g(x1): implicit function theorem
                yq -= lv.p2q * self.dg[j];
                yv -= lv.p2v * self.dg[j];
                let dw = jinv * (gq * yq + gv * yv + self.gchi[j]);
                (yq + lv.p2q * dw, yv + lv.p2v * dw, dw)
            };
            self.dlast[j] = dg1 - self.dg[j];
            self.sq[j] = q1;
            self.sv[j] = v1;
            self.dg[j] = dg1;
        }
        Ok(())
    }
}
