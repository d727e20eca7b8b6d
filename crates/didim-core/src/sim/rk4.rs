//! Classical RK4 with `substeps` equal substeps per sample period ([`Integrator::Rk4`],
//! the reference), and the forward sensitivities integrated with the same stages.
//!
//! [`Integrator::Rk4`]: super::Integrator::Rk4

use super::driver::{CommandSens, Stepper, Tangent, V};
use super::expint::Plant;
use super::SimOptions;
use crate::controller::TransferFunction;
use crate::error::{filled, Result};
use crate::model::{FrictionLaw, Law, Model};

/// One RK4 stage of the state: position, velocity, acceleration.
pub(super) type Stage<const N: usize> = (V<N>, V<N>, V<N>);

/// One RK4 substep of length `h`: the state's four stages.
pub(super) struct Substep<const N: usize> {
    pub stages: [Stage<N>; 4],
    pub h: f64,
}

/// RK4 as a [`Stepper`]. The accelerations come from the model split into its affine
/// part and the rest ([`Plant`]): per stage, a few small matrix products and the
/// nonlinear terms only.
pub(super) struct Rk4<'a, const N: usize, L: Law = FrictionLaw> {
    pub model: &'a Model<N>,
    pub chi: &'a [f64],
    pub plant: Plant<N, L>,
    h: f64,
    substeps: usize,
}

impl<'a, const N: usize, L: Law> Rk4<'a, N, L> {
    /// RK4 on `model` with parameters `chi` and the model's friction law `law`.
    pub fn new(model: &'a Model<N>, chi: &'a [f64], law: L, opts: &SimOptions) -> Result<Self> {
        Ok(Self {
            model,
            chi,
            plant: Plant::new(model, chi, law, opts.dt, 0.0)?,
            h: opts.dt / opts.substeps as f64,
            substeps: opts.substeps,
        })
    }
}

impl<'a, const N: usize, L: Law> Stepper<N> for Rk4<'a, N, L> {
    type Ctx = Self;
    type Step = Substep<N>;
    const DIVERGENCE_HINT: &'static str = ", and try more substeps";

    fn ctx(&self) -> &Self {
        self
    }

    fn start(&mut self, _: &V<N>, _: &V<N>) {}

    #[inline(always)]
    fn accel(&self, q: &V<N>, v: &V<N>, tau: f64) -> V<N> {
        self.plant
            .accel(q, v, &self.plant.input(tau), &self.plant.g(q, v))
    }

    #[inline(always)]
    fn advance<T: Tangent<N, Self>>(
        &mut self,
        q: &mut V<N>,
        v: &mut V<N>,
        tau: f64,
        tangent: &mut T,
    ) -> Result<()> {
        let h = self.h;
        let b = self.plant.input(tau); // held over the period
                                       // the state in locals over the period (registers), not behind the references
        let (mut q0, mut v0) = (*q, *v);
        for _ in 0..self.substeps {
            let plant = &self.plant;
            let accel = |q: &V<N>, v: &V<N>| plant.accel(q, v, &b, &plant.g(q, v));
            let (q1, v1) = (q0, v0);
            let a1 = accel(&q1, &v1);
            let (q2, v2) = (q1 + v1 * (0.5 * h), v1 + a1 * (0.5 * h));
            let a2 = accel(&q2, &v2);
            let (q3, v3) = (q1 + v2 * (0.5 * h), v1 + a2 * (0.5 * h));
            let a3 = accel(&q3, &v3);
            let (q4, v4) = (q1 + v3 * h, v1 + a3 * h);
            let a4 = accel(&q4, &v4);
            let step = Substep {
                stages: [(q1, v1, a1), (q2, v2, a2), (q3, v3, a3), (q4, v4, a4)],
                h,
            };
            tangent.step(self, &step)?;
            q0 += (v1 + (v2 + v3) * 2.0 + v4) * (h / 6.0);
            v0 += (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0);
        }
        (*q, *v) = (q0, v0);
        Ok(())
    }
}

/// Sensitivities `Sq = ∂q/∂χ`, `Sv = ∂q̇/∂χ` (dof × parameter, flat `[d * p + j]`)
/// and the work buffers of their RK4 integration.
pub(super) struct Sensitivity<const N: usize> {
    p: usize,
    n: usize,
    sq: Vec<f64>,
    sv: Vec<f64>,
    /// The command's sensitivities.
    pub cmd: CommandSens,
    pub dq: Vec<f64>,
    // RK4 work buffers
    kq: [Vec<f64>; 4],
    kv: [Vec<f64>; 4],
    stage_q: Vec<f64>,
    stage_v: Vec<f64>,
    phi: Vec<f64>,
}

impl<const N: usize> Sensitivity<N> {
    pub fn new(p: usize, n: usize, delay: usize) -> Result<Self> {
        let z = vec![0.0; N * p];
        Ok(Self {
            p,
            n,
            sq: z.clone(),
            sv: z.clone(),
            cmd: CommandSens::new(p, n, delay)?,
            dq: filled(N * p * n, 0.0, "the position sensitivities")?,
            kq: [z.clone(), z.clone(), z.clone(), z.clone()],
            kv: [z.clone(), z.clone(), z.clone(), z.clone()],
            stage_q: z.clone(),
            stage_v: z.clone(),
            phi: z,
        })
    }
}

impl<'a, const N: usize> Tangent<N, Rk4<'a, N>> for Sensitivity<N> {
    fn start(&mut self, _: &Rk4<'a, N>, _: &V<N>, _: &V<N>) {}

    fn command(&mut self, k: usize, law: &TransferFunction, active: bool, _: f64) {
        let sq = &self.sq;
        self.cmd.command(k, law, active, |j| sq[j]);
    }

    fn record(&mut self, k: usize) {
        let (p, n) = (self.p, self.n);
        for d in 0..N {
            for j in 0..p {
                self.dq[(d * p + j) * n + k] = self.sq[d * p + j];
            }
        }
    }

    fn step(&mut self, ctx: &Rk4<'a, N>, s: &Substep<N>) -> Result<()> {
        let (model, chi, inv_mass) = (ctx.model, ctx.chi, &ctx.plant.inv_mass);
        let (stages, h) = (&s.stages, s.h);
        let p = self.p;
        let len = N * p;
        for (i, (q, v, a)) in stages.iter().enumerate() {
            if i == 0 {
                self.stage_q.copy_from_slice(&self.sq);
                self.stage_v.copy_from_slice(&self.sv);
            } else {
                let f = if i == 3 { h } else { 0.5 * h };
                for x in 0..len {
                    self.stage_q[x] = self.sq[x] + f * self.kq[i - 1][x];
                    self.stage_v[x] = self.sv[x] + f * self.kv[i - 1][x];
                }
            }
            let (aq, av) = model.accel_partials(chi, inv_mass, q, v);
            model.regressor_into(q, v, a, &mut self.phi);
            for d in 0..N {
                for j in 0..p {
                    let mut s = -self.phi[d * p + j] * inv_mass[d];
                    for e in 0..N {
                        s += aq[(d, e)] * self.stage_q[e * p + j] + av[(d, e)] * self.stage_v[e * p + j];
                    }
                    if d == 0 {
                        s += inv_mass[0] * self.cmd.dtau[j];
                    }
                    self.kv[i][d * p + j] = s;
                    self.kq[i][d * p + j] = self.stage_v[d * p + j];
                }
            }
        }
        for x in 0..len {
            self.sq[x] += h / 6.0 * (self.kq[0][x] + 2.0 * (self.kq[1][x] + self.kq[2][x]) + self.kq[3][x]);
            self.sv[x] += h / 6.0 * (self.kv[0][x] + 2.0 * (self.kv[1][x] + self.kv[2][x]) + self.kv[3][x]);
        }
        Ok(())
    }
}
